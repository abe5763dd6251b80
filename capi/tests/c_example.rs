//! The C example player (`examples/player.c`), compiled with the system C compiler against the
//! cdylib, decodes a real multi-GOP file and prints the same checksums as the Rust API.
//! The file is built from a REAL scene with SYNTHETIC motion (no trained DLGStream model
//! exists here): 3 GOPs, sequential binary voxel residuals, language, HEVC time features.

mod common;
use common::{compile_example, fnv1a};

use std::path::Path;
use std::process::Command;

use dlgs::container::ResidualMode;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::EncoderConfig;
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};

const SCENE: &str = "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply";

/// `t=... n=... fnv=...` lines of the Rust API for the same times.
fn rust_lines(file: &Path, times: &[String]) -> Vec<String> {
    let mut dec = Decoder::open_path(file).unwrap();
    let opts = FrameOptions {
        camera_center: [0.0; 3],
        language: true,
    };
    times
        .iter()
        .map(|t| {
            let t: f64 = t.parse().unwrap();
            let g = dec.frame_at(t, &opts).unwrap().merged();
            let mut h = 1_469_598_103_934_665_603u64;
            h = fnv1a(h, g.positions.as_flattened());
            h = fnv1a(h, g.log_scales.as_flattened());
            h = fnv1a(h, g.rotations.as_flattened());
            h = fnv1a(h, &g.opacity);
            h = fnv1a(h, &g.sh);
            h = fnv1a(h, &g.lang_opacity);
            h = fnv1a(h, &g.lang);
            format!("t={t:.6} n={} fnv={h:016x}", g.len())
        })
        .collect()
}

#[test]
fn c_player_prints_the_rust_checksums() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = SynthSpec {
        gops: 3,
        gop_length: 20,
        key_interval: 5,
        language: true,
        residual_mode: ResidualMode::Sequential,
        ..SynthSpec::default()
    };
    let model = synth_dynamic(&dlgs_tests::load(SCENE), &spec).unwrap();
    let file = tmp.path().join("three_gops.dlgs");
    let bytes = write_model(&model, EncoderConfig::default(), Vec::new()).unwrap();
    std::fs::write(&file, bytes).unwrap();

    let fps = model.scene.fps();
    let mut times: Vec<f64> = Vec::new();
    for g in 0..3u32 {
        // Two consecutive frames, as a player asks for them: the next GOP is decoded ahead.
        times.push((g * 20) as f64 / fps);
        times.push((g * 20 + 1) as f64 / fps);
        times.push((g * 20 + 19) as f64 / fps);
    }
    times.extend([1.2345 / fps, 37.5 / fps, model.scene.duration_seconds()]);
    // Shortest round-trip decimal: C's strtod and Rust's parse give the same double.
    let times: Vec<String> = times.iter().map(|t| format!("{t:?}")).collect();
    let want = rust_lines(&file, &times);

    let player = compile_example("player", tmp.path());
    for memory in [false, true] {
        let mut cmd = Command::new(&player);
        cmd.arg(&file);
        if memory {
            cmd.arg("--memory");
        }
        let out = cmd.args(&times).output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "player failed: {stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let lines: Vec<&str> = stdout.lines().collect();
        assert!(lines[0].contains("3 GOPs x 20 frames"), "{}", lines[0]);
        assert!(lines[0].contains("language 9"), "{}", lines[0]);
        let got: Vec<&str> = lines
            .iter()
            .filter(|l| l.starts_with("t="))
            .copied()
            .collect();
        assert_eq!(got, want, "memory = {memory}");
        // Distinct frames give distinct checksums (the comparison is not vacuous).
        let mut unique = want.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), want.len());
        // GOPs 1 and 2 were decoded ahead (each after two consecutive frames of the GOP before
        // it); the frames are the Rust decoder's all the same.
        assert!(lines.contains(&"GOPs ready from read-ahead: 2"), "{stdout}");
        assert_eq!(
            lines.last().copied(),
            Some("past the end: DLGS_STATUS_TIME_OUT_OF_RANGE")
        );
    }

    // A damaged file is an error with a message, not a crash.
    let mut bad = std::fs::read(&file).unwrap();
    let n = bad.len();
    bad.truncate(n / 2);
    let bad_path = tmp.path().join("bad.dlgs");
    std::fs::write(&bad_path, bad).unwrap();
    let out = Command::new(&player).arg(&bad_path).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("DLGS_STATUS_FORMAT"), "{err}");
}
