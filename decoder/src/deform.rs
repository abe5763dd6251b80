//! Turn a GOP's canonical dynamic Gaussians plus its deformation field into the Gaussians of
//! one instant (format-spec §6.4). Geometry that depends only on a key is computed once per GOP;
//! per frame only the Hermite/slerp blend and the view-dependent appearance (and language, if
//! asked) are evaluated, as GEMMs over fixed blocks of rows so the result never depends on the
//! thread count.

use dlgs::container::header::DeformModel;
use dlgs::model::{DynamicGop, Gaussians, TimeFeatures};
use ndarray::{Array2, ArrayView2};
use rayon::prelude::*;

use crate::interp::{hermite, lerp, normalize4, slerp_reference};
use crate::mlp::PreparedMlp;

/// Rows per block. Fixed (not derived from the thread count) so output is deterministic.
pub const BLOCK: usize = 1024;

/// What the caller wants of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameOptions {
    /// Camera centre in world space, for the view-dependent opacity and colour decoders.
    pub camera_center: [f32; 3],
    /// Evaluate the language decoder (otherwise dynamic Gaussians keep canonical language).
    pub language: bool,
}

/// Per-key geometry of the reference model (§6.4), `[i * keys + k]`.
struct KeyGeometry {
    pos: Vec<[f32; 3]>,
    tangent: Vec<[f32; 3]>,
    /// Normalised `q_c + Δq_k`.
    quat: Vec<[f32; 4]>,
    /// `Δlog-scale_k`, when the GOP applies scale offsets.
    dscale: Option<Vec<[f32; 3]>>,
}

/// A GOP's deformation field, ready to produce frames.
pub struct Deformer {
    model: DeformModel,
    /// The decoded field; the prepared MLPs below are its weights, transposed.
    gop: DynamicGop,
    deform: PreparedMlp,
    cov: PreparedMlp,
    opacity: PreparedMlp,
    color: PreparedMlp,
    lang: Option<PreparedMlp>,
    scale_offsets: bool,
    geometry: Option<KeyGeometry>,
}

fn blocks(n: usize) -> impl IndexedParallelIterator<Item = std::ops::Range<usize>> {
    (0..n.div_ceil(BLOCK))
        .into_par_iter()
        .map(move |b| b * BLOCK..((b + 1) * BLOCK).min(n))
}

/// Rows `F[i, k, c0..c0+w]` of a block, as a matrix.
fn key_rows(
    f: &TimeFeatures,
    rows: std::ops::Range<usize>,
    k: usize,
    c0: usize,
    w: usize,
) -> Array2<f32> {
    let mut x = Array2::zeros((rows.len(), w));
    for (r, i) in rows.enumerate() {
        x.row_mut(r)
            .as_slice_mut()
            .expect("standard layout")
            .copy_from_slice(&f.at(i, k)[c0..c0 + w]);
    }
    x
}

/// `lerp(F_k, F_k1, δ)[c0..c0+w]` of a block, written into the first `w` columns of a
/// `(rows, w + extra)` matrix.
fn lerp_rows(
    f: &TimeFeatures,
    rows: std::ops::Range<usize>,
    k: usize,
    d: f32,
    c0: usize,
    w: usize,
    extra: usize,
) -> Array2<f32> {
    let cols = w + extra;
    let mut buf = vec![0f32; rows.len() * cols];
    let (keys, ch) = (f.keys, f.channels);
    for (dst, i) in buf.chunks_exact_mut(cols).zip(rows) {
        let a0 = (i * keys + k) * ch + c0;
        let a = &f.data[a0..a0 + w];
        let b = &f.data[a0 + ch..a0 + ch + w];
        for ((d_, &x), &y) in dst[..w].iter_mut().zip(a).zip(b) {
            *d_ = lerp(x, y, d);
        }
    }
    Array2::from_shape_vec((buf.len() / cols, cols), buf).expect("sized above")
}

impl Deformer {
    /// Prepare a GOP: transposes weights and, for the reference model, evaluates the geometry
    /// decoders on every key (`N * K` rows).
    pub fn new(canon: &Gaussians, gop: DynamicGop, model: DeformModel) -> Self {
        let m = &gop.mlps;
        let mut d = Deformer {
            model,
            deform: PreparedMlp::new(&m.deform),
            cov: PreparedMlp::new(&m.cov),
            opacity: PreparedMlp::new(&m.opacity),
            color: PreparedMlp::new(&m.color),
            lang: m.lang.as_ref().map(PreparedMlp::new),
            scale_offsets: m.scale_offsets,
            geometry: None,
            gop,
        };
        if model == DeformModel::Reference {
            d.geometry = Some(d.key_geometry(canon));
        }
        d
    }

    /// The time features and decoders this deformer was built from.
    pub fn gop(&self) -> &DynamicGop {
        &self.gop
    }

    fn features(&self) -> &TimeFeatures {
        &self.gop.features
    }

    fn key_geometry(&self, canon: &Gaussians) -> KeyGeometry {
        let f = self.features();
        let keys = f.keys;
        let parts: Vec<KeyGeometry> = blocks(f.n)
            .map(|rows| {
                let len = rows.len() * keys;
                let mut g = KeyGeometry {
                    pos: vec![[0.0; 3]; len],
                    tangent: vec![[0.0; 3]; len],
                    quat: vec![[0.0; 4]; len],
                    dscale: self.scale_offsets.then(|| vec![[0.0; 3]; len]),
                };
                for k in 0..keys {
                    let x = key_rows(f, rows.clone(), k, 0, 12);
                    let o = self.deform.run(x.view());
                    let c = self.cov.run(x.view());
                    for (r, i) in rows.clone().enumerate() {
                        let j = r * keys + k;
                        let (o, c) = (o.row(r), c.row(r));
                        let p = canon.positions[i];
                        g.pos[j] = [p[0] + o[0], p[1] + o[1], p[2] + o[2]];
                        g.tangent[j] = [o[3], o[4], o[5]];
                        let q = canon.rotations[i];
                        g.quat[j] =
                            normalize4([q[0] + c[3], q[1] + c[4], q[2] + c[5], q[3] + c[6]]);
                        if let Some(ds) = &mut g.dscale {
                            ds[j] = [c[0], c[1], c[2]];
                        }
                    }
                }
                g
            })
            .collect();
        let mut out = KeyGeometry {
            pos: Vec::with_capacity(f.n * keys),
            tangent: Vec::with_capacity(f.n * keys),
            quat: Vec::with_capacity(f.n * keys),
            dscale: self.scale_offsets.then(|| Vec::with_capacity(f.n * keys)),
        };
        for p in parts {
            out.pos.extend(p.pos);
            out.tangent.extend(p.tangent);
            out.quat.extend(p.quat);
            if let (Some(o), Some(s)) = (&mut out.dscale, p.dscale) {
                o.extend(s);
            }
        }
        out
    }

    /// The dynamic Gaussians at key pair (`key`, `key + 1`) and fraction `delta`.
    pub fn frame(
        &self,
        canon: &Gaussians,
        key: usize,
        delta: f32,
        opts: &FrameOptions,
    ) -> Gaussians {
        let language = opts.language && self.lang.is_some() && canon.has_language();
        let parts: Vec<Gaussians> = blocks(self.features().n)
            .map(|rows| self.frame_block(canon, rows, key, delta, opts.camera_center, language))
            .collect();
        let mut out = Gaussians::new(canon.sh_degree, canon.lang_width);
        for p in &parts {
            out.extend(p);
        }
        out
    }

    fn frame_block(
        &self,
        canon: &Gaussians,
        rows: std::ops::Range<usize>,
        k: usize,
        d: f32,
        cam: [f32; 3],
        language: bool,
    ) -> Gaussians {
        let f = self.features();
        let n = rows.len();
        let mut g = Gaussians::new(canon.sh_degree, canon.lang_width);
        g.positions.reserve(n);
        g.log_scales.reserve(n);
        g.rotations.reserve(n);

        // Geometry.
        match (&self.geometry, self.model) {
            (Some(geo), DeformModel::Reference) => {
                let keys = f.keys;
                for i in rows.clone() {
                    let (a, b) = (i * keys + k, i * keys + k + 1);
                    g.positions.push(hermite(
                        geo.pos[a],
                        geo.tangent[a],
                        geo.pos[b],
                        geo.tangent[b],
                        d,
                    ));
                    g.rotations
                        .push(slerp_reference(geo.quat[a], geo.quat[b], d));
                    let s = canon.log_scales[i];
                    g.log_scales.push(match &geo.dscale {
                        // Key `k` only, no interpolation (the reference's eval path).
                        Some(ds) => [s[0] + ds[a][0], s[1] + ds[a][1], s[2] + ds[a][2]],
                        None => s,
                    });
                }
            }
            _ => {
                // The paper's plain form: decoders applied to the interpolated feature.
                let x = lerp_rows(f, rows.clone(), k, d, 0, 12, 0);
                let o = self.deform.run(x.view());
                let c = self.cov.run(x.view());
                for (r, i) in rows.clone().enumerate() {
                    let (o, c) = (o.row(r), c.row(r));
                    let p = canon.positions[i];
                    g.positions.push([p[0] + o[0], p[1] + o[1], p[2] + o[2]]);
                    let q = canon.rotations[i];
                    g.rotations.push(normalize4([
                        q[0] + c[3],
                        q[1] + c[4],
                        q[2] + c[5],
                        q[3] + c[6],
                    ]));
                    let s = canon.log_scales[i];
                    g.log_scales.push(if self.scale_offsets {
                        [s[0] + c[0], s[1] + c[1], s[2] + c[2]]
                    } else {
                        s
                    });
                }
            }
        }

        // Appearance: lerp(F[4:12]) ‖ view dir ‖ distance, from the canonical position.
        let mut x = lerp_rows(f, rows.clone(), k, d, 4, 8, 4);
        for (r, i) in rows.clone().enumerate() {
            let p = canon.positions[i];
            let v = [p[0] - cam[0], p[1] - cam[1], p[2] - cam[2]];
            let dist = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            // The reference divides without an epsilon; a Gaussian exactly at the camera gets
            // direction 0 here instead of NaN.
            let inv = if dist > 0.0 { 1.0 / dist } else { 0.0 };
            let row = x.row_mut(r).into_slice().expect("standard layout");
            row[8] = v[0] * inv;
            row[9] = v[1] * inv;
            row[10] = v[2] * inv;
            row[11] = dist;
        }
        let dop = self.opacity.run(x.view());
        let dsh = self.color.run(x.view());
        let stride = canon.sh_stride();
        g.sh = canon.sh[rows.start * stride..rows.end * stride].to_vec();
        let m = dsh.ncols().min(stride);
        for r in 0..n {
            let dst = &mut g.sh[r * stride..r * stride + m];
            for (s, v) in dst.iter_mut().zip(dsh.row(r).iter()) {
                *s += v;
            }
        }
        g.opacity = rows
            .clone()
            .enumerate()
            .map(|(r, i)| canon.opacity[i] + dop[[r, 0]])
            .collect();
        if canon.has_language() {
            g.lang_opacity = rows
                .clone()
                .enumerate()
                .map(|(r, i)| {
                    canon.lang_opacity[i] + if dop.ncols() > 1 { dop[[r, 1]] } else { 0.0 }
                })
                .collect();
            let lw = canon.lang_width;
            g.lang = canon.lang[rows.start * lw..rows.end * lw].to_vec();
            if language {
                let y = lerp_rows(f, rows.clone(), k, d, 8, 8, 0);
                let dl = self.lang.as_ref().expect("checked").run(y.view());
                add_rows(&mut g.lang, lw, dl.view());
            }
        }
        g
    }
}

fn add_rows(dst: &mut [f32], width: usize, delta: ArrayView2<f32>) {
    for (r, row) in dst.chunks_exact_mut(width).enumerate() {
        for (s, v) in row.iter_mut().zip(delta.row(r).iter()) {
            *s += v;
        }
    }
}
