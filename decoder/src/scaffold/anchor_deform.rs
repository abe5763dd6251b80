//! Dynamic anchors at a time (§5.2 of ../shared/reference; format-spec to follow): the four
//! bias-free MLPs read the anchor's time features, linearly interpolated between two keys, and
//! offset its position, feature, offsets and log-scalings.

use rayon::prelude::*;

use dlgs::model::scaffold::{
    AnchorDeformMlps, Anchors, FEAT_DIM, N_OFFSETS, SCALING_DIM, TIME_CHANNELS,
};
use dlgs::model::TimeFeatures;

use super::mlp::eval;

/// Rows per parallel block (fixed: the result does not depend on the thread count).
const BLOCK: usize = 256;

/// One anchor's offsets: position, feature, offsets, log-scalings.
struct Delta {
    a: usize,
    dp: [f32; 3],
    df: Vec<f32>,
    doff: Vec<f32>,
    ds: Vec<f32>,
}

/// The dynamic anchors deformed at key pair (`key`, `key + 1`) and fraction `delta`:
/// `F = F_k (1-δ) + F_k1 δ` per channel, then
/// `position += xyz(F ‖ (a - min) / (max - min))`, `feature += cov(F)`,
/// `offsets += opacity(F)`, `log_scalings += color(F)` (the reference's names). `bounds` are
/// the model's `x_bound_min`, `x_bound_max`; the normalised anchor is the canonical one.
pub fn deform_anchors(
    anchors: &Anchors,
    features: &TimeFeatures,
    key: usize,
    delta: f32,
    mlps: &AnchorDeformMlps,
    bounds: ([f32; 3], [f32; 3]),
) -> Anchors {
    let n = anchors.len();
    let mut out = anchors.clone();
    let (lo, hi) = bounds;
    let hidden = [&mlps.position, &mlps.feature, &mlps.offsets, &mlps.scaling]
        .iter()
        .map(|m| m.first.outputs)
        .max()
        .unwrap_or(0);
    let rows: Vec<usize> = (0..n).collect();
    let deltas: Vec<Delta> = rows
        .par_chunks(BLOCK)
        .flat_map_iter(|ids| {
            let mut h = vec![0f32; hidden];
            ids.iter()
                .map(|&a| {
                    let (fk, fk1) = (features.at(a, key), features.at(a, key + 1));
                    let mut x = [0f32; TIME_CHANNELS + 3];
                    for c in 0..TIME_CHANNELS {
                        x[c] = fk[c] * (1.0 - delta) + fk1[c] * delta;
                    }
                    let p = anchors.positions[a];
                    for d in 0..3 {
                        x[TIME_CHANNELS + d] = (p[d] - lo[d]) / (hi[d] - lo[d]);
                    }
                    let mut dp = [0f32; 3];
                    eval(&mlps.position, &x, &mut h, &mut dp);
                    let f = &x[..TIME_CHANNELS];
                    let mut df = vec![0f32; FEAT_DIM];
                    eval(&mlps.feature, f, &mut h, &mut df);
                    let mut doff = vec![0f32; 3 * N_OFFSETS];
                    eval(&mlps.offsets, f, &mut h, &mut doff);
                    let mut ds = vec![0f32; SCALING_DIM];
                    eval(&mlps.scaling, f, &mut h, &mut ds);
                    Delta {
                        a,
                        dp,
                        df,
                        doff,
                        ds,
                    }
                })
                .collect::<Vec<_>>()
        })
        .collect();
    for Delta {
        a,
        dp,
        df,
        doff,
        ds,
    } in deltas
    {
        for d in 0..3 {
            out.positions[a][d] += dp[d];
        }
        for (v, d) in out.features[a * FEAT_DIM..(a + 1) * FEAT_DIM]
            .iter_mut()
            .zip(&df)
        {
            *v += d;
        }
        let o = a * 3 * N_OFFSETS;
        for (v, d) in out.offsets[o..o + 3 * N_OFFSETS].iter_mut().zip(&doff) {
            *v += d;
        }
        for (v, d) in out.log_scalings[a * SCALING_DIM..(a + 1) * SCALING_DIM]
            .iter_mut()
            .zip(&ds)
        {
            *v += d;
        }
    }
    out
}
