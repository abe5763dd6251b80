//! The fast evaluation of the residual field (format-spec §6.6.4): `LANES` Gaussians at once,
//! one per SIMD lane, through the gate, the plane features and the MLP. Written as loops over
//! lanes that the compiler vectorises, compiled for several CPUs and picked at run time.
//!
//! Every lane does exactly the floating-point operations of the plain evaluation in `ntc.rs`,
//! in the same order, so the rows are bit-identical to it on every CPU (test
//! `ntc_residuals_are_the_plain_evaluation_on_any_thread_count`). Two rewrites keep that:
//! a feature sign is applied as `±w` (which is `w * ±1` exactly), and a dropped corner adds a
//! zero weight instead of being skipped (adding ±0 to a sum that starts at +0 changes no bit).

use multiversion::multiversion;

use super::ntc_config::{NtcConfig, NtcMlp, PLANES, PRIMES, WEIGHT_EPS};

/// Rows evaluated together, one per SIMD lane.
pub(super) const LANES: usize = 16;
/// Units (hidden or output) accumulated at once: independent FMA chains hide their latency.
const UNITS: usize = 4;

/// The decoded field in the form the lanes read.
pub(super) struct LaneField<'a> {
    config: &'a NtcConfig,
    /// Per plane level: two entries per byte (features <= 4) or one.
    levels: &'a [Vec<u8>],
    nibbles: bool,
    gate_words: &'a [u64],
    l1: PackedLayer,
    l2: PackedLayer,
    /// The MLP's widths, for sizing batches.
    inputs: usize,
    hidden: usize,
    outputs: usize,
}

/// Scratch of one batch: unit positions, MLP input, hidden units and output, lane-minor.
pub(super) struct Batch {
    pub u: [[f32; LANES]; 3],
    xt: Vec<[f32; LANES]>,
    ht: Vec<[f32; LANES]>,
    pub yt: Vec<[f32; LANES]>,
}

impl<'a> LaneField<'a> {
    pub(super) fn new(
        config: &'a NtcConfig,
        mlp: &NtcMlp,
        levels: &'a [Vec<u8>],
        nibbles: bool,
        gate_words: &'a [u64],
    ) -> Self {
        LaneField {
            config,
            levels,
            nibbles,
            gate_words,
            l1: PackedLayer::new(&mlp.w1, &mlp.b1, mlp.inputs),
            l2: PackedLayer::new(&mlp.w2, &mlp.b2, mlp.hidden),
            inputs: mlp.inputs,
            hidden: mlp.hidden,
            outputs: mlp.outputs,
        }
    }

    pub(super) fn batch(&self) -> Batch {
        Batch {
            u: [[0.5; LANES]; 3],
            xt: vec![[0.0; LANES]; self.inputs],
            ht: vec![[0.0; LANES]; self.hidden],
            yt: vec![[0.0; LANES]; self.outputs],
        }
    }

    /// The residual rows of the unit positions in `b.u` (all in [0, 1]), into `b.yt`.
    pub(super) fn eval(&self, b: &mut Batch) {
        eval_lanes(self, b);
    }
}

#[multiversion(targets("x86_64+avx512f+avx512vl+avx2+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn eval_lanes(f: &LaneField, b: &mut Batch) {
    let gate = gate_lanes(f.config, f.gate_words, &b.u);
    plane_features_lanes(f, &b.u, &gate, &mut b.xt);
    layer_lanes(&b.xt, &f.l1, &mut b.ht, false);
    layer_lanes(&b.ht, &f.l2, &mut b.yt, true);
}

/// Grid coordinate and fraction of `u` along an axis of resolution `r`: `pos = u (r-2) + 0.5`,
/// `g = floor(pos)` (truncation, as pos >= 0.5), `frac = pos - g`.
#[inline(always)]
fn axis_lanes(u: &[f32; LANES], r: u32) -> ([u32; LANES], [f32; LANES]) {
    let mut g = [0u32; LANES];
    let mut frac = [0f32; LANES];
    for l in 0..LANES {
        let pos = u[l] * (r - 2) as f32 + 0.5;
        // floor is the plain path's truncation as pos >= 0.5; fl is an integer below 2^21,
        // so adding 2^23 puts it in the low mantissa bits exactly: a conversion that
        // vectorises (a float-to-int cast does not).
        let fl = pos.floor();
        g[l] = (fl + 8_388_608.0).to_bits() - 0x4B00_0000;
        frac[l] = pos - fl;
    }
    (g, frac)
}

/// The gate of each lane (§6.6.4): sigmoid, in f64, of the interpolated 3D gate bit.
#[inline(always)]
fn gate_lanes(c: &NtcConfig, words: &[u64], u: &[[f32; LANES]; 3]) -> [f32; LANES] {
    let r = c.gate_resolution;
    let dense = (r as u64).pow(3) <= c.gate_table() as u64;
    let mask = c.gate_table() as u32 - 1;
    let axes = [
        axis_lanes(&u[0], r),
        axis_lanes(&u[1], r),
        axis_lanes(&u[2], r),
    ];
    let mut gv = [0f32; LANES];
    let mut wsum = [0f32; LANES];
    for corner in 0..8 {
        let mut w = [1f32; LANES];
        let mut index = [0u32; LANES];
        for l in 0..LANES {
            let mut idx = 0u32;
            let mut stride = 1u32;
            let mut hash = 0u32;
            let mut dropped = false;
            for (d, (g, frac)) in axes.iter().enumerate() {
                let up = corner >> d & 1 == 1;
                let k = (g[l] + up as u32).min(r - 1);
                dropped |= k == 0 || k == r - 1;
                w[l] *= if up { frac[l] } else { 1.0 - frac[l] };
                // Dense grids have at most 2^24 entries, so u32 holds the index exactly.
                idx = idx.wrapping_add(k.wrapping_mul(stride));
                stride = stride.wrapping_mul(r);
                hash ^= k.wrapping_mul(PRIMES[d]);
            }
            if dropped {
                w[l] = 0.0;
            }
            index[l] = if dense { idx } else { hash } & mask;
        }
        for l in 0..LANES {
            let i = index[l] as usize;
            let bit = words[i / 64] >> (i % 64) & 1 == 1;
            wsum[l] += w[l];
            gv[l] += if bit { w[l] } else { -w[l] };
        }
    }
    let mut gate = [0f32; LANES];
    for l in 0..LANES {
        let s = wsum[l] + WEIGHT_EPS;
        gate[l] = crate::elementary::sigmoid_f32(gv[l] / s);
    }
    gate
}

/// The MLP input of each lane: per plane and level, the bilinear blend of the ±1 features of
/// the 4 corners, renormalised over the kept corners and scaled by the gate (§6.6.4).
#[inline(always)]
fn plane_features_lanes(
    f: &LaneField,
    u: &[[f32; LANES]; 3],
    gate: &[f32; LANES],
    xt: &mut [[f32; LANES]],
) {
    let c = f.config;
    let nf = c.features as usize;
    let lv = c.levels();
    let mask = c.table() as u32 - 1;
    for (pi, &(a, b)) in PLANES.iter().enumerate() {
        for (level, &r) in c.resolutions.iter().enumerate() {
            let k = pi * lv + level;
            let tab = &f.levels[k][..];
            // Dense levels have at most 2^24 entries, so u32 holds the index exactly.
            let dense = (r as u64).pow(2) <= c.table() as u64;
            let (ga, fa) = axis_lanes(&u[a], r);
            let (gb, fb) = axis_lanes(&u[b], r);
            let mut acc = [[0f32; LANES]; 8];
            let mut wsum = [0f32; LANES];
            for corner in 0..4 {
                let (i, j) = (corner & 1, corner >> 1);
                let mut w = [0f32; LANES];
                let mut index = [0u32; LANES];
                for l in 0..LANES {
                    let ka = if i == 0 {
                        ga[l]
                    } else {
                        (ga[l] + 1).min(r - 1)
                    };
                    let kb = if j == 0 {
                        gb[l]
                    } else {
                        (gb[l] + 1).min(r - 1)
                    };
                    let wa = if i == 0 { 1.0 - fa[l] } else { fa[l] };
                    let wb = if j == 0 { 1.0 - fb[l] } else { fb[l] };
                    let keep = ka != 0 && ka != r - 1 && kb != 0 && kb != r - 1;
                    w[l] = if keep { wa * wb } else { 0.0 };
                    index[l] = if dense {
                        ka.wrapping_add(kb.wrapping_mul(r))
                    } else {
                        ka.wrapping_mul(PRIMES[0]) ^ kb.wrapping_mul(PRIMES[1])
                    } & mask;
                }
                let mut entry = [0u32; LANES];
                for l in 0..LANES {
                    let e = index[l] as usize;
                    entry[l] = if f.nibbles {
                        (tab[e >> 1] >> ((e & 1) * 4) & 0xf) as u32
                    } else {
                        tab[e] as u32
                    };
                }
                for l in 0..LANES {
                    wsum[l] += w[l];
                }
                for (feat, acc) in acc.iter_mut().enumerate().take(nf) {
                    for l in 0..LANES {
                        acc[l] += if entry[l] >> feat & 1 == 1 {
                            w[l]
                        } else {
                            -w[l]
                        };
                    }
                }
            }
            for (feat, acc) in acc.iter().enumerate().take(nf) {
                let out = &mut xt[k * nf + feat];
                for l in 0..LANES {
                    out[l] = acc[l] / (wsum[l] + WEIGHT_EPS) * gate[l];
                }
            }
        }
    }
}

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

/// `out[u] = b[u] + sum_i w[u][i] * f(input[i])` per lane, `f` = ReLU when `relu_input`: each
/// unit starts at its bias and takes the fused multiply-adds of its inputs in order, as the
/// plain `NtcField::mlp_into` does; `mul_add` is exact everywhere, so every CPU gives the same
/// bits.
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
