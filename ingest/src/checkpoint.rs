//! A GOP read from the reference's checkpoints instead of its compressed files: GOP 0 from
//! `model.pth` (`GaussianModel.state_dict()`: the trained values before the JPEG XL / HEVC
//! packing), GOP g >= 1 from `model_offset.pth` (`GaussianModel.save`: the state dict plus
//! every attribute accumulated as `_<attr>[_dynamic]_offset`, i.e. `get_*_ori`, and the
//! absolute refined positions). Used only when a GOP folder has no `compression_info.csv`;
//! where both exist the compressed files win (`run::read_run`).

use std::collections::HashMap;
use std::path::Path;

use dlgs::model::dynamic::{DeformMlps, MlpRole};
use dlgs::model::TimeFeatures;
use dlgs::{Gaussians, Limits};

use crate::ref_gop::{self, FeatureSource, RefGop, SetTensors, CHANNELS, KEYS, LANG};
use crate::torch::{self, Tensor};
use crate::{check_finite, IngestError};

/// GOP 0's checkpoint and the accumulated one of later GOPs.
pub const CHECKPOINT: &str = "model.pth";
pub const OFFSET_CHECKPOINT: &str = "model_offset.pth";

/// The tensors of one checkpoint by name.
struct StateDict {
    what: String,
    tensors: HashMap<String, Tensor>,
}

impl StateDict {
    fn open(dir: &Path, file: &str, limits: &Limits) -> Result<Self, IngestError> {
        let path = dir.join(file);
        let what = path.display().to_string();
        let bytes = ref_gop::read(
            &path,
            "a checkpoint (the GOP has no compression_info.csv)",
            limits,
        )?;
        let tensors = torch::read_zip_state_dict(std::io::Cursor::new(bytes), &what)?
            .into_iter()
            .collect();
        Ok(StateDict { what, tensors })
    }

    fn get(&self, key: &str) -> Option<&Tensor> {
        self.tensors.get(key)
    }

    /// `key`, or an error naming the checkpoint and the tensor.
    fn require(&self, key: &str) -> Result<&Tensor, IngestError> {
        self.get(key).ok_or_else(|| IngestError::Missing {
            path: self.what.clone().into(),
            what: format!("tensor {key}"),
        })
    }

    /// Float values of `key`, whose shape must be `n` rows of `row` values (any trailing
    /// dimensions, e.g. SH's (N, K, 3)).
    fn rows(&self, key: &str, row: Option<usize>) -> Result<(Vec<f32>, usize), IngestError> {
        let what = format!("{}: {key}", self.what);
        let t = self.require(key)?;
        let width = t.shape.iter().skip(1).product::<usize>();
        if t.shape.len() < 2 || row.is_some_and(|r| r != width) {
            return Err(IngestError::shape(
                &what,
                format!(
                    "{:?}, expected (N, {})",
                    t.shape,
                    row.map_or("..".into(), |r| r.to_string())
                ),
            ));
        }
        let v = t.f32s(&what)?;
        if v.len() != t.shape[0] * width {
            return Err(IngestError::shape(&what, "values do not fill the shape"));
        }
        check_finite(&what, &v)?;
        Ok((v, width))
    }

    /// One set's attributes under `name(attr)` keys (`_xyz`, `_xyz_dynamic`, `_xyz_offset`, ...).
    fn set(&self, name: impl Fn(&str) -> String) -> Result<SetTensors, IngestError> {
        let lang = match self.get(&name("language_feature")) {
            Some(_) => Some(self.rows(&name("language_feature"), Some(LANG))?.0),
            None => None,
        };
        let opacity_dim = if lang.is_some() { 2 } else { 1 };
        let (rest, rest_channels) = match self.get(&name("features_rest")) {
            Some(_) => self.rows(&name("features_rest"), None)?,
            None => (vec![], 0),
        };
        Ok(SetTensors {
            xyz: self.rows(&name("xyz"), Some(3))?.0,
            dc: self.rows(&name("features_dc"), Some(3))?.0,
            rest,
            scaling: self.rows(&name("scaling"), Some(3))?.0,
            rotation: self.rows(&name("rotation"), Some(4))?.0,
            opacity: self.rows(&name("opacity"), Some(opacity_dim))?.0,
            opacity_dim,
            lang,
            rest_channels,
        })
    }

    /// `_point_feats` (N_dynamic, 7, 16), exactly as trained.
    fn features(&self, n: usize) -> Result<TimeFeatures, IngestError> {
        let what = format!("{}: _point_feats", self.what);
        let t = self.require("_point_feats")?;
        if t.shape != [n, KEYS, CHANNELS] {
            return Err(IngestError::shape(
                &what,
                format!("{:?}, expected [{n}, {KEYS}, {CHANNELS}]", t.shape),
            ));
        }
        let data = t.f32s(&what)?;
        check_finite(&what, &data)?;
        Ok(TimeFeatures {
            n,
            keys: KEYS,
            channels: CHANNELS,
            data,
        })
    }

    /// The decoders, from the state dict's `mlp_<role>.<i>.weight` entries.
    fn mlps(&self, language: bool, scale_offsets: bool) -> Result<DeformMlps, IngestError> {
        let mlp = |prefix: &str, role: MlpRole| {
            let p = format!("{prefix}.");
            let entries = self
                .tensors
                .iter()
                .filter_map(|(k, t)| Some((k.strip_prefix(&p)?, t)));
            ref_gop::mlp_from_state(entries, role, &format!("{}: {prefix}", self.what))
        };
        Ok(DeformMlps {
            deform: mlp("mlp_deform", MlpRole::Deform)?,
            cov: mlp("mlp_cov", MlpRole::Cov)?,
            opacity: mlp("mlp_opacity", MlpRole::Opacity)?,
            color: mlp("mlp_color", MlpRole::Color)?,
            lang: if language {
                Some(mlp("mlp_lang", MlpRole::Lang)?)
            } else {
                None
            },
            scale_offsets,
        })
    }
}

fn gop(
    dir: &Path,
    sd: &StateDict,
    statics: Gaussians,
    dynamics: Gaussians,
    scale_offsets: bool,
) -> Result<RefGop, IngestError> {
    ref_gop::check_sets(&statics, &dynamics, &sd.what)?;
    let language = statics.lang_width > 0;
    Ok(RefGop {
        dir: dir.to_path_buf(),
        features: sd.features(dynamics.len())?,
        feature_source: FeatureSource::Exact,
        mlps: sd.mlps(language, scale_offsets)?,
        // Checkpoints are not the reference's counted packing: no byte comparison.
        files: vec![],
        statics,
        dynamics,
        latents: vec![],
    })
}

/// GOP 0 from `model.pth`.
pub fn read_first(dir: &Path, limits: &Limits) -> Result<RefGop, IngestError> {
    let sd = StateDict::open(dir, CHECKPOINT, limits)?;
    let statics = sd.set(|a| format!("_{a}"))?.gaussians(&sd.what, limits)?;
    let dynamics = sd
        .set(|a| format!("_{a}_dynamic"))?
        .gaussians(&sd.what, limits)?;
    gop(dir, &sd, statics, dynamics, false)
}

/// GOP g >= 1 from `model_offset.pth`: the dynamic set's accumulated `_<attr>_dynamic_offset`
/// values, and the static set's `_<attr>_offset` when present (`offset_mode >= 10`), else the
/// previous GOP's static set unchanged (the reference's `get_*_ori` for lower modes).
pub fn read_next(dir: &Path, prev: &RefGop, limits: &Limits) -> Result<RefGop, IngestError> {
    let sd = StateDict::open(dir, OFFSET_CHECKPOINT, limits)?;
    let dynamics = sd
        .set(|a| format!("_{a}_dynamic_offset"))?
        .gaussians(&sd.what, limits)?;
    let statics = match sd.get("_features_dc_offset") {
        Some(_) => sd
            .set(|a| format!("_{a}_offset"))?
            .gaussians(&sd.what, limits)?,
        None => prev.statics.clone(),
    };
    for (now, before, set) in [
        (statics.len(), prev.statics.len(), "static"),
        (dynamics.len(), prev.dynamics.len(), "dynamic"),
    ] {
        if now != before {
            return Err(IngestError::shape(
                &sd.what,
                format!("{now} {set} Gaussians, the previous GOP has {before}"),
            ));
        }
    }
    gop(dir, &sd, statics, dynamics, true)
}
