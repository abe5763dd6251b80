//! Bias-free MLPs evaluated on panels of [`PANEL`] rows stored column-wise (`x[input][row]`),
//! so every multiply-add runs across rows in SIMD lanes and the hidden layer stays in L1.
//!
//! The sum over inputs always runs in ascending order with fused multiply-adds
//! (`f32::mul_add`), so a row's result depends neither on the thread count nor on which SIMD
//! width the CPU offers: the runtime-dispatched versions and the portable fallback produce the
//! same bits (format-spec §6.4, determinism rule).

use dlgs::model::Mlp;

use crate::panel_nofma::{self, Lane64};
use multiversion::multiversion;

/// Layers by `panel_nofma` on CPUs without an FMA instruction (wasm32).
const NO_FMA: bool = cfg!(target_arch = "wasm32");

/// Rows per panel: one AVX-512 register, two AVX2 registers.
pub const PANEL: usize = 16;

/// One panel column: a value for each of the panel's rows.
pub type Lane = [f32; PANEL];

#[derive(Debug, Clone)]
struct PanelLayer {
    inputs: usize,
    outputs: usize,
    /// PyTorch layout `weights[o * inputs + i]`.
    weights: Vec<f32>,
    /// The same widened to binary64 where `panel_nofma` evaluates the layers (else empty).
    weights64: Vec<f64>,
}

/// An MLP ready for panel evaluation: ReLU between layers, tanh at the end if its role has it.
#[derive(Debug, Clone)]
pub struct PanelMlp {
    layers: Vec<PanelLayer>,
    tanh: bool,
}

/// Scratch space for the hidden layers, reused across panels of one block.
#[derive(Default)]
pub struct Scratch {
    a: Vec<Lane>,
    b: Vec<Lane>,
    /// The layer input widened to binary64 (`panel_nofma`).
    wide: Vec<Lane64>,
}

/// `y[o] = Σ_i w[o, i] · x[i]` for every row of the panel, inputs in ascending order.
/// Four outputs at a time share each load of `x[i]` (register blocking).
#[multiversion(targets("x86_64+avx512f+avx512vl+avx2+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn layer(x: &[Lane], weights: &[f32], y: &mut [Lane]) {
    let inputs = x.len();
    let mut quads = y.chunks_exact_mut(4);
    let mut wq = weights.chunks_exact(4 * inputs);
    for (yq, w) in (&mut quads).zip(&mut wq) {
        let (w0, rest) = w.split_at(inputs);
        let (w1, rest) = rest.split_at(inputs);
        let (w2, w3) = rest.split_at(inputs);
        let mut acc = [[0f32; PANEL]; 4];
        for (j, xi) in x.iter().enumerate() {
            let wj = [w0[j], w1[j], w2[j], w3[j]];
            for q in 0..4 {
                for l in 0..PANEL {
                    acc[q][l] = xi[l].mul_add(wj[q], acc[q][l]);
                }
            }
        }
        yq.copy_from_slice(&acc);
    }
    for (yo, wo) in quads
        .into_remainder()
        .iter_mut()
        .zip(wq.remainder().chunks_exact(inputs))
    {
        let mut acc = [0f32; PANEL];
        for (xi, &w) in x.iter().zip(wo) {
            for l in 0..PANEL {
                acc[l] = xi[l].mul_add(w, acc[l]);
            }
        }
        *yo = acc;
    }
}

/// `tanh` of every value, vectorisable: `sign(x)·(1 − e)/(1 + e)` with `e = exp(−2|x|)`
/// from a Cody–Waite range reduction and a degree-7 Taylor polynomial. Absolute error below
/// 3e-7 (test below), the same bits on every CPU (format-spec §6.4).
#[multiversion(targets("x86_64+avx512f+avx512vl+avx2+fma", "x86_64+avx2+fma", "aarch64+neon"))]
pub fn tanh_lanes(v: &mut [Lane]) {
    for lane in v {
        for x in lane.iter_mut() {
            *x = tanh_f32(*x);
        }
    }
}

/// The decoder's `tanh` (format-spec §6.4): `sign(x)(1-e)/(1+e)`, `e = exp(-2 min(|x|, 9))`,
/// `exp` by Cody-Waite reduction and a degree-7 Taylor polynomial; the same bits on every
/// platform and SIMD width.
#[inline(always)]
pub fn tanh_f32(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    // tanh(9) rounds to 1 in f32; the clamp also maps NaN to 9 (inputs are finite).
    let a = x.abs().min(9.0);
    let y = -2.0 * a;
    let n = (y * LOG2E).round();
    let r = (-n).mul_add(LN2_LO, (-n).mul_add(LN2_HI, y));
    let mut p: f32 = 1.0 / 5040.0;
    for c in [
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p.mul_add(r, c);
    }
    // n is in [-26, 0]: a normal power of two.
    let e = p * f32::from_bits(((n as i32 + 127) as u32) << 23);
    let t = (1.0 - e) / (1.0 + e);
    t.copysign(x)
}

fn relu(v: &mut [Lane]) {
    for lane in v {
        for x in lane.iter_mut() {
            *x = x.max(0.0);
        }
    }
}

impl PanelMlp {
    pub fn new(m: &Mlp) -> Self {
        PanelMlp {
            layers: m
                .layers
                .iter()
                .map(|l| PanelLayer {
                    inputs: l.inputs,
                    outputs: l.outputs,
                    weights: l.weights.clone(),
                    weights64: if NO_FMA {
                        l.weights.iter().map(|&w| f64::from(w)).collect()
                    } else {
                        Vec::new()
                    },
                })
                .collect(),
            tanh: m.role.output_tanh(),
        }
    }

    /// One layer, by hardware FMA or (wasm32) by `panel_nofma`: the same bits.
    fn layer(&self, x: &[Lane], l: &PanelLayer, y: &mut [Lane], wide: &mut Vec<Lane64>) {
        if NO_FMA {
            panel_nofma::layer(x, &l.weights64, y, wide);
        } else {
            layer(x, &l.weights, y);
        }
    }

    pub fn inputs(&self) -> usize {
        self.layers.first().map_or(0, |l| l.inputs)
    }
    pub fn outputs(&self) -> usize {
        self.layers.last().map_or(0, |l| l.outputs)
    }

    /// Evaluate one panel: `x` has [`Self::inputs`] columns, `out` receives
    /// [`Self::outputs`] columns.
    pub fn run(&self, x: &[Lane], scratch: &mut Scratch, out: &mut [Lane]) {
        debug_assert_eq!(x.len(), self.inputs());
        debug_assert_eq!(out.len(), self.outputs());
        let last = self.layers.len() - 1;
        let Scratch { a, b, wide } = scratch;
        for (i, l) in self.layers.iter().enumerate() {
            let input: &[Lane] = if i == 0 { x } else { a };
            if i == last {
                self.layer(input, l, out, wide);
            } else {
                b.resize(l.outputs, [0.0; PANEL]);
                self.layer(input, l, b, wide);
                relu(b);
                std::mem::swap(a, b);
            }
        }
        if self.tanh {
            tanh_lanes(out);
        }
    }
}

#[cfg(test)]
#[allow(clippy::disallowed_methods)] // the platform libm as a reference or test data
mod tests {
    use super::*;
    use dlgs::model::{Layer, MlpRole};

    fn mlp(role: MlpRole, widths: &[usize]) -> Mlp {
        let mut seed = 7u32;
        let mut next = || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        Mlp {
            role,
            layers: widths
                .windows(2)
                .map(|w| Layer {
                    inputs: w[0],
                    outputs: w[1],
                    weights: (0..w[0] * w[1]).map(|_| next()).collect(),
                })
                .collect(),
        }
    }

    /// Row-by-row f64 evaluation, the definition the panel kernel must match.
    fn plain(m: &Mlp, x: &[f32]) -> Vec<f64> {
        let mut h: Vec<f64> = x.iter().map(|&v| v as f64).collect();
        for (i, l) in m.layers.iter().enumerate() {
            let mut y = vec![0f64; l.outputs];
            for o in 0..l.outputs {
                for j in 0..l.inputs {
                    y[o] += l.weights[o * l.inputs + j] as f64 * h[j];
                }
            }
            if i + 1 < m.layers.len() {
                y.iter_mut().for_each(|v| *v = v.max(0.0));
            }
            h = y;
        }
        if m.role.output_tanh() {
            h.iter_mut().for_each(|v| *v = v.tanh());
        }
        h
    }

    #[test]
    fn tanh_is_accurate_and_odd() {
        let xs: Vec<f32> = (-200_000..=200_000)
            .map(|i| i as f32 * 1e-4)
            .chain([0.0, -0.0, 1e-30, -1e-30, 8.99, 9.5, 50.0, -1e30, f32::MAX])
            .collect();
        let mut lanes: Vec<Lane> = xs
            .chunks(PANEL)
            .map(|c| std::array::from_fn(|l| c.get(l).copied().unwrap_or(0.0)))
            .collect();
        tanh_lanes(&mut lanes);
        for (i, &x) in xs.iter().enumerate() {
            let got = lanes[i / PANEL][i % PANEL];
            let want = (x as f64).tanh();
            assert!(
                (got as f64 - want).abs() < 3e-7,
                "tanh({x}) = {got}, want {want}"
            );
            assert!(got.abs() <= 1.0);
        }
    }

    #[test]
    fn panel_matches_row_by_row_evaluation() {
        for (role, widths) in [
            (MlpRole::Opacity, vec![12, 64, 2]),
            (MlpRole::Color, vec![12, 64, 12]),
            (MlpRole::Lang, vec![8, 32, 16, 9]),
        ] {
            let m = mlp(role, &widths);
            let p = PanelMlp::new(&m);
            let rows: Vec<Vec<f32>> = (0..PANEL)
                .map(|r| {
                    (0..widths[0])
                        .map(|j| ((r * 7 + j * 3) % 11) as f32 * 0.3 - 1.4)
                        .collect()
                })
                .collect();
            let x: Vec<Lane> = (0..widths[0])
                .map(|j| std::array::from_fn(|r| rows[r][j]))
                .collect();
            let mut out = vec![[0f32; PANEL]; p.outputs()];
            p.run(&x, &mut Scratch::default(), &mut out);
            for r in 0..PANEL {
                let want = plain(&m, &rows[r]);
                for o in 0..p.outputs() {
                    assert!(
                        (out[o][r] as f64 - want[o]).abs() < 1e-4,
                        "{role:?} row {r} output {o}: {} vs {}",
                        out[o][r],
                        want[o]
                    );
                }
            }
        }
    }
}
