//! The deformation field of one GOP fitted to the per-frame attributes of its dynamic
//! Gaussians, in the reference's form (format-spec §6.4, `deform_model = 0`).
//!
//! The decoders are single bias-free linear layers, so every offset the field produces is a
//! linear function of the time features, and the best features for a set of frames solve
//! small linear least-squares problems. They are solved exactly instead of by gradient descent
//! (which would only approach the same optimum, with a learning rate and an iteration budget to
//! tune, and slower):
//!
//! - **positions**: Hermite splines through the keys. Per Gaussian and axis, the key offsets
//!   `p_k` and tangents `m_k` minimise the squared position error over every frame of the GOP
//!   (and the next GOP's first frame, the last key). The normal equations are the same for
//!   every Gaussian: one Cholesky factorisation per GOP. Channels 0-5 hold `[p_k, m_k]`; the
//!   `deform` decoder is the identity on them.
//! - **rotations, log-scales, SH DC colour, opacity**: their offsets at each key (rotations
//!   as the key frame's quaternion minus the canonical one, log-scales as the mean over the
//!   frames that show key k, colours as a piecewise-linear least-squares fit, opacity as the
//!   `atanh` of the key frame's change) form one vector per Gaussian and key. Channels 6-11
//!   hold its principal components (uncentred PCA over the GOP, by [`symmetric_eigen`]); the
//!   `cov`, `color` and `opacity` decoders map them back. Only the components the six channels
//!   cannot hold are lost; the report says how much that is.
//!
//! Channels 12-15 feed only the language decoder and stay zero.

use dlgs::container::header::DeformModel;
use dlgs::model::{DeformMlps, DynamicGop, Gaussians, Layer, Mlp, MlpRole, TimeFeatures};

use super::linalg::{symmetric_eigen, Cholesky};

/// Time-feature channels (§6.4's routing needs 16).
pub const CHANNELS: usize = 16;
/// Channels that carry the shared offsets (rotation, scale, colour, opacity).
pub const SHARED_CHANNELS: usize = 6;
/// Dimensions of the shared offset vector: Δlog-scale 3, Δquaternion 4, ΔSH DC 3, Δopacity 1.
const SHARED_DIMS: usize = 11;
/// Largest opacity change (pre-sigmoid) the tanh of the opacity decoder can give.
const MAX_OPACITY_STEP: f64 = 0.99;

/// What the fit of one GOP could not represent, before any coding.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GopFit {
    /// Root-mean-square position error over every dynamic Gaussian and frame of the fit.
    pub position_rms: f64,
    /// The same per local frame of the GOP (the next GOP's first frame, which the last key
    /// also fits, is not listed: it is that GOP's frame 0).
    pub frame_position_rms: Vec<f64>,
    /// Share of the shared offsets' energy that the six shared channels hold (1 = all).
    pub shared_energy_kept: f64,
    /// Whether log-scales change within the GOP (then the decoder applies them).
    pub scale_offsets: bool,
}

/// (key, δ) of local frame `u` (§6.4, at frame times).
fn locate(u: usize, key_interval: usize, keys: usize) -> (usize, f64) {
    let k = (u / key_interval).min(keys - 2);
    let d = ((u - k * key_interval) as f64 / key_interval as f64).clamp(0.0, 1.0);
    // §6.4 rounds δ to f32 before the formulas.
    (k, d as f32 as f64)
}

fn hermite(d: f64) -> [f64; 4] {
    let (d2, d3) = (d * d, d * d * d);
    [
        2.0 * d3 - 3.0 * d2 + 1.0,
        d3 - 2.0 * d2 + d,
        -2.0 * d3 + 3.0 * d2,
        d3 - d2,
    ]
}

/// Normal equations of a basis (rows `(index, weight)` per observation) plus a small ridge that
/// keeps keys no frame constrains at zero.
fn normal_matrix(rows: &[Vec<(usize, f64)>], n: usize) -> Cholesky {
    let mut a = vec![0.0f64; n * n];
    for r in rows {
        for &(i, wi) in r {
            for &(j, wj) in r {
                a[i * n + j] += wi * wj;
            }
        }
    }
    for i in 0..n {
        a[i * n + i] += 1e-9;
    }
    Cholesky::new(&a, n).expect("a ridge-regularised normal matrix is positive definite")
}

fn solve(
    chol: &Cholesky,
    rows: &[Vec<(usize, f64)>],
    y: impl Fn(usize) -> f64,
    n: usize,
) -> Vec<f64> {
    let mut b = vec![0.0f64; n];
    for (u, r) in rows.iter().enumerate() {
        let v = y(u);
        for &(i, w) in r {
            b[i] += w * v;
        }
    }
    chol.solve(&mut b);
    b
}

fn unit_quat(q: [f32; 4]) -> [f64; 4] {
    let n = q.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
    if n < 1e-12 {
        return [1.0, 0.0, 0.0, 0.0];
    }
    q.map(|v| v as f64 / n)
}

fn single_layer(role: MlpRole, outputs: usize, weights: Vec<f64>) -> Mlp {
    Mlp {
        role,
        layers: vec![Layer {
            inputs: role.inputs(),
            outputs,
            weights: weights.into_iter().map(|w| w as f32).collect(),
        }],
    }
}

/// The local frame whose Gaussians are the GOP's canonical state: the middle of the GOP's own
/// frames, so that the offsets the time features carry are about half as large as from its
/// first frame (the 12-bit features lose a share of their range, and HEVC more on busier
/// pictures).
pub fn canonical_frame(frames: usize, gop_length: usize) -> usize {
    frames.min(gop_length).saturating_sub(1) / 2
}

/// Fit one GOP. `frames[u]` is local frame `u` (0 ..= at most `gop_length`, the last being the
/// next GOP's first frame when there is one), all in track order; `ids` are the dynamic
/// Gaussians. Returns their canonical state (that of [`canonical_frame`], rotations
/// normalised) and the field.
pub fn fit_gop(
    frames: &[&Gaussians],
    ids: &[usize],
    gop_length: usize,
    key_interval: usize,
) -> (Gaussians, DynamicGop, GopFit) {
    let first = frames[canonical_frame(frames.len(), gop_length)];
    let mut canon = Gaussians::new(first.sh_degree, 0);
    for &i in ids {
        canon.push_from(first, i);
    }
    for q in &mut canon.rotations {
        *q = unit_quat(*q).map(|v| v as f32);
    }
    let (field, fit) = fit_gop_to(frames, ids, &canon, gop_length, key_interval);
    (canon, field, fit)
}

/// Fit one GOP's field to a given canonical state of its dynamic Gaussians (row r of `canon`
/// is Gaussian `ids[r]`): e.g. the state a residual field gives from the previous GOP, as the
/// decoder will hold it. Raw quaternions that are not of unit length take offsets that make
/// `normalize(q_c + offset)` the frame's rotation (§6.4).
pub fn fit_gop_to(
    frames: &[&Gaussians],
    ids: &[usize],
    canon: &Gaussians,
    gop_length: usize,
    key_interval: usize,
) -> (DynamicGop, GopFit) {
    let keys = gop_length / key_interval + 1;
    let first = frames[0];
    let n = ids.len();
    let stride = first.sh_stride();
    // Hermite rows over [p_0..p_K-1, m_0..m_K-1]; hat rows over [c_0..c_K-1].
    let herm: Vec<Vec<(usize, f64)>> = (0..frames.len())
        .map(|u| {
            let (k, d) = locate(u, key_interval, keys);
            let h = hermite(d);
            vec![
                (k, h[0]),
                (keys + k, h[1]),
                (k + 1, h[2]),
                (keys + k + 1, h[3]),
            ]
        })
        .collect();
    let hats: Vec<Vec<(usize, f64)>> = (0..frames.len())
        .map(|u| {
            let (k, d) = locate(u, key_interval, keys);
            vec![(k, 1.0 - d), (k + 1, d)]
        })
        .collect();
    let herm_chol = normal_matrix(&herm, 2 * keys);
    let hat_chol = normal_matrix(&hats, keys);
    // The frame that stands for key k (clamped to the frames there are).
    let key_frame = |k: usize| (k * key_interval).min(frames.len() - 1);

    // The frames that show key k's log-scale offset (key k applies to them, §6.4).
    let spans: Vec<Vec<usize>> = (0..keys)
        .map(|k| {
            (0..frames.len())
                .filter(|&u| locate(u, key_interval, keys).0 == k.min(keys - 2))
                .collect()
        })
        .collect();
    let mut features = TimeFeatures::zeros(n, keys, CHANNELS);
    let mut shared = vec![[0.0f64; SHARED_DIMS]; n * keys];
    let mut sq_err = 0.0f64;
    let mut frame_sq = vec![0.0f64; frames.len()];
    let mut scale_moves = false;
    for (row, &i) in ids.iter().enumerate() {
        let xc = canon.positions[row];
        for a in 0..3 {
            let z = solve(
                &herm_chol,
                &herm,
                |u| (frames[u].positions[i][a] - xc[a]) as f64,
                2 * keys,
            );
            for k in 0..keys {
                let f = features.at_mut(row, k);
                f[a] = z[k] as f32;
                f[3 + a] = z[keys + k] as f32;
            }
            for (u, r) in herm.iter().enumerate() {
                let fit: f64 = r.iter().map(|&(j, w)| w * z[j]).sum();
                let e = (fit - (frames[u].positions[i][a] - xc[a]) as f64).powi(2);
                sq_err += e;
                frame_sq[u] += e;
            }
        }
        // A unit canonical quaternion (the frame's own) takes `q - q_c`; any other (a residual
        // field's output) `|q_c| q - q_c`, whose sum with q_c normalises to q.
        let raw = canon.rotations[row].map(|v| v as f64);
        let len = raw.iter().map(|v| v * v).sum::<f64>().sqrt();
        let (qc, qlen) = if (len - 1.0).abs() < 1e-6 {
            (unit_quat(canon.rotations[row]), 1.0)
        } else {
            (raw, len)
        };
        let sc = canon.log_scales[row];
        let dc = &canon.sh[row * stride..row * stride + 3];
        let colour: Vec<Vec<f64>> = (0..3)
            .map(|c| {
                solve(
                    &hat_chol,
                    &hats,
                    |u| (frames[u].sh[i * stride + c] - dc[c]) as f64,
                    keys,
                )
            })
            .collect();
        for k in 0..keys {
            let v = &mut shared[row * keys + k];
            let span = &spans[k];
            for a in 0..3 {
                let m = span
                    .iter()
                    .map(|&u| (frames[u].log_scales[i][a] - sc[a]) as f64)
                    .sum::<f64>()
                    / span.len().max(1) as f64;
                v[a] = m;
                scale_moves |= m.abs() > 1e-6;
            }
            let mut q = unit_quat(frames[key_frame(k)].rotations[i]);
            if (0..4).map(|c| q[c] * qc[c]).sum::<f64>() < 0.0 {
                q = q.map(|x| -x);
            }
            for c in 0..4 {
                v[3 + c] = q[c] * qlen - qc[c];
            }
            for c in 0..3 {
                v[7 + c] = colour[c][k];
            }
            let dop = (frames[key_frame(k)].opacity[i] - canon.opacity[row]) as f64;
            v[10] = dop.clamp(-MAX_OPACITY_STEP, MAX_OPACITY_STEP).atanh();
        }
    }
    // Principal axes of the shared offsets.
    let mut cov = vec![0.0f64; SHARED_DIMS * SHARED_DIMS];
    for v in &shared {
        for a in 0..SHARED_DIMS {
            for b in 0..SHARED_DIMS {
                cov[a * SHARED_DIMS + b] += v[a] * v[b];
            }
        }
    }
    let (values, axes) = symmetric_eigen(&cov, SHARED_DIMS);
    let total: f64 = values.iter().map(|v| v.max(0.0)).sum();
    let kept: f64 = values[..SHARED_CHANNELS].iter().map(|v| v.max(0.0)).sum();
    for (row, v) in shared.chunks(keys).enumerate() {
        for (k, v) in v.iter().enumerate() {
            let f = features.at_mut(row, k);
            for (j, axis) in axes[..SHARED_CHANNELS].iter().enumerate() {
                f[6 + j] = (0..SHARED_DIMS).map(|d| axis[d] * v[d]).sum::<f64>() as f32;
            }
        }
    }
    // Decoders: deform is the identity on channels 0-5; the others read channels 6-11 (cov
    // from F[0:12], colour and opacity from F[4:12], where channel c is input c - 4).
    let mut deform = vec![0.0; 6 * 12];
    for o in 0..6 {
        deform[o * 12 + o] = 1.0;
    }
    let mut cov_w = vec![0.0; 7 * 12];
    let mut colour_w = vec![0.0; 3 * 12];
    let mut opacity_w = vec![0.0; 12];
    for (j, axis) in axes[..SHARED_CHANNELS].iter().enumerate() {
        for o in 0..7 {
            cov_w[o * 12 + 6 + j] = axis[o];
        }
        for o in 0..3 {
            colour_w[o * 12 + 2 + j] = axis[7 + o];
        }
        opacity_w[2 + j] = axis[10];
    }
    let mlps = DeformMlps {
        deform: single_layer(MlpRole::Deform, 6, deform),
        cov: single_layer(MlpRole::Cov, 7, cov_w),
        opacity: single_layer(MlpRole::Opacity, 1, opacity_w),
        color: single_layer(MlpRole::Color, 3, colour_w),
        lang: None,
        scale_offsets: scale_moves,
    };
    let own = frames.len().min(gop_length);
    let fit = GopFit {
        position_rms: (sq_err / (3 * n * frames.len()).max(1) as f64).sqrt(),
        frame_position_rms: frame_sq[..own]
            .iter()
            .map(|e| (e / (3 * n).max(1) as f64).sqrt())
            .collect(),
        shared_energy_kept: if total > 0.0 { kept / total } else { 1.0 },
        scale_offsets: scale_moves,
    };
    (
        DynamicGop {
            features,
            mlps,
            life: None,
        },
        fit,
    )
}

/// The deformation model the fit produces.
pub const DEFORM_MODEL: DeformModel = DeformModel::Reference;
