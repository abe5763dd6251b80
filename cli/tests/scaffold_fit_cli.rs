//! `dlgs encode raw.dlgs` of a Scaffold-GS file with raw anchors (issue 68): the steps are
//! searched against the rendered-quality budget and the anchors coded with a context model
//! fitted to them, on the fitted fixture run (tests/fixtures/scaffold_run).

use std::path::{Path, PathBuf};
use std::process::Command;

fn run(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dlgs"))
        .args(args)
        .output()
        .expect("run dlgs")
}

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/scaffold_run")
}

fn ok(o: &std::process::Output) -> String {
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    text
}

/// The fixture run with GOP 0's anchors raw (`ANCR`) at `out`.
fn raw_file(out: &str) {
    ok(&run(&[
        "encode",
        fixture().to_str().unwrap(),
        "-o",
        out,
        "--raw-anchors",
    ]));
}

/// Payload bytes of chunk type `ty` in `dlgs info`'s table.
fn chunk_bytes(file: &str, ty: &str) -> u64 {
    let info = ok(&run(&["info", file]));
    info.lines()
        .find_map(|l| {
            let mut w = l.split_whitespace();
            (w.next() == Some(ty)).then(|| w.next().unwrap().parse().unwrap())
        })
        .unwrap_or_else(|| panic!("no {ty} in\n{info}"))
}

fn psnr_against(a: &str, b: &str, t: &str) -> f64 {
    let cams = fixture().join("reference_decode/cameras.json");
    let o = run(&[
        "compare",
        a,
        b,
        "--cameras",
        cams.to_str().unwrap(),
        "--t",
        t,
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_slice(ok(&o).as_bytes()).unwrap();
    // Identical renders: inf, which JSON writes as null.
    v["mean_psnr"].as_f64().unwrap_or(f64::INFINITY)
}

/// The default: at most the trained HAC model's 98.6 kB for GOP 0's anchors, within the
/// 45 dB budget on the judge views, and on the fixture's own cameras too (GOP 1 at t = 2.5 s,
/// with its residual MLP rounded); smaller than the prior at the same steps.
#[test]
fn raw_anchors_get_searched_steps_and_a_fitted_context_model() {
    let dir = tempfile::tempdir().unwrap();
    let path = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    raw_file(&path("raw.dlgs"));
    let text = ok(&run(&[
        "encode",
        &path("raw.dlgs"),
        "-o",
        &path("fit.dlgs"),
    ]));
    println!("{text}");
    assert!(text.contains("the coarsest within 45 dB"), "{text}");
    let colour: f64 = text
        .split("colour ")
        .nth(1)
        .and_then(|s| s.split(" dB").next())
        .and_then(|s| s.parse().ok())
        .expect("the judged colour PSNR");
    assert!(colour >= 45.0, "{colour} dB");
    let fitted = chunk_bytes(&path("fit.dlgs"), "AHAC");
    assert!(fitted <= 98_600, "{fitted} B");
    let line = text
        .lines()
        .find(|l| l.contains("context model fitted"))
        .expect("a fit report");
    assert!(!line.contains("the prior was kept"), "{line}");
    // GOP 1's anchor residual: its MLP weights at fewer mantissa bits, smaller.
    let rntc = text
        .lines()
        .find(|l| l.starts_with("anchor residuals (RNTC) of 1 GOP(s)"))
        .expect("an RNTC report");
    let sizes: Vec<u64> = rntc
        .split(", ")
        .nth(1)
        .unwrap()
        .trim_end_matches(" bytes")
        .split(" -> ")
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(sizes[1] < sizes[0], "{rntc}");
    for t in ["0.5", "2.5"] {
        let psnr = psnr_against(&path("raw.dlgs"), &path("fit.dlgs"), t);
        println!("t = {t}: {psnr:.2} dB against the raw file");
        assert!(psnr >= 45.0, "{psnr} dB at t = {t}");
    }
    // The prior at the same steps: the same values (so the same renders), more bytes.
    let steps = text
        .split("steps [")
        .nth(1)
        .and_then(|s| s.split(']').next())
        .expect("the steps")
        .replace(' ', "");
    ok(&run(&[
        "encode",
        &path("raw.dlgs"),
        "-o",
        &path("prior.dlgs"),
        "--anchor-steps",
        &steps,
        "--anchor-prior",
    ]));
    let prior = chunk_bytes(&path("prior.dlgs"), "AHAC");
    assert!(fitted < prior, "fitted {fitted} B, prior {prior} B");
    assert!(psnr_against(&path("prior.dlgs"), &path("fit.dlgs"), "0.5").is_infinite());
}

/// Explicit steps skip the search; bad ones are refused with a clear error.
#[test]
fn explicit_anchor_steps_are_used_and_checked() {
    let dir = tempfile::tempdir().unwrap();
    let path = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    raw_file(&path("raw.dlgs"));
    let text = ok(&run(&[
        "encode",
        &path("raw.dlgs"),
        "-o",
        &path("a.dlgs"),
        "--anchor-steps",
        "0.1,0.01,0.02",
        "--anchor-fit-iterations",
        "40",
    ]));
    assert!(
        text.contains("steps [0.1, 0.01, 0.02]") && !text.contains("judged"),
        "{text}"
    );
    assert!(text.contains("(40 iterations)"), "{text}");
    for bad in ["0.1,0.01", "0.1,-1,0.02", "a,b,c"] {
        let o = run(&[
            "encode",
            &path("raw.dlgs"),
            "-o",
            &path("b.dlgs"),
            "--anchor-steps",
            bad,
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains("anchor-steps"),
            "{bad}: {err}"
        );
        assert!(!Path::new(&path("b.dlgs")).exists());
    }
}
