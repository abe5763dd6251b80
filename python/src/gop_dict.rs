//! One decoded GOP as Python holds a trained model: `{"static", "dynamic", "time_features",
//! "decoders", "scale_offsets"}` (the way in is `gop_input`).

use dlgs::model::DynamicGop;
use dlgs::Canonical;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::arrays::{gaussians_to_dict, owned_array};
use crate::errors::Res;

/// A decoded GOP as a dict (the canonical sets are copied: the decoder keeps its own).
pub fn gop_to_dict<'py>(
    py: Python<'py>,
    canonical: &Canonical,
    dynamic: Option<DynamicGop>,
    ntc: Option<&dlgs::model::ntc::NtcField>,
) -> Res<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    if let Some(f) = ntc {
        d.set_item("residual_field", crate::ntc_dict::ntc_to_dict(py, f)?)?;
    }
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
