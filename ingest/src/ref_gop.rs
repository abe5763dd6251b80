//! What a reference run's GOP decodes to (`RefGop`), shared by the two ways of reading one: its
//! compressed files (`run`) and its checkpoints (`checkpoint`); the attribute tensors of a set
//! in the reference's layout, its decoders' `state_dict`s, and the file reading both use.

use std::path::{Path, PathBuf};

use dlgs::model::dynamic::{DeformMlps, Layer, Mlp, MlpRole};
use dlgs::model::TimeFeatures;
use dlgs::Gaussians;

use dlgs::Limits;

use crate::latents::LatentResidual;
use crate::torch::Tensor;
use crate::{check_finite, IngestError};

/// Keys per GOP and channels, fixed by the reference (`time_line 60 / interval 10 + 1`, 16).
pub const KEYS: usize = 7;
pub const CHANNELS: usize = 16;
/// Language width (3 levels x 3 dims).
pub const LANG: usize = 9;

/// A file of the run, for the byte report.
#[derive(Debug, Clone, PartialEq)]
pub struct RunFile {
    pub name: String,
    pub bytes: u64,
    /// Counted by the reference's frame-size scripts (`test_fdsd.py:test_all`, `read_size.py`).
    pub counted: bool,
}

/// The time features of one GOP as the reference codes them.
#[derive(Debug, Clone, PartialEq)]
pub enum FeatureSource {
    /// `_point_feats.mp4`: HEVC access units (Annex B) and the CSV's single (min, max).
    Video {
        packets: Vec<Vec<u8>>,
        side: usize,
        range: (f64, f64),
    },
    /// `model.pth`'s exact `_point_feats` (no video present).
    Exact,
}

/// One GOP, decoded.
#[derive(Debug, Clone)]
pub struct RefGop {
    pub dir: PathBuf,
    /// The GOP's canonical state as the reference holds it after decoding (GOP >= 1: the
    /// previous GOP's state plus the latent residuals, and the re-sent positions).
    pub statics: Gaussians,
    pub dynamics: Gaussians,
    pub features: TimeFeatures,
    pub feature_source: FeatureSource,
    pub mlps: DeformMlps,
    /// GOP >= 1: the latent residuals, in the pickle's order.
    pub latents: Vec<LatentResidual>,
    pub files: Vec<RunFile>,
}

/// Read a file of the run whole, refusing one larger than `limits.max_alloc` before reading.
pub(crate) fn read(path: &Path, what: &str, limits: &Limits) -> Result<Vec<u8>, IngestError> {
    if let Ok(m) = std::fs::metadata(path) {
        limits.check_alloc("reference run file size", m.len(), 0)?;
    }
    std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => IngestError::Missing {
            path: path.to_path_buf(),
            what: what.to_string(),
        },
        _ => IngestError::Io {
            what: path.display().to_string(),
            source: e,
        },
    })
}

/// Attribute tensors of one set (static or dynamic), reference layout.
pub(crate) struct SetTensors {
    pub(crate) xyz: Vec<f32>,
    pub(crate) dc: Vec<f32>,
    pub(crate) rest: Vec<f32>,
    pub(crate) scaling: Vec<f32>,
    pub(crate) rotation: Vec<f32>,
    pub(crate) opacity: Vec<f32>,
    pub(crate) opacity_dim: usize,
    pub(crate) lang: Option<Vec<f32>>,
    pub(crate) rest_channels: usize,
}

impl SetTensors {
    pub(crate) fn count(&self) -> usize {
        self.xyz.len() / 3
    }

    pub(crate) fn gaussians(&self, what: &str, limits: &Limits) -> Result<Gaussians, IngestError> {
        let n = self.count();
        limits.check_gaussians("reference run Gaussians", n as u64, 0)?;
        let degree = match self.rest_channels {
            0 => 0,
            9 => 1,
            24 => 2,
            45 => 3,
            c => {
                return Err(IngestError::shape(
                    what,
                    format!("SH rest has {c} channels"),
                ))
            }
        };
        let lang_width = if self.lang.is_some() { LANG } else { 0 };
        let mut g = Gaussians::new(degree, lang_width);
        let check = |name: &str, v: &[f32], w: usize| -> Result<(), IngestError> {
            if v.len() != n * w {
                return Err(IngestError::shape(
                    what,
                    format!("{name} has {} values for {n} Gaussians x {w}", v.len()),
                ));
            }
            Ok(())
        };
        check("features_dc", &self.dc, 3)?;
        check("features_rest", &self.rest, self.rest_channels)?;
        check("scaling", &self.scaling, 3)?;
        check("rotation", &self.rotation, 4)?;
        check("opacity", &self.opacity, self.opacity_dim)?;
        if let Some(l) = &self.lang {
            check("language_feature", l, LANG)?;
            if self.opacity_dim != 2 {
                return Err(IngestError::shape(
                    what,
                    "language features need two opacities (colour, language)",
                ));
            }
        }
        for i in 0..n {
            g.positions
                .push([self.xyz[3 * i], self.xyz[3 * i + 1], self.xyz[3 * i + 2]]);
            g.log_scales.push([
                self.scaling[3 * i],
                self.scaling[3 * i + 1],
                self.scaling[3 * i + 2],
            ]);
            let r = &self.rotation[4 * i..4 * i + 4];
            g.rotations.push([r[0], r[1], r[2], r[3]]);
            g.opacity.push(self.opacity[self.opacity_dim * i]);
            // (N,1,3) DC then (N,K,3) rest: coefficient-major, as .dlgs stores SH.
            g.sh.extend_from_slice(&self.dc[3 * i..3 * i + 3]);
            g.sh.extend_from_slice(
                &self.rest[self.rest_channels * i..self.rest_channels * (i + 1)],
            );
            if let Some(l) = &self.lang {
                g.lang_opacity.push(self.opacity[2 * i + 1]);
                g.lang.extend_from_slice(&l[LANG * i..LANG * (i + 1)]);
            }
        }
        Ok(g)
    }
}

/// An MLP from its `state_dict` entries (`<i>.weight` keys, prefix already stripped).
pub(crate) fn mlp_from_state<'t>(
    tensors: impl Iterator<Item = (&'t str, &'t Tensor)>,
    role: MlpRole,
    what: &str,
) -> Result<Mlp, IngestError> {
    let what = what.to_string();
    let mut layers = Vec::new();
    let mut weights: Vec<(usize, &Tensor)> = Vec::new();
    for (k, t) in tensors {
        if k.ends_with(".bias") {
            return Err(IngestError::shape(
                &what,
                "the reference's decoders have no biases",
            ));
        }
        let idx = k
            .strip_suffix(".weight")
            .and_then(|i| i.parse::<usize>().ok());
        match idx {
            Some(i) => weights.push((i, t)),
            None => return Err(IngestError::format(&what, format!("unexpected tensor {k}"))),
        }
    }
    weights.sort_by_key(|w| w.0);
    for (_, t) in weights {
        if t.shape.len() != 2 {
            return Err(IngestError::shape(
                &what,
                format!("weight of shape {:?}", t.shape),
            ));
        }
        let w = t.f32s(&what)?;
        check_finite(&what, &w)?;
        layers.push(Layer {
            inputs: t.shape[1],
            outputs: t.shape[0],
            weights: w,
        });
    }
    if layers.is_empty() {
        return Err(IngestError::format(&what, "no layers"));
    }
    Ok(Mlp { role, layers })
}

/// Static and dynamic sets of one GOP must agree on SH degree and language.
pub(crate) fn check_sets(
    statics: &Gaussians,
    dynamics: &Gaussians,
    what: &str,
) -> Result<(), IngestError> {
    if statics.sh_degree != dynamics.sh_degree || statics.lang_width != dynamics.lang_width {
        return Err(IngestError::shape(
            what,
            "static and dynamic sets differ in SH degree or language",
        ));
    }
    Ok(())
}
