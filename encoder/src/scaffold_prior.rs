//! HAC coding (`AHAC`, format-spec §6.13) for Scaffold-GS anchors that come without a trained
//! context model (a model written through the API, a raw `ANCR` file): the context model is a
//! fixed per-channel prior. The grids are one 8-entry level of zeros and `mlp_grid` has one
//! hidden unit whose output weights are zero, so every anchor gets the same model: for each
//! channel the mean and standard deviation of that channel over all anchors, and the caller's
//! steps (`adj = 0`, so `Q = Q_BASE`). Values are quantised to `round(v / Q)` (each moves by
//! at most `Q / 2`) and positions to the 16-bit grid of §6.13.3 over the anchors' box.
//!
//! Without a trained model the symbols cost about their per-channel entropy; what a HAC run's
//! context model saves on top is in docs/benchmarks/scaffold.md.

use bitvec::prelude::*;
use dlgs::chunks::ahac::{HacAnchors, REFERENCE_BATCH};
use dlgs::model::hac_context::{GridShape, HacContext, ATTR_CHANNELS, CONTEXT_OUT};
use dlgs::model::scaffold::ScaffoldCanonical;
use dlgs::{Error, Result};

/// Steps of feature, log-scaling and offsets used when none are given: fine enough that the
/// fixture's anchors render at > 60 dB against the raw ones (docs/benchmarks/scaffold.md).
pub const DEFAULT_PRIOR_STEPS: [f32; 3] = [0.01, 0.001, 0.002];

/// The anchors' box, widened where it is flat so that `bmax > bmin` on every axis.
fn bounds(positions: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in positions {
        for d in 0..3 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    for d in 0..3 {
        if positions.is_empty() {
            (lo[d], hi[d]) = (0.0, 1.0);
        }
        let pad = ((hi[d] - lo[d]) * 1e-6)
            .max(lo[d].abs().max(hi[d].abs()) * 1e-6)
            .max(1e-6);
        (lo[d], hi[d]) = (lo[d] - pad, hi[d] + pad);
    }
    (lo, hi)
}

/// The nearest of the 65,536 positions §6.13.3 dequantises to, per axis.
fn quantize_position(p: [f32; 3], lo: [f32; 3], hi: [f32; 3]) -> [u16; 3] {
    let c = f32::from_bits(0x3780_0080);
    let tiny = f32::from_bits(0x3586_37BD);
    std::array::from_fn(|d| {
        let interval = (hi[d] - lo[d]) * c + tiny;
        let q = ((p[d] - lo[d]) / interval).round().clamp(0.0, 65535.0) as i64;
        // The rounding of the division can land one step off: take the best neighbour.
        let value = |q: i64| (q as f32) * interval + lo[d];
        (q - 1..=q + 1)
            .filter(|q| (0..=65535).contains(q))
            .min_by(|&a, &b| (value(a) - p[d]).abs().total_cmp(&(value(b) - p[d]).abs()))
            .expect("q itself is in range") as u16
    })
}

/// Mean and standard deviation of each channel of `values` (`channels` per anchor), the
/// deviation at least `floor`.
fn channel_stats(values: &[f32], channels: usize, floor: f32) -> Vec<(f32, f32)> {
    let n = (values.len() / channels).max(1) as f64;
    (0..channels)
        .map(|ch| {
            let col = values
                .iter()
                .skip(ch)
                .step_by(channels)
                .map(|&v| f64::from(v));
            let mean = col.clone().sum::<f64>() / n;
            let var = col.map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
            (mean as f32, (var.sqrt() as f32).max(floor))
        })
        .collect()
}

/// `AHAC` anchors for `c` with the per-channel prior and `steps` (feature, log-scaling,
/// offsets). Refuses non-finite values and steps, and steps so fine for the values' range that
/// a batch's alphabet passes §6.13.7's 2^16.
pub fn prior_anchors(c: &ScaffoldCanonical, steps: [f32; 3]) -> Result<HacAnchors> {
    if steps.iter().any(|q| !(q.is_finite() && *q > 0.0)) {
        return Err(Error::input(format!(
            "anchor steps {steps:?}: each must be finite and > 0"
        )));
    }
    let all = c.joined();
    let attrs: [&[f32]; 3] = [&all.features, &all.log_scalings, &all.offsets];
    let bad = |v: &f32| !v.is_finite();
    if all.positions.iter().flatten().any(bad) || attrs.iter().any(|a| a.iter().any(bad)) {
        return Err(Error::input(
            "Scaffold-GS anchors with NaN or infinite values cannot be HAC-coded",
        ));
    }
    let (lo, hi) = bounds(&all.positions);
    let quantized = all
        .positions
        .iter()
        .map(|&p| quantize_position(p, lo, hi))
        .collect();
    let mut b2 = vec![0f32; CONTEXT_OUT];
    let mut at = 0;
    let mut symbols: [Vec<i32>; 3] = Default::default();
    for a in 0..3 {
        let ch = ATTR_CHANNELS[a];
        let stats = channel_stats(attrs[a], ch, steps[a] * 0.25);
        for (k, (mean, sd)) in stats.into_iter().enumerate() {
            b2[at + k] = mean;
            b2[at + ch + k] = sd;
        }
        at += 2 * ch;
        symbols[a] = attrs[a]
            .iter()
            .map(|&v| {
                let x = (v / steps[a]).round();
                if x.abs() > 8_000_000.0 {
                    return Err(Error::input(format!(
                        "anchor step {} is too fine for value {v} (attribute {a})",
                        steps[a]
                    )));
                }
                Ok(x as i32)
            })
            .collect::<Result<_>>()?;
    }
    let grid3 = GridShape {
        resolutions: vec![3],
        log2_table: 1,
        features: 1,
    };
    let grid2 = GridShape {
        resolutions: Vec::new(),
        log2_table: 1,
        features: 1,
    };
    let bits = HacContext::level_bits(&grid3, &grid2);
    let context = HacContext {
        grid3,
        grid2,
        bound_min: lo,
        bound_max: hi,
        q_base: steps,
        levels: bits.iter().map(|&n| bitvec![u64, Lsb0; 0; n]).collect(),
        hidden: 1,
        w1: vec![0.0],
        b1: vec![1.0],
        w2: vec![0.0; CONTEXT_OUT],
        b2,
    };
    context.validate().map_err(Error::input)?;
    let hac = HacAnchors {
        n_static: c.statics.len() as u32,
        n_dynamic: c.dynamics.len() as u32,
        batch: REFERENCE_BATCH,
        context,
        quantized,
        symbols,
    };
    check_alphabets(&hac)?;
    Ok(hac)
}

/// Every batch's alphabet within §6.13.7's 2^16 symbols.
fn check_alphabets(h: &HacAnchors) -> Result<()> {
    for a in 0..3 {
        let per_batch = h.batch as usize * ATTR_CHANNELS[a];
        for (b, s) in h.symbols[a].chunks(per_batch).enumerate() {
            let (lo, hi) = (s.iter().min(), s.iter().max());
            if let (Some(&lo), Some(&hi)) = (lo, hi) {
                if i64::from(hi) - i64::from(lo) + 1 > 1 << 16 {
                    return Err(Error::input(format!(
                        "anchor step {} is too fine: batch {b} of attribute {a} spans {} \
                         steps (at most 65,536); use a coarser step",
                        h.context.q_base[a],
                        i64::from(hi) - i64::from(lo) + 1
                    )));
                }
            }
        }
    }
    Ok(())
}
