//! `dlgs encode` of a per-frame sequence through the binary, on frames of the REAL PlayCanvas
//! SOG sequence: a folder of frames plays back as a dynamic .dlgs, a frame between two source
//! frames decodes, and a damaged frame is named in the error.

use std::process::Command;

fn run(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dlgs"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap()
}

fn frame(n: usize) -> std::path::PathBuf {
    dlgs_tests::data(&format!("sequence/playcanvas_wave_200f/wave_{n:04}.sog"))
}

#[test]
fn a_folder_of_frames_encodes_checks_and_decodes_between_frames() {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("frames");
    std::fs::create_dir(&seq).unwrap();
    // Names that sort wrongly as plain strings: natural order must put 9 before 10.
    for (i, n) in (1..=12).enumerate() {
        std::fs::copy(frame(n), seq.join(format!("f{i}.sog"))).unwrap();
    }
    let out = dir.path().join("anim.dlgs");
    let o = run(&[
        "encode",
        seq.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--gop-length",
        "6",
        "--key-interval",
        "3",
        "--check",
    ]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(text.contains("12 frames of 4225 Gaussians"), "{text}");
    assert!(text.contains("100.00% confident"), "{text}");
    let mean: f64 = text
        .split("mean ")
        .nth(1)
        .and_then(|s| s.split(" dB").next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    assert!(mean > 40.0, "mean PSNR {mean} dB: {text}");
    let info = run(&["info", out.to_str().unwrap()]);
    let info = String::from_utf8_lossy(&info.stdout);
    assert!(info.contains("12 frames at 30/1 fps"), "{info}");
    assert!(info.contains("2 GOPs of 6 frames"), "{info}");
    // Halfway between frames 4 and 5.
    let ply = dir.path().join("between.ply");
    let o = run(&[
        "decode",
        out.to_str().unwrap(),
        "--t",
        "0.15",
        "-o",
        ply.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("4225 Gaussians"));
}

#[test]
fn a_damaged_frame_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("wave_0003.sog");
    std::fs::write(&bad, b"PK\x03\x04 not a zip").unwrap();
    let o = run(&[
        "encode",
        frame(1).to_str().unwrap(),
        frame(2).to_str().unwrap(),
        bad.to_str().unwrap(),
        "-o",
        dir.path().join("x.dlgs").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("frame 2") && err.contains("wave_0003.sog"),
        "{err}"
    );
}
