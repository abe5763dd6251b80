//! antimatter15 `.splat` writing (the library reads `.splat` in `dlgs::interop::splat`; this
//! is its inverse): 32 bytes per Gaussian, SH degree 0, sorted as antimatter15's converter
//! sorts (largest `exp(sum log-scale) * sigmoid(opacity)` first).
#![allow(clippy::disallowed_methods)] // a foreign format, as `dlgs::interop`: platform exp/ln

use dlgs::interop::splat::SH_C0;
use dlgs::model::sigmoid;
use dlgs::Gaussians;

fn u8_of(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// The `.splat` bytes of `g` (SH bands above 0, language and view dependence are dropped).
pub fn write_splat(g: &Gaussians) -> Vec<u8> {
    let n = g.len();
    let stride = g.sh_stride();
    let weight = |i: usize| {
        let s = g.log_scales[i];
        (s[0] + s[1] + s[2]).exp() * sigmoid(g.opacity[i])
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| weight(b).total_cmp(&weight(a)));
    let mut out = Vec::with_capacity(n * 32);
    for i in order {
        for v in g.positions[i] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for v in g.log_scales[i] {
            out.extend_from_slice(&v.exp().to_le_bytes());
        }
        let dc = &g.sh[i * stride..i * stride + 3];
        for c in dc {
            out.push(u8_of((0.5 + SH_C0 * c) * 255.0));
        }
        // The reader takes alpha 0 and 255 as 0.5/255 and 254.5/255: map those back.
        let a = sigmoid(g.opacity[i]) * 255.0;
        out.push(if a <= 0.5 {
            0
        } else if a >= 254.5 {
            255
        } else {
            u8_of(a)
        });
        let q = g.rotations[i];
        let len = q.iter().map(|v| v * v).sum::<f32>().sqrt();
        let q = if len > 0.0 {
            q.map(|v| v / len)
        } else {
            [1.0, 0.0, 0.0, 0.0]
        };
        for v in q {
            out.push(u8_of(v * 128.0 + 128.0));
        }
    }
    out
}
