//! `dlgs encode RUN_DIR... -o scene.dlgs`: a model trained with the DLGStream reference
//! implementation (its per-GOP `jxl_quant` output folders) re-packed as `.dlgs`, with a report
//! of bytes per frame against the reference's own packing.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use dlgs_ingest::{convert, run};

use crate::encode_cmd::{bar, CodecArgs};

pub fn run_ingest(inputs: &[PathBuf], output: &Path, codec: &CodecArgs, fps: u32) -> Result<()> {
    let dirs = run::resolve(inputs)?;
    let pb = bar(dirs.len() as u64, "reading");
    let gops = run::read_run(&dirs, &dlgs::Limits::default(), |g| {
        pb.set_position(g as u64 + 1)
    })?;
    pb.finish_and_clear();
    let settings = codec.changed_settings();
    let meta = serde_json::json!({
        "source": "DLGStream reference implementation output (fdsd / 3DGS variant)",
        "gop_folders": dirs.iter().map(|d| d.display().to_string()).collect::<Vec<_>>(),
        "encoder": concat!("dlgs ", env!("CARGO_PKG_VERSION")),
        "settings": settings,
    });
    // The reference's feature video is passed through unless exact features are asked for
    // (`convert::encode` decides from `cfg.features`).
    let cfg = codec.config(meta)?;
    let pb = bar(gops.len() as u64, "encoding");
    let bytes = convert::encode(&gops, fps, cfg, Vec::new(), |g| {
        pb.set_position(g as u64 + 1)
    })?;
    pb.finish_and_clear();
    std::fs::write(output, &bytes).with_context(|| format!("writing {}", output.display()))?;
    let report = convert::byte_report(&gops, &bytes)?;
    let frames = convert::GOP_LENGTH as f64;
    println!(
        "{} GOPs, {} static + {} dynamic Gaussians (SH {}, language {}) -> {} ({} bytes)",
        gops.len(),
        gops[0].statics.len(),
        gops[0].dynamics.len(),
        gops[0].statics.sh_degree,
        if gops[0].statics.lang_width > 0 {
            "yes"
        } else {
            "no"
        },
        output.display(),
        bytes.len()
    );
    println!("bytes per frame (GOP bytes / {frames}):");
    println!(
        "  GOP   reference (counted)   reference + mlp_lang.pth   .dlgs      .dlgs / ref+lang"
    );
    let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
    for (g, r) in report.iter().enumerate() {
        let (x, y, z) = (
            r.reference_counted as f64 / frames,
            r.reference_with_lang_mlp as f64 / frames,
            r.dlgs / frames,
        );
        (a, b, c) = (a + x, b + y, c + z);
        if y > 0.0 {
            println!(
                "  {g:3}   {x:19.1}   {y:24.1}   {z:8.1}   {:7.1} %",
                100.0 * z / y
            );
        } else {
            println!(
                "  {g:3}   {:>19}   {:>24}   {z:8.1}   (read from its checkpoint)",
                "-", "-"
            );
        }
    }
    let n = report.len() as f64;
    if report.iter().all(|r| r.reference_with_lang_mlp > 0) {
        println!(
            "  mean  {:19.1}   {:24.1}   {:8.1}   {:7.1} %",
            a / n,
            b / n,
            c / n,
            100.0 * c / b
        );
    } else {
        println!(
            "  mean  {:>19}   {:>24}   {:8.1}   (no comparison: some GOPs have no compressed files)",
            "-",
            "-",
            c / n
        );
    }
    Ok(())
}
