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
    assert!(
        info.contains("ANCR") && info.contains("AMLP") && info.contains("ADEF"),
        "{info}"
    );
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
