//! Draw preparation: the visible Gaussians sorted back to front by view depth (radix sort) and
//! packed, 16 floats each, for the WebGL2 vertex shader.

use wasm_bindgen::prelude::*;

use crate::colour::{eval_sh, heat};
use crate::Player;

#[wasm_bindgen]
impl Player {
    /// Sort the current frame's visible Gaussians back to front for the camera (world-to-camera
    /// rotation `w2c` row-major, centre `c`) and pack 16 floats each for the vertex shader:
    /// [x y z opacity] [cov xx xy xz yy] [cov yz zz - -] [r g b -]. `mode` 0: colour (SH at the
    /// view direction + 0.5, clamped at 0; colour opacity), 1: language relevance as heat
    /// (language opacity). Returns the number packed.
    pub fn prepare_draw(&mut self, w2c: &[f32], c: &[f32], mode: u32) -> u32 {
        let n = self.rows;
        let lang = mode == 1 && self.buf.lang_width > 0 && self.buf.lang_opacity.len() == n;
        if lang {
            self.compute_relevance();
        }
        let (rmin, rmax) = if lang && !self.relevance.is_empty() {
            self.relevance
                .iter()
                .filter(|v| v.is_finite())
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                })
        } else {
            (0.0, 1.0)
        };
        let b = &self.buf;
        self.keys.clear();
        self.order.clear();
        for i in 0..n {
            let p = b.positions[i];
            let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            let z = w2c[6] * d[0] + w2c[7] * d[1] + w2c[8] * d[2];
            let o = if lang {
                b.lang_opacity[i]
            } else {
                b.opacity[i]
            };
            let finite = p
                .iter()
                .chain(&b.log_scales[i])
                .chain(&b.rotations[i])
                .all(|v| v.is_finite())
                && o.is_finite();
            if !(z > 0.2) || !finite || o < -6.0 {
                // o < -6: sigmoid < 1/255 (alpha never reaches the threshold)
                continue;
            }
            // Positive f32 bits sort as the values; far first: invert.
            self.keys.push(!z.to_bits());
            self.order.push(i as u32);
        }
        radix_sort(&mut self.keys, &mut self.order, &mut self.tmp);
        let m = self.order.len();
        self.splats.resize(m * 16, 0.0);
        let coeffs = (b.sh_degree as usize + 1).pow(2);
        let stride = coeffs * 3;
        for (k, &i) in self.order.iter().enumerate() {
            let i = i as usize;
            let out = &mut self.splats[k * 16..k * 16 + 16];
            let p = b.positions[i];
            let o = if lang {
                b.lang_opacity[i]
            } else {
                b.opacity[i]
            };
            out[0..3].copy_from_slice(&p);
            out[3] = 1.0 / (1.0 + (-o).exp());
            let ls = b.log_scales[i];
            let s = [ls[0].exp(), ls[1].exp(), ls[2].exp()];
            let r = quat_to_mat(b.rotations[i]);
            // M = R S (columns scaled), Sigma = M M^T.
            let mm = [
                [r[0][0] * s[0], r[0][1] * s[1], r[0][2] * s[2]],
                [r[1][0] * s[0], r[1][1] * s[1], r[1][2] * s[2]],
                [r[2][0] * s[0], r[2][1] * s[1], r[2][2] * s[2]],
            ];
            let dot = |a: &[f32; 3], b: &[f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            out[4] = dot(&mm[0], &mm[0]);
            out[5] = dot(&mm[0], &mm[1]);
            out[6] = dot(&mm[0], &mm[2]);
            out[7] = dot(&mm[1], &mm[1]);
            out[8] = dot(&mm[1], &mm[2]);
            out[9] = dot(&mm[2], &mm[2]);
            out[10] = 0.0;
            out[11] = 0.0;
            let rgb = if lang {
                let v = self.relevance.get(i).copied().unwrap_or(0.0);
                let u = if rmax > rmin {
                    (v - rmin) / (rmax - rmin)
                } else {
                    0.5
                };
                heat(if u.is_finite() { u } else { 0.0 })
            } else {
                let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
                let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let d = if l > 0.0 {
                    d.map(|v| v / l)
                } else {
                    [0.0, 0.0, 1.0]
                };
                eval_sh(b.sh_degree, &b.sh[i * stride..(i + 1) * stride], d)
            };
            out[12..15].copy_from_slice(&rgb);
            out[15] = 0.0;
        }
        m as u32
    }

    pub fn splats_ptr(&self) -> usize {
        self.splats.as_ptr() as usize
    }
}

/// LSD radix sort of (key, value) pairs by key, stable, 2 passes of 16 bits.
fn radix_sort(keys: &mut Vec<u32>, vals: &mut Vec<u32>, tmp: &mut Vec<u32>) {
    let n = keys.len();
    let mut k2 = vec![0u32; n];
    tmp.resize(n, 0);
    for shift in [0u32, 16] {
        let mut count = vec![0usize; 65537];
        for &k in keys.iter() {
            count[((k >> shift) & 0xffff) as usize + 1] += 1;
        }
        for i in 1..65537 {
            count[i] += count[i - 1];
        }
        for j in 0..n {
            let b = ((keys[j] >> shift) & 0xffff) as usize;
            let at = count[b];
            count[b] += 1;
            k2[at] = keys[j];
            tmp[at] = vals[j];
        }
        std::mem::swap(keys, &mut k2);
        std::mem::swap(vals, tmp);
    }
}

/// Rotation matrix (rows) of a raw w-first quaternion; zero gives the identity
/// (format-spec/renderer.md).
fn quat_to_mat(q: [f32; 4]) -> [[f32; 3]; 3] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = if n > 0.0 { q.map(|v| v / n) } else { [0.0; 4] };
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}
