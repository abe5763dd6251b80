//! From per-pixel relevance to a mask, as the reference evaluation does it
//! (`activate_stream_2`, `--mask_threshold 0.4`, `--chose_mask_strategy mean`):
//!
//! 1. `R' = 0.5 (R + mean_k(R))`, `k x k` mean with stride 1, border windows averaging only
//!    the pixels inside the image (`count_include_pad=False`);
//! 2. `o = (R' - min R') / (max R' - min R' + 1e-9)`, then `o = clamp(2o - 1, 0, 1)`;
//! 3. prediction `o > threshold`;
//! 4. smoothing: the `s x s` mean of the prediction, zero-padded and divided by `s^2`
//!    (`AvgPool2d` with its default `count_include_pad=True`), `> 0.5`.
//!
//! The level is the one with the largest mean of `R'` inside `o > threshold` (0 if empty).

use rayon::prelude::*;

use crate::relevance::RelevanceField;

/// Mask parameters (the reference's values by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaskParams {
    pub mean_kernel: usize,
    pub threshold: f32,
    pub smooth_kernel: usize,
    /// Force a level (0-based) instead of choosing by score.
    pub level: Option<usize>,
    /// The mask is empty when the chosen level's score is below this. Not in the reference:
    /// its min-max normalisation stretches an image where the text wins nowhere (relevance
    /// ~0.1 everywhere) to a full mask; 0.5 = "the text beats the negatives". 0 = reference.
    pub min_score: f32,
}

impl Default for MaskParams {
    fn default() -> Self {
        MaskParams {
            mean_kernel: 29,
            threshold: 0.4,
            smooth_kernel: 7,
            level: None,
            min_score: 0.5,
        }
    }
}

/// One level's maps.
#[derive(Debug, Clone)]
pub struct LevelMaps {
    /// Raw relevance `R`.
    pub relevance: Vec<f32>,
    /// `R'` (step 1).
    pub filtered: Vec<f32>,
    /// `o` (step 2).
    pub normalised: Vec<f32>,
    /// Mean of `R'` where `o > threshold`.
    pub score: f32,
}

/// The answer to one positive on one image.
#[derive(Debug, Clone)]
pub struct ImageQuery {
    pub width: usize,
    pub height: usize,
    pub levels: Vec<LevelMaps>,
    /// Chosen level (0-based).
    pub level: usize,
    /// Smoothed mask of the chosen level.
    pub mask: Vec<bool>,
}

/// Box sums over `k x k` windows centred on each pixel (k odd), with the number of in-image
/// pixels in each window. Summed-area table in f64 so that sums are exact enough for any size.
fn box_sums(v: &[f32], w: usize, h: usize, k: usize) -> (Vec<f64>, Vec<u32>) {
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0.0f64;
        for x in 0..w {
            row += v[y * w + x] as f64;
            sat[(y + 1) * (w + 1) + x + 1] = sat[y * (w + 1) + x + 1] + row;
        }
    }
    let r = k / 2;
    let mut sums = vec![0.0f64; w * h];
    let mut counts = vec![0u32; w * h];
    for y in 0..h {
        let (y0, y1) = (y.saturating_sub(r), (y + r + 1).min(h));
        for x in 0..w {
            let (x0, x1) = (x.saturating_sub(r), (x + r + 1).min(w));
            let s = sat[y1 * (w + 1) + x1] - sat[y0 * (w + 1) + x1] - sat[y1 * (w + 1) + x0]
                + sat[y0 * (w + 1) + x0];
            sums[y * w + x] = s;
            counts[y * w + x] = ((y1 - y0) * (x1 - x0)) as u32;
        }
    }
    (sums, counts)
}

/// Steps 1-2 and the level score for one relevance map.
pub fn level_maps(relevance: Vec<f32>, w: usize, h: usize, p: &MaskParams) -> LevelMaps {
    let (sums, counts) = box_sums(&relevance, w, h, p.mean_kernel.max(1) | 1);
    let filtered: Vec<f32> = relevance
        .iter()
        .zip(sums.iter().zip(&counts))
        .map(|(&r, (&s, &c))| 0.5 * (r + (s / c as f64) as f32))
        .collect();
    let lo = filtered.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = filtered.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let span = hi - lo + 1e-9;
    let normalised: Vec<f32> = filtered
        .iter()
        .map(|&v| (2.0 * ((v - lo) / span) - 1.0).clamp(0.0, 1.0))
        .collect();
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (&o, &f) in normalised.iter().zip(&filtered) {
        if o > p.threshold {
            sum += f as f64;
            n += 1;
        }
    }
    LevelMaps {
        relevance,
        filtered,
        normalised,
        score: if n > 0 { (sum / n as f64) as f32 } else { 0.0 },
    }
}

/// Step 3-4: threshold and smooth.
pub fn smoothed_mask(normalised: &[f32], w: usize, h: usize, p: &MaskParams) -> Vec<bool> {
    let pred: Vec<f32> = normalised
        .iter()
        .map(|&o| if o > p.threshold { 1.0 } else { 0.0 })
        .collect();
    let k = p.smooth_kernel.max(1) | 1;
    let (sums, _) = box_sums(&pred, w, h, k);
    let full = (k * k) as f64;
    sums.iter().map(|&s| s / full > 0.5).collect()
}

/// Steps 5-6: the level (forced, or the first with the largest score) and its smoothed mask,
/// empty when that level's score is below `min_score`.
fn level_and_mask(maps: &[LevelMaps], w: usize, h: usize, p: &MaskParams) -> (usize, Vec<bool>) {
    let level = p.level.unwrap_or_else(|| {
        // First level with the largest score (ties go to the finer level).
        let mut best = 0;
        for (i, m) in maps.iter().enumerate() {
            if m.score > maps[best].score {
                best = i;
            }
        }
        best
    });
    let mask = if maps[level].score < p.min_score {
        vec![false; w * h]
    } else {
        smoothed_mask(&maps[level].normalised, w, h, p)
    };
    (level, mask)
}

/// Answer every positive of `field` on a rendered language image: `features` holds
/// `levels * dims` values per pixel (level-major within a pixel, as rendered).
pub fn query_levels(
    features: &[f32],
    width: usize,
    height: usize,
    levels: usize,
    dims: usize,
    field: &RelevanceField,
    params: &MaskParams,
) -> Vec<ImageQuery> {
    let n = width * height;
    let k = field.positives();
    if dims == 3 {
        field.prepare(features);
    }
    // Relevance per level for every positive: [level][pixel * k + positive].
    let per_level: Vec<Vec<f32>> = (0..levels)
        .into_par_iter()
        .map(|l| {
            let mut f = Vec::with_capacity(n * dims);
            for px in features.chunks_exact(levels * dims) {
                f.extend_from_slice(&px[l * dims..(l + 1) * dims]);
            }
            field.relevance(&f)
        })
        .collect();
    (0..k)
        .map(|q| {
            let maps: Vec<LevelMaps> = per_level
                .par_iter()
                .map(|r| {
                    let rel: Vec<f32> = r.chunks_exact(k).map(|c| c[q]).collect();
                    level_maps(rel, width, height, params)
                })
                .collect();
            let (level, mask) = level_and_mask(&maps, width, height, params);
            ImageQuery {
                width,
                height,
                levels: maps,
                level,
                mask,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 64x48 relevance image: `inside` in a 20x16 block, `outside` elsewhere, plus a
    /// deterministic ripple so that min-max normalisation has something to stretch.
    fn image(inside: f32, outside: f32) -> Vec<f32> {
        (0..64 * 48)
            .map(|i| {
                let (x, y) = (i % 64, i / 64);
                let base = if (20..40).contains(&x) && (16..32).contains(&y) {
                    inside
                } else {
                    outside
                };
                base + 0.002 * ((i * 7919 % 13) as f32 / 13.0)
            })
            .collect()
    }

    #[test]
    fn a_visible_object_is_masked_and_an_absent_one_is_not() {
        let p = MaskParams {
            mean_kernel: 1,
            ..MaskParams::default()
        };
        let visible = [level_maps(image(0.95, 0.1), 64, 48, &p)];
        let (_, mask) = level_and_mask(&visible, 64, 48, &p);
        let on = mask.iter().filter(|&&m| m).count();
        assert!(
            (300..=320).contains(&on),
            "{on} pixels for a 320-pixel object"
        );
        assert!(visible[0].score > 0.9);

        // Relevance ~0.1 everywhere: the reference's normalisation would mask the ripple.
        let absent = [level_maps(image(0.11, 0.1), 64, 48, &p)];
        assert!(absent[0].score < 0.2);
        let (_, mask) = level_and_mask(&absent, 64, 48, &p);
        assert!(mask.iter().all(|&m| !m));
        let reference = MaskParams {
            min_score: 0.0,
            ..p
        };
        let (_, mask) = level_and_mask(&absent, 64, 48, &reference);
        assert!(mask.iter().filter(|&&m| m).count() > 100);
    }

    #[test]
    fn the_level_with_the_best_score_wins_and_can_be_forced() {
        let p = MaskParams {
            mean_kernel: 1,
            ..MaskParams::default()
        };
        let maps = [
            level_maps(image(0.6, 0.1), 64, 48, &p),
            level_maps(image(0.9, 0.1), 64, 48, &p),
            level_maps(image(0.9, 0.1), 64, 48, &p),
        ];
        assert_eq!(level_and_mask(&maps, 64, 48, &p).0, 1);
        let forced = MaskParams {
            level: Some(0),
            ..p
        };
        assert_eq!(level_and_mask(&maps, 64, 48, &forced).0, 0);
    }
}
