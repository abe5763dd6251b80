//! One GOP from Python's arrays for the writer: canonical sets, key time features and
//! decoder weights (the inverse of `gop_dict`).

use dlgs::model::{DeformMlps, DynamicGop, Layer, Mlp, MlpRole, TimeFeatures};
use dlgs::Canonical;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::{dict_to_gaussians, read_f32};
use crate::errors::{input, Res};

fn mlp(decoders: &Bound<'_, PyDict>, role: MlpRole) -> Res<Option<Mlp>> {
    let Some(list) = decoders.get_item(role.name())? else {
        return Ok(None);
    };
    let mut layers = Vec::new();
    for (i, w) in list.try_iter()?.enumerate() {
        let what = format!("decoders[{}][{i}]", role.name());
        let (weights, s) = read_f32(&w?, &what)?;
        let [outputs, inputs] = s[..] else {
            return Err(input(format!(
                "{what}: expected a 2-D (out, in) weight matrix"
            )));
        };
        layers.push(Layer {
            inputs,
            outputs,
            weights,
        });
    }
    Ok(Some(Mlp { role, layers }))
}

/// The time features `(N_dyn, K, C)` and decoders of one GOP.
pub fn dynamic_from_py(
    time_features: &Bound<'_, PyAny>,
    decoders: &Bound<'_, PyDict>,
    scale_offsets: bool,
) -> Res<DynamicGop> {
    let (data, s) = read_f32(time_features, "time_features")?;
    let [n, keys, channels] = s[..] else {
        return Err(input("time_features: expected shape (N_dyn, K, 16)"));
    };
    let need = |role: MlpRole| {
        mlp(decoders, role)?.ok_or_else(|| input(format!("decoders: missing `{}`", role.name())))
    };
    Ok(DynamicGop {
        features: TimeFeatures {
            n,
            keys,
            channels,
            data,
        },
        mlps: DeformMlps {
            deform: need(MlpRole::Deform)?,
            cov: need(MlpRole::Cov)?,
            opacity: need(MlpRole::Opacity)?,
            color: need(MlpRole::Color)?,
            lang: mlp(decoders, MlpRole::Lang)?,
            scale_offsets,
        },
        life: None,
    })
}

/// A canonical state from its two dicts (`dynamic` may be absent: no dynamic Gaussians).
pub fn canonical_from_py(
    statics: &Bound<'_, PyDict>,
    dynamics: Option<&Bound<'_, PyDict>>,
) -> Res<Canonical> {
    let s = dict_to_gaussians(statics, "static")?;
    let d = match dynamics {
        Some(d) => dict_to_gaussians(d, "dynamic")?,
        None => dlgs::Gaussians::new(s.sh_degree, s.lang_width),
    };
    Ok(Canonical {
        statics: s,
        dynamics: d,
    })
}
