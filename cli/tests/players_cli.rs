//! The player-facing commands run end to end through the `dlgs` binary on a REAL scene with
//! SYNTHETIC motion (no trained DLGStream model exists here): `synth`, `export` (PLY, SPZ,
//! frame sequences), `play` over a file and over stdin, and `rd` (CSV and plots).

use std::path::Path;
use std::process::{Command, Stdio};

const SCENE: &str = "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply";

fn dlgs(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_dlgs"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "dlgs {}: {text}{}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

fn dlgs_fails(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_dlgs"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    assert!(!out.status.success(), "dlgs {} should fail", args.join(" "));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

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
fn encode_octree_positions_by_default_and_grid_positions_on_request() {
    // Format 1.10: the default codes static positions as an octree (CSOG layout 2);
    // `--grid-positions` keeps them in the grid (layout 0). Same quantised values, so both
    // render alike; the octree file is smaller on this real scene.
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let path = |n: &str| tmp.path().join(n).to_str().unwrap().to_owned();
    let (octree, grid) = (path("octree.dlgs"), path("grid.dlgs"));
    dlgs(&["encode", scene, "-o", &octree, "--quality", "medium"]);
    let g = ["encode", scene, "-o", &grid, "--quality", "medium"];
    dlgs(&[&g[..], &["--grid-positions"]].concat());
    let size = |p: &str| std::fs::metadata(p).unwrap().len();
    assert!(
        size(&octree) < size(&grid),
        "{} vs {}",
        size(&octree),
        size(&grid)
    );
    let psnr = |p: &str| -> f64 {
        let cmp = dlgs(&["compare", scene, p, "--json", "--orbit", "2"]);
        serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
            .as_f64()
            .unwrap()
    };
    let (a, b) = (psnr(&octree), psnr(&grid));
    assert!((a - b).abs() < 0.05 && a > 45.0, "{a} vs {b} dB");
    let err = dlgs_fails(&[&g[..], &["--sort-passes", "2"]].concat());
    assert!(err.contains("--grid-positions"), "{err}");
    dlgs(&[&g[..], &["--grid-positions", "--sort-passes", "2"]].concat());
    // Format 1.11: octree files are layout 3 with coarse rotations at factor 1 by default;
    // at factor 8 most of this scene's Gaussians turn coarser, so the file shrinks and the
    // image moves a little. Factor 0 writes layout 2.
    let coarse = path("coarse.dlgs");
    let c = ["encode", scene, "-o", &coarse, "--quality", "medium"];
    dlgs(&[&c[..], &["--coarse-rotations", "8"]].concat());
    assert!(
        size(&coarse) < size(&octree),
        "{} vs {}",
        size(&coarse),
        size(&octree)
    );
    let p = psnr(&coarse);
    assert!(p < a && p > a - 6.0, "{p} vs {a} dB");
    dlgs(&[&c[..], &["--coarse-rotations", "0"]].concat());
    let err = dlgs_fails(&[&g[..], &["--grid-positions", "--coarse-rotations", "1"]].concat());
    assert!(err.contains("octree positions"), "{err}");
    let err = dlgs_fails(&[&c[..], &["--coarse-rotations=-1"]].concat());
    assert!(err.contains("factor >= 0"), "{err}");
}

#[test]
fn fast_decode_codes_the_same_levels_without_mixed_contexts() {
    // `--fast-decode` leaves codec 5's mixed modes out: on this real scene at `high` the
    // default takes them (the file is smaller) and both decode to the same Gaussians, octree
    // positions and grid positions (layout 1 then, one part) alike.
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let path = |n: &str| tmp.path().join(n).to_str().unwrap().to_owned();
    let size = |p: &str| std::fs::metadata(p).unwrap().len();
    let ply = |f: &str| {
        let p = format!("{f}.ply");
        dlgs(&["decode", f, "-o", &p]);
        std::fs::read(p).unwrap()
    };
    for extra in [&[][..], &["--grid-positions"][..]] {
        let (mixed, fast) = (path("mixed.dlgs"), path("fast.dlgs"));
        let e = ["encode", scene, "--quality", "high", "--no-meta"];
        dlgs(&[&e[..], &["-o", &mixed], extra].concat());
        dlgs(&[&e[..], &["-o", &fast, "--fast-decode"], extra].concat());
        assert!(
            size(&mixed) < size(&fast),
            "{extra:?}: {} vs {}",
            size(&mixed),
            size(&fast)
        );
        assert!(ply(&mixed) == ply(&fast), "{extra:?}");
        // `dlgs info --channels` shows it: no channel of the fast file takes mode 5 or 6.
        let codings = |f: &str| -> Vec<String> {
            let info = channel_info(f);
            let records = info["csog"][0]["records"].as_array().unwrap().clone();
            records
                .iter()
                .map(|r| r["coding"].as_str().unwrap().to_owned())
                .collect()
        };
        let mixed_modes = |c: &[String]| {
            c.iter()
                .filter(|c| c.contains("(mode 5)") || c.contains("(mode 6)"))
                .count()
        };
        let (cm, cf) = (codings(&mixed), codings(&fast));
        assert!(mixed_modes(&cm) > 0, "{extra:?}: {cm:?}");
        assert_eq!(mixed_modes(&cf), 0, "{extra:?}: {cf:?}");
        let octree = cm.iter().filter(|c| *c == "octree").count();
        assert_eq!(octree > 0, extra.is_empty(), "{extra:?}: {cm:?}");
        // The table a person reads: one row per record, then the bytes by attribute.
        let text = dlgs(&["info", &mixed, "--channels"]);
        let rows = text
            .lines()
            .filter(|l| l.starts_with("    static "))
            .count();
        assert_eq!(rows, cm.len(), "{text}");
        for says in ["bits/G  coding", "by attribute:", "sh_dc", "record heads"] {
            assert!(text.contains(says), "{says}: {text}");
        }
    }
    let lossless = ["--quality", "lossless"];
    let err = dlgs_fails(
        &[
            &["encode", scene, "-o", &path("x.dlgs"), "--fast-decode"],
            &lossless[..],
        ]
        .concat(),
    );
    assert!(err.contains("lossy --quality"), "{err}");

    // `--mixed-margin`: between the two. A 5 % margin lets fewer channels take the mixed
    // modes than the default 1 %, for a file between the two sizes, with the same Gaussians.
    let e = ["encode", scene, "--quality", "high", "--no-meta", "-o"];
    let (one, five, none) = (path("m1.dlgs"), path("m5.dlgs"), path("m0.dlgs"));
    dlgs(&[&e[..], &[&one]].concat());
    dlgs(&[&e[..], &[&five, "--mixed-margin", "5"]].concat());
    dlgs(&[&e[..], &[&none, "--fast-decode"]].concat());
    let mixed_records = |f: &str| {
        channel_info(f)["csog"][0]["records"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| {
                let c = r["coding"].as_str().unwrap();
                c.contains("(mode 5)") || c.contains("(mode 6)")
            })
            .count()
    };
    let (m1, m5) = (mixed_records(&one), mixed_records(&five));
    assert!(m1 > m5, "{m1} vs {m5} mixed records");
    assert!(
        size(&one) < size(&five) && size(&five) < size(&none),
        "{} {} {}",
        size(&one),
        size(&five),
        size(&none)
    );
    assert!(ply(&one) == ply(&five));
    let x = path("x.dlgs");
    let err = dlgs_fails(&[&e[..], &[&x, "--mixed-margin", "5", "--fast-decode"]].concat());
    assert!(err.contains("cannot be used with"), "{err}");
    let err = dlgs_fails(&[&e[..], &[&x, "--mixed-margin", "200"]].concat());
    assert!(err.contains("from 0 to 100"), "{err}");
    let err = dlgs_fails(&[
        "encode",
        scene,
        "-o",
        &x,
        "--mixed-margin",
        "5",
        "--quality",
        "lossless",
    ]);
    assert!(err.contains("lossy --quality"), "{err}");
}

/// `dlgs info FILE --channels --json`, checked against the file: one `CSOG` chunk whose
/// parts hold every static Gaussian and whose records' bytes, with the record heads, make up
/// the chunk's payload.
fn channel_info(f: &str) -> serde_json::Value {
    let info: serde_json::Value =
        serde_json::from_str(&dlgs(&["info", f, "--channels", "--json"])).unwrap();
    let csog = info["csog"].as_array().unwrap();
    assert_eq!(csog.len(), 1, "{info}");
    let payload = csog[0]["payload_bytes"].as_u64().unwrap();
    assert_eq!(Some(payload), info["chunk_bytes_by_type"]["CSOG"].as_u64());
    let records = csog[0]["records"].as_array().unwrap();
    let coded: u64 = records.iter().map(|r| r["bytes"].as_u64().unwrap()).sum();
    // Heads, ranges and counts: a few bytes per record (14 in layout 1's full records).
    assert!(
        coded < payload && payload - coded < 16 * records.len() as u64,
        "{coded} of {payload}"
    );
    let mut parts: Vec<(u64, u64)> = records
        .iter()
        .filter(|r| r["set"] == "static")
        .map(|r| {
            (
                r["part"].as_u64().unwrap(),
                r["gaussians"].as_u64().unwrap(),
            )
        })
        .collect();
    parts.dedup();
    let n: u64 = parts.iter().map(|p| p.1).sum();
    assert_eq!(Some(n), info["header"]["n_static"].as_u64(), "{parts:?}");
    info
}

#[test]
fn a_failed_encode_leaves_no_file_and_an_in_place_re_encode_reads_its_input_first() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let out = tmp.path().join("x.dlgs");
    let out_s = out.to_str().unwrap();
    let listing = || {
        let mut names: Vec<String> = std::fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    };
    // Rejected settings: nothing is created, not even an empty file or a temporary one.
    let err = dlgs_fails(&["encode", scene, "-o", out_s, "--tiers", "0.1,0.2"]);
    assert!(err.contains("must not increase"), "{err}");
    let err = dlgs_fails(&[
        "encode",
        scene,
        "-o",
        out_s,
        "--refit-colours",
        "--quality",
        "lossless",
    ]);
    assert!(
        err.contains("--refit-colours refits the colours of a lossy coding"),
        "{err}"
    );
    assert!(listing().is_empty(), "{:?}", listing());
    // An existing output survives a failed encode unchanged.
    dlgs(&["encode", scene, "-o", out_s, "--quality", "high"]);
    let before = std::fs::read(&out).unwrap();
    dlgs_fails(&["encode", "/nonexistent/scene.ply", "-o", out_s]);
    assert_eq!(std::fs::read(&out).unwrap(), before);
    assert_eq!(listing(), ["x.dlgs"]);
    // Re-encoding a stream into itself: the input is read before it is replaced.
    let text = dlgs(&["encode", out_s, "-o", out_s, "--quality", "low"]);
    assert!(text.contains("% of input"), "{text}");
    let after = std::fs::read(&out).unwrap();
    assert!(
        after.len() < before.len(),
        "{} vs {}",
        after.len(),
        before.len()
    );
    dlgs(&["verify", out_s]);
    assert_eq!(listing(), ["x.dlgs"]);
}

#[test]
fn refit_colours_reports_its_judgement_and_writes_a_valid_file() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let scene = scene.to_str().unwrap();
    let file = |name: &str| tmp.path().join(name).to_str().unwrap().to_string();
    let (plain, refit) = (file("plain.dlgs"), file("refit.dlgs"));
    let opts = ["--quality", "medium", "--tiers", "0.5,0.2"];
    dlgs(&[&["encode", scene, "-o", &plain][..], &opts].concat());
    let text = dlgs(
        &[
            &["encode", scene, "-o", &refit, "--refit-colours"][..],
            &opts,
        ]
        .concat(),
    );
    // Real lod3: the held-out views gain, so the refit is stored.
    let line = text
        .lines()
        .find(|l| l.contains("colour refit"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(line.contains("colour refit stored ("), "{text}");
    dlgs(&["verify", &refit]);
    let psnr = |f: &str| -> f64 {
        let json = dlgs(&[
            "compare", scene, f, "--json", "--width", "320", "--height", "240",
        ]);
        let v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["mean_psnr"].as_f64().unwrap()
    };
    let (pp, pr) = (psnr(&plain), psnr(&refit));
    assert!(pr > pp, "refit {pr:.2} dB vs {pp:.2} dB");
}

#[test]
fn target_psnr_keeps_the_smallest_candidate_at_the_target_or_stores_lossless() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let out = tmp.path().join("target.dlgs");
    let out = out.to_str().unwrap();
    let text = dlgs(&["encode", scene, "-o", out, "--target-psnr", "45"]);
    // Every candidate is listed with its bytes and PSNR on the search's views; the chosen one
    // reaches 45 dB and no candidate that reaches it is smaller.
    let trials: Vec<(u64, f64, bool)> = text
        .lines()
        .filter(|l| l.trim_end().ends_with("dB") || l.contains("<- chosen"))
        .filter_map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            let b = w.iter().position(|&x| x == "B")?;
            Some((
                w[b - 1].parse().ok()?,
                w[b + 1].parse().ok()?,
                l.contains("<- chosen"),
            ))
        })
        .collect();
    assert!(trials.len() >= 6, "{text}");
    let chosen: Vec<_> = trials.iter().filter(|t| t.2).collect();
    assert_eq!(chosen.len(), 1, "{text}");
    let (bytes, psnr, _) = *chosen[0];
    assert!(psnr >= 45.0, "{text}");
    assert!(trials.iter().all(|t| t.1 < 45.0 || t.0 >= bytes), "{text}");
    assert_eq!(std::fs::metadata(out).unwrap().len(), bytes);
    // The options printed for the chosen file code the same Gaussians (only META differs).
    let options = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("the same file from options: "))
        .unwrap_or_else(|| panic!("{text}"));
    let again = tmp.path().join("again.dlgs");
    let again = again.to_str().unwrap();
    let mut a = vec!["encode", scene, "-o", again];
    a.extend(options.split_whitespace());
    dlgs(&a);
    let ply = |f: &str| {
        let p = format!("{f}.ply");
        dlgs(&["decode", f, "-o", &p]);
        std::fs::read(p).unwrap()
    };
    assert!(ply(out) == ply(again), "{options}");
    // The benchmark's views (other cameras) land near the target too.
    let cmp = dlgs(&["compare", scene, out, "--json", "--orbit", "4"]);
    let bench: f64 = serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
        .as_f64()
        .unwrap();
    assert!(bench > 43.0, "{bench} dB");
    // The search reports the file's PSNR on `dlgs compare`'s default views, which it never
    // measured: the same number `dlgs compare` gives.
    let held_out: f64 = text
        .lines()
        .find_map(|l| {
            l.trim()
                .strip_prefix("on `dlgs compare`'s 8 default views (not searched): ")
        })
        .and_then(|v| v.trim_end_matches(" dB").parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    let cmp = dlgs(&["compare", scene, out, "--json"]);
    let compared: f64 = serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
        .as_f64()
        .unwrap();
    assert!(
        (held_out - compared).abs() < 0.006,
        "{held_out} vs {compared}"
    );
    // Out of reach of every preset: the scene is stored lossless.
    let text = dlgs(&["encode", scene, "-o", out, "--target-psnr", "150"]);
    assert!(text.contains("storing the scene lossless"), "{text}");
    let cmp = dlgs(&["compare", scene, out, "--json", "--orbit", "2"]);
    assert!(cmp.contains("inf") || cmp.contains("null"), "{cmp}");
    for (args, says) in [
        (
            vec!["--target-psnr", "45", "--quality", "high"],
            "cannot be used with",
        ),
        (
            vec!["--target-psnr", "45", "--tiers", "0.1"],
            "cannot be used with",
        ),
        (vec!["--target-psnr", "0"], "> 0"),
    ] {
        let mut a = vec!["encode", scene, "-o", out];
        a.extend(&args);
        let err = dlgs_fails(&a);
        assert!(err.contains(says), "{args:?}: {err}");
    }
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

#[test]
fn a_real_sog_frame_encodes_and_compares_bundled_or_not() {
    // The wave sequence's frames are PlayCanvas SOG v2 files nobody here wrote.
    let tmp = tempfile::tempdir().unwrap();
    let sog = dlgs_tests::data("sequence/playcanvas_wave_200f/wave_0001.sog");
    let sog = sog.to_str().unwrap();
    let path = |n: &str| tmp.path().join(n).to_str().unwrap().to_owned();
    let out = dlgs(&[
        "encode",
        sog,
        "-o",
        &path("a.dlgs"),
        "--quality",
        "medium",
        "--no-meta",
    ]);
    assert!(out.contains("% of input"), "{out}");
    let cmp = dlgs(&["compare", sog, &path("a.dlgs"), "--json", "--orbit", "2"]);
    let psnr = serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
        .as_f64()
        .unwrap();
    assert!(psnr > 55.0, "{psnr} dB");
    // The same frame unbundled (meta.json beside its textures) codes to the same file, and its
    // size is reported against all of its files, as the zip's is.
    let dir = tmp.path().join("unbundled");
    std::fs::create_dir(&dir).unwrap();
    let mut zip = zip::ZipArchive::new(std::fs::File::open(sog).unwrap()).unwrap();
    zip.extract(&dir).unwrap();
    let meta = dir.join("meta.json");
    let out_unbundled = dlgs(&[
        "encode",
        meta.to_str().unwrap(),
        "-o",
        &path("b.dlgs"),
        "--quality",
        "medium",
        "--no-meta",
    ]);
    // (`--no-meta`: the META chunk would name the two source files.)
    assert!(std::fs::read(path("a.dlgs")).unwrap() == std::fs::read(path("b.dlgs")).unwrap());
    let percent = |s: &str| -> f64 {
        let at = s.find("% of input").unwrap();
        s[..at].rsplit('(').next().unwrap().parse().unwrap()
    };
    let (a, b) = (percent(&out), percent(&out_unbundled));
    assert!((a - b).abs() < 2.0, "{a} % vs {b} %");
    // A damaged SOG names what is wrong.
    std::fs::write(path("bad.sog"), b"PK\x03\x04 not a zip").unwrap();
    let err = dlgs_fails(&["encode", &path("bad.sog"), "-o", &path("c.dlgs")]);
    assert!(err.contains("SOG: not a readable zip"), "{err}");
}

#[test]
fn still_scenes_encode_lossy_by_default_and_streams_stay_lossless() {
    // A codec asked to encode a still scene gives a visually lossless file (preset `high`);
    // `--quality lossless` keeps every float; re-encoding a `.dlgs` keeps its values.
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let path = |n: &str| tmp.path().join(n).to_str().unwrap().to_owned();
    let canonical_chunk = |f: &str| {
        let info: serde_json::Value = serde_json::from_str(&dlgs(&["info", f, "--json"])).unwrap();
        let gop = &info["chunk_bytes_by_type"];
        ["CSOG", "CRAW"]
            .into_iter()
            .find(|c| gop.get(c).is_some())
            .unwrap_or_else(|| panic!("{info}"))
    };
    dlgs(&["encode", scene, "-o", &path("default.dlgs"), "--no-meta"]);
    dlgs(&[
        "encode",
        scene,
        "-o",
        &path("high.dlgs"),
        "--no-meta",
        "--quality",
        "high",
    ]);
    dlgs(&[
        "encode",
        scene,
        "-o",
        &path("exact.dlgs"),
        "--quality",
        "lossless",
    ]);
    assert_eq!(canonical_chunk(&path("default.dlgs")), "CSOG");
    assert!(
        std::fs::read(path("default.dlgs")).unwrap() == std::fs::read(path("high.dlgs")).unwrap(),
        "the default is `--quality high`"
    );
    assert_eq!(canonical_chunk(&path("exact.dlgs")), "CRAW");
    let size = |f: &str| std::fs::metadata(f).unwrap().len();
    assert!(size(&path("default.dlgs")) * 3 < size(&path("exact.dlgs")));
    let cmp = dlgs(&[
        "compare",
        scene,
        &path("default.dlgs"),
        "--json",
        "--orbit",
        "2",
    ]);
    let psnr = serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
        .as_f64()
        .unwrap();
    assert!(psnr > 45.0, "{psnr} dB");
    // Re-encoding a stream without --quality keeps the canonical floats.
    dlgs(&["encode", &path("exact.dlgs"), "-o", &path("again.dlgs")]);
    assert_eq!(canonical_chunk(&path("again.dlgs")), "CRAW");
}
