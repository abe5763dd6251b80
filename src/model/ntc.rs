//! The binary-voxel residual field (`RNTC`, format-spec §6.6): three 2D binary hash planes
//! (xy, xz, yz) with several levels, a 3D binary gate grid, and a small MLP with biases that
//! maps the gated plane features of a Gaussian's position to offsets of its attributes.
//!
//! This is the reference's `NTC_encoding` (binary STE grids, 4 levels 512..4096, 2^15 entries,
//! 4 features; gate 514^3 hashed into 2^15; `ntc_mlp` 48 -> 100 -> out) applied, as the paper
//! describes for 3DGS, to every attribute group of static and dynamic Gaussians. The lookup
//! follows the reference's grid encoder as documented in ../shared/reference (§3.5 there).

use bitvec::prelude::*;
use multiversion::multiversion;
use rayon::prelude::*;

use crate::error::{Error, ErrorKind, Result};
use crate::model::residual::{AttrGroup, SET_DYNAMIC, SET_STATIC};
use crate::model::Canonical;

/// Hash primes of the grid encoder, per dimension.
pub const PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];
/// Planes in their storage order, as (first axis, second axis).
pub const PLANES: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];
/// Added to the sum of kept corner weights before dividing.
pub const WEIGHT_EPS: f32 = 1e-9;

/// Shapes of the binary grids.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NtcConfig {
    /// Resolution of each plane level (reference: 512, 1024, 2048, 4096).
    pub resolutions: Vec<u32>,
    /// Features per plane entry (reference: 4).
    pub features: u8,
    /// log2 of the entries per plane level (reference: 15).
    pub log2_table: u8,
    /// Resolution of the 3D gate grid (reference: 514); one level, one feature.
    pub gate_resolution: u32,
    /// log2 of the gate grid's entries (reference: 15).
    pub gate_log2_table: u8,
}

impl Default for NtcConfig {
    fn default() -> Self {
        NtcConfig {
            resolutions: vec![512, 1024, 2048, 4096],
            features: 4,
            log2_table: 15,
            gate_resolution: 514,
            gate_log2_table: 15,
        }
    }
}

impl NtcConfig {
    pub fn levels(&self) -> usize {
        self.resolutions.len()
    }
    pub fn table(&self) -> usize {
        1 << self.log2_table
    }
    pub fn gate_table(&self) -> usize {
        1 << self.gate_log2_table
    }
    /// Width of the MLP input: planes x levels x features.
    pub fn input_width(&self) -> usize {
        3 * self.levels() * self.features as usize
    }
    /// Bits in one plane level.
    pub fn level_bits(&self) -> usize {
        self.table() * self.features as usize
    }
}

/// `Linear(in -> hidden) + ReLU + Linear(hidden -> out)`, with biases, PyTorch layout
/// (`w1[j * in + i]`).
#[derive(Debug, Clone, PartialEq)]
pub struct NtcMlp {
    pub inputs: usize,
    pub hidden: usize,
    pub outputs: usize,
    pub w1: Vec<f32>,
    pub b1: Vec<f32>,
    pub w2: Vec<f32>,
    pub b2: Vec<f32>,
}

impl NtcMlp {
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.w1.len() != self.inputs * self.hidden
            || self.b1.len() != self.hidden
            || self.w2.len() != self.hidden * self.outputs
            || self.b2.len() != self.outputs
        {
            return Err(format!(
                "MLP weights do not match {} -> {} -> {}",
                self.inputs, self.hidden, self.outputs
            ));
        }
        Ok(())
    }
    pub fn params(&self) -> impl Iterator<Item = &f32> {
        self.w1
            .iter()
            .chain(&self.b1)
            .chain(&self.w2)
            .chain(&self.b2)
    }
}

/// One GOP's binary residual field.
#[derive(Debug, Clone, PartialEq)]
pub struct NtcField {
    pub config: NtcConfig,
    /// Normalisation box: `u = (x - min) / (max - min)` per axis; Gaussians with any `u`
    /// outside [0, 1] get no residual.
    pub bound_min: [f32; 3],
    pub bound_max: [f32; 3],
    /// `3 * levels` bit arrays (xy levels, then xz, then yz), each `table * features` bits,
    /// entry-major: bit `e * features + f` is feature f of entry e; 1 = +1, 0 = -1.
    pub planes: Vec<BitVec<u64, Lsb0>>,
    /// `gate_table` bits.
    pub gate: BitVec<u64, Lsb0>,
    pub mlp: NtcMlp,
    /// Attribute groups the MLP output covers, bit `g` for `AttrGroup` g; output columns follow
    /// the groups in ascending order.
    pub groups: u8,
    /// Sets the residual applies to: `SET_STATIC | SET_DYNAMIC`.
    pub sets: u8,
}

fn invalid(msg: String) -> Error {
    Error::new(ErrorKind::InvalidInput(msg), 0)
}

/// The groups a mask selects, ascending.
pub fn groups_in(mask: u8) -> impl Iterator<Item = AttrGroup> {
    AttrGroup::ALL
        .into_iter()
        .filter(move |g| mask & g.bit() != 0)
}

/// Interpolated feature of a `D`-dimensional binary grid at `u` (in [0,1]^D) (§6.6.3).
/// `fetch(index)` returns the ±1 values of the entry's features through `acc`.
#[inline]
fn lookup<const D: usize>(
    u: [f32; D],
    resolution: u32,
    table: usize,
    mut add: impl FnMut(usize, f32),
) -> f32 {
    let r = resolution;
    let mut g = [0u32; D];
    let mut frac = [0f32; D];
    for d in 0..D {
        let pos = u[d] * (r - 2) as f32 + 0.5;
        // u is in [0, 1] (checked by the caller), so pos >= 0.5 and truncation is floor,
        // without a libm call.
        let fl = (pos as u32) as f32;
        g[d] = fl as u32;
        frac[d] = pos - fl;
    }
    let dense = (r as u64).pow(D as u32) <= table as u64;
    // `table` is a power of two: masking is the modulo of §6.6.3 without a division.
    let mask = table - 1;
    let mut wsum = 0f32;
    for corner in 0..(1usize << D) {
        let mut w = 1f32;
        let mut idx: u64 = 0;
        let mut stride: u64 = 1;
        let mut hash: u32 = 0;
        let mut dropped = false;
        for d in 0..D {
            let up = corner >> d & 1 == 1;
            let c = (g[d] + up as u32).min(r - 1);
            dropped |= c == 0 || c == r - 1;
            w *= if up { frac[d] } else { 1.0 - frac[d] };
            idx += c as u64 * stride;
            stride *= r as u64;
            hash ^= c.wrapping_mul(PRIMES[d]);
        }
        if dropped {
            continue;
        }
        let index = if dense {
            idx as usize & mask
        } else {
            hash as usize & mask
        };
        wsum += w;
        add(index, w);
    }
    wsum + WEIGHT_EPS
}

/// Decoded grids in a lookup-friendly form: per plane level one byte per entry holding its
/// feature bits (the plain path), the same levels packed two entries per byte when they have
/// at most 4 features (the fast path: all 12 reference levels fit in 192 KiB, so they stay in
/// L2 cache), and the gate bits as words.
struct Tables {
    planes: Vec<Vec<u8>>,
    packed: Vec<Vec<u8>>,
    gate_words: Vec<u64>,
}

/// `SIGNS[m][f]` is +1 when bit f of `m` is set, else -1: one entry's features as floats.
static SIGNS: [[f32; 8]; 256] = {
    let mut t = [[0f32; 8]; 256];
    let mut m = 0;
    while m < 256 {
        let mut f = 0;
        while f < 8 {
            t[m][f] = if m >> f & 1 == 1 { 1.0 } else { -1.0 };
            f += 1;
        }
        m += 1;
    }
    t
};

/// The four corners of a 2D level read at `(ua, ub)` (§6.6.4 steps 1-2): entry indices and
/// weights, with the weight of a dropped corner marked by `keep = false`.
#[inline(always)]
fn plane_corners(
    ua: f32,
    ub: f32,
    r: u32,
    mask: usize,
    dense: bool,
) -> ([usize; 4], [f32; 4], [bool; 4]) {
    let axis = |u: f32| {
        let pos = u * (r - 2) as f32 + 0.5;
        let fl = (pos as u32) as f32;
        let g = fl as u32;
        let frac = pos - fl;
        let k = [g, (g + 1).min(r - 1)];
        (
            [1.0 - frac, frac],
            k,
            [k[0] != 0 && k[0] != r - 1, k[1] != 0 && k[1] != r - 1],
        )
    };
    let (wa, ka, oka) = axis(ua);
    let (wb, kb, okb) = axis(ub);
    let mut idx = [0usize; 4];
    let mut w = [0f32; 4];
    let mut keep = [false; 4];
    for c in 0..4 {
        let (i, j) = (c & 1, c >> 1);
        // The plain path multiplies 1 * w_a * w_b; 1 * w_a is w_a exactly.
        w[c] = wa[i] * wb[j];
        keep[c] = oka[i] && okb[j];
        idx[c] = if dense {
            (ka[i] as u64 + kb[j] as u64 * r as u64) as usize & mask
        } else {
            (ka[i].wrapping_mul(PRIMES[0]) ^ kb[j].wrapping_mul(PRIMES[1])) as usize & mask
        };
    }
    (idx, w, keep)
}

/// The gate at `u`: sigmoid of the interpolated gate bit, in f64 then rounded (portable).
fn gate_value(t: &Tables, c: &NtcConfig, u: [f32; 3]) -> f32 {
    let mut gv = 0f32;
    let gsum = lookup::<3>(u, c.gate_resolution, c.gate_table(), |i, w| {
        gv += w * if t.gate_words[i / 64] >> (i % 64) & 1 == 1 {
            1.0
        } else {
            -1.0
        }
    });
    (1.0 / (1.0 + (-((gv / gsum) as f64)).exp())) as f32
}

impl NtcField {
    /// Structural checks (also run on decode): shapes, bounds, groups present in the scene.
    pub fn validate(&self, sh_degree: u8, lang_width: usize) -> std::result::Result<(), String> {
        let c = &self.config;
        if c.resolutions.is_empty() || c.resolutions.len() > 16 {
            return Err(format!("{} plane levels (1..=16)", c.resolutions.len()));
        }
        if c.resolutions.iter().any(|&r| !(3..=1 << 20).contains(&r))
            || !(3..=1 << 20).contains(&c.gate_resolution)
        {
            return Err("grid resolutions must be in 3..=2^20".into());
        }
        if !(1..=8).contains(&c.features) {
            return Err(format!("{} features per entry (1..=8)", c.features));
        }
        if !(1..=24).contains(&c.log2_table) || !(1..=24).contains(&c.gate_log2_table) {
            return Err("log2 table sizes must be in 1..=24".into());
        }
        if self.planes.len() != 3 * c.levels()
            || self.planes.iter().any(|p| p.len() != c.level_bits())
            || self.gate.len() != c.gate_table()
        {
            return Err("grid bit counts do not match the configuration".into());
        }
        for a in 0..3 {
            let (lo, hi) = (self.bound_min[a], self.bound_max[a]);
            if !(lo.is_finite() && hi.is_finite() && hi > lo) {
                return Err(format!("bounds of axis {a} must be finite with max > min"));
            }
        }
        if self.sets == 0 || self.sets & !(SET_STATIC | SET_DYNAMIC) != 0 {
            return Err(format!("set mask {:#x}", self.sets));
        }
        let mut width = 0;
        for g in groups_in(self.groups) {
            let w = g.width(sh_degree, lang_width);
            if w == 0 {
                return Err(format!("group {} does not exist in this scene", g.name()));
            }
            width += w;
        }
        if width == 0 {
            return Err("the residual changes no attribute".into());
        }
        self.mlp.check()?;
        if self.mlp.inputs != c.input_width() || self.mlp.outputs != width {
            return Err(format!(
                "MLP is {} -> {}, the grids give {} inputs and the groups take {} outputs",
                self.mlp.inputs,
                self.mlp.outputs,
                c.input_width(),
                width
            ));
        }
        if self.mlp.params().any(|v| !v.is_finite()) {
            return Err("MLP weights must be finite".into());
        }
        Ok(())
    }

    fn tables(&self) -> Tables {
        let f = self.config.features as usize;
        let planes: Vec<Vec<u8>> = self
            .planes
            .iter()
            .map(|bits| entry_masks(bits, f))
            .collect();
        let packed = if f <= 4 {
            planes
                .iter()
                .map(|t| {
                    t.chunks(2)
                        .map(|e| e[0] | e.get(1).map_or(0, |m| m << 4))
                        .collect()
                })
                .collect()
        } else {
            Vec::new()
        };
        let mut gate_words = vec![0u64; self.gate.len().div_ceil(64)];
        for i in self.gate.iter_ones() {
            gate_words[i / 64] |= 1 << (i % 64);
        }
        Tables {
            planes,
            packed,
            gate_words,
        }
    }

    /// The position in the unit cube of the box, or `None` outside it (or NaN) (§6.6.4).
    fn unit_position(&self, p: [f32; 3]) -> Option<[f32; 3]> {
        let mut u = [0f32; 3];
        for a in 0..3 {
            u[a] = (p[a] - self.bound_min[a]) / (self.bound_max[a] - self.bound_min[a]);
            if !(0.0..=1.0).contains(&u[a]) {
                return None;
            }
        }
        Some(u)
    }

    /// [`Self::features`] for grids of at most 4 features, bit-identical to it: the same
    /// floating-point operations in the same order, with the corner indices of all levels
    /// computed before any table byte is read (so the reads overlap instead of waiting on one
    /// another), nibble-packed tables and a sign table instead of per-bit branches.
    fn features_packed(&self, t: &Tables, p: [f32; 3], out: &mut [f32]) -> bool {
        let Some(u) = self.unit_position(p) else {
            return false;
        };
        let c = &self.config;
        let nf = c.features as usize;
        let lv = c.levels();
        let mask = c.table() - 1;
        let gate = gate_value(t, c, u);
        const MAX: usize = 3 * 16;
        let mut idx = [[0usize; 4]; MAX];
        let mut wts = [[0f32; 4]; MAX];
        let mut keep = [[false; 4]; MAX];
        for (pi, &(a, b)) in PLANES.iter().enumerate() {
            for (l, &r) in c.resolutions.iter().enumerate() {
                let dense = (r as u64).pow(2) <= c.table() as u64;
                let k = pi * lv + l;
                (idx[k], wts[k], keep[k]) = plane_corners(u[a], u[b], r, mask, dense);
            }
        }
        let mut ent = [[0u8; 4]; MAX];
        for k in 0..3 * lv {
            let tab = &t.packed[k];
            for q in 0..4 {
                let e = idx[k][q];
                ent[k][q] = tab[e >> 1] >> ((e & 1) * 4) & 0xf;
            }
        }
        for k in 0..3 * lv {
            let mut acc = [0f32; 4];
            let mut wsum = 0f32;
            for q in 0..4 {
                if !keep[k][q] {
                    continue;
                }
                let w = wts[k][q];
                wsum += w;
                let s = &SIGNS[ent[k][q] as usize];
                for f in 0..4 {
                    acc[f] += w * s[f];
                }
            }
            let s = wsum + WEIGHT_EPS;
            for (o, &v) in out[k * nf..(k + 1) * nf].iter_mut().zip(&acc) {
                *o = v / s * gate;
            }
        }
        true
    }

    /// The MLP input of a position, or `None` outside the box (§6.6.3).
    fn features(&self, t: &Tables, p: [f32; 3], out: &mut [f32]) -> bool {
        let Some(u) = self.unit_position(p) else {
            return false;
        };
        let c = &self.config;
        let nf = c.features as usize;
        let sign = |bit: bool| if bit { 1.0f32 } else { -1.0 };
        let gate = gate_value(t, c, u);
        for (pi, &(a, b)) in PLANES.iter().enumerate() {
            for (l, &r) in c.resolutions.iter().enumerate() {
                let tab = &t.planes[pi * c.levels() + l];
                let o = (pi * c.levels() + l) * nf;
                let acc = &mut out[o..o + nf];
                acc.fill(0.0);
                let s = lookup::<2>([u[a], u[b]], r, c.table(), |i, w| {
                    let m = tab[i];
                    for (f, v) in acc.iter_mut().enumerate() {
                        *v += w * sign(m >> f & 1 == 1);
                    }
                });
                for v in acc.iter_mut() {
                    *v = *v / s * gate;
                }
            }
        }
        true
    }

    /// `out = W2 relu(W1 x + b1) + b2`: each output starts at its bias and takes the fused
    /// multiply-add of its inputs in order (§6.6.4).
    fn mlp_into(&self, x: &[f32], hidden: &mut [f32], out: &mut [f32]) {
        let m = &self.mlp;
        for (j, h) in hidden.iter_mut().enumerate() {
            *h = m.b1[j];
            for (i, &xi) in x.iter().enumerate() {
                *h = m.w1[j * m.inputs + i].mul_add(xi, *h);
            }
        }
        for (o, v) in out.iter_mut().enumerate() {
            *v = m.b2[o];
            for (j, &h) in hidden.iter().enumerate() {
                *v = m.w2[o * m.hidden + j].mul_add(h.max(0.0), *v);
            }
        }
    }

    /// The residual rows of the given positions: `outputs` values each (zeros outside the
    /// box). Rows are independent, so the result is the same on any thread count.
    pub fn residuals_at(&self, positions: &[[f32; 3]]) -> Vec<f32> {
        const BLOCK: usize = 256;
        let t = self.tables();
        let m = &self.mlp;
        let (ni, nh, no) = (m.inputs, m.hidden, m.outputs);
        let l1 = PackedLayer::new(&m.w1, &m.b1, ni);
        let l2 = PackedLayer::new(&m.w2, &m.b2, nh);
        let mut rows = vec![0f32; positions.len() * no];
        rows.par_chunks_mut(BLOCK * no)
            .zip(positions.par_chunks(BLOCK))
            .for_each(|(chunk, pos)| {
                // LANES rows inside the box go through the MLP together, one per SIMD lane.
                let mut x = vec![0f32; ni];
                let mut xt = vec![[0f32; LANES]; ni];
                let mut ht = vec![[0f32; LANES]; nh];
                let mut yt = vec![[0f32; LANES]; no];
                let mut which = [0usize; LANES];
                let mut k = 0;
                let mut flush =
                    |k: usize, which: &[usize], xt: &[[f32; LANES]], chunk: &mut [f32]| {
                        mlp_lanes(xt, &l1, &l2, &mut ht, &mut yt);
                        for (l, &i) in which[..k].iter().enumerate() {
                            for (o, y) in yt.iter().enumerate() {
                                chunk[i * no + o] = y[l];
                            }
                        }
                    };
                for (i, &p) in pos.iter().enumerate() {
                    let inside = if t.packed.is_empty() {
                        self.features(&t, p, &mut x)
                    } else {
                        self.features_packed(&t, p, &mut x)
                    };
                    if !inside {
                        continue;
                    }
                    for (col, &v) in xt.iter_mut().zip(&x) {
                        col[k] = v;
                    }
                    which[k] = i;
                    k += 1;
                    if k == LANES {
                        flush(k, &which, &xt, chunk);
                        k = 0;
                    }
                }
                if k > 0 {
                    flush(k, &which, &xt, chunk);
                }
            });
        rows
    }

    /// Residual row of one position with the plain row-major arithmetic of §6.6.4 (a second,
    /// independent evaluation for tests and tools).
    pub fn residual_at(&self, p: [f32; 3]) -> Vec<f32> {
        let t = self.tables();
        let mut x = vec![0f32; self.mlp.inputs];
        let mut h = vec![0f32; self.mlp.hidden];
        let mut out = vec![0f32; self.mlp.outputs];
        if self.features(&t, p, &mut x) {
            self.mlp_into(&x, &mut h, &mut out);
        }
        out
    }

    /// The canonical state this field produces from `reference` (§6.6.5).
    pub fn apply(&self, reference: &Canonical) -> Result<Canonical> {
        let s = &reference.statics;
        self.validate(s.sh_degree, s.lang_width).map_err(invalid)?;
        let mut out = reference.clone();
        for (set, bit) in [
            (&mut out.statics, SET_STATIC),
            (&mut out.dynamics, SET_DYNAMIC),
        ] {
            if self.sets & bit == 0 {
                continue;
            }
            let rows = self.residuals_at(&set.positions);
            let no = self.mlp.outputs;
            for i in 0..set.len() {
                let row = &rows[i * no..(i + 1) * no];
                let mut col = 0;
                for g in groups_in(self.groups) {
                    let v = g.values_mut(set, i);
                    for (x, d) in v.iter_mut().zip(&row[col..]) {
                        *x += d;
                    }
                    col += v.len();
                }
            }
        }
        Ok(out)
    }
}

/// Rows the NTC MLP evaluates together, one per SIMD lane.
const LANES: usize = 8;
/// Units (hidden or output) accumulated at once: independent FMA chains hide their latency.
const UNITS: usize = 8;

/// One MLP layer with its units in blocks of `UNITS`: `w[block * inputs + i][q]` is the weight
/// of input i for unit `block * UNITS + q`, so the inner loop reads one contiguous row of
/// weights per input with no bounds checks. Units past the layer's width have zero weights and
/// are never read back.
struct PackedLayer {
    w: Vec<[f32; UNITS]>,
    b: Vec<[f32; UNITS]>,
}

impl PackedLayer {
    /// From PyTorch layout (`w[u * inputs + i]`).
    fn new(w: &[f32], b: &[f32], inputs: usize) -> Self {
        let blocks = b.len().div_ceil(UNITS);
        let mut pw = vec![[0f32; UNITS]; blocks * inputs];
        let mut pb = vec![[0f32; UNITS]; blocks];
        for (u, &bias) in b.iter().enumerate() {
            pb[u / UNITS][u % UNITS] = bias;
            for i in 0..inputs {
                pw[u / UNITS * inputs + i][u % UNITS] = w[u * inputs + i];
            }
        }
        PackedLayer { w: pw, b: pb }
    }
}

/// The NTC MLP on `LANES` rows at once, transposed (`xt[i][lane]`, `ht[j][lane]`,
/// `yt[o][lane]`). Each lane takes exactly the fused multiply-adds of [`NtcField::mlp_into`] in
/// the same order (unit starts at its bias, inputs in order), so the rows are bit-identical to
/// it; unused lanes compute garbage that is never read. Compiled for several CPUs and picked at
/// run time; `mul_add` is exact everywhere, so every path gives the same bits.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx2+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn mlp_lanes(
    xt: &[[f32; LANES]],
    l1: &PackedLayer,
    l2: &PackedLayer,
    ht: &mut [[f32; LANES]],
    yt: &mut [[f32; LANES]],
) {
    layer_lanes(xt, l1, ht, false);
    layer_lanes(ht, l2, yt, true);
}

/// `out[u] = b[u] + sum_i w[u][i] * f(input[i])` per lane, `f` = ReLU when `relu_input`.
#[inline(always)]
fn layer_lanes(
    input: &[[f32; LANES]],
    layer: &PackedLayer,
    out: &mut [[f32; LANES]],
    relu_input: bool,
) {
    let ni = input.len();
    for (blk, (wb, bias)) in layer.w.chunks_exact(ni).zip(&layer.b).enumerate() {
        let mut acc = [[0f32; LANES]; UNITS];
        for (a, &bq) in acc.iter_mut().zip(bias) {
            *a = [bq; LANES];
        }
        for (x, wv) in input.iter().zip(wb) {
            let x = if relu_input {
                x.map(|v| v.max(0.0))
            } else {
                *x
            };
            for (a, &wq) in acc.iter_mut().zip(wv) {
                for (al, &xl) in a.iter_mut().zip(&x) {
                    *al = wq.mul_add(xl, *al);
                }
            }
        }
        let base = blk * UNITS;
        let n = UNITS.min(out.len() - base);
        out[base..base + n].copy_from_slice(&acc[..n]);
    }
}

/// One byte per entry holding its `f` feature bits (bit k = feature k).
fn entry_masks(bits: &BitSlice<u64, Lsb0>, f: usize) -> Vec<u8> {
    let n = bits.len() / f;
    if 64 % f == 0 {
        // Entries never straddle a word: shift them out of the raw words directly.
        let words = bits.domain().region().map_or(&[][..], |(_, body, _)| body);
        if words.len() * 64 == bits.len() {
            let mask = ((1u16 << f) - 1) as u64;
            return (0..n)
                .map(|e| (words[e * f / 64] >> (e * f % 64) & mask) as u8)
                .collect();
        }
    }
    bits.chunks_exact(f).map(|e| e.load_le::<u8>()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookup_drops_border_corners_and_renormalises() {
        // u = 0 on a resolution-4 grid: pos = 0.5, corners 0 (dropped) and 1 (kept).
        let mut seen = Vec::new();
        let s = lookup::<1>([0.0], 4, 1 << 10, |i, w| seen.push((i, w)));
        assert_eq!(seen, vec![(1, 0.5)]);
        assert!((s - 0.5).abs() < 1e-6);
        // Interior point: both corners kept, weights sum to 1.
        seen.clear();
        let s = lookup::<1>([0.5], 4, 1 << 10, |i, w| seen.push((i, w)));
        assert_eq!(seen.len(), 2);
        assert!((s - 1.0).abs() < 1e-6);
    }

    #[test]
    fn hashed_index_uses_xor_of_prime_products() {
        let mut seen = Vec::new();
        // 100^2 > 16 entries: hashed.
        lookup::<2>([0.5, 0.5], 100, 16, |i, _| seen.push(i));
        // pos = 0.5*98+0.5 = 49.5: corners (49|50, 49|50).
        let h = |x: u32, y: u32| (x ^ y.wrapping_mul(PRIMES[1])) as usize % 16;
        assert_eq!(seen, vec![h(49, 49), h(50, 49), h(49, 50), h(50, 50)]);
    }
}
