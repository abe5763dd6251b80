//! The Scaffold-GS variant through the binary: the reference's HAC run folders (the fitted
//! fixture in tests/fixtures/scaffold_run) encode to a Scaffold-GS .dlgs, which `info`
//! describes and `render` draws, with and without frustum culling to the same image.

use std::path::PathBuf;
use std::process::Command;

fn run(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dlgs"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap()
}

fn fixture() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/scaffold_run")
}

#[test]
fn a_hac_run_encodes_renders_and_culls() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("hac.dlgs");
    let o = run(&[
        "encode",
        fixture().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(text.contains("1845 static + 555 dynamic anchors"), "{text}");
    // GOP 1 is the reference's NTC residual (format 1.17), its view MLPs inherited.
    assert!(
        text.contains("GOP 1: RNTC residual, AMLP inherited"),
        "{text}"
    );
    let o = run(&["info", out.to_str().unwrap()]);
    let info = String::from_utf8_lossy(&o.stdout);
    assert!(info.contains("variant Scaffold"), "{info}");
    // GOP 0's anchors HAC-coded by default (format 1.17, §6.13).
    assert!(
        info.contains("AHAC") && !info.contains("ANCR") && info.contains("AMLP"),
        "{info}"
    );
    assert!(info.contains("ADEF"), "{info}");
    assert!(
        info.contains("residuals Sequential") && info.contains("RNTC"),
        "{info}"
    );
    let cams = fixture().join("reference_decode/cameras.json");
    let mut pngs = Vec::new();
    for cull in [true, false] {
        let png = dir.path().join(format!("view_{cull}.png"));
        let mut args = vec![
            "render",
            out.to_str().unwrap(),
            "--cameras",
            cams.to_str().unwrap(),
            "--view",
            "1",
            "--t",
            "2.5",
            "-o",
            png.to_str().unwrap(),
        ];
        if !cull {
            args.push("--no-cull");
        }
        let o = run(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        pngs.push(std::fs::read(&png).unwrap());
    }
    assert_eq!(pngs[0], pngs[1], "culling changed the image");
    // The image is not blank (a white background alone has no value under 200).
    let decoded = image_pixels(&pngs[0]);
    let dark = decoded.iter().filter(|&&v| v < 200).count();
    assert!(
        dark > decoded.len() / 500,
        "{dark} dark values of {}",
        decoded.len()
    );
}

fn image_pixels(png: &[u8]) -> Vec<u8> {
    let img = image::load_from_memory(png).unwrap().to_rgb8();
    img.into_raw()
}

/// The fixture encoded once per test (each test has its own directory).
fn encoded(dir: &std::path::Path) -> PathBuf {
    let out = dir.join("hac.dlgs");
    let o = run(&[
        "encode",
        fixture().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

fn json_of(o: &std::process::Output) -> serde_json::Value {
    assert!(
        o.status.success(),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn play_decodes_every_frame_for_the_camera() {
    let dir = tempfile::tempdir().unwrap();
    let file = encoded(dir.path());
    let mut means = Vec::new();
    for cull in [true, false] {
        let mut args = vec![
            "play",
            file.to_str().unwrap(),
            "--max-speed",
            "--json",
            "--view",
            "0",
            "--distance",
            "0.3",
        ];
        if !cull {
            args.push("--no-cull");
        }
        let r = json_of(&run(&args));
        assert_eq!(
            (r["frames"].as_u64(), r["shown"].as_u64()),
            (Some(120), Some(120))
        );
        assert_eq!(r["dropped"].as_u64(), Some(0));
        assert_eq!(r["gop_decode_ms"].as_array().unwrap().len(), 2);
        let mean = r["gaussians_mean"].as_f64().unwrap();
        // 2,400 anchors of 10 children each at most.
        assert!(mean > 10.0 && mean <= 24_000.0, "{mean}");
        means.push(mean);
    }
    // Orbit camera 0 placed inside the scene sees a small part of it: culling decodes the
    // children of far fewer anchors.
    assert!(means[0] < 0.5 * means[1] && means[1] > 1000.0, "{means:?}");
}

/// `dlgs play` of a Scaffold-GS stream from stdin and at a network rate: the GOPs decode as
/// their bytes arrive (`ScaffoldStreamDecoder`) and the frames are those played from the file;
/// a stream cut short plays up to the damage, then fails with the reason.
#[test]
fn play_streams_scaffold_files_from_stdin_and_at_a_bandwidth() {
    use std::process::Stdio;
    let dir = tempfile::tempdir().unwrap();
    let file = encoded(dir.path());
    let bytes = std::fs::read(&file).unwrap();
    let cams = fixture().join("reference_decode/cameras.json");
    let base = [
        "--max-speed",
        "--json",
        "--cameras",
        cams.to_str().unwrap(),
        "--view",
        "1",
    ];
    let play = |src: &str, extra: &[&str], stdin: Stdio| {
        Command::new(env!("CARGO_BIN_EXE_dlgs"))
            .args(["play", src])
            .args(base)
            .args(extra)
            .env("RUST_BACKTRACE", "0")
            .stdin(stdin)
            .output()
            .unwrap()
    };
    let from_file = json_of(&play(file.to_str().unwrap(), &[], Stdio::null()));
    let from_stdin = json_of(&play(
        "-",
        &[],
        Stdio::from(std::fs::File::open(&file).unwrap()),
    ));
    // 8 Mbit/s: GOP 0 (about 384 kB) cannot be ready before about 0.38 s.
    let throttled = json_of(&play(
        file.to_str().unwrap(),
        &["--bandwidth-mbps", "8"],
        Stdio::null(),
    ));
    for r in [&from_file, &from_stdin, &throttled] {
        assert_eq!(
            (
                r["frames"].as_u64(),
                r["shown"].as_u64(),
                r["dropped"].as_u64()
            ),
            (Some(120), Some(120), Some(0)),
            "{r}"
        );
        assert_eq!(r["gop_decode_ms"].as_array().unwrap().len(), 2, "{r}");
        // The same camera and frames: the same neural Gaussians.
        assert_eq!(r["gaussians_mean"], from_file["gaussians_mean"], "{r}");
    }
    let ready = throttled["gop_ready_ms"][0].as_f64().unwrap();
    assert!(ready > 300.0, "GOP 0 ready after {ready} ms at 8 Mbit/s");
    assert!(throttled["time_to_first_frame_ms"].as_f64().unwrap() > 300.0);
    // 90 % of the stream (GOP 0 is the first 72 %) over stdin: GOP 0 plays, then a clear error.
    let cut = dir.path().join("cut.dlgs");
    std::fs::write(&cut, &bytes[..bytes.len() * 9 / 10]).unwrap();
    let o = play("-", &[], Stdio::from(std::fs::File::open(&cut).unwrap()));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("decoding the GOP of frame 60"),
        "{e}"
    );
}

#[test]
fn query_reads_the_neural_gaussians_language() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = encoded(d);
    let data = dlgs_tests::data("ply");
    let labels = d.join("labels");
    let o = run(&[
        "labels",
        data.join("supersplat_fruit_drops_minimal_4721_sh3.ply")
            .to_str()
            .unwrap(),
        "--annotations",
        data.join("supersplat_fruit_drops_minimal.annotations.json")
            .to_str()
            .unwrap(),
        "-o",
        labels.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The orbit `dlgs export` evaluates the view-dependent MLPs from (its camera 0), placed
    // around the anchors at t = 0 as `dlgs cameras` places it.
    let cams = d.join("cams.json");
    let o = run(&[
        "cameras",
        file.to_str().unwrap(),
        "-o",
        cams.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let ply = d.join("frame.ply");
    let o = run(&[
        "export",
        file.to_str().unwrap(),
        "--t",
        "0",
        "--extras",
        "-o",
        ply.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Query the Scaffold-GS file and the exported frame (the same Gaussians, language
    // included) from camera 0: the same answer, pixel for pixel.
    let mut answers = Vec::new();
    for (scene, tag) in [(&file, "scaffold"), (&ply, "ply")] {
        let prefix = d.join(tag);
        let r = json_of(&run(&[
            "query",
            scene.to_str().unwrap(),
            "--t",
            "0",
            "--cameras",
            cams.to_str().unwrap(),
            "--view",
            "0",
            "--width",
            "400",
            "--lang-decoder",
            labels.join("lang_decoder.safetensors").to_str().unwrap(),
            "--negatives",
            labels.join("negatives.npy").to_str().unwrap(),
            "--text-embedding",
            labels.join("category_1.npy").to_str().unwrap(),
            "-o",
            prefix.to_str().unwrap(),
            "--json",
        ]));
        let mask = std::fs::read(d.join(format!("{tag}.mask.png"))).unwrap();
        answers.push((
            r[0]["scores"].clone(),
            r[0]["selected_pixels"].clone(),
            mask,
        ));
    }
    assert_eq!(answers[0], answers[1]);
    let scores: Vec<f64> = serde_json::from_value(answers[0].0.clone()).unwrap();
    assert_eq!(scores.len(), 3);
    // The language image is not constant: the levels score differently.
    assert!(
        scores.iter().any(|s| (s - scores[0]).abs() > 1e-3),
        "{scores:?}"
    );
}

#[test]
fn export_writes_sog_that_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let file = encoded(dir.path());
    let (ply, sog) = (dir.path().join("f.ply"), dir.path().join("f.sog"));
    for (out, format) in [(&ply, "ply"), (&sog, "sog")] {
        let o = run(&[
            "export",
            file.to_str().unwrap(),
            "--t",
            "1.0",
            "--format",
            format,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let a = dlgs::interop::read_splat_file(&ply).unwrap();
    let b = dlgs::interop::read_splat_file(&sog).unwrap();
    assert_eq!((a.len(), b.len()), (a.len(), a.len()));
    assert!(a.len() > 1000);
    // Positions within SOG's 16-bit log-domain quantisation.
    let worst = a
        .positions
        .iter()
        .zip(&b.positions)
        .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs() / (1.0 + p[k].abs())))
        .fold(0f32, f32::max);
    assert!(worst < 1e-3, "{worst}");
}

/// `dlgs rd` of a Scaffold-GS file sweeps the anchor steps, re-coding the file's own `AHAC`:
/// k = 1 is the file itself (its bytes, infinite PSNR), larger steps cost bytes less and
/// quality more, and each k gives the file `dlgs encode HAC_RUN --anchor-step-scale k` writes.
#[test]
fn rd_sweeps_the_anchor_steps_of_a_scaffold_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = encoded(dir.path());
    let len = std::fs::metadata(&file).unwrap().len();
    let k2 = dir.path().join("k2.dlgs");
    let o = run(&[
        "encode",
        fixture().to_str().unwrap(),
        "--anchor-step-scale",
        "2",
        "-o",
        k2.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let k2_len = std::fs::metadata(&k2).unwrap().len();
    let cams = fixture().join("reference_decode/cameras.json");
    let out = dir.path().join("rd");
    let o = run(&[
        "rd",
        file.to_str().unwrap(),
        "--anchor-step-scale",
        "1,2,8",
        "--times",
        "2",
        "--cameras",
        cams.to_str().unwrap(),
        "--width",
        "160",
        "--height",
        "120",
        "-o",
        out.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        text.contains("anchor-step-scale 8") && text.contains("lang dB"),
        "{text}"
    );
    let csv = std::fs::read_to_string(out.join("rd.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert!(
        lines[0].ends_with("anchor_step_scale,lang_psnr_db"),
        "{csv}"
    );
    let rows: Vec<Vec<&str>> = lines[1..].iter().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 3, "{csv}");
    // Columns: quality,bits,crf,bytes,frames,bytes_per_frame,psnr_db,ssim,decode_ms_per_frame,
    // encode_s,anchor_step_scale,lang_psnr_db
    let col = |r: &Vec<&str>, i: usize| r[i].parse::<f64>().unwrap();
    for (r, k) in rows.iter().zip([1.0, 2.0, 8.0]) {
        assert_eq!((r[0], col(r, 10), col(r, 4)), ("anchor-steps", k, 120.0));
        assert!(col(r, 8) > 0.0);
    }
    // k = 1: the file itself, lossless in colour and language.
    assert_eq!(col(&rows[0], 3), len as f64);
    assert!(col(&rows[0], 6).is_infinite() && col(&rows[0], 11).is_infinite());
    assert_eq!(col(&rows[0], 7), 1.0);
    // k = 2: the bytes of the file written from the run with that step.
    assert_eq!(col(&rows[1], 3), k2_len as f64);
    // Fewer bytes and less quality as the steps grow.
    assert!(col(&rows[0], 3) > col(&rows[1], 3) && col(&rows[1], 3) > col(&rows[2], 3));
    for i in [6, 11] {
        let (p2, p8) = (col(&rows[1], i), col(&rows[2], i));
        assert!(p2.is_finite() && p2 > p8 && p8 > 10.0, "{csv}");
    }
    // The 3DGS sweep's options are refused with a clear message.
    let o = run(&[
        "rd",
        file.to_str().unwrap(),
        "--crf",
        "6",
        "-o",
        out.to_str().unwrap(),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("--crf") && e.contains("--anchor-step-scale"),
        "{e}"
    );
}

/// A file with raw anchors (`--raw-anchors`) re-encoded with `--anchor-prior`: its `ANCR`
/// becomes `AHAC` with the per-channel prior model, smaller, rendering within 60 dB of the raw file; a coarser step is
/// smaller still and renders further from it.
#[test]
fn raw_anchors_are_hac_coded_with_the_prior_on_re_encode() {
    let dir = tempfile::tempdir().unwrap();
    let path = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let fx = fixture();
    let o = run(&[
        "encode",
        fx.to_str().unwrap(),
        "-o",
        &path("raw.dlgs"),
        "--raw-anchors",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cams = fx.join("reference_decode/cameras.json");
    let mut last = (u64::MAX, f64::INFINITY);
    for k in ["1", "4"] {
        let out = path(&format!("prior{k}.dlgs"));
        let o = run(&[
            "encode",
            &path("raw.dlgs"),
            "-o",
            &out,
            "--anchor-step-scale",
            k,
            "--anchor-prior",
        ]);
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success(),
            "{text}{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(
            text.contains("coded with the per-channel prior (--anchor-prior)"),
            "{text}"
        );
        let info = String::from_utf8_lossy(&run(&["info", &out]).stdout).to_string();
        assert!(info.contains("AHAC") && !info.contains("ANCR"), "{info}");
        let o = run(&[
            "compare",
            &path("raw.dlgs"),
            &out,
            "--cameras",
            cams.to_str().unwrap(),
            "--t",
            "0.5",
            "--json",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let psnr = v["mean_psnr"].as_f64().unwrap();
        let bytes = std::fs::metadata(&out).unwrap().len();
        let raw = std::fs::metadata(path("raw.dlgs")).unwrap().len();
        println!("k = {k}: {bytes} B (raw {raw} B), {psnr:.2} dB against the raw file");
        assert!(bytes < raw && bytes < last.0, "{bytes} B");
        assert!(psnr < last.1, "{psnr} dB");
        if k == "1" {
            assert!(psnr >= 60.0, "{psnr} dB");
        }
        last = (bytes, psnr);
    }
}
