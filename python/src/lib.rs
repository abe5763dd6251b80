//! Python bindings of dlgs (module `dlgs._dlgs`; the package `dlgs` re-exports it with
//! array conversion helpers): read frames, renders and queries of `.dlgs` streams into numpy,
//! write `.dlgs` from a trained model's arrays, read and write other splat formats.
//!
//! Every long call releases the GIL. Errors are the exceptions of [`errors`].

mod arrays;
mod camera;
#[cfg(feature = "hevc")]
mod config;
mod errors;
mod gop_dict;
#[cfg(feature = "hevc")]
mod gop_input;
mod ntc_dict;
#[cfg(feature = "hevc")]
mod ntc_input;
mod reader;
mod recycle;
mod scaffold;
mod scenes;
mod splat_write;
mod timing;
mod view;
#[cfg(feature = "hevc")]
mod writer;

use pyo3::prelude::*;
#[cfg(feature = "hevc")]
use pyo3::types::PyDict;

/// Licence of this build: GPL when FFmpeg/libx265 is linked (feature `hevc`).
const LICENSE_NOTE: &str = if cfg!(feature = "hevc") {
    "GPL-2.0-or-later: this build links FFmpeg with libx265 (GPL) for HEVC time features"
} else {
    "MIT OR Apache-2.0: this build links no FFmpeg (no HEVC time features, no Writer)"
};

/// Encode one still scene (dict of arrays) as `dlgs encode SCENE -o PATH` does; returns the
/// file's size in bytes.
#[cfg(feature = "hevc")]
#[pyfunction]
#[pyo3(signature = (scene, path, quality="high", zstd_level=9, meta=None))]
fn encode_scene(
    py: Python<'_>,
    scene: &Bound<'_, PyDict>,
    path: std::path::PathBuf,
    quality: &str,
    zstd_level: i32,
    meta: Option<&Bound<'_, PyAny>>,
) -> PyResult<u64> {
    let g = arrays::dict_to_gaussians(scene, "scene")?;
    let codec = config::CodecOptions {
        quality: quality.to_owned(),
        crf: 6,
        preset: "medium".into(),
        exact_features: false,
        quantised_features: None,
        lossless_features: false,
        intra_features: false,
        fast_start: Default::default(),
        per_gop_range: false,
        mlp_f16: false,
        max_compression: false,
        zstd_level,
        meta: config::meta_from_py(py, meta)?,
        lang_decoder: None,
    };
    writer::encode_still(py, &g, path, codec.config()?)
}

#[pymodule]
fn _dlgs(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("LICENSE_NOTE", LICENSE_NOTE)?;
    m.add("HAS_HEVC", cfg!(feature = "hevc"))?;
    m.add_class::<reader::Reader>()?;
    m.add_class::<reader::FrameIter>()?;
    m.add_function(wrap_pyfunction!(reader::open_reader, m)?)?;
    m.add_function(wrap_pyfunction!(scenes::read_scene, m)?)?;
    m.add_function(wrap_pyfunction!(scenes::write_scene, m)?)?;
    m.add_function(wrap_pyfunction!(scenes::compare, m)?)?;
    #[cfg(feature = "hevc")]
    {
        m.add_class::<writer::Writer>()?;
        m.add_function(wrap_pyfunction!(encode_scene, m)?)?;
    }
    Ok(())
}
