//! A binary voxel residual field (`RNTC`) from the dict `ntc_dict` describes (writer side).

use bitvec::prelude::*;
use dlgs::model::ntc::{NtcConfig, NtcField, NtcMlp};
use numpy::{PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::read_f32;
use crate::errors::{input, Res};

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
