//! Turn a GOP's canonical dynamic Gaussians plus its deformation field into the Gaussians of
//! one instant (format-spec §6.4). Geometry that depends only on a key is computed once per GOP,
//! the first time a frame needs that key (a seek needs 2 of the 7); per frame only the
//! Hermite/slerp blend and the view-dependent appearance (and language, if asked) are evaluated.
//! Work is split into fixed blocks of rows, each written in place into the output, so the result
//! never depends on the thread count.

use std::ops::Range;
use std::sync::OnceLock;

use dlgs::container::header::DeformModel;
use dlgs::elementary::sin_lanes;
use dlgs::model::{DeformMlps, DynamicGop, Gaussians, Lifetimes};
use dlgs::{Error, Result};
use rayon::prelude::*;

use crate::interp::{hermite, normalize4, slerp_angles, slerp_arguments, slerp_panel};
use crate::panel::{PanelMlp, Scratch, PANEL};
use crate::planar::PlanarFeatures;

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

/// Geometry of the reference model (§6.4) at one key, `[i]`.
#[derive(Default)]
struct KeyGeometry {
    pos: Vec<[f32; 3]>,
    tangent: Vec<[f32; 3]>,
    /// Normalised `q_c + Δq_k`.
    quat: Vec<[f32; 4]>,
    /// `Δlog-scale_k`, when the GOP applies scale offsets.
    dscale: Option<Vec<[f32; 3]>>,
}

/// The reference model's key geometry, each key (and each key pair's slerp angles) computed
/// on first use. Every value depends only on its key, so the order keys are filled in does not
/// change any bit.
struct LazyGeometry {
    keys: Vec<OnceLock<KeyGeometry>>,
    /// `(ω, sin ω)` of the slerp from key `k` to `k + 1`, `[i]`.
    angles: Vec<OnceLock<Vec<[f32; 2]>>>,
}

/// A GOP's deformation field, ready to produce frames.
pub struct Deformer {
    model: DeformModel,
    /// The time features, key- and channel-major.
    features: PlanarFeatures,
    /// The decoders as decoded; the panel MLPs below hold copies of their weights.
    mlps: DeformMlps,
    deform: PanelMlp,
    cov: PanelMlp,
    opacity: PanelMlp,
    color: PanelMlp,
    lang: Option<PanelMlp>,
    scale_offsets: bool,
    geometry: Option<LazyGeometry>,
    /// Gaussians shown for only part of the GOP (`LIFE`, §6.14).
    life: Option<Lifetimes>,
}

fn block_ranges(n: usize) -> Vec<Range<usize>> {
    (0..n.div_ceil(BLOCK))
        .map(|b| b * BLOCK..((b + 1) * BLOCK).min(n))
        .collect()
}

/// Cut `v` into one slice per block, `per_row` elements per row (empty slices if `v` is).
fn split_rows<'a, T>(
    mut v: &'a mut [T],
    per_row: usize,
    blocks: &[Range<usize>],
) -> Vec<&'a mut [T]> {
    blocks
        .iter()
        .map(|r| {
            let (head, tail) = std::mem::take(&mut v).split_at_mut(r.len() * per_row);
            v = tail;
            head
        })
        .collect()
}

/// Panels of at most [`PANEL`] rows covering `rows`.
fn panels(rows: Range<usize>) -> impl Iterator<Item = Range<usize>> {
    rows.clone()
        .step_by(PANEL)
        .map(move |s| s..(s + PANEL).min(rows.end))
}

/// The output rows of one block, written in place.
/// Caller-owned output rows of one frame's dynamic set (see
/// [`Deformer::frame_into_slices`]).
pub struct FrameSlices<'a> {
    pub positions: &'a mut [[f32; 3]],
    pub log_scales: &'a mut [[f32; 3]],
    pub rotations: &'a mut [[f32; 4]],
    pub opacity: &'a mut [f32],
    pub lang_opacity: &'a mut [f32],
    pub sh: &'a mut [f32],
    pub lang: &'a mut [f32],
}

struct BlockOut<'a> {
    rows: Range<usize>,
    pos: &'a mut [[f32; 3]],
    scale: &'a mut [[f32; 3]],
    rot: &'a mut [[f32; 4]],
    opacity: &'a mut [f32],
    lang_opacity: &'a mut [f32],
    sh: &'a mut [f32],
    lang: &'a mut [f32],
}

impl Deformer {
    /// Prepare a GOP; for the reference model, the geometry decoders run on a key (`N` rows)
    /// the first time a frame needs it ([`Self::prepare_all_keys`] does all at once).
    pub fn new(gop: DynamicGop, model: DeformModel) -> Self {
        Self::from_planar(PlanarFeatures::new(&gop.features), gop.mlps, model).with_life(gop.life)
    }

    /// The GOP's lifetimes (§6.14): frames hide the Gaussians outside theirs.
    pub fn with_life(mut self, life: Option<Lifetimes>) -> Self {
        self.life = life;
        self
    }

    /// The GOP's lifetimes, if some Gaussians are shown for only part of it.
    pub fn life(&self) -> Option<&Lifetimes> {
        self.life.as_ref()
    }

    /// Hide (§6.14) the Gaussians not shown at GOP-local frame `local_frame` in a frame's
    /// opacities (nothing without `LIFE`).
    pub fn hide_outside_life(
        &self,
        local_frame: u32,
        opacity: &mut [f32],
        lang_opacity: &mut [f32],
    ) {
        if let Some(l) = &self.life {
            l.hide(local_frame, opacity, lang_opacity);
        }
    }

    /// [`Self::new`] from time features already laid out key- and channel-major.
    pub fn from_planar(features: PlanarFeatures, mlps: DeformMlps, model: DeformModel) -> Self {
        let m = &mlps;
        let keys = features.keys;
        let mut d = Deformer {
            model,
            deform: PanelMlp::new(&m.deform),
            cov: PanelMlp::new(&m.cov),
            opacity: PanelMlp::new(&m.opacity),
            color: PanelMlp::new(&m.color),
            lang: m.lang.as_ref().map(PanelMlp::new),
            scale_offsets: m.scale_offsets,
            geometry: None,
            life: None,
            features,
            mlps,
        };
        if model == DeformModel::Reference {
            d.geometry = Some(LazyGeometry {
                keys: (0..keys).map(|_| OnceLock::new()).collect(),
                angles: (0..keys.saturating_sub(1))
                    .map(|_| OnceLock::new())
                    .collect(),
            });
        }
        d
    }

    /// Compute every key's geometry now (players that will show the whole GOP; a seek leaves
    /// the keys it does not need for later).
    pub fn prepare_all_keys(&self, canon: &Gaussians) -> Result<()> {
        self.prepare_keys(canon, 0..self.features.keys)
    }

    /// Decode the time-feature keys of `keys` and compute their geometry now, with the slerp
    /// angles between neighbours inside the range (`0..2` is what the frames of the first key
    /// interval need). Keys already prepared are not redone; the values are the same whether
    /// a key is prepared here, by another thread, or by the first frame that needs it.
    pub fn prepare_keys(&self, canon: &Gaussians, keys: Range<usize>) -> Result<()> {
        let keys = keys.start.min(self.features.keys)..keys.end.min(self.features.keys);
        self.features.ensure_keys(keys.clone())?;
        if self.geometry.is_none() {
            return Ok(());
        }
        if keys.len() == 1 {
            self.key(canon, keys.start);
        }
        for k in keys.start..keys.end.saturating_sub(1) {
            self.angles(canon, k);
        }
        Ok(())
    }

    /// Key `k`'s geometry, computed on first use.
    fn key(&self, canon: &Gaussians, k: usize) -> &KeyGeometry {
        let geo = self.geometry.as_ref().expect("reference model");
        geo.keys[k].get_or_init(|| self.key_geometry(canon, k))
    }

    /// Slerp angles from key `k` to `k + 1` (computing both keys if needed).
    fn angles(&self, canon: &Gaussians, k: usize) -> &[[f32; 2]] {
        let geo = self.geometry.as_ref().expect("reference model");
        geo.angles[k].get_or_init(|| {
            let (a, b) = (self.key(canon, k), self.key(canon, k + 1));
            let mut angles = vec![[0f32; 2]; a.quat.len()];
            angles
                .par_chunks_mut(BLOCK)
                .zip(a.quat.par_chunks(BLOCK).zip(b.quat.par_chunks(BLOCK)))
                .for_each(|(out, (qa, qb))| slerp_angles(qa, qb, out));
            angles
        })
    }

    /// The time features and decoders this deformer was built from (rebuilt in the file's
    /// `(N, K, C)` layout).
    pub fn dynamic_gop(&self) -> Result<DynamicGop> {
        Ok(DynamicGop {
            features: self.features.to_time_features()?,
            mlps: self.mlps.clone(),
            life: self.life.clone(),
        })
    }

    /// Time-feature keys per GOP.
    pub fn key_count(&self) -> usize {
        self.features.keys
    }

    /// Time-feature keys decoded so far (intra-only features decode the keys frames need).
    pub fn loaded_keys(&self) -> usize {
        self.features.loaded_keys()
    }

    fn features(&self) -> &PlanarFeatures {
        &self.features
    }

    fn key_geometry(&self, canon: &Gaussians, k: usize) -> KeyGeometry {
        let f = self.features();
        let parts: Vec<KeyGeometry> = block_ranges(f.n)
            .into_par_iter()
            .map(|rows| {
                let len = rows.len();
                let mut g = KeyGeometry {
                    pos: vec![[0.0; 3]; len],
                    tangent: vec![[0.0; 3]; len],
                    quat: vec![[0.0; 4]; len],
                    dscale: self.scale_offsets.then(|| vec![[0.0; 3]; len]),
                };
                let mut scratch = Scratch::default();
                let mut x = vec![[0.0; PANEL]; 12];
                let mut o = vec![[0.0; PANEL]; self.deform.outputs()];
                let mut c = vec![[0.0; PANEL]; self.cov.outputs()];
                for p in panels(rows.clone()) {
                    f.key_panel(p.clone(), k, 0, &mut x);
                    self.deform.run(&x, &mut scratch, &mut o);
                    self.cov.run(&x, &mut scratch, &mut c);
                    for (l, i) in p.enumerate() {
                        let j = i - rows.start;
                        let pc = canon.positions[i];
                        g.pos[j] = std::array::from_fn(|a| pc[a] + o[a][l]);
                        g.tangent[j] = std::array::from_fn(|a| o[3 + a][l]);
                        let q = canon.rotations[i];
                        g.quat[j] = normalize4(std::array::from_fn(|a| q[a] + c[3 + a][l]));
                        if let Some(ds) = &mut g.dscale {
                            ds[j] = std::array::from_fn(|a| c[a][l]);
                        }
                    }
                }
                g
            })
            .collect();
        let mut out = KeyGeometry {
            dscale: self.scale_offsets.then(Vec::new),
            ..Default::default()
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
    ) -> Result<Gaussians> {
        let mut out = Gaussians::new(canon.sh_degree, canon.lang_width);
        self.frame_into(canon, key, delta, opts, &mut out)?;
        Ok(out)
    }

    /// Like [`Self::frame`], reusing `out`'s allocations (a player's frame buffer).
    pub fn frame_into(
        &self,
        canon: &Gaussians,
        key: usize,
        delta: f32,
        opts: &FrameOptions,
        out: &mut Gaussians,
    ) -> Result<()> {
        self.frame_into_after(canon, key, delta, opts, out, 0)
    }

    /// Like [`Self::frame_into`], writing the dynamic Gaussians as rows `first..` of `out`
    /// and leaving its first `first` rows as they are (e.g. the static set: the merged
    /// frame is then built without copying the dynamic set). `out` must have `first` rows with
    /// `canon`'s SH degree and language width.
    pub fn frame_into_after(
        &self,
        canon: &Gaussians,
        key: usize,
        delta: f32,
        opts: &FrameOptions,
        out: &mut Gaussians,
        first: usize,
    ) -> Result<()> {
        if first > 0
            && (out.len() < first
                || out.sh_degree != canon.sh_degree
                || out.lang_width != canon.lang_width)
        {
            return Err(Error::request(
                "frame_into_after: the first rows differ from the dynamic set in layout",
            ));
        }
        let n = canon.len();
        out.sh_degree = canon.sh_degree;
        out.lang_width = canon.lang_width;
        let stride = canon.sh_stride();
        let lw = canon.lang_width;
        let lo = usize::from(canon.has_language());
        out.positions.resize(first + n, [0.0; 3]);
        out.log_scales.resize(first + n, [0.0; 3]);
        out.rotations.resize(first + n, [0.0; 4]);
        out.opacity.resize(first + n, 0.0);
        out.lang_opacity
            .resize(first * lo + canon.lang_opacity.len(), 0.0);
        out.sh.resize(first * stride + canon.sh.len(), 0.0);
        out.lang.resize(first * lw + canon.lang.len(), 0.0);
        let slices = FrameSlices {
            positions: &mut out.positions[first..],
            log_scales: &mut out.log_scales[first..],
            rotations: &mut out.rotations[first..],
            opacity: &mut out.opacity[first..],
            lang_opacity: &mut out.lang_opacity[first * lo..],
            sh: &mut out.sh[first * stride..],
            lang: &mut out.lang[first * lw..],
        };
        self.frame_into_slices(canon, key, delta, opts, slices)
    }

    /// The dynamic Gaussians at key pair (`key`, `key + 1`) and fraction `delta`, written into
    /// caller-owned slices of exactly the dynamic set's size (`canon`'s layout; the language
    /// slices empty when `canon` has no language), e.g. memory a binding hands out.
    pub fn frame_into_slices(
        &self,
        canon: &Gaussians,
        key: usize,
        delta: f32,
        opts: &FrameOptions,
        out: FrameSlices<'_>,
    ) -> Result<()> {
        // The two keys the frame interpolates (decoded now if the features are per key).
        self.features.ensure_keys(key..key + 2)?;
        let n = self.features().n;
        let stride = canon.sh_stride();
        let lw = canon.lang_width;
        let lo = usize::from(canon.has_language());
        if n != canon.len()
            || out.positions.len() != n
            || out.log_scales.len() != n
            || out.rotations.len() != n
            || out.opacity.len() != n
            || out.lang_opacity.len() != n * lo
            || out.sh.len() != n * stride
            || out.lang.len() != n * lw
        {
            return Err(Error::request(
                "frame_into_slices: the slices do not hold the dynamic set",
            ));
        }
        let language = opts.language && self.lang.is_some() && canon.has_language();
        let blocks = block_ranges(n);
        let mut pos = split_rows(out.positions, 1, &blocks).into_iter();
        let mut scale = split_rows(out.log_scales, 1, &blocks).into_iter();
        let mut rot = split_rows(out.rotations, 1, &blocks).into_iter();
        let mut opacity = split_rows(out.opacity, 1, &blocks).into_iter();
        let mut lang_opacity = split_rows(out.lang_opacity, lo, &blocks).into_iter();
        let mut sh = split_rows(out.sh, stride, &blocks).into_iter();
        let mut lang = split_rows(out.lang, lw, &blocks).into_iter();
        let jobs: Vec<BlockOut> = blocks
            .iter()
            .map(|rows| BlockOut {
                rows: rows.clone(),
                pos: pos.next().expect("one slice per block"),
                scale: scale.next().expect("one slice per block"),
                rot: rot.next().expect("one slice per block"),
                opacity: opacity.next().expect("one slice per block"),
                lang_opacity: lang_opacity.next().expect("one slice per block"),
                sh: sh.next().expect("one slice per block"),
                lang: lang.next().expect("one slice per block"),
            })
            .collect();
        let geo = match (&self.geometry, self.model) {
            (Some(_), DeformModel::Reference) => Some((
                self.key(canon, key),
                self.key(canon, key + 1),
                self.angles(canon, key),
            )),
            _ => None,
        };
        jobs.into_par_iter().for_each(|mut b| {
            self.fill_block(canon, &mut b, geo, key, delta, opts.camera_center, language)
        });
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn fill_block(
        &self,
        canon: &Gaussians,
        out: &mut BlockOut,
        geo: Option<(&KeyGeometry, &KeyGeometry, &[[f32; 2]])>,
        k: usize,
        d: f32,
        cam: [f32; 3],
        language: bool,
    ) {
        let f = self.features();
        let rows = out.rows.clone();
        let stride = canon.sh_stride();
        let lw = canon.lang_width;
        // Canonical values that the offsets are added to.
        out.scale.copy_from_slice(&canon.log_scales[rows.clone()]);
        out.opacity.copy_from_slice(&canon.opacity[rows.clone()]);
        out.sh
            .copy_from_slice(&canon.sh[rows.start * stride..rows.end * stride]);
        if canon.has_language() {
            out.lang_opacity
                .copy_from_slice(&canon.lang_opacity[rows.clone()]);
            out.lang
                .copy_from_slice(&canon.lang[rows.start * lw..rows.end * lw]);
        }
        let mut scratch = Scratch::default();
        let mut x = vec![[0.0; PANEL]; 12];

        // Geometry.
        match geo {
            Some((ga, gb, angles)) => {
                // The slerp a panel at a time, in SIMD lanes (the same bits as row by row):
                // `sin((1 - d) ω)` of the panel's rows, then `sin(d ω)`, then the blend.
                let mut sines = [0f64; 2 * PANEL];
                let (mut q0, mut q1, mut q) =
                    ([[0f32; PANEL]; 4], [[0f32; PANEL]; 4], [[0f32; PANEL]; 4]);
                let (mut s, mut s0, mut s1) = ([1f32; PANEL], [0f32; PANEL], [0f32; PANEL]);
                for p in panels(rows.clone()) {
                    let m = p.len();
                    for (l, i) in p.clone().enumerate() {
                        let (a0, a1) = slerp_arguments(angles[i][0], d);
                        sines[l] = a0 as f64;
                        sines[m + l] = a1 as f64;
                    }
                    sin_lanes(&mut sines[..2 * m]);
                    for (l, i) in p.clone().enumerate() {
                        for c in 0..4 {
                            q0[c][l] = ga.quat[i][c];
                            q1[c][l] = gb.quat[i][c];
                        }
                        s[l] = angles[i][1];
                        s0[l] = sines[l] as f32;
                        s1[l] = sines[m + l] as f32;
                    }
                    slerp_panel(&q0, &q1, [&s, &s0, &s1], &mut q);
                    for (l, i) in p.enumerate() {
                        out.rot[i - rows.start] = [q[0][l], q[1][l], q[2][l], q[3][l]];
                    }
                }
                for (r, i) in rows.clone().enumerate() {
                    out.pos[r] = hermite(ga.pos[i], ga.tangent[i], gb.pos[i], gb.tangent[i], d);
                    if let Some(ds) = &ga.dscale {
                        // Key `k` only, no interpolation (the reference's eval path).
                        for c in 0..3 {
                            out.scale[r][c] += ds[i][c];
                        }
                    }
                }
            }
            _ => {
                // The paper's plain form: decoders applied to the interpolated feature.
                let mut o = vec![[0.0; PANEL]; self.deform.outputs()];
                let mut c = vec![[0.0; PANEL]; self.cov.outputs()];
                for p in panels(rows.clone()) {
                    f.lerp_panel(p.clone(), k, d, 0, &mut x);
                    self.deform.run(&x, &mut scratch, &mut o);
                    self.cov.run(&x, &mut scratch, &mut c);
                    for (l, i) in p.enumerate() {
                        let r = i - rows.start;
                        let pc = canon.positions[i];
                        out.pos[r] = std::array::from_fn(|a| pc[a] + o[a][l]);
                        let q = canon.rotations[i];
                        out.rot[r] = normalize4(std::array::from_fn(|a| q[a] + c[3 + a][l]));
                        if self.scale_offsets {
                            for a in 0..3 {
                                out.scale[r][a] += c[a][l];
                            }
                        }
                    }
                }
            }
        }

        // Appearance: lerp(F[4:12]) ‖ view dir ‖ distance, from the canonical position.
        let mut dop = vec![[0.0; PANEL]; self.opacity.outputs()];
        let mut dsh = vec![[0.0; PANEL]; self.color.outputs()];
        let sh_out = self.color.outputs().min(stride);
        for p in panels(rows.clone()) {
            f.lerp_panel(p.clone(), k, d, 4, &mut x[..8]);
            for (l, i) in p.clone().enumerate() {
                let pc = canon.positions[i];
                let v = [pc[0] - cam[0], pc[1] - cam[1], pc[2] - cam[2]];
                let dist = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                // The reference divides without an epsilon; a Gaussian exactly at the camera
                // gets direction 0 here instead of NaN.
                let inv = if dist > 0.0 { 1.0 / dist } else { 0.0 };
                x[8][l] = v[0] * inv;
                x[9][l] = v[1] * inv;
                x[10][l] = v[2] * inv;
                x[11][l] = dist;
            }
            self.opacity.run(&x, &mut scratch, &mut dop);
            self.color.run(&x, &mut scratch, &mut dsh);
            for (l, i) in p.enumerate() {
                let r = i - rows.start;
                out.opacity[r] += dop[0][l];
                if canon.has_language() && dop.len() > 1 {
                    out.lang_opacity[r] += dop[1][l];
                }
                let s = &mut out.sh[r * stride..r * stride + sh_out];
                for (c, v) in s.iter_mut().enumerate() {
                    *v += dsh[c][l];
                }
            }
        }

        if language {
            let lang = self.lang.as_ref().expect("checked by the caller");
            let mut dl = vec![[0.0; PANEL]; lang.outputs()];
            for p in panels(rows.clone()) {
                f.lerp_panel(p.clone(), k, d, 8, &mut x[..8]);
                lang.run(&x[..8], &mut scratch, &mut dl);
                for (l, i) in p.enumerate() {
                    let r = i - rows.start;
                    for (c, v) in out.lang[r * lw..(r + 1) * lw].iter_mut().enumerate() {
                        *v += dl[c][l];
                    }
                }
            }
        }
    }
}
