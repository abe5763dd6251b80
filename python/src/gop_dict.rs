//! One GOP as Python holds a trained model: `{"static", "dynamic", "time_features",
//! "decoders", "scale_offsets"}`, in both directions.

use dlgs::model::{DeformMlps, DynamicGop, Layer, Mlp, MlpRole, TimeFeatures};
use dlgs::Canonical;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::arrays::{dict_to_gaussians, gaussians_to_dict, owned_array, read_f32};
use crate::errors::{input, Res};

/// A decoded GOP as a dict (the canonical sets are copied: the decoder keeps its own).
pub fn gop_to_dict<'py>(
    py: Python<'py>,
    canonical: &Canonical,
    dynamic: Option<DynamicGop>,
) -> Res<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("static", gaussians_to_dict(py, canonical.statics.clone())?)?;
    d.set_item(
        "dynamic",
        gaussians_to_dict(py, canonical.dynamics.clone())?,
    )?;
    if let Some(dy) = dynamic {
        let f = dy.features;
        d.set_item(
            "time_features",
            owned_array(py, f.data, &[f.n, f.keys, f.channels])?,
        )?;
        let dec = PyDict::new(py);
        for m in dy.mlps.iter() {
            let layers = PyList::empty(py);
            for l in &m.layers {
                layers.append(owned_array(py, l.weights.clone(), &[l.outputs, l.inputs])?)?;
            }
            dec.set_item(m.role.name(), layers)?;
        }
        d.set_item("decoders", dec)?;
        d.set_item("scale_offsets", dy.mlps.scale_offsets)?;
    }
    Ok(d)
}

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
