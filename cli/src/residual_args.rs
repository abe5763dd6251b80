//! The residual-mode options of `dlgs encode` and `dlgs synth`: `--residual-mode` and
//! `--refresh K` (format-spec §4.1).

use anyhow::{bail, Result};
use dlgs::container::header::ResidualMode;

/// `intra`, `sequential` or `parallel` (format-spec §4.1).
pub fn parse_residual_mode(s: &str) -> Result<ResidualMode> {
    Ok(match s {
        "intra" => ResidualMode::Intra,
        "sequential" => ResidualMode::Sequential,
        "parallel" => ResidualMode::Parallel,
        _ => bail!("residual mode `{s}`: expected intra, sequential or parallel"),
    })
}

/// `--refresh K` on a scene about to be written: only sequential scenes refresh.
pub fn refresh_interval(k: u32, mode: ResidualMode) -> Result<u32> {
    match (k, mode) {
        (0, _) => Ok(0),
        (1, _) => bail!("--refresh 1 would make every GOP intra: use --residual-mode intra"),
        (k, ResidualMode::Sequential) => Ok(k),
        (_, m) => bail!(
            "--refresh applies to sequential scenes (each GOP a residual of the one before); this one is {m:?}: give --residual-mode sequential"
        ),
    }
}
