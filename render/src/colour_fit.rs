//! Colour offsets that make one set of Gaussians render like target images, its geometry held
//! fixed: with positions, shapes and opacities fixed, a pixel's colour is linear in the
//! Gaussians' colours (`C = sum_i w_i c_i + T bg`, `w_i = a_i T_i`), so the offsets that best
//! match the targets over a set of views solve a linear least-squares problem. The encoder's
//! colour refit uses it to let the stored colours absorb part of the error that quantising the
//! geometry made.
//!
//! Solved by CGLS (conjugate gradients on the normal equations, Jacobi-preconditioned, damped),
//! each colour channel on its own, a few iterations from zero: damping and stopping early keep
//! offsets small where the views say little. The `max(0, .)` of SH colour is ignored by the
//! linear model.
//!
//! Deterministic: tiles are composited in parallel but summed in tile order.

use rayon::prelude::*;

use crate::camera::Camera;
use crate::contribution::for_each_weight;
use crate::project::{project_all, Splat2d};
use crate::raster::{bin_tiles, tile_rect};
use dlgs::Gaussians;

/// One view's projected Gaussians and tile lists, computed once (the geometry does not move).
struct View {
    width: u32,
    height: u32,
    splats: Vec<Splat2d>,
    lists: Vec<Vec<u32>>,
}

impl View {
    fn new(g: &Gaussians, cam: &Camera) -> View {
        let splats = project_all(g, cam, false);
        let lists = bin_tiles(&splats, cam.width, cam.height);
        View {
            width: cam.width,
            height: cam.height,
            splats,
            lists,
        }
    }

    fn tile_rect(&self, i: usize) -> (u32, u32, u32, u32) {
        tile_rect(self.width, self.height, i)
    }

    /// The image pixel of pixel `l` (row-major) of the tile at `rect` ([`Self::tile_rect`]).
    fn tile_pixel(&self, (x0, y0, w, _): (u32, u32, u32, u32), l: usize) -> usize {
        let (lx, ly) = (l as u32 % w, l as u32 / w);
        ((y0 + ly) * self.width + x0 + lx) as usize
    }

    /// Adds tile `i`'s per-slot sums (colour, squared weight) to their Gaussians' `out` and
    /// `diag`, in list order.
    fn add_tile_sums(
        &self,
        i: usize,
        sums: Vec<([f64; 3], f64)>,
        out: &mut [[f64; 3]],
        diag: &mut Option<&mut [f64]>,
    ) {
        for (&k, (s, d)) in self.lists[i].iter().zip(sums) {
            let g = self.splats[k as usize].index as usize;
            for ch in 0..3 {
                out[g][ch] += s[ch];
            }
            if let Some(diag) = diag.as_deref_mut() {
                diag[g] += d;
            }
        }
    }

    /// `visit(slot in list, pixel index in the image, blending weight)` for every pixel a
    /// splat of tile `i` adds to ([`for_each_weight`]).
    fn walk_tile(&self, i: usize, mut visit: impl FnMut(usize, usize, f32)) {
        let width = self.width;
        for_each_weight(
            &self.splats,
            &self.lists[i],
            self.tile_rect(i),
            |slot, x, y, wgt| visit(slot, (y * width + x) as usize, wgt),
        );
    }

    /// The image `sum_i w_i x_i` (3 channels, no background) of per-Gaussian colours `x`.
    fn forward(&self, x: &[[f32; 3]]) -> Vec<f32> {
        let tiles: Vec<Vec<[f32; 3]>> = (0..self.lists.len())
            .into_par_iter()
            .map(|i| {
                let (x0, y0, w, h) = self.tile_rect(i);
                let mut acc = vec![[0.0f32; 3]; (w * h) as usize];
                let list = &self.lists[i];
                for_each_weight(&self.splats, list, (x0, y0, w, h), |slot, px, py, wgt| {
                    let c = &x[self.splats[list[slot] as usize].index as usize];
                    let a = &mut acc[((py - y0) * w + (px - x0)) as usize];
                    for ch in 0..3 {
                        a[ch] += wgt * c[ch];
                    }
                });
                acc
            })
            .collect();
        let mut img = vec![0.0f32; (self.width * self.height * 3) as usize];
        for (i, acc) in tiles.iter().enumerate() {
            let rect = self.tile_rect(i);
            for (l, c) in acc.iter().enumerate() {
                let p = self.tile_pixel(rect, l);
                img[p * 3..p * 3 + 3].copy_from_slice(c);
            }
        }
        img
    }

    /// The residual image `b - sum_i w_i x_i` ([`Self::forward`]), with its [`Self::backward`]
    /// added to `out` (and `diag`), from one walk of each tile instead of two: a tile's
    /// residual depends on that tile's pixels only. The same floats as the two calls.
    fn residual_and_backward(
        &self,
        x: &[[f32; 3]],
        b: &[f32],
        out: &mut [[f64; 3]],
        mut diag: Option<&mut [f64]>,
    ) -> Vec<f32> {
        type TileResult = (Vec<[f32; 3]>, Vec<([f64; 3], f64)>);
        let tiles: Vec<TileResult> = (0..self.lists.len())
            .into_par_iter()
            .map(|i| {
                let (x0, y0, w, h) = self.tile_rect(i);
                let list = &self.lists[i];
                let mut visits: Vec<(u32, u32, f32)> = Vec::new();
                let mut acc = vec![[0.0f32; 3]; (w * h) as usize];
                for_each_weight(&self.splats, list, (x0, y0, w, h), |slot, px, py, wgt| {
                    let l = (py - y0) * w + (px - x0);
                    visits.push((slot as u32, l, wgt));
                    let c = &x[self.splats[list[slot] as usize].index as usize];
                    let a = &mut acc[l as usize];
                    for ch in 0..3 {
                        a[ch] += wgt * c[ch];
                    }
                });
                // acc becomes the tile's residual.
                for (l, a) in acc.iter_mut().enumerate() {
                    let p = self.tile_pixel((x0, y0, w, h), l);
                    for ch in 0..3 {
                        a[ch] = b[p * 3 + ch] - a[ch];
                    }
                }
                let mut sums = vec![([0.0f64; 3], 0.0f64); list.len()];
                for &(slot, l, wgt) in &visits {
                    let s = &mut sums[slot as usize];
                    for ch in 0..3 {
                        s.0[ch] += (wgt * acc[l as usize][ch]) as f64;
                    }
                    s.1 += (wgt * wgt) as f64;
                }
                (acc, sums)
            })
            .collect();
        let mut r = vec![0.0f32; (self.width * self.height * 3) as usize];
        for (i, (res, sums)) in tiles.into_iter().enumerate() {
            let rect = self.tile_rect(i);
            for (l, c) in res.iter().enumerate() {
                let p = self.tile_pixel(rect, l);
                r[p * 3..p * 3 + 3].copy_from_slice(c);
            }
            self.add_tile_sums(i, sums, out, &mut diag);
        }
        r
    }

    /// Adds `sum_p w_ip r_p` to `out[i]` (and `sum_p w_ip^2` to `diag[i]` when given) for every
    /// Gaussian `i`, for the 3-channel image `r`.
    fn backward(&self, r: &[f32], out: &mut [[f64; 3]], mut diag: Option<&mut [f64]>) {
        let per_tile: Vec<Vec<([f64; 3], f64)>> = (0..self.lists.len())
            .into_par_iter()
            .map(|i| {
                let mut sums = vec![([0.0f64; 3], 0.0f64); self.lists[i].len()];
                self.walk_tile(i, |slot, p, wgt| {
                    let s = &mut sums[slot];
                    for ch in 0..3 {
                        s.0[ch] += (wgt * r[p * 3 + ch]) as f64;
                    }
                    s.1 += (wgt * wgt) as f64;
                });
                sums
            })
            .collect();
        for (i, sums) in per_tile.into_iter().enumerate() {
            self.add_tile_sums(i, sums, out, &mut diag);
        }
    }
}

/// Per-Gaussian colour offsets (added to every view's colour) that bring `g`'s renders from
/// `cams` closer to `targets` (one 3-channel image per camera, background included, as
/// [`crate::render`] gives), after `iterations` CGLS steps. `background` is the renders'.
pub fn fit_colour_offsets(
    g: &Gaussians,
    cams: &[Camera],
    targets: &[Vec<f32>],
    background: [f32; 3],
    iterations: usize,
    damping: f64,
) -> Vec<[f32; 3]> {
    assert_eq!(cams.len(), targets.len(), "one target per camera");
    let views: Vec<View> = cams.iter().map(|c| View::new(g, c)).collect();
    let n = g.len();
    // b = target - current render, per view.
    let mut resid: Vec<Vec<f32>> = Vec::with_capacity(views.len());
    for (cam, target) in cams.iter().zip(targets) {
        let img = crate::render(
            g,
            cam,
            &crate::RenderOptions {
                background,
                features: false,
                ..Default::default()
            },
        )
        .expect("renderable camera");
        resid.push(target.iter().zip(&img.color).map(|(t, c)| t - c).collect());
    }
    let mut s = vec![[0.0f64; 3]; n];
    let mut diag = vec![0.0f64; n];
    for (v, r) in views.iter().zip(&resid) {
        v.backward(r, &mut s, Some(&mut diag));
    }
    // Minimise |A x - b|^2 + damping |x|^2. Jacobi scaling: y = sqrt(M) x with
    // M = diag(A^T A) + damping, so A' = A M^-1/2 and the damping term is |L y|^2 with
    // L = sqrt(damping) M^-1/2 (the stacked system [A'; L] y = [b; 0]).
    let scale: Vec<f64> = diag
        .iter()
        .map(|&d| {
            if d > 1e-12 {
                1.0 / (d + damping).sqrt()
            } else {
                0.0
            }
        })
        .collect();
    for (si, sc) in s.iter_mut().zip(&scale) {
        si.iter_mut().for_each(|v| *v *= sc);
    }
    let mut y = vec![[0.0f64; 3]; n];
    let mut p = s.clone();
    let mut gamma = norms(&s);
    for _ in 0..iterations {
        if gamma.iter().all(|&v| v <= 0.0) {
            break;
        }
        // q = A' p, per view.
        let px: Vec<[f32; 3]> = p
            .iter()
            .zip(&scale)
            .map(|(v, sc)| v.map(|c| (c * sc) as f32))
            .collect();
        let qs: Vec<Vec<f32>> = views.iter().map(|v| v.forward(&px)).collect();
        let mut qq = [0.0f64; 3];
        for q in &qs {
            for (k, v) in q.iter().enumerate() {
                qq[k % 3] += (*v as f64) * (*v as f64);
            }
        }
        for (pi, sc) in p.iter().zip(&scale) {
            for c in 0..3 {
                qq[c] += damping * sc * sc * pi[c] * pi[c];
            }
        }
        let alpha: [f64; 3] =
            std::array::from_fn(|c| if qq[c] > 0.0 { gamma[c] / qq[c] } else { 0.0 });
        for (yi, pi) in y.iter_mut().zip(&p) {
            for c in 0..3 {
                yi[c] += alpha[c] * pi[c];
            }
        }
        for (r, q) in resid.iter_mut().zip(&qs) {
            for (k, (rv, qv)) in r.iter_mut().zip(q).enumerate() {
                *rv -= (alpha[k % 3] * *qv as f64) as f32;
            }
        }
        let mut s = vec![[0.0f64; 3]; n];
        for (v, r) in views.iter().zip(&resid) {
            v.backward(r, &mut s, None);
        }
        for ((si, sc), yi) in s.iter_mut().zip(&scale).zip(&y) {
            for c in 0..3 {
                si[c] = si[c] * sc - damping * sc * sc * yi[c];
            }
        }
        let next = norms(&s);
        let beta: [f64; 3] = std::array::from_fn(|c| {
            if gamma[c] > 0.0 {
                next[c] / gamma[c]
            } else {
                0.0
            }
        });
        for (pi, si) in p.iter_mut().zip(&s) {
            for c in 0..3 {
                pi[c] = si[c] + beta[c] * pi[c];
            }
        }
        gamma = next;
    }
    y.iter()
        .zip(&scale)
        .map(|(v, sc)| v.map(|c| (c * sc) as f32))
        .collect()
}

/// Colour offsets on a lattice: Gaussian `i`'s channel `c` may only move by whole steps
/// `steps[i][c]` (its quantiser's step, in colour; 0 = it stays), within `moves[i][c]` steps.
/// Starts from `offsets` (the continuous fit's) rounded to steps, then sweeps `sweeps` times
/// over [`LATTICE_GROUPS`] interleaved groups of Gaussians: each group moves by one step every
/// Gaussian whose own best move (the rest held) is more than half a step, then the residual is
/// computed again for the next group. Rounding each offset alone loses most of what the fit
/// found where steps are wide; moving a few Gaussians at a time lets overlapping ones share
/// the correction instead of all overshooting together. Returns the best moves found by the
/// damped objective (the rounding if no sweep improved on it).
#[allow(clippy::too_many_arguments)]
pub fn snap_colour_offsets(
    g: &Gaussians,
    cams: &[Camera],
    targets: &[Vec<f32>],
    background: [f32; 3],
    offsets: &[[f32; 3]],
    steps: &[[f32; 3]],
    moves: &[[(i32, i32); 3]],
    sweeps: usize,
    damping: f64,
) -> Vec<[i32; 3]> {
    let n = g.len();
    assert!(offsets.len() == n && steps.len() == n && moves.len() == n);
    assert_eq!(cams.len(), targets.len(), "one target per camera");
    let views: Vec<View> = cams.iter().map(|c| View::new(g, c)).collect();
    let opts = crate::RenderOptions {
        background,
        features: false,
        ..Default::default()
    };
    // b = target - current render, per view.
    let base: Vec<Vec<f32>> = cams
        .iter()
        .zip(targets)
        .map(|(cam, target)| {
            let img = crate::render(g, cam, &opts).expect("renderable camera");
            target.iter().zip(&img.color).map(|(t, c)| t - c).collect()
        })
        .collect();
    let mut m: Vec<[i32; 3]> = (0..n)
        .map(|i| {
            std::array::from_fn(|c| {
                let (lo, hi) = moves[i][c];
                if steps[i][c] > 0.0 {
                    ((offsets[i][c] / steps[i][c]).round() as i32).clamp(lo, hi)
                } else {
                    0
                }
            })
        })
        .collect();
    let mut diag = vec![0.0f64; n];
    let mut best: Option<(f64, Vec<[i32; 3]>)> = None;
    let last = sweeps * LATTICE_GROUPS;
    for step in 0..=last {
        let x: Vec<[f32; 3]> = m
            .iter()
            .zip(steps)
            .map(|(mi, si)| std::array::from_fn(|c| mi[c] as f32 * si[c]))
            .collect();
        // Residual, its objective and A^T r (and, once, diag(A^T A)).
        let mut grad = vec![[0.0f64; 3]; n];
        let mut cost = 0.0f64;
        for (v, b) in views.iter().zip(&base) {
            let r = v.residual_and_backward(&x, b, &mut grad, (step == 0).then_some(&mut diag[..]));
            cost += r.iter().map(|&e| (e as f64) * (e as f64)).sum::<f64>();
        }
        cost += damping
            * x.iter()
                .flat_map(|xi| xi.iter().map(|&v| (v as f64) * (v as f64)))
                .sum::<f64>();
        if best.as_ref().is_none_or(|b| cost < b.0) {
            best = Some((cost, m.clone()));
        }
        if step == last {
            break;
        }
        for i in (step % LATTICE_GROUPS..n).step_by(LATTICE_GROUPS) {
            for c in 0..3 {
                let s = steps[i][c] as f64;
                if s <= 0.0 {
                    continue;
                }
                // This Gaussian's best move alone, in steps: (A^T r - damping x) / (h + damping).
                let want = (grad[i][c] - damping * x[i][c] as f64) / ((diag[i] + damping) * s);
                let (lo, hi) = moves[i][c];
                if want > 0.5 && m[i][c] < hi {
                    m[i][c] += 1;
                } else if want < -0.5 && m[i][c] > lo {
                    m[i][c] -= 1;
                }
            }
        }
    }
    best.expect("the rounding is scored").1
}

/// Interleaved groups of [`snap_colour_offsets`] (Gaussian `i` is in group `i mod 8`): on lod2
/// 8 and 16 groups reach the same objective, all at once (1 group) makes it worse.
pub const LATTICE_GROUPS: usize = 8;

fn norms(v: &[[f64; 3]]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for x in v {
        for c in 0..3 {
            out[c] += x[c] * x[c];
        }
    }
    out
}

#[cfg(test)]
mod tests;
