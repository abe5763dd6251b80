//! How much each Gaussian of a still scene is worth in the grid shaper
//! (`dlgs::chunks::csog::grid_codecs::MAX_MOVE`): a Gaussian that adds little to any image may take a level
//! the entropy coder pays less for, at a larger error.
//!
//! Importance is the Gaussian's blending weight summed over 36 views of its own
//! ([`importance_views`], not the benchmark's), relative to the mean, `u`.
//! Its shaping weight (bits one squared quantisation step of error is worth) is `u /
//! tolerance`: the image error a level change adds scales with the pixels the Gaussian covers.

use dlgs::chunks::csog::QuantBits;
use dlgs::Gaussians;
use dlgs_render::contribution::contributions;

use crate::grid_sort::{grid_order, permute, SortSpec};
pub use crate::judge_views::importance_views;

/// Shaping weight per Gaussian from its summed blending weights (any non-negative unit).
pub fn shaping_weights(blend: &[f64], tolerance: f64) -> Vec<f32> {
    let mean = blend.iter().sum::<f64>() / blend.len().max(1) as f64;
    blend
        .iter()
        .map(|&w| {
            let u = if mean > 0.0 && w > 0.0 { w / mean } else { 0.0 };
            (u / tolerance) as f32
        })
        .collect()
}

/// Shaping weights for a set stored as `parts` ([`tiers`], or one part), in stored order:
/// `blend[order[k]]` is the blending weight of the `k`-th Gaussian of the parts' concatenation.
/// A shaping weight prices one squared quantisation step, and a part `t` bits coarser than
/// the first has steps `2^t` times as large (in positions, which no preset takes below 12
/// bits, so the difference is exact): its weights are `4^t` times larger for the same error
/// in value.
pub fn part_shaping_weights(
    blend: &[f64],
    order: &[u32],
    parts: &[(Gaussians, QuantBits)],
    tolerance: f64,
) -> Vec<f32> {
    let ordered: Vec<f64> = order.iter().map(|&i| blend[i as usize]).collect();
    let mut w = shaping_weights(&ordered, tolerance);
    let first = parts.first().map_or(0, |p| p.1.position);
    let mut start = 0;
    for (g, b) in parts {
        let t = first.saturating_sub(b.position) as i32;
        for x in &mut w[start..start + g.len()] {
            *x *= 4f32.powi(t);
        }
        start += g.len();
    }
    w
}

/// Each Gaussian's blending weight summed over [`importance_views`].
pub fn blend_weights(g: &Gaussians) -> Vec<f64> {
    contributions(g, &importance_views(g))
}

/// Split a still scene's static set into parts (layout 1) by importance: `fractions[j]`
/// (descending, each in (0, 1)) is the share of the summed blending weight held by the least
/// important Gaussians stored `j + 1` bits coarser than `bits` (those of a later, smaller
/// fraction go to the later part). The most important Gaussians are the first part, at `bits`.
/// With `grid_sort`, each part is grid-sorted on its own; empty parts are left out. Also returns
/// the parts' order (indices into `g`).
/// `blend`: [`blend_weights`] of `g`.
pub fn tiers(
    g: &Gaussians,
    blend: &[f64],
    fractions: &[f64],
    sort: SortSpec,
    bits: QuantBits,
    grid_sort: bool,
) -> (Vec<(Gaussians, QuantBits)>, Vec<u32>) {
    assert_eq!(blend.len(), g.len(), "one blending weight per Gaussian");
    // Tier of each Gaussian: how many of the fractions it falls under.
    let mut tier = vec![0usize; g.len()];
    for &f in fractions {
        for i in least_weight(blend, f) {
            tier[i as usize] += 1;
        }
    }
    let mut parts = Vec::new();
    let mut order = Vec::with_capacity(g.len());
    for t in 0..=fractions.len() {
        let idx: Vec<u32> = (0..g.len() as u32)
            .filter(|&i| tier[i as usize] == t)
            .collect();
        if idx.is_empty() && !(t == 0 && g.is_empty()) {
            continue;
        }
        let subset = permute(g, &idx);
        let local = if grid_sort {
            grid_order(&subset, sort)
        } else {
            (0..subset.len() as u32).collect()
        };
        order.extend(local.iter().map(|&j| idx[j as usize]));
        parts.push((permute(&subset, &local), bits.coarser(t as u8)));
    }
    (parts, order)
}

/// Indices (ascending) of the lowest-weight entries that together hold at most `fraction` of
/// the total; ties broken by index, so the choice is deterministic.
pub fn least_weight(blend: &[f64], fraction: f64) -> Vec<u32> {
    let total: f64 = blend.iter().sum();
    let mut by_weight: Vec<u32> = (0..blend.len() as u32).collect();
    by_weight.sort_by(|&a, &b| {
        blend[a as usize]
            .total_cmp(&blend[b as usize])
            .then(a.cmp(&b))
    });
    let mut acc = 0.0;
    let mut low: Vec<u32> = by_weight
        .into_iter()
        .take_while(|&i| {
            acc += blend[i as usize];
            acc <= fraction * total
        })
        .collect();
    low.sort_unstable();
    low
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_weight_takes_the_lightest_up_to_the_fraction() {
        let w = [4.0, 0.0, 1.0, 1.0, 2.0, 0.0];
        // Total 8: 10 % is 0.8 -> only the two never-seen ones; 25 % adds both 1.0s (tie
        // broken by index, both fit); 30 % cannot take the 2.0.
        assert_eq!(least_weight(&w, 0.1), vec![1, 5]);
        assert_eq!(least_weight(&w, 0.25), vec![1, 2, 3, 5]);
        assert_eq!(least_weight(&w, 0.3), vec![1, 2, 3, 5]);
        assert_eq!(least_weight(&w, 0.0), vec![1, 5]);
        // Nothing seen at all: every Gaussian holds none of the (zero) total.
        assert_eq!(least_weight(&[0.0; 3], 0.04), vec![0, 1, 2]);
        assert!(least_weight(&[], 0.5).is_empty());
    }

    #[test]
    fn weights_follow_the_relative_blending_weight() {
        // mean 1.0 over [0, 0.01, 0.25, 3.74].
        let w = shaping_weights(&[0.0, 0.01, 0.25, 3.74], 0.5);
        assert_eq!(w, vec![0.0, 0.02, 0.5, 7.48]);
        assert_eq!(shaping_weights(&[0.0, 0.0], 1.0), vec![0.0; 2]);
    }
}
