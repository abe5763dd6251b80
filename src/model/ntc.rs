//! The binary-voxel residual field (`RNTC`, format-spec §6.6): three 2D binary hash planes
//! (xy, xz, yz) with several levels, a 3D binary gate grid, and a small MLP with biases that
//! maps the gated plane features of a Gaussian's position to offsets of its attributes.
//!
//! This is the reference's `NTC_encoding` (binary STE grids, 4 levels 512..4096, 2^15 entries,
//! 4 features; gate 514^3 hashed into 2^15; `ntc_mlp` 48 -> 100 -> out) applied, as the paper
//! describes for 3DGS, to every attribute group of static and dynamic Gaussians. The lookup
//! follows the reference's grid encoder as documented in ../shared/reference (§3.5 there).

use bitvec::prelude::*;
use rayon::prelude::*;

use crate::entropy::binary_bits::BitWord;
use crate::error::{Error, Result};
use crate::model::residual::{AttrGroup, SET_DYNAMIC, SET_STATIC};
use crate::model::Canonical;

pub use super::ntc_config::{NtcConfig, NtcMlp, PLANES, PRIMES, WEIGHT_EPS};
use super::ntc_lanes::{LaneField, LANES};

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
    pub planes: Vec<BitVec<BitWord, Lsb0>>,
    /// `gate_table` bits.
    pub gate: BitVec<BitWord, Lsb0>,
    pub mlp: NtcMlp,
    /// Attribute groups the MLP output covers, bit `g` for `AttrGroup` g; output columns follow
    /// the groups in ascending order.
    pub groups: u8,
    /// Sets the residual applies to: `SET_STATIC | SET_DYNAMIC`.
    pub sets: u8,
}

/// What a residual row's group mask names (§6.6.1): the attribute groups of a 3DGS scene's
/// Gaussians (`HEAD.variant` 0) or of a Scaffold-GS scene's anchors (variant 1, since 1.17).
/// The grids, lookup, gate and MLP are the same for both; only the row's columns differ.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowLayout {
    Gaussians { sh_degree: u8, lang_width: usize },
    Anchors,
}

impl RowLayout {
    /// The layout of a scene's residual rows.
    pub fn of(scene: &crate::container::SceneHeader) -> Self {
        match scene.variant {
            crate::container::Variant::Scaffold => RowLayout::Anchors,
            crate::container::Variant::Gaussians3d => RowLayout::Gaussians {
                sh_degree: scene.sh_degree,
                lang_width: scene.lang_width(),
            },
        }
    }

    /// Width of the row `mask` selects, or why the mask is invalid in this layout (a group of
    /// width 0 here, an undefined bit, or no group at all).
    pub fn row_width(self, mask: u8) -> std::result::Result<usize, String> {
        let width = match self {
            RowLayout::Gaussians {
                sh_degree,
                lang_width,
            } => {
                let mut width = 0;
                for g in groups_in(mask) {
                    let w = g.width(sh_degree, lang_width);
                    if w == 0 {
                        return Err(format!("group {} does not exist in this scene", g.name()));
                    }
                    width += w;
                }
                width
            }
            RowLayout::Anchors => {
                use crate::model::scaffold::AnchorGroup;
                if mask & !AnchorGroup::MASK != 0 {
                    return Err(format!(
                        "group mask {mask:#x}: an anchor residual has groups feature, offsets \
                         and log_scaling only (bits 0-2)"
                    ));
                }
                AnchorGroup::selected(mask).map(AnchorGroup::width).sum()
            }
        };
        if width == 0 {
            return Err("the residual changes no attribute".into());
        }
        Ok(width)
    }
}

/// The groups a mask selects, ascending.
pub fn groups_in(mask: u8) -> impl Iterator<Item = AttrGroup> {
    AttrGroup::ALL
        .into_iter()
        .filter(move |g| mask & g.bit() != 0)
}

/// The kept corners of a `D`-dimensional grid lookup at `u` (in [0,1]^D) (§6.6.4 steps 1-2):
/// `add(entry, weight)` for each, in corner order; returns the weights' sum plus `WEIGHT_EPS`
/// (step 3's divisor). Public for encoders that fit a field with the decoder's own lookup.
#[inline]
pub fn lookup<const D: usize>(
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

/// The gate at `u`: sigmoid of the interpolated gate bit, in f64 with the crate's own `exp`
/// (Appendix B), then rounded: the same bits on every platform.
fn gate_value(t: &Tables, c: &NtcConfig, u: [f32; 3]) -> f32 {
    let mut gv = 0f32;
    let gsum = lookup::<3>(u, c.gate_resolution, c.gate_table(), |i, w| {
        gv += w * if t.gate_words[i / 64] >> (i % 64) & 1 == 1 {
            1.0
        } else {
            -1.0
        }
    });
    crate::elementary::sigmoid_f32(gv / gsum)
}

impl NtcField {
    /// Structural checks (also run on decode): shapes, bounds, groups present in the scene
    /// (a 3DGS scene with this SH degree and language width).
    pub fn validate(&self, sh_degree: u8, lang_width: usize) -> std::result::Result<(), String> {
        self.validate_layout(RowLayout::Gaussians {
            sh_degree,
            lang_width,
        })
    }

    /// As [`Self::validate`], for residual rows of `layout`.
    pub fn validate_layout(&self, layout: RowLayout) -> std::result::Result<(), String> {
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
        let width = layout.row_width(self.groups)?;
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

    /// The MLP input at unit position `u` with gate `gate` (§6.6.4), the plain way.
    fn features(&self, t: &Tables, u: [f32; 3], gate: f32, out: &mut [f32]) {
        let c = &self.config;
        let nf = c.features as usize;
        let sign = |bit: bool| if bit { 1.0f32 } else { -1.0 };
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
        let no = self.mlp.outputs;
        let nibbles = !t.packed.is_empty();
        let levels = if nibbles { &t.packed } else { &t.planes };
        let field = LaneField::new(&self.config, &self.mlp, levels, nibbles, &t.gate_words);
        let mut rows = vec![0f32; positions.len() * no];
        rows.par_chunks_mut(BLOCK * no)
            .zip(positions.par_chunks(BLOCK))
            .for_each(|(chunk, pos)| {
                // The rows inside the box go through the field LANES at a time; a short last
                // batch repeats its last position in the spare lanes, which are never read.
                let inside: Vec<(usize, [f32; 3])> = pos
                    .iter()
                    .enumerate()
                    .filter_map(|(i, &p)| Some((i, self.unit_position(p)?)))
                    .collect();
                let mut batch = field.batch();
                for group in inside.chunks(LANES) {
                    for l in 0..LANES {
                        let (_, u) = group[l.min(group.len() - 1)];
                        for a in 0..3 {
                            batch.u[a][l] = u[a];
                        }
                    }
                    field.eval(&mut batch);
                    for (l, &(i, _)) in group.iter().enumerate() {
                        for (o, y) in batch.yt.iter().enumerate() {
                            chunk[i * no + o] = y[l];
                        }
                    }
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
        if let Some(u) = self.unit_position(p) {
            self.features(&t, u, gate_value(&t, &self.config, u), &mut x);
            self.mlp_into(&x, &mut h, &mut out);
        }
        out
    }

    /// The canonical state this field produces from `reference` (§6.6.5).
    pub fn apply(&self, reference: &Canonical) -> Result<Canonical> {
        let s = &reference.statics;
        self.validate(s.sh_degree, s.lang_width)
            .map_err(Error::input)?;
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

/// One byte per entry holding its `f` feature bits (bit k = feature k).
fn entry_masks(bits: &BitSlice<BitWord, Lsb0>, f: usize) -> Vec<u8> {
    let n = bits.len() / f;
    const W: usize = BitWord::BITS as usize;
    if W.is_multiple_of(f) {
        // Entries never straddle a word: shift them out of the raw words directly.
        let words = bits.domain().region().map_or(&[][..], |(_, body, _)| body);
        if words.len() * W == bits.len() {
            let mask = ((1u16 << f) - 1) as BitWord;
            return (0..n)
                .map(|e| (words[e * f / W] >> (e * f % W) & mask) as u8)
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
