//! How much each Gaussian adds to the colour images of a set of views: the sum over pixels of
//! its blending weight `a T` (the compositing rule of [`crate::raster`]). A Gaussian whose total
//! is small can be dropped with little change to those views (LightGaussian's "global
//! significance"); one with zero total is never drawn by them.
//!
//! Scalar and per tile, so it is exact to the rule rather than fast; tiles are summed in tile
//! order, so the result does not depend on the thread count.

use rayon::prelude::*;

use crate::camera::Camera;
use crate::fastexp::exp_neg;
use crate::project::{project_all, Splat2d, ALPHA_MIN};
use crate::raster::{bin_tiles, tile_rect, ALPHA_MAX, T_MIN};
use dlgs::Gaussians;

/// Per Gaussian, its blending weight summed over every pixel of every view (in pixels).
pub fn contributions(g: &Gaussians, cams: &[Camera]) -> Vec<f64> {
    let mut total = vec![0.0f64; g.len()];
    for cam in cams {
        let splats = project_all(g, cam, false);
        let lists = bin_tiles(&splats, cam.width, cam.height);
        let per_tile: Vec<Vec<f64>> = lists
            .par_iter()
            .enumerate()
            .map(|(i, list)| {
                let (x0, y0, w, h) = tile_rect(cam.width, cam.height, i);
                tile_weights(&splats, list, x0, y0, w, h)
            })
            .collect();
        for (list, weights) in lists.iter().zip(per_tile) {
            for (&k, wgt) in list.iter().zip(weights) {
                total[splats[k as usize].index as usize] += wgt;
            }
        }
    }
    total
}

/// Blending weight of each splat of `list` over the tile's pixels, in list order.
fn tile_weights(splats: &[Splat2d], list: &[u32], x0: u32, y0: u32, w: u32, h: u32) -> Vec<f64> {
    let mut sums = vec![0.0f32; list.len()];
    for_each_weight(splats, list, (x0, y0, w, h), |slot, _, _, wgt| {
        sums[slot] += wgt
    });
    sums.into_iter().map(f64::from).collect()
}

/// `visit(slot in list, x, y, blending weight a T)` for every pixel of the tile
/// `(x0, y0, w, h)` that a splat of `list` (in depth order) adds to, by the compositing rule of
/// [`crate::raster`]. Scalar, so exact to the rule rather than fast.
pub fn for_each_weight(
    splats: &[Splat2d],
    list: &[u32],
    rect: (u32, u32, u32, u32),
    mut visit: impl FnMut(usize, u32, u32, f32),
) {
    for_each_blend(splats, list, rect, |slot, x, y, a, t| {
        visit(slot, x, y, a * t)
    });
}

/// [`for_each_weight`] with the weight's two factors: `visit(slot, x, y, alpha a,
/// transmittance T before this splat)`.
pub fn for_each_blend(
    splats: &[Splat2d],
    list: &[u32],
    (x0, y0, w, h): (u32, u32, u32, u32),
    mut visit: impl FnMut(usize, u32, u32, f32, f32),
) {
    let mut t = vec![1.0f32; (w * h) as usize];
    // Pixels finished so far: once all are, no later splat adds to the tile (the raster's
    // early stop; on the opaque donut most of the fit's time was spent after it).
    let mut finished = 0usize;
    // The same per row: a splat skips the rows of the tile that are finished.
    let mut row_finished = vec![0u32; h as usize];
    for (slot, &k) in list.iter().enumerate() {
        if finished == t.len() {
            break;
        }
        let s = &splats[k as usize];
        let [ca, cb, cc] = s.conic;
        let xs = (s.px[0] as u32).max(x0)..(s.px[2] as u32).min(x0 + w);
        let ys = (s.px[1] as u32).max(y0)..(s.px[3] as u32).min(y0 + h);
        for y in ys {
            if row_finished[(y - y0) as usize] == w {
                continue;
            }
            let dy = y as f32 - s.mean[1];
            for x in xs.clone() {
                let p = ((y - y0) * w + (x - x0)) as usize;
                if t[p] < T_MIN {
                    continue;
                }
                let dx = x as f32 - s.mean[0];
                let power = (-0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy).min(0.0);
                let a = (s.opacity * exp_neg(power)).min(ALPHA_MAX);
                if a < ALPHA_MIN {
                    continue;
                }
                let next = t[p] * (1.0 - a);
                if next < T_MIN {
                    // The pixel is finished; this Gaussian is not added (the raster rule).
                    t[p] = 0.0;
                    finished += 1;
                    row_finished[(y - y0) as usize] += 1;
                    continue;
                }
                visit(slot, x, y, a, t[p]);
                t[p] = next;
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::camera::{orbit_cameras, OrbitSpec};

    /// Opaque small Gaussians along a curve (also the colour fit's test scene).
    pub(crate) fn blob(n: usize) -> Gaussians {
        let mut g = Gaussians::new(0, 0);
        for i in 0..n {
            let f = i as f32 / n as f32;
            g.positions
                .push([f - 0.5, (f * 7.0).sin() * 0.3, (f * 3.0).cos() * 0.3]);
            g.log_scales.push([-3.0; 3]);
            g.rotations.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity.push(2.0);
            g.sh.extend_from_slice(&[0.5, 0.2, 0.1]);
        }
        g
    }

    #[test]
    fn invisible_gaussians_contribute_nothing_and_totals_match_the_image() {
        let mut g = blob(200);
        g.opacity[7] = -8.0; // sigmoid < 1/255: never drawn
        let spec = OrbitSpec {
            count: 3,
            width: 96,
            height: 72,
            ..OrbitSpec::default()
        };
        let cams = orbit_cameras(&g, &spec);
        let c = contributions(&g, &cams);
        assert_eq!(c[7], 0.0);
        assert!(c.iter().filter(|&&v| v > 0.0).count() > 150);
        // Sum of weights = drawn coverage = pixels * (1 - transmittance), per view.
        let covered: f64 = cams
            .iter()
            .map(|cam| {
                let img = crate::render(&g, cam, &Default::default()).unwrap();
                img.transmittance
                    .iter()
                    .map(|&t| 1.0 - t as f64)
                    .sum::<f64>()
            })
            .sum();
        let total: f64 = c.iter().sum();
        assert!(
            (total - covered).abs() < 1e-3 * covered,
            "{total} vs {covered}"
        );
    }

    #[test]
    fn finished_pixels_and_rows_end_the_walk_without_changing_the_totals() {
        // Opaque Gaussians stacked along the view axis: most pixels they cover finish (the
        // walk then skips those rows and tiles), and the totals still match the image.
        let mut g = blob(400);
        for (i, p) in g.positions.iter_mut().enumerate() {
            p[0] = (i % 20) as f32 * 0.01 - 0.1;
            p[1] = (i / 20 % 5) as f32 * 0.01;
        }
        g.opacity.iter_mut().for_each(|o| *o = 9.0);
        let cams = orbit_cameras(
            &g,
            &OrbitSpec {
                count: 2,
                width: 96,
                height: 72,
                ..OrbitSpec::default()
            },
        );
        let c = contributions(&g, &cams);
        let mut finished = 0;
        let covered: f64 = cams
            .iter()
            .map(|cam| {
                let img = crate::render(&g, cam, &Default::default()).unwrap();
                // A finished pixel keeps the transmittance it stopped at (>= T_MIN).
                finished += img.transmittance.iter().filter(|&&t| t < 1e-3).count();
                img.transmittance
                    .iter()
                    .map(|&t| 1.0 - t as f64)
                    .sum::<f64>()
            })
            .sum();
        assert!(finished > 100, "{finished} finished pixels");
        let total: f64 = c.iter().sum();
        assert!(
            (total - covered).abs() < 1e-4 * covered,
            "{total} vs {covered}"
        );
    }

    #[test]
    fn same_result_on_any_thread_count() {
        let g = blob(300);
        let cams = orbit_cameras(
            &g,
            &OrbitSpec {
                count: 2,
                width: 64,
                height: 48,
                ..OrbitSpec::default()
            },
        );
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let a = one.install(|| contributions(&g, &cams));
        let b = contributions(&g, &cams);
        assert_eq!(a, b);
    }
}
