//! A binary voxel residual field (`RNTC`, format-spec §6.6) as a dict of arrays (the way in,
//! for the writer, is `ntc_input`):
//! `planes` (3 x levels arrays of shape (2^log2_table, features), uint8 0/1: 1 = +1),
//! `gate` (2^gate_log2_table,) uint8, `mlp` {w1 (hidden, in), b1, w2 (out, hidden), b2},
//! `resolutions`, `features`, `log2_table`, `gate_resolution`, `gate_log2_table`,
//! `bound_min`, `bound_max`, `groups` (bit mask of attribute groups), `sets` (1 static,
//! 2 dynamic).

use bitvec::prelude::*;
use dlgs::model::ntc::NtcField;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::arrays::owned_array;
use crate::errors::Res;

fn bits_array<'py>(
    py: Python<'py>,
    b: &BitVec<u64, Lsb0>,
    shape: &[usize],
) -> Res<Bound<'py, PyAny>> {
    let v: Vec<u8> = b.iter().map(|x| u8::from(*x)).collect();
    Ok(PyArray1::from_vec(py, v)
        .reshape(shape.to_vec())?
        .into_any())
}

/// The field as a dict (copies: the decoder keeps its own).
pub fn ntc_to_dict<'py>(py: Python<'py>, f: &NtcField) -> Res<Bound<'py, PyDict>> {
    let c = &f.config;
    let d = PyDict::new(py);
    d.set_item("resolutions", c.resolutions.clone())?;
    d.set_item("features", c.features)?;
    d.set_item("log2_table", c.log2_table)?;
    d.set_item("gate_resolution", c.gate_resolution)?;
    d.set_item("gate_log2_table", c.gate_log2_table)?;
    d.set_item("bound_min", f.bound_min.to_vec())?;
    d.set_item("bound_max", f.bound_max.to_vec())?;
    let planes = PyList::empty(py);
    for p in &f.planes {
        planes.append(bits_array(py, p, &[c.table(), c.features as usize])?)?;
    }
    d.set_item("planes", planes)?;
    d.set_item("gate", bits_array(py, &f.gate, &[c.gate_table()])?)?;
    let m = &f.mlp;
    let mlp = PyDict::new(py);
    mlp.set_item("w1", owned_array(py, m.w1.clone(), &[m.hidden, m.inputs])?)?;
    mlp.set_item("b1", owned_array(py, m.b1.clone(), &[m.hidden])?)?;
    mlp.set_item("w2", owned_array(py, m.w2.clone(), &[m.outputs, m.hidden])?)?;
    mlp.set_item("b2", owned_array(py, m.b2.clone(), &[m.outputs])?)?;
    d.set_item("mlp", mlp)?;
    d.set_item("groups", f.groups)?;
    d.set_item("sets", f.sets)?;
    Ok(d)
}
