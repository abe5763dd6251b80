//! The player-facing commands run end to end through the `dlgs` binary on a REAL scene with
//! SYNTHETIC motion (no trained DLGStream model exists here): `synth`, `export` (PLY, SPZ,
//! frame sequences), `play` over a file and over stdin (and seeking with a GOP cache), `rd`
//! (CSV and plots), and output to a reader that goes away.

mod dlgs_binary;

use std::path::Path;
use std::process::{Command, Stdio};

use dlgs_binary::{dlgs, dlgs_fails, SCENE};

fn model(dir: &Path, gops: u32) -> String {
    let scene = dlgs_tests::data(SCENE);
    let out = dir.join(format!("model_{gops}.dlgs"));
    dlgs(&[
        "synth",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--gops",
        &gops.to_string(),
        "--gop-length",
        "20",
        "--key-interval",
        "5",
        "--residual-mode",
        "sequential",
        "--language",
    ]);
    out.to_str().unwrap().to_string()
}

#[test]
fn export_writes_frames_other_readers_load() {
    let tmp = tempfile::tempdir().unwrap();
    let m = model(tmp.path(), 2);
    let p = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    dlgs(&[
        "export",
        &m,
        "--t",
        "0.9",
        "--format",
        "spz",
        "-o",
        &p("f.spz"),
    ]);
    dlgs(&["export", &m, "--t", "0.9", "-o", &p("f.ply")]);
    dlgs(&["export", &m, "--t", "0.9", "--extras", "-o", &p("fx.ply")]);
    let spz = dlgs::interop::read_splat_file(Path::new(&p("f.spz"))).unwrap();
    let ply = dlgs::interop::read_splat_file(Path::new(&p("f.ply"))).unwrap();
    let plx = dlgs::interop::read_splat_file(Path::new(&p("fx.ply"))).unwrap();
    assert_eq!((spz.len(), ply.len()), (1971, 1971));
    assert!(!ply.has_language() && plx.has_language() && plx.lang_width == 9);
    let d = spz
        .positions
        .iter()
        .zip(&ply.positions)
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
        .fold(0.0, f32::max);
    assert!(d <= 0.5 / 4096.0 + 1e-6, "SPZ positions off by {d}");

    // A sequence at twice the file's rate: frames 10..20 of a 30 fps file at 60 fps.
    let out = dlgs(&[
        "export",
        &m,
        "--frames",
        "10..20",
        "--fps",
        "60",
        "--format",
        "spz",
        "-o",
        &p("seq"),
    ]);
    assert!(out.contains("20 frames"), "{out}");
    let files = std::fs::read_dir(p("seq")).unwrap().count();
    assert_eq!(files, 20);
    let first = std::fs::read(p("seq/frame_00000.spz")).unwrap();
    let second = std::fs::read(p("seq/frame_00001.spz")).unwrap();
    assert_ne!(
        first, second,
        "interpolated frames differ from their neighbours"
    );

    let e = dlgs_fails(&["export", &m, "--frames", "0..99", "-o", &p("x")]);
    assert!(e.contains("the file has frames 0..40"), "{e}");
    let e = dlgs_fails(&[
        "export",
        &m,
        "--format",
        "spz",
        "--extras",
        "-o",
        &p("x.spz"),
    ]);
    assert!(e.contains("SPZ has no place for language"), "{e}");
}

#[test]
fn play_decodes_every_frame_from_a_file_and_from_stdin() {
    let tmp = tempfile::tempdir().unwrap();
    let m = model(tmp.path(), 3);
    let report = |text: &str| -> serde_json::Value { serde_json::from_str(text).unwrap() };
    let fast = report(&dlgs(&["play", &m, "--max-speed", "--json"]));
    assert_eq!(fast["frames"], 60);
    assert_eq!(fast["shown"], 60);
    assert_eq!(fast["dropped"], 0);
    assert_eq!(fast["gop_decode_ms"].as_array().unwrap().len(), 3);
    assert!(fast["sustained_decode_fps"].as_f64().unwrap() > 0.0);

    // Real time at 120 fps over stdin: every frame is either shown or counted as dropped.
    let child = Command::new(env!("CARGO_BIN_EXE_dlgs"))
        .args(["play", "-", "--fps", "120", "--json"])
        .stdin(Stdio::from(std::fs::File::open(&m).unwrap()))
        .output()
        .unwrap();
    assert!(
        child.status.success(),
        "{}",
        String::from_utf8_lossy(&child.stderr)
    );
    let live = report(&String::from_utf8_lossy(&child.stdout));
    let (shown, dropped) = (
        live["shown"].as_u64().unwrap(),
        live["dropped"].as_u64().unwrap(),
    );
    assert_eq!(shown + dropped, 60);
    assert!(shown > 0);
    let wall = live["wall_s"].as_f64().unwrap();
    assert!(
        (0.45..5.0).contains(&wall),
        "60 frames at 120 fps took {wall} s"
    );

    // A truncated stream: the frames before the damage play, then a clear error.
    let bytes = std::fs::read(&m).unwrap();
    let cut = tmp.path().join("cut.dlgs");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let e = dlgs_fails(&["play", cut.to_str().unwrap(), "--max-speed"]);
    assert!(e.contains("decoding the GOP of frame"), "{e}");
}

#[test]
fn rd_writes_csv_and_plots() {
    let tmp = tempfile::tempdir().unwrap();
    let m = model(tmp.path(), 1);
    let out = tmp.path().join("rd");
    let text = dlgs(&[
        "rd",
        &m,
        "--crf",
        "6,30",
        "--quality",
        "lossless,low",
        "--times",
        "2",
        "--orbit",
        "2",
        "--width",
        "160",
        "--height",
        "120",
        "-o",
        out.to_str().unwrap(),
    ]);
    let csv = std::fs::read_to_string(out.join("rd.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 4, "{csv}");
    let col = |r: &Vec<&str>, i: usize| r[i].parse::<f64>().unwrap();
    // Columns: quality,bits,crf,bytes,frames,bytes_per_frame,psnr_db,...
    for r in &rows {
        assert!(col(r, 3) > 0.0 && col(r, 4) == 20.0);
    }
    let find = |q: &str, crf: &str| rows.iter().find(|r| r[0] == q && r[2] == crf).unwrap();
    // Coarser settings cost quality and save bytes.
    assert!(col(find("lossless", "6"), 6) > col(find("low", "6"), 6));
    assert!(col(find("lossless", "6"), 3) > col(find("low", "6"), 3));
    assert!(col(find("lossless", "6"), 3) > col(find("lossless", "30"), 3));
    assert!(text.contains("rd.csv"));
    if text.contains("rd_bytes_psnr.png") {
        for f in ["rd_bytes_psnr.png", "rd_decode_psnr.png"] {
            let img = image::open(out.join(f)).unwrap();
            assert_eq!((img.width(), img.height()), (960, 640));
        }
    } else {
        eprintln!("no plot font on this machine (install fonts-dejavu-core): plots not checked");
    }
}

#[test]
fn encode_with_tiers_and_seek_with_a_gop_cache() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let out = tmp.path().join("tiered.dlgs");
    let out = out.to_str().unwrap();
    dlgs(&[
        "encode",
        scene,
        "-o",
        out,
        "--quality",
        "medium",
        "--tiers",
        "0.1,0.02",
    ]);
    let cmp = dlgs(&["compare", scene, out, "--json", "--orbit", "2"]);
    let psnr: f64 = serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
        .as_f64()
        .unwrap();
    assert!(psnr > 40.0, "{psnr} dB");
    // META records only the options that differ from their defaults.
    let info: serde_json::Value = serde_json::from_str(&dlgs(&["info", out, "--json"])).unwrap();
    assert_eq!(
        info["meta"]["settings"],
        serde_json::json!({"quality": "medium", "tiers": [0.1, 0.02]}),
        "{info}"
    );
    assert!(
        info["scene_chunks"]["META"].as_u64().unwrap() < 200,
        "{info}"
    );
    for (args, says) in [
        (vec!["--tiers", "0.01,0.1"], "must not increase"),
        (vec!["--tiers", "1.5"], "[0, 1)"),
        (vec!["--quality", "lossless", "--tiers", "0.1"], "lossy"),
    ] {
        let mut a = vec!["encode", scene, "-o", out];
        a.extend(&args);
        let err = dlgs_fails(&a);
        assert!(err.contains(says), "{args:?}: {err}");
    }
    let m = model(tmp.path(), 3);
    let seek = dlgs(&["seek", &m, "--count", "4", "--gop-cache", "3"]);
    assert!(seek.contains("GOP cache 3"), "{seek}");
}

#[test]
fn a_reader_that_goes_away_ends_the_output_quietly() {
    // `dlgs compare ... | head -0`: the pipe's reader is closed before dlgs prints. Printing then
    // fails with a broken pipe; dlgs must stop with status 141 (128 + SIGPIPE), not a panic.
    let scene = dlgs_tests::data(SCENE);
    let mut child = Command::new(env!("CARGO_BIN_EXE_dlgs"))
        .args(["compare", scene.to_str().unwrap(), scene.to_str().unwrap()])
        .args(["--orbit", "2"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(141), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

/// `--quantised-features` (TFEA codec 4, the web player's time features): re-encoding a model
/// writes codec 4 at the asked depth, smaller than exact features, rendering close to them; out
/// of range depths and the exact-features flag beside it are refused.
#[test]
fn quantised_features_re_encode_for_web_players() {
    let tmp = tempfile::tempdir().unwrap();
    let m = model(tmp.path(), 2);
    let p = |name: &str| tmp.path().join(name).to_str().unwrap().to_string();
    let (exact, q8) = (p("exact.dlgs"), p("q8.dlgs"));
    dlgs(&["encode", &m, "-o", &exact, "--exact-features"]);
    dlgs(&["encode", &m, "-o", &q8, "--quantised-features", "8"]);
    let info = |f: &str| -> serde_json::Value {
        serde_json::from_str(&dlgs(&["info", f, "--json"])).unwrap()
    };
    let (ie, iq) = (info(&exact), info(&q8));
    assert!(
        iq["time_features"].as_str().unwrap().contains("codec 4"),
        "{iq}"
    );
    let tfea = |i: &serde_json::Value| i["chunk_bytes_by_type"]["TFEA"].as_u64().unwrap();
    assert!(
        tfea(&iq) * 2 < tfea(&ie),
        "codec 4 {} vs exact {}",
        tfea(&iq),
        tfea(&ie)
    );
    let cmp = dlgs(&[
        "compare", &exact, &q8, "--json", "--orbit", "2", "--t", "0.37",
    ]);
    let psnr: f64 = serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
        .as_f64()
        .unwrap();
    assert!(psnr > 50.0, "{psnr} dB");
    for bad in ["5", "13"] {
        let err = dlgs_fails(&["encode", &m, "-o", &q8, "--quantised-features", bad]);
        assert!(
            err.contains("6..=12") || err.contains("6..12"),
            "{bad}: {err}"
        );
    }
    let err = dlgs_fails(&[
        "encode",
        &m,
        "-o",
        &q8,
        "--quantised-features",
        "--exact-features",
    ]);
    assert!(err.contains("cannot be used with"), "{err}");
}
