//! A context model for Scaffold-GS anchors that come without one (issue 68): the `AHAC`
//! context model (format-spec §6.13.5: binary 3D hash grid, three binary planes, `mlp_grid`)
//! fitted in the encoder by minimising the coded bits of the anchors' symbols, on the CPU,
//! without rendering. The symbols and steps are those of [`crate::scaffold_prior`] (one step
//! per attribute, `adj = 0`); the fit only changes each symbol's mean and scale.
//!
//! The model's own bytes count: after the fit, grid entries no anchor reads take the more
//! common bit (they then cost almost nothing), the weights are tried at a few precisions
//! (mantissa bits dropped, so zstd packs them), and the smallest whole payload wins, the
//! prior's included, so the fit never makes a GOP larger.

mod finish;
mod rate;
mod train;

use std::time::Instant;

use dlgs::chunks::ahac::{encode_payload, AhacSizes, HacAnchors};
use dlgs::model::hac_context::{dequantize, GridShape, ATTR_CHANNELS};
use dlgs::model::scaffold::ScaffoldCanonical;
use dlgs::Result;

use crate::scaffold_prior::prior_anchors;

/// Size and schedule of the fitted context model.
#[derive(Debug, Clone, PartialEq)]
pub struct ContextFitSettings {
    /// Steps of feature, log-scaling and offsets.
    pub steps: [f32; 3],
    /// Gradient steps (0: the prior only).
    pub iterations: usize,
    /// `mlp_grid`'s hidden width.
    pub hidden: usize,
    /// The grids; `None`: sized for the anchor count ([`grids_for`]).
    pub grids: Option<(GridShape, GridShape)>,
    /// Anchors per gradient step (all of them when fewer).
    pub batch: usize,
    pub zstd_level: i32,
    pub seed: u64,
}

impl ContextFitSettings {
    pub fn new(steps: [f32; 3]) -> Self {
        ContextFitSettings {
            steps,
            iterations: 300,
            hidden: 16,
            grids: None,
            batch: 2048,
            zstd_level: 19,
            seed: 0x00ac_0c7e_5eed,
        }
    }
}

/// What a fit reached.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ContextFitReport {
    /// Payload bytes with the per-channel prior, and with the fitted model (the smaller kept).
    pub prior_bytes: usize,
    pub fitted_bytes: usize,
    /// The kept payload's parts.
    pub sizes: AhacSizes,
    /// Whether the fitted model was kept (false: the prior was smaller).
    pub kept_fit: bool,
    /// Mantissa bits kept in `mlp_grid`'s weights (23: all).
    pub mantissa_bits: u32,
    /// Mean model bits per anchor over the fit (iteration, bits).
    pub bits_log: Vec<(usize, f64)>,
    pub fit_seconds: f64,
}

/// Grids for `n` anchors: a 3D grid of six levels from resolution 8 and two levels per plane,
/// two features per entry, tables of about two entries per anchor (at least 2^10).
pub fn grids_for(n: usize) -> (GridShape, GridShape) {
    let log2 = ((2 * n.max(1)) as f64).log2().ceil().clamp(10.0, 18.0) as u8;
    let top = ((n.max(1) as f64).cbrt() * 1.5).clamp(12.0, 512.0);
    let levels = 6;
    let resolutions = (0..levels)
        .map(|l| (8.0 * (top / 8.0).powf(l as f64 / (levels - 1) as f64)).round() as u32)
        .collect();
    let plane_top = ((n.max(1) as f64).sqrt() * 0.75).clamp(16.0, 2048.0);
    (
        GridShape {
            resolutions,
            log2_table: log2,
            features: 2,
        },
        GridShape {
            resolutions: vec![(plane_top / 3.0).round().max(4.0) as u32, plane_top as u32],
            log2_table: log2,
            features: 2,
        },
    )
}

/// `AHAC` anchors for `c` at `s.steps` with a context model fitted to them (or the prior's
/// when that codes smaller). `progress(done, total)` after each iteration.
pub fn fit_anchors(
    c: &ScaffoldCanonical,
    s: &ContextFitSettings,
    mut progress: impl FnMut(usize, usize),
) -> Result<(HacAnchors, ContextFitReport)> {
    let prior = prior_anchors(c, s.steps)?;
    let (_, prior_sizes) = encode_payload(&prior, s.zstd_level)?;
    let prior_bytes = total(&prior_sizes);
    let mut report = ContextFitReport {
        prior_bytes,
        fitted_bytes: prior_bytes,
        sizes: prior_sizes,
        mantissa_bits: 23,
        ..Default::default()
    };
    let n = prior.quantized.len();
    if s.iterations == 0 || n == 0 {
        return Ok((prior, report));
    }
    let started = Instant::now();
    let ctx = &prior.context;
    let (g3, g2) = s.grids.clone().unwrap_or_else(|| grids_for(n));
    let positions = dequantize(&prior.quantized, ctx.bound_min, ctx.bound_max);
    let u = positions
        .iter()
        .map(|p| {
            std::array::from_fn(|d| {
                let v = (p[d] - ctx.bound_min[d]) / (ctx.bound_max[d] - ctx.bound_min[d]);
                v.clamp(0.0, 1.0)
            })
        })
        .collect();
    // Training units: each output relative to its channel's mean and spread (the prior's).
    let mut shift = Vec::with_capacity(train::TRAINED_OUT);
    let mut unit = Vec::with_capacity(train::TRAINED_OUT);
    let mut at = 0;
    for &ch in &ATTR_CHANNELS {
        let means = &ctx.b2[at..at + ch];
        let spreads = &ctx.b2[at + ch..at + 2 * ch];
        shift.extend_from_slice(means);
        unit.extend_from_slice(spreads);
        shift.extend(std::iter::repeat_n(0.0, ch));
        unit.extend_from_slice(spreads);
        at += 2 * ch;
    }
    let problem = train::Problem {
        grid3: &g3,
        grid2: &g2,
        u,
        symbols: &prior.symbols,
        steps: s.steps,
        shift,
        unit,
    };
    let schedule = train::Schedule {
        hidden: s.hidden,
        iterations: s.iterations,
        batch: s.batch,
        seed: s.seed,
    };
    let trained = train::fit(&problem, &schedule, &mut progress);
    report.bits_log = trained.log.clone();
    let mut best: Option<(HacAnchors, AhacSizes, u32)> = None;
    for mantissa in [23, 8, 4, 3, 2, 1, 0] {
        let context = finish::context(&trained, &problem, ctx, mantissa);
        let hac = HacAnchors {
            context,
            ..prior.clone()
        };
        let (_, sizes) = encode_payload(&hac, s.zstd_level)?;
        if best.as_ref().is_none_or(|b| total(&sizes) < total(&b.1)) {
            best = Some((hac, sizes, mantissa));
        }
    }
    report.fit_seconds = started.elapsed().as_secs_f64();
    let (hac, sizes, mantissa) = best.expect("at least one precision was tried");
    report.fitted_bytes = total(&sizes);
    report.mantissa_bits = mantissa;
    if report.fitted_bytes < prior_bytes {
        report.kept_fit = true;
        report.sizes = sizes;
        Ok((hac, report))
    } else {
        Ok((prior, report))
    }
}

fn total(s: &AhacSizes) -> usize {
    s.header + s.positions + s.grids + s.mlp + s.batch_headers + s.streams.iter().sum::<usize>()
}

#[cfg(test)]
mod tests;
