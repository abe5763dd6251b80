//! Neural Gaussians: the children each anchor's MLPs generate for one camera (§5.2 of
//! ../shared/reference, the reference's `generate_neural_gaussians`).
//!
//! Per anchor `a` with (possibly deformed) position `p`, feature `f`, offsets `o_k` and
//! log-scalings `s`, and the camera centre `e`:
//!
//! - `v = c - e` with `c` the anchor's **pre-deformation** position, `dist = |v|`
//!   (`sqrt((v0² + v1²) + v2²)`), `dir = v / dist` (`0` if `dist = 0`);
//! - `x = f ‖ dir ‖ dist` (54 values);
//! - opacities `tanh(opacity(x))`: child k's colour opacity is output `2k` (with language; `k`
//!   without) and its language opacity `2k + 1`. A child is **kept iff its colour opacity > 0**;
//!   both are passed on as they are (the language one may be negative);
//! - colour `sigmoid(color(x))[3k..3k+3]`; `cov(x)[7k..7k+7]` = `(σ0, σ1, σ2, q)`;
//! - scale `exp(s[3+d]) × sigmoid(σ_d)`, rotation `q / max(|q|, 1e-12)`, position
//!   `p + o_k × exp(s[0..3])`; language `language(x)[9k..9k+9]` when asked.
//!
//! `exp` and the logistic function are `dlgs::elementary`'s (binary64, rounded to binary32).

use rayon::prelude::*;

use dlgs::elementary::{exp, sigmoid_f32};
use dlgs::model::scaffold::{Anchors, ScaffoldMlps, FEAT_DIM, LANG_DIM, N_OFFSETS, VIEW_INPUTS};

use super::mlp::eval;

/// Anchors per parallel block (fixed: the result does not depend on the thread count).
const BLOCK: usize = 128;

/// The Gaussians one view of a Scaffold-GS scene shows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NeuralGaussians {
    pub positions: Vec<[f32; 3]>,
    /// Linear scales (not logarithms).
    pub scales: Vec<[f32; 3]>,
    /// Unit quaternions (w, x, y, z).
    pub rotations: Vec<[f32; 4]>,
    /// RGB in [0, 1].
    pub colors: Vec<[f32; 3]>,
    /// Colour opacity: the tanh output, in (0, 1) for every kept child.
    pub opacity: Vec<f32>,
    /// Language opacity (tanh output, may be negative); empty without language.
    pub lang_opacity: Vec<f32>,
    /// `LANG_DIM` per child when language was asked for, else empty.
    pub lang: Vec<f32>,
    /// The anchor each child comes from and its offset index.
    pub source: Vec<(u32, u8)>,
}

impl NeuralGaussians {
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
    fn append(&mut self, mut o: NeuralGaussians) {
        self.positions.append(&mut o.positions);
        self.scales.append(&mut o.scales);
        self.rotations.append(&mut o.rotations);
        self.colors.append(&mut o.colors);
        self.opacity.append(&mut o.opacity);
        self.lang_opacity.append(&mut o.lang_opacity);
        self.lang.append(&mut o.lang);
        self.source.append(&mut o.source);
    }
}

/// What one view asks of the anchors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewRequest<'a> {
    pub camera_center: [f32; 3],
    /// Evaluate the language MLP (otherwise `lang` stays empty).
    pub language: bool,
    /// Anchors to decode (e.g. those in the view frustum); `None`: all.
    pub visible: Option<&'a [bool]>,
}

/// The neural Gaussians of `anchors` for one view. `view_positions[a]` is anchor a's
/// pre-deformation position (the view direction and distance come from it); `anchors` holds
/// the (possibly deformed) state. Children appear anchor by anchor, offset by offset.
pub fn neural_gaussians(
    view_positions: &[[f32; 3]],
    anchors: &Anchors,
    mlps: &ScaffoldMlps,
    view: &ViewRequest,
) -> NeuralGaussians {
    let n = anchors.len();
    let ids: Vec<u32> = (0..n as u32)
        .filter(|&a| view.visible.is_none_or(|v| v[a as usize]))
        .collect();
    let language = view.language && mlps.language.is_some();
    let with_lang_opacity = mlps.language.is_some();
    let hidden = [
        Some(&mlps.opacity),
        Some(&mlps.color),
        Some(&mlps.cov),
        mlps.language.as_ref(),
    ]
    .iter()
    .flatten()
    .map(|m| m.first.outputs)
    .max()
    .unwrap_or(0);
    let parts: Vec<NeuralGaussians> = ids
        .par_chunks(BLOCK)
        .map(|block| {
            let mut out = NeuralGaussians::default();
            let mut h = vec![0f32; hidden];
            let mut x = [0f32; VIEW_INPUTS];
            let mut op = [0f32; 2 * N_OFFSETS];
            let mut col = [0f32; 3 * N_OFFSETS];
            let mut cov = [0f32; 7 * N_OFFSETS];
            let mut lang = [0f32; LANG_DIM * N_OFFSETS];
            for &a in block {
                let a = a as usize;
                let c = view_positions[a];
                let e = view.camera_center;
                let v = [c[0] - e[0], c[1] - e[1], c[2] - e[2]];
                let dist = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                x[..FEAT_DIM].copy_from_slice(anchors.feature(a));
                for d in 0..3 {
                    x[FEAT_DIM + d] = if dist > 0.0 { v[d] / dist } else { 0.0 };
                }
                x[FEAT_DIM + 3] = dist;
                eval(&mlps.opacity, &x, &mut h, &mut op);
                let colour_op = |k: usize| if with_lang_opacity { op[2 * k] } else { op[k] };
                if !(0..N_OFFSETS).any(|k| colour_op(k) > 0.0) {
                    continue;
                }
                eval(&mlps.color, &x, &mut h, &mut col);
                eval(&mlps.cov, &x, &mut h, &mut cov);
                if language {
                    if let Some(l) = &mlps.language {
                        eval(l, &x, &mut h, &mut lang);
                    }
                }
                let s = anchors.log_scaling(a);
                let es: [f32; 6] = std::array::from_fn(|d| exp(s[d] as f64) as f32);
                let p = anchors.positions[a];
                let off = anchors.offset(a);
                for k in 0..N_OFFSETS {
                    if !(colour_op(k) > 0.0) {
                        continue;
                    }
                    let cv = &cov[7 * k..7 * k + 7];
                    out.scales
                        .push(std::array::from_fn(|d| es[3 + d] * sigmoid_f32(cv[d])));
                    let q = [cv[3], cv[4], cv[5], cv[6]];
                    let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
                        .sqrt()
                        .max(1e-12);
                    out.rotations.push(q.map(|v| v / norm));
                    out.positions
                        .push(std::array::from_fn(|d| p[d] + off[3 * k + d] * es[d]));
                    out.colors
                        .push([col[3 * k], col[3 * k + 1], col[3 * k + 2]]);
                    out.opacity.push(colour_op(k));
                    if with_lang_opacity {
                        out.lang_opacity.push(op[2 * k + 1]);
                    }
                    if language {
                        out.lang
                            .extend_from_slice(&lang[LANG_DIM * k..LANG_DIM * (k + 1)]);
                    }
                    out.source.push((a as u32, k as u8));
                }
            }
            out
        })
        .collect();
    let mut all = NeuralGaussians::default();
    for p in parts {
        all.append(p);
    }
    all
}

/// Standard deviations of a child's reach (above `sqrt(2 ln 255)`, the 1/255 cut-off).
pub const REACH_SIGMAS: f32 = 3.5;

/// The SH degree-0 constant: colour = 0.5 + C0 × DC.
const SH_C0: f32 = 0.282_094_8;

impl NeuralGaussians {
    /// As plain 3D Gaussians for the 3DGS renderer and exporters: colours as SH degree 0
    /// (`(rgb - 0.5) / C0`), scales as logarithms, opacities as logits of the tanh outputs.
    /// Lossy where the two models differ: an opacity within 1e-7 of 0 or 1 is clamped there
    /// first, and a negative language opacity (which the reference's rasteriser accepts and
    /// 3DGS cannot express) becomes the logit of 1e-7, i.e. no language contribution.
    pub fn to_gaussians(&self) -> dlgs::Gaussians {
        use dlgs::elementary::ln_f32;
        let logit = |a: f32| {
            let a = a.clamp(1e-7, 1.0 - 1e-7);
            ln_f32(a / (1.0 - a))
        };
        let lang_width = if self.lang.is_empty() { 0 } else { LANG_DIM };
        let mut g = dlgs::Gaussians::new(0, lang_width);
        g.positions = self.positions.clone();
        g.log_scales = self
            .scales
            .iter()
            .map(|s| s.map(|v| ln_f32(v.max(f32::MIN_POSITIVE))))
            .collect();
        g.rotations = self.rotations.clone();
        g.opacity = self.opacity.iter().map(|&a| logit(a)).collect();
        g.sh = self
            .colors
            .iter()
            .flat_map(|c| c.map(|v| (v - 0.5) / SH_C0))
            .collect();
        if lang_width > 0 {
            g.lang_opacity = self.lang_opacity.iter().map(|&a| logit(a)).collect();
            g.lang = self.lang.clone();
        }
        g
    }
}

/// How far any child of each anchor can reach from the anchor's position: the longest scaled
/// offset plus [`REACH_SIGMAS`] of the largest child scale (`exp(s[3..6])` bounds every
/// child's scale, the logistic factor being below 1). A renderer draws a splat out to where its
/// opacity times the Gaussian falls to 1/255: at most `sqrt(2 ln 255) = 3.33` standard
/// deviations, so culling anchors by these spheres against a view frustum (widened by the
/// renderer's dilation) drops no child the view shows.
pub fn anchor_reach(anchors: &Anchors) -> Vec<f32> {
    anchor_reach_range(anchors, 0..anchors.len())
}

/// [`anchor_reach`] of the anchors in `range` only.
pub(crate) fn anchor_reach_range(anchors: &Anchors, range: std::ops::Range<usize>) -> Vec<f32> {
    range
        .map(|a| {
            let s = anchors.log_scaling(a);
            let e: [f32; 6] = std::array::from_fn(|d| exp(s[d] as f64) as f32);
            let off = anchors.offset(a);
            let far = (0..N_OFFSETS)
                .map(|k| {
                    (0..3)
                        .map(|d| {
                            let v = off[3 * k + d] * e[d];
                            v * v
                        })
                        .sum::<f32>()
                        .sqrt()
                })
                .fold(0.0f32, f32::max);
            far + REACH_SIGMAS * e[3].max(e[4]).max(e[5])
        })
        .collect()
}
