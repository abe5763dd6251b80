//! A generator of *synthetic* dynamic DLGStream models built on a real canonical scene.
//!
//! No trained dynamic DLGStream model exists in this repository's data, so tests and benches
//! animate a real scene: a spatially compact subset becomes dynamic, its key time features are
//! smooth sinusoids of time and position (not white noise), and the bias-free decoders get
//! random weights rescaled so their offsets give visible but plausible motion. Everything is
//! seeded and deterministic.

use dlgs::container::header::{DeformModel, ResidualMode, Variant};
use dlgs::container::SceneHeader;
use dlgs::model::ntc::{NtcConfig, NtcField, NtcMlp};
use dlgs::model::residual::{groups_of, AttrGroup, SET_DYNAMIC, SET_STATIC};
use dlgs::model::{
    Canonical, DeformMlps, DynamicGop, Gaussians, Layer, Mlp, MlpRole, TimeFeatures,
};
use dlgs::{Error, Result};

/// What to generate.
#[derive(Debug, Clone)]
pub struct SynthSpec {
    /// Fraction of the scene's Gaussians that move.
    pub dynamic_fraction: f32,
    /// Upper bound on dynamic Gaussians (0 = no bound).
    pub max_dynamic: usize,
    pub gops: u32,
    pub gop_length: u32,
    pub key_interval: u32,
    pub fps: u32,
    /// Motion amplitude relative to the scene's size.
    pub motion: f32,
    /// Add DLGStream's 9-dim language (synthetic if the scene has none) and a language decoder.
    pub language: bool,
    /// Typical offset the generated language MLP adds to each language feature (the features
    /// are unit-scale codes; 0 = language that does not change over time).
    pub language_motion: f32,
    pub deform_model: DeformModel,
    pub seed: u64,
    /// Residual mode of the generated scene. Intra: every GOP has the same canonical state.
    /// Sequential/parallel: GOP g >= 1 carries a generated binary voxel residual field
    /// against GOP g-1 / GOP 0.
    pub residual_mode: ResidualMode,
    /// Sequential mode: every K-th GOP carries its full canonical state (0 = none).
    pub refresh_interval: u32,
}

impl Default for SynthSpec {
    fn default() -> Self {
        SynthSpec {
            dynamic_fraction: 0.3,
            max_dynamic: 0,
            gops: 1,
            gop_length: 60,
            key_interval: 10,
            fps: 30,
            motion: 0.03,
            language: false,
            language_motion: 0.1,
            deform_model: DeformModel::Reference,
            seed: 6666,
            residual_mode: ResidualMode::Intra,
            refresh_interval: 0,
        }
    }
}

/// A generated model: GOP 0's canonical state, one deformation field per GOP and, in
/// residual scenes, one binary voxel residual field per GOP from GOP 1 on.
#[derive(Debug, Clone)]
pub struct SynthModel {
    pub scene: SceneHeader,
    pub canonical: Canonical,
    pub gops: Vec<DynamicGop>,
    /// `residuals[g]` for GOP g (None for GOP 0 and in intra scenes).
    pub residuals: Vec<Option<NtcField>>,
}

impl SynthModel {
    /// Every GOP's canonical state, computed from the model's own fields (the ground truth a
    /// decoder of a losslessly coded model must reproduce).
    pub fn canonical_states(&self) -> Result<Vec<Canonical>> {
        let mut out: Vec<Canonical> = Vec::with_capacity(self.gops.len());
        for (g, r) in self.residuals.iter().enumerate() {
            let next = match (r, self.scene.residual_mode) {
                (None, _) => self.canonical.clone(),
                (Some(f), ResidualMode::Parallel) => f.apply(&out[0])?,
                (Some(f), _) => f.apply(&out[g - 1])?,
            };
            out.push(next);
        }
        Ok(out)
    }
}

/// Size of the residual each attribute group gets, relative to `size` for positions and
/// absolute for the others (pre-sigmoid opacities, log-scales, SH, language).
fn residual_scale(group: AttrGroup, size: f32) -> f32 {
    match group {
        AttrGroup::Position => 0.002 * size,
        AttrGroup::LogScale | AttrGroup::Rotation => 0.02,
        AttrGroup::ShDc => 0.03,
        AttrGroup::ShRest => 0.01,
        AttrGroup::Opacity | AttrGroup::LangOpacity => 0.1,
        AttrGroup::Lang => 0.02,
    }
}

/// A *generated* binary voxel residual field with the reference's shapes: plane levels whose
/// +1 frequency falls from 0.5 (coarsest) to 0.05 (finest), as a rate-penalised training
/// leaves them; a random MLP rescaled so every output has a plausible size.
pub fn synth_ntc(c: &Canonical, rng: &mut fastrand::Rng, size: f32, config: NtcConfig) -> NtcField {
    let all: Vec<[f32; 3]> = c
        .statics
        .positions
        .iter()
        .chain(&c.dynamics.positions)
        .copied()
        .collect();
    let mut bound_min = [0f32; 3];
    let mut bound_max = [0f32; 3];
    for a in 0..3 {
        let mut v: Vec<f32> = all.iter().map(|p| p[a]).collect();
        v.sort_by(|x, y| x.total_cmp(y));
        let (lo, hi) = (v[v.len() / 100], v[(v.len() * 99) / 100]);
        let pad = 0.1 * (hi - lo).max(1e-3);
        bound_min[a] = lo - pad;
        bound_max[a] = hi + pad;
    }
    let freq = [0.5, 0.3, 0.15, 0.05];
    let planes = (0..3 * config.levels())
        .map(|i| {
            let p = freq[(i % config.levels()).min(3)];
            (0..config.level_bits()).map(|_| rng.f64() < p).collect()
        })
        .collect();
    let gate = (0..config.gate_table()).map(|_| rng.bool()).collect();
    let s = &c.statics;
    let groups = groups_of(s.sh_degree, s.lang_width);
    let outputs: usize = groups
        .iter()
        .map(|g| g.width(s.sh_degree, s.lang_width))
        .sum();
    let (inputs, hidden) = (config.input_width(), 100);
    let mut uni = |n: usize, bound: f32| -> Vec<f32> {
        (0..n).map(|_| (rng.f32() * 2.0 - 1.0) * bound).collect()
    };
    let mlp = NtcMlp {
        inputs,
        hidden,
        outputs,
        w1: uni(inputs * hidden, 1.0 / (inputs as f32).sqrt()),
        b1: uni(hidden, 1.0 / (inputs as f32).sqrt()),
        w2: uni(hidden * outputs, 1.0 / (hidden as f32).sqrt()),
        b2: uni(outputs, 1.0 / (hidden as f32).sqrt()),
    };
    let mut field = NtcField {
        config,
        bound_min,
        bound_max,
        planes,
        gate,
        mlp,
        groups: groups.iter().fold(0, |m, g| m | g.bit()),
        sets: SET_STATIC | SET_DYNAMIC,
    };
    // Rescale each output column to its group's size over a sample of positions.
    let step = (all.len() / 2000).max(1);
    let sample: Vec<[f32; 3]> = all.iter().step_by(step).copied().collect();
    let rows: Vec<Vec<f32>> = field
        .residuals_at(&sample)
        .chunks(outputs)
        .filter(|r| r.iter().any(|&v| v != 0.0))
        .map(|r| r.to_vec())
        .collect();
    let mut col = 0;
    for g in &groups {
        for _ in 0..g.width(s.sh_degree, s.lang_width) {
            let n = rows.len().max(1) as f32;
            let rms = (rows.iter().map(|r| r[col] * r[col]).sum::<f32>() / n).sqrt();
            let k = residual_scale(*g, size) / rms.max(1e-12);
            for j in 0..hidden {
                field.mlp.w2[col * hidden + j] *= k;
            }
            field.mlp.b2[col] *= k;
            col += 1;
        }
    }
    field
}

fn median(mut v: Vec<f32>) -> f32 {
    v.sort_by(|a, b| a.total_cmp(b));
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// 30-bit Morton code of a position inside `[lo, lo + size]^3`.
fn morton(p: [f32; 3], lo: [f32; 3], size: f32) -> u32 {
    let spread = |v: u32| {
        let mut x = v & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    };
    let q = |a: usize| (((p[a] - lo[a]) / size).clamp(0.0, 1.0) * 1023.0) as u32;
    spread(q(0)) | (spread(q(1)) << 1) | (spread(q(2)) << 2)
}

/// Smooth synthetic language: three levels of a 3-vector that varies slowly over space.
pub fn synthetic_language(g: &Gaussians) -> Gaussians {
    let mut out = g.clone();
    out.lang_width = 9;
    out.lang_opacity = g.opacity.clone();
    out.lang = g
        .positions
        .iter()
        .flat_map(|p| {
            (0..3).flat_map(move |l| {
                let f = 1.0 + l as f32 * 2.0;
                [
                    (p[0] * f).sin(),
                    (p[1] * f + 1.0).cos(),
                    ((p[0] + p[2]) * f).sin() * 0.5,
                ]
            })
        })
        .collect();
    out
}

fn random_mlp(rng: &mut fastrand::Rng, role: MlpRole, outputs: usize) -> Mlp {
    let dims = [role.inputs(), 64, outputs];
    let layers = dims
        .windows(2)
        .map(|w| {
            // PyTorch's default Linear init range.
            let bound = 1.0 / (w[0] as f32).sqrt();
            Layer {
                inputs: w[0],
                outputs: w[1],
                weights: (0..w[0] * w[1])
                    .map(|_| (rng.f32() * 2.0 - 1.0) * bound)
                    .collect(),
            }
        })
        .collect();
    Mlp { role, layers }
}

fn eval(m: &Mlp, x: &[f32]) -> Vec<f32> {
    let mut h = x.to_vec();
    for (li, l) in m.layers.iter().enumerate() {
        let mut o = vec![0.0f32; l.outputs];
        for (r, out) in o.iter_mut().enumerate() {
            *out = l.weights[r * l.inputs..(r + 1) * l.inputs]
                .iter()
                .zip(&h)
                .map(|(w, v)| w * v)
                .sum();
        }
        if li + 1 < m.layers.len() {
            o.iter_mut().for_each(|v| *v = v.max(0.0));
        }
        h = o;
    }
    h
}

/// Rescale the last layer so every output has standard deviation `target[j]` over `samples`.
fn calibrate(m: &mut Mlp, samples: &[Vec<f32>], target: &[f32]) {
    let outs: Vec<Vec<f32>> = samples.iter().map(|x| eval(m, x)).collect();
    let last = m.layers.last_mut().expect("two layers");
    for j in 0..last.outputs {
        let n = outs.len().max(1) as f32;
        let mean = outs.iter().map(|o| o[j]).sum::<f32>() / n;
        let var = outs.iter().map(|o| (o[j] - mean).powi(2)).sum::<f32>() / n;
        let k = target[j] / var.sqrt().max(1e-12);
        for w in &mut last.weights[j * last.inputs..(j + 1) * last.inputs] {
            *w *= k;
        }
    }
}

/// Build a dynamic model from a real canonical scene.
pub fn synth_dynamic(scene_g: &Gaussians, spec: &SynthSpec) -> Result<SynthModel> {
    let bad = |m: String| Error::input(m);
    scene_g.check_shapes()?;
    if scene_g.len() < 2 {
        return Err(bad("the scene needs at least 2 Gaussians".into()));
    }
    if !(spec.language_motion.is_finite() && spec.language_motion >= 0.0) {
        return Err(bad("language motion must be finite and >= 0".into()));
    }
    if !(spec.dynamic_fraction > 0.0 && spec.dynamic_fraction < 1.0) {
        return Err(bad("dynamic fraction must be in (0, 1)".into()));
    }
    if spec.gops == 0
        || spec.gop_length == 0
        || spec.key_interval == 0
        || !spec.gop_length.is_multiple_of(spec.key_interval)
        || spec.fps == 0
    {
        return Err(bad(
            "GOP length must be a positive multiple of the key interval".into(),
        ));
    }
    let mut g = if spec.language && !scene_g.has_language() {
        synthetic_language(scene_g)
    } else {
        scene_g.clone()
    };
    if !spec.language && g.has_language() {
        g = g.without_language();
    }
    let n = g.len();
    let centre: [f32; 3] =
        std::array::from_fn(|a| median(g.positions.iter().map(|p| p[a]).collect()));
    let dist: Vec<f32> = g
        .positions
        .iter()
        .map(|p| {
            ((p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2) + (p[2] - centre[2]).powi(2))
                .sqrt()
        })
        .collect();
    // Scene size: the 90th-percentile distance from the median centre (robust to floaters).
    let mut sorted = dist.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let size = sorted[(n * 9) / 10].max(1e-6);

    // The dynamic set: Gaussians nearest to a point off-centre, i.e. one compact "object".
    let mut rng = fastrand::Rng::with_seed(spec.seed);
    let seed_pt: [f32; 3] = std::array::from_fn(|a| centre[a] + (rng.f32() - 0.5) * 0.3 * size);
    let mut order: Vec<usize> = (0..n).collect();
    let d2 = |i: usize| {
        let p = g.positions[i];
        (p[0] - seed_pt[0]).powi(2) + (p[1] - seed_pt[1]).powi(2) + (p[2] - seed_pt[2]).powi(2)
    };
    order.sort_by(|&a, &b| d2(a).total_cmp(&d2(b)).then(a.cmp(&b)));
    let mut n_dyn = ((n as f32 * spec.dynamic_fraction) as usize).clamp(1, n - 1);
    if spec.max_dynamic > 0 {
        n_dyn = n_dyn.min(spec.max_dynamic);
    }
    let mut is_dyn = vec![false; n];
    let mut dyn_idx: Vec<usize> = order[..n_dyn].to_vec();
    for &i in &dyn_idx {
        is_dyn[i] = true;
    }
    // Morton order keeps neighbours adjacent in the feature tiles (the reference uses PLAS).
    let lo: [f32; 3] = std::array::from_fn(|a| centre[a] - size);
    dyn_idx.sort_by_key(|&i| (morton(g.positions[i], lo, 2.0 * size), i));
    let mut statics = Gaussians::new(g.sh_degree, g.lang_width);
    let mut dynamics = Gaussians::new(g.sh_degree, g.lang_width);
    for i in 0..n {
        if !is_dyn[i] {
            statics.push_from(&g, i);
        }
    }
    for &i in &dyn_idx {
        dynamics.push_from(&g, i);
    }

    let keys = (spec.gop_length / spec.key_interval + 1) as usize;
    let frames = spec.gops * spec.gop_length;
    let scene = SceneHeader {
        variant: Variant::Gaussians3d,
        residual_mode: spec.residual_mode,
        deform_model: spec.deform_model,
        sh_degree: g.sh_degree,
        lang_levels: if g.has_language() { 3 } else { 0 },
        lang_dims: if g.has_language() { 3 } else { 0 },
        time_channels: 16,
        fps_num: spec.fps,
        fps_den: 1,
        gop_length: spec.gop_length,
        key_interval: spec.key_interval,
        gop_count: spec.gops,
        frame_count: frames,
        n_static: statics.len() as u32,
        n_dynamic: n_dyn as u32,
        refresh_interval: spec.refresh_interval,
    };

    // Per-channel temporal frequency (Hz), spatial direction and wavelength.
    let chan: Vec<([f32; 3], f32, f32)> = (0..16)
        .map(|_| {
            let v: [f32; 3] = std::array::from_fn(|_| rng.f32() * 2.0 - 1.0);
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-3);
            (
                [v[0] / l, v[1] / l, v[2] / l],
                0.2 + rng.f32() * 0.6,
                0.5 + rng.f32() * 1.5,
            )
        })
        .collect();
    let features_at = |gop: u32| {
        let mut f = TimeFeatures::zeros(n_dyn, keys, 16);
        for i in 0..n_dyn {
            let p = dynamics.positions[i];
            for k in 0..keys {
                let tau =
                    (gop * spec.gop_length + k as u32 * spec.key_interval) as f32 / spec.fps as f32;
                let dst = f.at_mut(i, k);
                for (c, (dir, hz, waves)) in chan.iter().enumerate() {
                    let s = ((p[0] - centre[0]) * dir[0]
                        + (p[1] - centre[1]) * dir[1]
                        + (p[2] - centre[2]) * dir[2])
                        / size;
                    dst[c] = (std::f32::consts::TAU * (hz * tau + waves * s)).sin();
                }
            }
        }
        f
    };

    // Decoders: random, then calibrated on sample inputs.
    let coeffs = dlgs::model::sh_coeffs(g.sh_degree).min(4);
    let mut gops = Vec::with_capacity(spec.gops as usize);
    let sample_feats = features_at(0);
    let step = (n_dyn / 512).max(1);
    let geo_x: Vec<Vec<f32>> = (0..n_dyn)
        .step_by(step)
        .flat_map(|i| (0..keys).map(move |k| (i, k)))
        .map(|(i, k)| sample_feats.at(i, k)[..12].to_vec())
        .collect();
    let app_x: Vec<Vec<f32>> = (0..n_dyn)
        .step_by(step)
        .map(|i| {
            let mut x = sample_feats.at(i, 0)[4..12].to_vec();
            x.extend([0.0, 0.0, -1.0, 3.0]);
            x
        })
        .collect();
    let lang_x: Vec<Vec<f32>> = (0..n_dyn)
        .step_by(step)
        .map(|i| sample_feats.at(i, 0)[8..16].to_vec())
        .collect();
    let m = spec.motion * size;
    for gop in 0..spec.gops {
        let mut deform = random_mlp(&mut rng, MlpRole::Deform, 6);
        calibrate(&mut deform, &geo_x, &[m, m, m, m, m, m]);
        let mut cov = random_mlp(&mut rng, MlpRole::Cov, 7);
        calibrate(
            &mut cov,
            &geo_x,
            &[0.05, 0.05, 0.05, 0.05, 0.05, 0.05, 0.05],
        );
        let mut opacity = random_mlp(
            &mut rng,
            MlpRole::Opacity,
            if g.has_language() { 2 } else { 1 },
        );
        calibrate(&mut opacity, &app_x, &[0.3, 0.3]);
        let mut color = random_mlp(&mut rng, MlpRole::Color, 3 * coeffs);
        calibrate(&mut color, &app_x, &vec![0.08; 3 * coeffs]);
        let lang = g.has_language().then(|| {
            let mut l = random_mlp(&mut rng, MlpRole::Lang, 9);
            calibrate(&mut l, &lang_x, &[spec.language_motion; 9]);
            l
        });
        gops.push(DynamicGop {
            features: features_at(gop),
            mlps: DeformMlps {
                deform,
                cov,
                opacity,
                color,
                lang,
                // As the reference: GOP 0 keeps canonical scales, later GOPs apply offsets.
                scale_offsets: gop > 0,
            },
            life: None,
        });
    }
    let canonical = Canonical { statics, dynamics };
    // Residual fields come from their own seed so that intra models keep their values.
    let mut rrng = fastrand::Rng::with_seed(spec.seed ^ 0x005e_ed0f_4e51_d0a1);
    let residuals = (0..spec.gops)
        .map(|g| {
            (g > 0 && spec.residual_mode != ResidualMode::Intra)
                .then(|| synth_ntc(&canonical, &mut rrng, size, NtcConfig::default()))
        })
        .collect();
    Ok(SynthModel {
        scene,
        canonical,
        gops,
        residuals,
    })
}

/// Write a generated model with the given encoder settings.
pub fn write_model<W: std::io::Write>(
    model: &SynthModel,
    cfg: dlgs_encoder::EncoderConfig,
    out: W,
) -> Result<W> {
    let mut enc = dlgs_encoder::StreamEncoder::new(out, model.scene.clone(), cfg)?;
    let dynamic = model.scene.n_dynamic > 0;
    for (d, r) in model.gops.iter().zip(&model.residuals) {
        let canonical = match r {
            Some(f) => dlgs_encoder::GopCanonical::Ntc(f),
            None => dlgs_encoder::GopCanonical::State(&model.canonical),
        };
        enc.push(canonical, dynamic.then_some(d))?;
    }
    enc.finish()
}
