//! `dlgs encode x.dlgs -o y.dlgs` of a Scaffold-GS file: its anchors re-coded
//! (`dlgs_encoder::scaffold_recode`): HAC-coded anchors (`AHAC`) with `--anchor-step-scale k`
//! times their steps, raw anchors (`ANCR`) HAC-coded with the per-channel prior model at `k`
//! times its default steps; every other chunk is copied.

use std::fs::File;
use std::io::{BufReader, Write};
use std::path::Path;

use anyhow::{Context, Result};
use dlgs_encoder::scaffold_prior::DEFAULT_PRIOR_STEPS;
use dlgs_encoder::scaffold_recode::recode_anchor_steps;

use crate::pending_file::PendingFile;

pub fn run(input: &Path, output: &Path, k: f32) -> Result<()> {
    let f = File::open(input).with_context(|| format!("opening {}", input.display()))?;
    let in_bytes = f.metadata().map(|m| m.len()).unwrap_or(0);
    let (bytes, report) = recode_anchor_steps(
        BufReader::new(f),
        k,
        crate::hac_ingest_cmd::ZSTD_LEVEL,
        dlgs::Limits::default(),
    )
    .with_context(|| format!("re-coding the anchors of {}", input.display()))?;
    let out = PendingFile::create(output)?;
    let mut w = out.writer()?;
    w.write_all(&bytes)
        .with_context(|| format!("writing {}", output.display()))?;
    out.commit_written(w)?;
    println!(
        "{} -> {}: {} bytes ({:.1} % of the input); anchors of {} GOP(s) HAC-coded: {} -> {} bytes{}",
        input.display(),
        output.display(),
        bytes.len(),
        100.0 * bytes.len() as f64 / in_bytes.max(1) as f64,
        report.ahac_chunks,
        report.ahac_bytes_before,
        report.ahac_bytes_after,
        if report.from_raw > 0 {
            format!(
                " ({} from raw anchors with the per-channel prior, steps {:?})",
                report.from_raw,
                DEFAULT_PRIOR_STEPS.map(|q| q * k)
            )
        } else {
            String::new()
        }
    );
    Ok(())
}
