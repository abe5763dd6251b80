//! Gaussians <-> dicts of float32 numpy arrays. Arrays handed to Python take over the Rust
//! buffers (no copy); arrays read from Python are C-contiguous float32 (the Python layer
//! converts) and copied once with `memcpy`.

use dlgs::Gaussians;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{input, Res};

/// A Vec as an array of shape `shape`, without copying its buffer.
pub fn owned_array<'py>(py: Python<'py>, v: Vec<f32>, shape: &[usize]) -> Res<Bound<'py, PyAny>> {
    let a = PyArray1::from_vec(py, v);
    if shape.len() == 1 {
        return Ok(a.into_any());
    }
    // A reshape of a contiguous array is a view of the same buffer.
    Ok(a.reshape(shape.to_vec())?.into_any())
}

/// The Gaussians as a dict of arrays (see `frame` in docs/python.md for the keys).
pub fn gaussians_to_dict<'py>(py: Python<'py>, g: Gaussians) -> Res<Bound<'py, PyDict>> {
    let n = g.len();
    let coeffs = g.coeffs();
    let lw = g.lang_width;
    let d = PyDict::new(py);
    d.set_item(
        "positions",
        owned_array(py, g.positions.into_flattened(), &[n, 3])?,
    )?;
    d.set_item(
        "log_scales",
        owned_array(py, g.log_scales.into_flattened(), &[n, 3])?,
    )?;
    d.set_item(
        "rotations",
        owned_array(py, g.rotations.into_flattened(), &[n, 4])?,
    )?;
    d.set_item("opacities", owned_array(py, g.opacity, &[n])?)?;
    d.set_item("sh", owned_array(py, g.sh, &[n, coeffs, 3])?)?;
    if lw > 0 {
        d.set_item("lang_features", owned_array(py, g.lang, &[n, lw])?)?;
        d.set_item("lang_opacities", owned_array(py, g.lang_opacity, &[n])?)?;
    }
    Ok(d)
}

/// A C-contiguous float32 array's values and shape.
pub fn read_f32(obj: &Bound<'_, PyAny>, what: &str) -> Res<(Vec<f32>, Vec<usize>)> {
    let a: PyReadonlyArrayDyn<'_, f32> = obj
        .extract()
        .map_err(|_| input(format!("{what}: expected a float32 numpy array")))?;
    let shape = a.shape().to_vec();
    let s = a
        .as_slice()
        .map_err(|_| input(format!("{what}: the array is not C-contiguous")))?;
    Ok((s.to_vec(), shape))
}

fn rows<const W: usize>(v: Vec<f32>, what: &str) -> Res<Vec<[f32; W]>> {
    if !v.len().is_multiple_of(W) {
        return Err(input(format!("{what}: length is not a multiple of {W}")));
    }
    Ok(v.chunks_exact(W)
        .map(|c| c.try_into().expect("chunk of W"))
        .collect())
}

fn required<'py>(d: &Bound<'py, PyDict>, key: &str, what: &str) -> Res<Bound<'py, PyAny>> {
    d.get_item(key)?
        .ok_or_else(|| input(format!("{what}: missing key `{key}`")))
}

fn expect_shape(shape: &[usize], want: &[usize], what: &str, key: &str) -> Res<()> {
    if shape != want {
        return Err(input(format!(
            "{what}[{key}]: shape {shape:?}, expected {want:?}"
        )));
    }
    Ok(())
}

/// Gaussians from a dict with the keys of [`gaussians_to_dict`]; `sh` is `(N, coeffs, 3)`
/// with coeffs 1, 4, 9 or 16. Language keys are optional (both or neither).
pub fn dict_to_gaussians(d: &Bound<'_, PyDict>, what: &str) -> Res<Gaussians> {
    let (pos, ps) = read_f32(&required(d, "positions", what)?, what)?;
    let n = *ps.first().unwrap_or(&0);
    expect_shape(&ps, &[n, 3], what, "positions")?;
    let (ls, s) = read_f32(&required(d, "log_scales", what)?, what)?;
    expect_shape(&s, &[n, 3], what, "log_scales")?;
    let (rot, s) = read_f32(&required(d, "rotations", what)?, what)?;
    expect_shape(&s, &[n, 4], what, "rotations")?;
    let (op, s) = read_f32(&required(d, "opacities", what)?, what)?;
    expect_shape(&s, &[n], what, "opacities")?;
    let (sh, s) = read_f32(&required(d, "sh", what)?, what)?;
    let coeffs = s.get(1).copied().unwrap_or(0);
    expect_shape(&s, &[n, coeffs, 3], what, "sh")?;
    let sh_degree = match coeffs {
        1 => 0,
        4 => 1,
        9 => 2,
        16 => 3,
        c => {
            return Err(input(format!(
                "{what}[sh]: {c} coefficients, expected 1, 4, 9 or 16"
            )))
        }
    };
    let lang = d.get_item("lang_features")?;
    let lang_op = d.get_item("lang_opacities")?;
    let (lang, lang_opacity, lang_width) = match (lang, lang_op) {
        (None, None) => (Vec::new(), Vec::new(), 0),
        (Some(l), Some(o)) => {
            let (l, ls) = read_f32(&l, what)?;
            let w = ls.get(1).copied().unwrap_or(0);
            expect_shape(&ls, &[n, w], what, "lang_features")?;
            let (o, os) = read_f32(&o, what)?;
            expect_shape(&os, &[n], what, "lang_opacities")?;
            (l, o, w)
        }
        _ => {
            return Err(input(format!(
                "{what}: give both lang_features and lang_opacities, or neither"
            )))
        }
    };
    let g = Gaussians {
        sh_degree,
        lang_width,
        positions: rows(pos, what)?,
        log_scales: rows(ls, what)?,
        rotations: rows(rot, what)?,
        opacity: op,
        lang_opacity,
        sh,
        lang,
    };
    g.check_shapes().map_err(crate::errors::to_py)?;
    Ok(g)
}
