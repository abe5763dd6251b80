//! HAC's context model of `AHAC` (format-spec §6.13.5): a binary 3D hash grid and three 2D
//! planes, looked up at an anchor's normalised position with the `RNTC` lookup (§6.6.4), and
//! `mlp_grid` (inputs -> hidden -> 175) giving each coded attribute's mean, scale and step.
//!
//! The MLP sums products rounded then added (not fused), each output from its bias in
//! increasing input order; the weights are kept transposed so the inner loop runs over the
//! outputs (vectorised) without changing any output's summation order.

use bitvec::prelude::*;
use multiversion::multiversion;

use super::hac_cdf::step;
use super::ntc::{lookup, PLANES};
use super::scaffold::{FEAT_DIM, N_OFFSETS, SCALING_DIM};
use crate::entropy::binary_bits::BitWord;

/// Channels of the coded attributes: feature, log-scaling, offsets.
pub const ATTR_CHANNELS: [usize; 3] = [FEAT_DIM, SCALING_DIM, 3 * N_OFFSETS];
/// `mlp_grid` outputs: mean and scale of every channel, then three step adjustments.
pub const CONTEXT_OUT: usize = 2 * (FEAT_DIM + SCALING_DIM + 3 * N_OFFSETS) + 3;
/// The reference's base steps of feature, log-scaling, offsets.
pub const Q_BASE_REFERENCE: [f32; 3] = [1.0, 0.001, 0.2];
/// Largest levels per grid, log2 entries, features per entry, hidden width, resolution.
pub const MAX_LEVELS: usize = 16;
pub const MAX_LOG2_TABLE: u8 = 22;
pub const MAX_FEATURES: u8 = 8;
pub const MAX_HIDDEN: usize = 1024;
pub const MAX_RESOLUTION: u32 = 1 << 20;

/// Shape of one multi-level binary grid (`dims` 3 for the grid, 2 for each plane).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GridShape {
    pub resolutions: Vec<u32>,
    pub log2_table: u8,
    pub features: u8,
}

impl GridShape {
    /// The reference's 3D grid: 12 levels, 2^13 entries, 4 features.
    pub fn reference_3d() -> Self {
        GridShape {
            resolutions: vec![18, 24, 33, 44, 59, 80, 108, 148, 201, 275, 376, 514],
            log2_table: 13,
            features: 4,
        }
    }
    /// The reference's planes: 4 levels, 2^15 entries, 4 features.
    pub fn reference_2d() -> Self {
        GridShape {
            resolutions: vec![130, 258, 514, 1026],
            log2_table: 15,
            features: 4,
        }
    }
    /// Entries of level `l` in `dims` dimensions: `ceil(min(2^T, R^dims) / 8) * 8`.
    pub fn rows(&self, l: usize, dims: u32) -> usize {
        let full = (self.resolutions[l] as u128).pow(dims);
        (full.min(1u128 << self.log2_table) as usize).div_ceil(8) * 8
    }
    pub fn check(&self, what: &str) -> Result<(), String> {
        if self.resolutions.len() > MAX_LEVELS
            || !(1..=MAX_LOG2_TABLE).contains(&self.log2_table)
            || !(1..=MAX_FEATURES).contains(&self.features)
            || self
                .resolutions
                .iter()
                .any(|r| !(3..=MAX_RESOLUTION).contains(r))
        {
            return Err(format!(
                "{what}: {} levels (0..={MAX_LEVELS}), log2 {} (1..={MAX_LOG2_TABLE}), {} \
                 features (1..={MAX_FEATURES}), resolutions 3..=2^20",
                self.resolutions.len(),
                self.log2_table,
                self.features
            ));
        }
        Ok(())
    }
}

/// The context model of one GOP's canonical anchors.
#[derive(Debug, Clone, PartialEq)]
pub struct HacContext {
    pub grid3: GridShape,
    pub grid2: GridShape,
    /// Normalisation box (also the position quantisation box).
    pub bound_min: [f32; 3],
    pub bound_max: [f32; 3],
    /// Base steps of feature, log-scaling, offsets.
    pub q_base: [f32; 3],
    /// One bit array per level: the 3D grid's levels, then xy, xz, yz plane levels; level `l`
    /// holds `rows * features` bits, entry-major (1 = +1).
    pub levels: Vec<BitVec<BitWord, Lsb0>>,
    pub hidden: usize,
    /// PyTorch layout: `w1[j * inputs + i]`, `w2[o * hidden + j]`.
    pub w1: Vec<f32>,
    pub b1: Vec<f32>,
    pub w2: Vec<f32>,
    pub b2: Vec<f32>,
}

impl HacContext {
    pub fn input_width(&self) -> usize {
        self.grid3.resolutions.len() * self.grid3.features as usize
            + 3 * self.grid2.resolutions.len() * self.grid2.features as usize
    }

    /// Bits of every level in storage order.
    pub fn level_bits(grid3: &GridShape, grid2: &GridShape) -> Vec<usize> {
        let mut v: Vec<usize> = (0..grid3.resolutions.len())
            .map(|l| grid3.rows(l, 3) * grid3.features as usize)
            .collect();
        for _ in 0..3 {
            v.extend(
                (0..grid2.resolutions.len()).map(|l| grid2.rows(l, 2) * grid2.features as usize),
            );
        }
        v
    }

    /// Parameter count of `mlp_grid`.
    pub fn param_count(inputs: usize, hidden: usize) -> usize {
        inputs * hidden + hidden + hidden * CONTEXT_OUT + CONTEXT_OUT
    }

    /// Shapes, box, steps, finite weights.
    pub fn validate(&self) -> Result<(), String> {
        self.grid3.check("3D grid")?;
        self.grid2.check("planes")?;
        let i = self.input_width();
        if i == 0 {
            return Err("the grids give no features".into());
        }
        for a in 0..3 {
            let (lo, hi) = (self.bound_min[a], self.bound_max[a]);
            if !(lo.is_finite() && hi.is_finite() && hi > lo && (hi - lo).is_finite()) {
                return Err(format!("box of axis {a} must be finite with max > min"));
            }
        }
        if self.q_base.iter().any(|q| !(q.is_finite() && *q > 0.0)) {
            return Err("base steps must be finite and > 0".into());
        }
        let bits = Self::level_bits(&self.grid3, &self.grid2);
        if self.levels.len() != bits.len()
            || self.levels.iter().zip(&bits).any(|(l, &n)| l.len() != n)
        {
            return Err("grid bit counts do not match the shapes".into());
        }
        let h = self.hidden;
        if !(1..=MAX_HIDDEN).contains(&h)
            || self.w1.len() != i * h
            || self.b1.len() != h
            || self.w2.len() != h * CONTEXT_OUT
            || self.b2.len() != CONTEXT_OUT
        {
            return Err(format!("mlp_grid is not {i} -> {h} -> {CONTEXT_OUT}"));
        }
        if [&self.w1, &self.b1, &self.w2, &self.b2]
            .iter()
            .any(|v| v.iter().any(|x| !x.is_finite()))
        {
            return Err("mlp_grid weights must be finite".into());
        }
        Ok(())
    }

    /// Lookup tables and transposed weights for [`Prepared::eval`].
    pub fn prepare(&self) -> Prepared {
        // Entry e's f bits straight from the words (bit k is bit k % W of word k / W).
        const W: usize = BitWord::BITS as usize;
        let entry = |bits: &BitVec<BitWord, Lsb0>, f: usize| -> Vec<u8> {
            let w = bits.as_raw_slice();
            let mask: BitWord = (1 << f) - 1;
            (0..bits.len() / f)
                .map(|e| {
                    let (i, o) = (e * f / W, e * f % W);
                    let mut v = w[i] >> o;
                    if o + f > W {
                        v |= w[i + 1] << (W - o);
                    }
                    (v & mask) as u8
                })
                .collect()
        };
        let n3 = self.grid3.resolutions.len();
        let tables = self
            .levels
            .iter()
            .enumerate()
            .map(|(l, b)| {
                let f = if l < n3 {
                    self.grid3.features
                } else {
                    self.grid2.features
                };
                entry(b, f as usize)
            })
            .collect();
        let i = self.input_width();
        let h = self.hidden;
        let mut w1t = vec![0f32; i * h];
        for j in 0..h {
            for k in 0..i {
                w1t[k * h + j] = self.w1[j * i + k];
            }
        }
        let mut w2t = vec![0f32; h * CONTEXT_OUT];
        for o in 0..CONTEXT_OUT {
            for j in 0..h {
                w2t[j * CONTEXT_OUT + o] = self.w2[o * h + j];
            }
        }
        Prepared {
            ctx: self.clone(),
            tables,
            w1t,
            w2t,
        }
    }
}

/// A context model ready to evaluate.
pub struct Prepared {
    ctx: HacContext,
    /// Per level one byte per entry: bit `f` is feature `f`.
    tables: Vec<Vec<u8>>,
    w1t: Vec<f32>,
    w2t: Vec<f32>,
}

/// One anchor's coding parameters: `mean` and `sigma` (before the `1e-9` clamp) per channel
/// of every attribute (feature 50, log-scaling 6, offsets 30), and the step per attribute.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnchorParams {
    pub out: [f32; CONTEXT_OUT],
    pub q: [f32; 3],
}

impl AnchorParams {
    /// Offset of attribute `a`'s means in `out`; its scales follow at `+ channels`.
    pub fn mean_at(a: usize) -> usize {
        2 * ATTR_CHANNELS[..a].iter().sum::<usize>()
    }
}

impl Prepared {
    pub fn context(&self) -> &HacContext {
        &self.ctx
    }

    /// The grid features at position `p` (§6.13.5): zeros if any `u` is outside [0, 1].
    pub fn features(&self, p: [f32; 3], x: &mut [f32]) {
        let c = &self.ctx;
        x.fill(0.0);
        let mut u = [0f32; 3];
        for a in 0..3 {
            u[a] = (p[a] - c.bound_min[a]) / (c.bound_max[a] - c.bound_min[a]);
            if !(0.0..=1.0).contains(&u[a]) {
                return;
            }
        }
        let g3 = &c.grid3;
        let f3 = g3.features as usize;
        let mut at = 0;
        for (l, &r) in g3.resolutions.iter().enumerate() {
            let tab = &self.tables[l];
            let acc = &mut x[at..at + f3];
            let s = lookup::<3>(u, r, 1usize << g3.log2_table, |i, w| {
                let m = tab[i];
                for (f, v) in acc.iter_mut().enumerate() {
                    *v += if m >> f & 1 == 1 { w } else { -w };
                }
            });
            acc.iter_mut().for_each(|v| *v /= s);
            at += f3;
        }
        let g2 = &c.grid2;
        let f2 = g2.features as usize;
        let n3 = g3.resolutions.len();
        for (pi, &(a, b)) in PLANES.iter().enumerate() {
            for (l, &r) in g2.resolutions.iter().enumerate() {
                let tab = &self.tables[n3 + pi * g2.resolutions.len() + l];
                let acc = &mut x[at..at + f2];
                let s = lookup::<2>([u[a], u[b]], r, 1usize << g2.log2_table, |i, w| {
                    let m = tab[i];
                    for (f, v) in acc.iter_mut().enumerate() {
                        *v += if m >> f & 1 == 1 { w } else { -w };
                    }
                });
                acc.iter_mut().for_each(|v| *v /= s);
                at += f2;
            }
        }
    }

    /// The coding parameters of the anchors at `positions`.
    pub fn eval(&self, positions: &[[f32; 3]]) -> Vec<AnchorParams> {
        let c = &self.ctx;
        let i_n = c.input_width();
        let h_n = c.hidden;
        let mut x = vec![0f32; i_n];
        let mut h = vec![0f32; h_n];
        positions
            .iter()
            .map(|&p| {
                self.features(p, &mut x);
                let mut out = [0f32; CONTEXT_OUT];
                mlp(&self.w1t, &c.b1, &self.w2t, &c.b2, &x, &mut h, &mut out);
                let adj = &out[CONTEXT_OUT - 3..];
                let q = [
                    step(c.q_base[0], adj[0]),
                    step(c.q_base[1], adj[1]),
                    step(c.q_base[2], adj[2]),
                ];
                AnchorParams { out, q }
            })
            .collect()
    }
}

/// `mlp_grid` at `x` (§6.13.5): every output from its bias, adding `W[o,i] x[i]` in increasing
/// `i`, product rounded then sum rounded (never fused: Rust does not contract `a * b + c`, so
/// the AVX2 version computes the same bits); the loops run over the outputs, which vectorise.
#[multiversion(targets("x86_64+avx2", "aarch64+neon"))]
fn mlp(
    w1t: &[f32],
    b1: &[f32],
    w2t: &[f32],
    b2: &[f32],
    x: &[f32],
    h: &mut [f32],
    out: &mut [f32],
) {
    let h_n = h.len();
    let o_n = out.len();
    h.copy_from_slice(b1);
    for (i, &xi) in x.iter().enumerate() {
        let w = &w1t[i * h_n..(i + 1) * h_n];
        for (hj, &wj) in h.iter_mut().zip(w) {
            *hj += wj * xi;
        }
    }
    out.copy_from_slice(b2);
    for (j, &hj) in h.iter().enumerate() {
        // relu: h > 0 ? h : 0 (NaN -> 0). A zero input adds only signed zeros, which change
        // no later step (§6.13.5): skipped.
        if !(hj > 0.0) {
            continue;
        }
        let w = &w2t[j * o_n..(j + 1) * o_n];
        for (o, &wo) in out.iter_mut().zip(w) {
            *o += wo * hj;
        }
    }
}

/// `â = q interval + min` per axis with `interval = (max - min) (1/65535) + 1e-6`, f32, each
/// operation rounded (§6.13.3; the reference's dequantisation).
pub fn dequantize(q: &[[u16; 3]], bound_min: [f32; 3], bound_max: [f32; 3]) -> Vec<[f32; 3]> {
    let interval: [f32; 3] = std::array::from_fn(|d| {
        (bound_max[d] - bound_min[d]) * (1.0f64 / 65535.0) as f32 + 1e-6f32
    });
    q.iter()
        .map(|v| std::array::from_fn(|d| v[d] as f32 * interval[d] + bound_min[d]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The transposed, vectorised (and on AVX2 machines, AVX2) MLP gives exactly the bits of
    /// the plain per-output loop of §6.13.5, zero-skipping included.
    #[test]
    fn mlp_matches_the_plain_loop() {
        let mut rng = fastrand::Rng::with_seed(9);
        let (i_n, h_n, o_n) = (96, 100, CONTEXT_OUT);
        for _ in 0..50 {
            let mut v = |n: usize| {
                (0..n)
                    .map(|_| (rng.f32() - 0.5) * 3.0)
                    .collect::<Vec<f32>>()
            };
            let (w1, b1, w2, b2, x) = (v(i_n * h_n), v(h_n), v(o_n * h_n), v(o_n), v(i_n));
            let mut hp = vec![0f32; h_n];
            for j in 0..h_n {
                let mut a = b1[j];
                for i in 0..i_n {
                    a += w1[j * i_n + i] * x[i];
                }
                hp[j] = if a > 0.0 { a } else { 0.0 };
            }
            let mut op = vec![0f32; o_n];
            for o in 0..o_n {
                let mut a = b2[o];
                for j in 0..h_n {
                    a += w2[o * h_n + j] * hp[j];
                }
                op[o] = a;
            }
            let mut w1t = vec![0f32; i_n * h_n];
            let mut w2t = vec![0f32; h_n * o_n];
            for j in 0..h_n {
                for i in 0..i_n {
                    w1t[i * h_n + j] = w1[j * i_n + i];
                }
                for o in 0..o_n {
                    w2t[j * o_n + o] = w2[o * h_n + j];
                }
            }
            let mut h = vec![0f32; h_n];
            let mut out = vec![0f32; o_n];
            mlp(&w1t, &b1, &w2t, &b2, &x, &mut h, &mut out);
            let bits = |v: &[f32]| v.iter().map(|x| (x + 0.0).to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&out), bits(&op));
        }
    }
}
