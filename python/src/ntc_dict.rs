//! A binary voxel residual field (`RNTC`, format-spec §6.6) as a dict of arrays, both ways:
//! `planes` (3 x levels arrays of shape (2^log2_table, features), uint8 0/1: 1 = +1),
//! `gate` (2^gate_log2_table,) uint8, `mlp` {w1 (hidden, in), b1, w2 (out, hidden), b2},
//! `resolutions`, `features`, `log2_table`, `gate_resolution`, `gate_log2_table`,
//! `bound_min`, `bound_max`, `groups` (bit mask of attribute groups), `sets` (1 static,
//! 2 dynamic).

use bitvec::prelude::*;
use dlgs::model::ntc::{NtcConfig, NtcField, NtcMlp};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::arrays::{owned_array, read_f32};
use crate::errors::{input, Res};

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

fn item<'py>(d: &Bound<'py, PyDict>, key: &str) -> Res<Bound<'py, PyAny>> {
    d.get_item(key)?
        .ok_or_else(|| input(format!("residual_field: missing `{key}`")))
}

fn bits(obj: &Bound<'_, PyAny>, len: usize, what: &str) -> Res<BitVec<u64, Lsb0>> {
    let a: PyReadonlyArrayDyn<'_, u8> = obj
        .extract()
        .map_err(|_| input(format!("residual_field {what}: expected a uint8 array")))?;
    if a.len() != len {
        return Err(input(format!(
            "residual_field {what}: {} values, expected {len}",
            a.len()
        )));
    }
    let s = a
        .as_slice()
        .map_err(|_| input(format!("residual_field {what}: not C-contiguous")))?;
    Ok(s.iter().map(|&v| v != 0).collect())
}

/// A field from its dict; shapes are checked by the encoder against the scene.
pub fn ntc_from_dict(d: &Bound<'_, PyDict>) -> Res<NtcField> {
    let config = NtcConfig {
        resolutions: item(d, "resolutions")?.extract()?,
        features: item(d, "features")?.extract()?,
        log2_table: item(d, "log2_table")?.extract()?,
        gate_resolution: item(d, "gate_resolution")?.extract()?,
        gate_log2_table: item(d, "gate_log2_table")?.extract()?,
    };
    if config.log2_table > 30 || config.gate_log2_table > 30 {
        return Err(input("residual_field: table sizes above 2^30"));
    }
    let planes_obj = item(d, "planes")?;
    let mut planes = Vec::new();
    for (i, p) in planes_obj.try_iter()?.enumerate() {
        planes.push(bits(&p?, config.level_bits(), &format!("planes[{i}]"))?);
    }
    let gate = bits(&item(d, "gate")?, config.gate_table(), "gate")?;
    let mlp_obj = item(d, "mlp")?;
    let mlp_d = mlp_obj
        .downcast::<PyDict>()
        .map_err(|_| input("residual_field mlp: expected a dict"))?;
    let (w1, s1) = read_f32(&item(mlp_d, "w1")?, "residual_field mlp w1")?;
    let (b1, _) = read_f32(&item(mlp_d, "b1")?, "residual_field mlp b1")?;
    let (w2, s2) = read_f32(&item(mlp_d, "w2")?, "residual_field mlp w2")?;
    let (b2, _) = read_f32(&item(mlp_d, "b2")?, "residual_field mlp b2")?;
    let (&[hidden, inputs], &[outputs, _]) = (s1.as_slice(), s2.as_slice()) else {
        return Err(input(
            "residual_field mlp: w1 (hidden, in) and w2 (out, hidden)",
        ));
    };
    let mlp = NtcMlp {
        inputs,
        hidden,
        outputs,
        w1,
        b1,
        w2,
        b2,
    };
    mlp.check().map_err(input)?;
    Ok(NtcField {
        config,
        bound_min: item(d, "bound_min")?.extract()?,
        bound_max: item(d, "bound_max")?.extract()?,
        planes,
        gate,
        mlp,
        groups: item(d, "groups")?.extract()?,
        sets: item(d, "sets")?.extract()?,
    })
}
