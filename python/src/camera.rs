//! Cameras from Python: a 3DGS `cameras.json` entry (dict), a tuple `(R, T, fx, fy, W, H)` in
//! the 3DGS `Camera` convention, or an index into the orbit the CLI places around the scene.

use dlgs::Gaussians;
use dlgs_render::{cameras_from_json, orbit_cameras, Camera, OrbitSpec};
use glam::{Mat3, Vec3};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::errors::{other, request, Res};

/// The orbit `dlgs render` uses without `--cameras` (8 views, 1352x1014, -y up).
pub fn orbit(scene: &Gaussians, count: usize, width: u32, height: u32) -> Vec<Camera> {
    let spec = OrbitSpec {
        count: count.max(1),
        width,
        height,
        ..OrbitSpec::default()
    };
    orbit_cameras(scene, &spec)
}

fn from_json_entry(d: &Bound<'_, PyDict>) -> Res<Camera> {
    let py = d.py();
    let text: String = py
        .import("json")?
        .call_method1("dumps", (vec![d.clone()],))?
        .extract()?;
    let mut cams = cameras_from_json(&text).map_err(other)?;
    cams.pop().ok_or_else(|| request("empty camera"))
}

fn from_tuple(t: &Bound<'_, PyTuple>) -> Res<Camera> {
    if t.len() != 6 {
        return Err(request(
            "a camera tuple is (R, T, fx, fy, W, H) (3DGS convention)",
        ));
    }
    let r: Vec<Vec<f32>> = t
        .get_item(0)?
        .call_method0("tolist")
        .or_else(|_| Ok::<_, PyErr>(t.get_item(0).expect("item 0")))?
        .extract()
        .map_err(|_| request("camera R: a 3x3 matrix"))?;
    let tv: Vec<f32> = t
        .get_item(1)?
        .call_method0("tolist")
        .or_else(|_| Ok::<_, PyErr>(t.get_item(1).expect("item 1")))?
        .extract()
        .map_err(|_| request("camera T: three numbers"))?;
    if r.len() != 3 || r.iter().any(|row| row.len() != 3) || tv.len() != 3 {
        return Err(request("camera R must be 3x3 and T three numbers"));
    }
    let fx: f32 = t.get_item(2)?.extract()?;
    let fy: f32 = t.get_item(3)?.extract()?;
    let width: u32 = t.get_item(4)?.extract()?;
    let height: u32 = t.get_item(5)?.extract()?;
    if width == 0 || height == 0 || !(fx > 0.0) || !(fy > 0.0) {
        return Err(request("camera width, height, fx and fy must be positive"));
    }
    // 3DGS: R is the transpose of the world-to-camera rotation, T the world-to-camera
    // translation (getWorld2View2), so the centre is -R T.
    let rm = Mat3::from_cols(
        Vec3::new(r[0][0], r[1][0], r[2][0]),
        Vec3::new(r[0][1], r[1][1], r[2][1]),
        Vec3::new(r[0][2], r[1][2], r[2][2]),
    );
    let t = Vec3::new(tv[0], tv[1], tv[2]);
    Ok(Camera {
        width,
        height,
        fx,
        fy,
        cx: width as f32 * 0.5,
        cy: height as f32 * 0.5,
        rotation: rm.transpose(),
        position: -(rm * t),
        name: "camera".into(),
    })
}

/// Resolve `obj` (dict, tuple, or index into `default_orbit()`: [`orbit`] with 8 views at
/// 1352x1014 around the scene), then resize to
/// `width` x `height` when given (as `--width/--height` do).
pub fn resolve(
    obj: &Bound<'_, PyAny>,
    width: Option<u32>,
    height: Option<u32>,
    default_orbit: impl FnOnce() -> Res<Vec<Camera>>,
) -> Res<Camera> {
    let cam = if let Ok(d) = obj.downcast::<PyDict>() {
        from_json_entry(d)?
    } else if let Ok(t) = obj.downcast::<PyTuple>() {
        from_tuple(t)?
    } else if let Ok(i) = obj.extract::<usize>() {
        let cams = default_orbit()?;
        cams.get(i)
            .cloned()
            .ok_or_else(|| request(format!("orbit view {i}: there are 8 (0..=7)")))?
    } else {
        return Err(request(
            "camera: a cameras.json entry (dict), (R, T, fx, fy, W, H), or an orbit view index",
        ));
    };
    Ok(match (width, height) {
        (Some(w), Some(h)) => cam.resized(w, h),
        (Some(w), None) => {
            let h = (cam.height as f32 * w as f32 / cam.width as f32).round() as u32;
            cam.resized(w, h)
        }
        (None, Some(_)) => return Err(request("give width with height")),
        (None, None) => cam,
    })
}

/// A camera as a 3DGS cameras.json entry (what `dlgs cameras` writes).
pub fn to_json_entry<'py>(py: Python<'py>, i: usize, c: &Camera) -> Res<Bound<'py, PyDict>> {
    let c2w = c.rotation.transpose();
    let rows: Vec<[f32; 3]> = (0..3)
        .map(|r| [c2w.col(0)[r], c2w.col(1)[r], c2w.col(2)[r]])
        .collect();
    let d = PyDict::new(py);
    d.set_item("id", i)?;
    d.set_item("img_name", &c.name)?;
    d.set_item("width", c.width)?;
    d.set_item("height", c.height)?;
    d.set_item("position", c.position.to_array().to_vec())?;
    d.set_item(
        "rotation",
        rows.iter().map(|r| r.to_vec()).collect::<Vec<_>>(),
    )?;
    d.set_item("fx", c.fx)?;
    d.set_item("fy", c.fy)?;
    Ok(d)
}
