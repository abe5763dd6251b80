//! Scaffold-GS files through the C ABI: `examples/scaffold_view.c`, compiled with the system C
//! compiler against the cdylib, decodes the Gaussians of one camera with
//! `dlgs_decode_frame_view` (every anchor, and frustum-culled) and prints the checksums the Rust
//! `ScaffoldDecoder` gives; `dlgs_decode_frame` refuses the file with
//! `DLGS_STATUS_WRONG_VARIANT`. The file is the conformance vector `scaffold-tiny` (3 anchors
//! with generated values, language, one dynamic anchor).

mod common;
use common::{compile_example, fnv1a};

use std::path::Path;
use std::process::Command;

use dlgs_decoder::scaffold::{ScaffoldDecoder, ViewRequest};
use dlgs_render::Camera;
use dlgs_tests::vectors::scaffold::{valid_bytes, CAMERA, TIMES};

/// The C program's camera: at `centre`, looking along +z, 100x100, f = 100.
fn camera(centre: [f32; 3]) -> Camera {
    Camera {
        width: 100,
        height: 100,
        fx: 100.0,
        fy: 100.0,
        cx: 50.0,
        cy: 50.0,
        rotation: glam::Mat3::IDENTITY,
        position: glam::Vec3::from_array(centre),
        name: String::new(),
    }
}

/// `t=... n=... fnv=...` lines of the Rust API.
fn rust_lines(bytes: &[u8], centre: [f32; 3], cull: bool) -> Vec<String> {
    let mut dec =
        ScaffoldDecoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap();
    let cam = camera(centre);
    TIMES
        .iter()
        .map(|&t| {
            let f = if cull {
                let in_view =
                    |p: &[[f32; 3]], r: &[f32]| dlgs_render::cull::spheres_in_view(&cam, p, r);
                dec.frame_in_view(t, centre, true, &in_view).unwrap().0
            } else {
                let view = ViewRequest {
                    camera_center: centre,
                    language: true,
                    visible: None,
                };
                dec.frame_at(t, &view).unwrap()
            };
            let g = f.to_gaussians();
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

fn run(exe: &Path, file: &Path, centre: [f32; 3], cull: bool) -> Vec<String> {
    let mut cmd = Command::new(exe);
    cmd.arg(file);
    cmd.args(centre.iter().map(|v| format!("{v:?}")));
    if cull {
        cmd.arg("--cull");
    }
    cmd.args(TIMES.iter().map(|t| format!("{t:?}")));
    let out = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout.lines().map(str::to_string).collect()
}

#[test]
fn c_decodes_scaffold_views_as_rust_does() {
    let tmp = tempfile::tempdir().unwrap();
    let bytes = valid_bytes();
    let file = tmp.path().join("scaffold-tiny.dlgs");
    std::fs::write(&file, &bytes).unwrap();
    let exe = compile_example("scaffold_view", tmp.path());

    let lines = run(&exe, &file, CAMERA, false);
    assert!(
        lines[0].starts_with("variant 1, 2 + 1 anchors") && lines[0].contains("at most 30"),
        "{}",
        lines[0]
    );
    assert_eq!(lines[1], "dlgs_decode_frame: DLGS_STATUS_WRONG_VARIANT");
    let got: Vec<&String> = lines.iter().filter(|l| l.starts_with("t=")).collect();
    let want = rust_lines(&bytes, CAMERA, false);
    assert_eq!(got, want.iter().collect::<Vec<_>>());
    // The frames are not empty, and differ over time (the comparison is not vacuous).
    assert!(want.iter().all(|l| !l.contains(" n=0 ")), "{want:?}");
    let mut unique = want.clone();
    unique.dedup();
    assert_eq!(unique.len(), want.len());
    // A buffer too small says how many Gaussians the frame needs.
    let need: Vec<&String> = lines.iter().filter(|l| l.starts_with("one-")).collect();
    assert_eq!(need.len(), want.len(), "{lines:?}");

    // Culled: the camera looks along +z from behind the scene (z = -2.5): same frames.
    let culled = run(&exe, &file, CAMERA, true);
    let got: Vec<&String> = culled.iter().filter(|l| l.starts_with("t=")).collect();
    assert_eq!(
        got,
        rust_lines(&bytes, CAMERA, true).iter().collect::<Vec<_>>()
    );
    // From past the scene, looking away from it: nothing is in view.
    let away = run(&exe, &file, [0.0, 0.0, 50.0], true);
    let got: Vec<&String> = away.iter().filter(|l| l.starts_with("t=")).collect();
    assert!(got.iter().all(|l| l.contains(" n=0 ")), "{got:?}");
    assert_eq!(
        got,
        rust_lines(&bytes, [0.0, 0.0, 50.0], true)
            .iter()
            .collect::<Vec<_>>()
    );
}
