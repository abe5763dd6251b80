//! Splat files of other tools (PLY, SPZ, .splat, SOG) in and out, and `compare`.

use std::path::{Path, PathBuf};

use dlgs::interop::spz_write::{write_spz, SpzVersion};
use dlgs::Gaussians;
use dlgs_render::metrics::{psnr, ssim};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::arrays::{dict_to_gaussians, gaussians_to_dict};
use crate::camera;
use crate::errors::{request, to_py, IntoPy, Res};
use crate::reader::{open_reader, Reader};

/// Read a PLY, `.splat`, SPZ or SOG (`.sog` or `meta.json`) file into a dict of arrays.
#[pyfunction]
pub fn read_scene<'py>(py: Python<'py>, path: PathBuf) -> Res<Bound<'py, PyDict>> {
    let g = py
        .allow_threads(|| dlgs::interop::read_splat_file(&path))
        .py_err()?;
    gaussians_to_dict(py, g)
}

/// Write a dict of arrays as INRIA PLY (`.ply`, with the language extras when present), SPZ
/// (`.spz`, v3; `spz_version=2` for v2), antimatter15 `.splat` or PlayCanvas SOG (`.sog`
/// bundled, or a path named `meta.json`: the unbundled files in its directory; no language).
/// Returns the bytes written.
#[pyfunction]
#[pyo3(signature = (path, scene, spz_version=3, format=None))]
pub fn write_scene(
    py: Python<'_>,
    path: PathBuf,
    scene: &Bound<'_, PyDict>,
    spz_version: u8,
    format: Option<String>,
) -> Res<usize> {
    let g = dict_to_gaussians(scene, "scene")?;
    let ext = format
        .as_deref()
        .or_else(|| path.extension().and_then(|e| e.to_str()))
        .unwrap_or("")
        .to_ascii_lowercase();
    let version = match spz_version {
        2 => SpzVersion::V2,
        3 => SpzVersion::V3,
        v => return Err(request(format!("spz_version {v}: 2 or 3"))),
    };
    let write = |p: &Path, bytes: &[u8]| {
        std::fs::write(p, bytes)
            .map_err(|e| to_py(dlgs::Error::io(format!("writing {}", p.display()), e, 0)))
    };
    let meta_json = path.file_name().and_then(|n| n.to_str()) == Some("meta.json");
    if meta_json && matches!(ext.as_str(), "json" | "sog") {
        // An unbundled SOG: meta.json and its textures side by side.
        let files = py
            .allow_threads(|| dlgs::interop::sog_write::write_sog_files(&g))
            .py_err()?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let mut total = 0;
        for (name, bytes) in &files {
            write(&dir.join(name), bytes)?;
            total += bytes.len();
        }
        return Ok(total);
    }
    let bytes = py
        .allow_threads(|| match ext.as_str() {
            "ply" => dlgs::interop::ply::write_ply(&g),
            "spz" => write_spz(&g, version),
            "splat" => Ok(crate::splat_write::write_splat(&g)),
            "sog" => dlgs::interop::sog_write::write_sog(&g),
            other => Err(dlgs::Error::request(format!(
                "writing `.{other}`: the bindings write .ply, .spz, .splat, .sog and SOG's meta.json"
            ))),
        })
        .py_err()?;
    write(&path, &bytes)?;
    Ok(bytes.len())
}

fn is_dlgs(p: &Path) -> bool {
    p.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dlgs"))
}

/// Gaussians of a scene file (or a `.dlgs` at `t`) for each camera position.
enum Scene {
    Dlgs(Box<Reader>),
    Splat(Gaussians),
}

impl Scene {
    fn open(py: Python<'_>, p: &Path) -> Res<Scene> {
        if is_dlgs(p) {
            let path = p.to_path_buf().into_pyobject(py)?;
            Ok(Scene::Dlgs(Box::new(open_reader(py, &path, None, true)?)))
        } else {
            let p = p.to_path_buf();
            let g = py
                .allow_threads(|| dlgs::interop::read_splat_file(&p))
                .py_err()?;
            Ok(Scene::Splat(g))
        }
    }
    fn at(&self, py: Python<'_>, t: f64, camera: &dlgs_render::Camera) -> Res<Gaussians> {
        match self {
            Scene::Splat(g) => Ok(g.clone()),
            Scene::Dlgs(r) => r.gaussians(py, t, camera, false),
        }
    }
}

/// Render two scenes (files: `.dlgs` at `t`, PLY, SPZ, .splat, SOG) from the same cameras
/// and return PSNR / SSIM per view and their means, as `dlgs compare --json`.
#[pyfunction]
#[pyo3(signature = (a, b, cameras=None, t=0.0, background=(1.0, 1.0, 1.0)))]
pub fn compare<'py>(
    py: Python<'py>,
    a: PathBuf,
    b: PathBuf,
    cameras: Option<&Bound<'py, PyAny>>,
    t: f64,
    background: (f32, f32, f32),
) -> Res<Bound<'py, PyDict>> {
    let sa = Scene::open(py, &a)?;
    let sb = Scene::open(py, &b)?;
    let cams = match cameras {
        Some(list) => {
            let mut v = Vec::new();
            for c in list.try_iter()? {
                v.push(camera::resolve(&c?, None, None, || {
                    Err(request("orbit index needs a scene"))
                })?);
            }
            v
        }
        None => {
            let g = match &sa {
                Scene::Splat(g) => g.clone(),
                Scene::Dlgs(r) => r.canonical(py, t)?,
            };
            camera::orbit(&g, 8, 1352, 1014)
        }
    };
    let opts = dlgs_render::RenderOptions {
        background: [background.0, background.1, background.2],
        features: false,
        ..Default::default()
    };
    let views = PyList::empty(py);
    let (mut sp, mut ss) = (0.0, 0.0);
    for cam in &cams {
        let ga = sa.at(py, t, cam)?;
        let gb = sb.at(py, t, cam)?;
        let (p, s) = py.allow_threads(|| {
            let ia = dlgs_render::render(&ga, cam, &opts).map_err(crate::errors::other)?;
            let ib = dlgs_render::render(&gb, cam, &opts).map_err(crate::errors::other)?;
            Ok::<_, PyErr>((
                psnr(&ia.color, &ib.color),
                ssim(&ia.color, &ib.color, ia.width, ia.height),
            ))
        })?;
        let d = PyDict::new(py);
        d.set_item("camera", &cam.name)?;
        d.set_item("psnr", p)?;
        d.set_item("ssim", s)?;
        views.append(d)?;
        sp += p;
        ss += s;
    }
    let n = cams.len().max(1) as f64;
    let out = PyDict::new(py);
    out.set_item("views", views)?;
    out.set_item("mean_psnr", sp / n)?;
    out.set_item("mean_ssim", ss / n)?;
    Ok(out)
}
