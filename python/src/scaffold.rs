//! Scaffold-GS files (`HEAD.variant = 1`, docs/scaffold.md) in a [`crate::reader::Reader`]:
//! their Gaussians are generated per camera by the anchors' MLPs, so every frame needs a
//! camera. The decoding is `dlgs_decoder::scaffold::ScaffoldDecoder`'s, as `dlgs render` and
//! `dlgs decode` do it.

use std::io::{Seek, SeekFrom};

use dlgs::container::header::Variant;
use dlgs::container::FileReader;
use dlgs::Gaussians;
use dlgs_decoder::scaffold::{NeuralGaussians, ScaffoldDecoder, ViewRequest};
use dlgs_render::Camera;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::{gaussians_to_dict, owned_array};
use crate::errors::{request, IntoPy, Res};
use crate::reader::{lock, Reader, Source, SCAFFOLD_ONLY_FRAMES};

pub type ScaffoldDec = ScaffoldDecoder<Box<dyn Source>>;

/// Whether `src` holds a Scaffold-GS file, and the file's format version; `src` is rewound to
/// its start.
pub fn sniff(src: &mut Box<dyn Source>, limits: &dlgs::Limits) -> dlgs::Result<(bool, (u16, u16))> {
    let r = FileReader::open_with_limits(&mut *src, limits.clone())?;
    let (variant, version) = (r.scene().variant, r.version());
    drop(r);
    src.seek(SeekFrom::Start(0))
        .map_err(|e| dlgs::Error::io("rewinding the source", e, 0))?;
    Ok((variant == Variant::Scaffold, version))
}

/// The neural Gaussians `camera` sees at `t`: with `cull`, only the anchors whose children
/// can reach into its frustum are decoded (what `dlgs render` draws; without `--no-cull`).
pub fn neural_at(
    dec: &mut ScaffoldDec,
    t: f64,
    camera: &Camera,
    language: bool,
    cull: bool,
) -> dlgs::Result<NeuralGaussians> {
    let language = language && dec.scene().lang_levels > 0;
    let centre = camera.position.to_array();
    if cull {
        let in_view = |p: &[[f32; 3]], r: &[f32]| dlgs_render::cull::spheres_in_view(camera, p, r);
        Ok(dec.frame_in_view(t, centre, language, &in_view)?.0)
    } else {
        dec.frame_at(
            t,
            &ViewRequest {
                camera_center: centre,
                language,
                visible: None,
            },
        )
    }
}

/// The anchors at `t` as stand-in Gaussians (bounds and orbit cameras), as the CLI's
/// `Source::canonical` builds them, so that orbit camera `i` is the CLI's.
pub fn anchor_stand_ins(dec: &mut ScaffoldDec, t: f64) -> dlgs::Result<Gaussians> {
    dec.anchor_stand_ins(t)
}

/// The MLP outputs as they are (`frame(..., neural=True)`): linear `scales`, unit
/// `rotations`, RGB `colors` in [0, 1], tanh `opacities`, raw tanh `lang_opacities` (may be
/// negative), `lang_features`, and each child's `anchor` index and `offset` slot.
pub fn neural_to_dict<'py>(py: Python<'py>, n: NeuralGaussians) -> Res<Bound<'py, PyDict>> {
    let len = n.len();
    let d = PyDict::new(py);
    let (anchor, offset): (Vec<u32>, Vec<u8>) = n.source.iter().copied().unzip();
    d.set_item(
        "positions",
        owned_array(py, n.positions.into_flattened(), &[len, 3])?,
    )?;
    d.set_item(
        "scales",
        owned_array(py, n.scales.into_flattened(), &[len, 3])?,
    )?;
    d.set_item(
        "rotations",
        owned_array(py, n.rotations.into_flattened(), &[len, 4])?,
    )?;
    d.set_item(
        "colors",
        owned_array(py, n.colors.into_flattened(), &[len, 3])?,
    )?;
    d.set_item("opacities", owned_array(py, n.opacity, &[len])?)?;
    if !n.lang.is_empty() {
        let w = n.lang.len() / len.max(1);
        d.set_item("lang_features", owned_array(py, n.lang, &[len, w])?)?;
        d.set_item("lang_opacities", owned_array(py, n.lang_opacity, &[len])?)?;
    }
    d.set_item("anchor", numpy::PyArray1::from_vec(py, anchor))?;
    d.set_item("offset", numpy::PyArray1::from_vec(py, offset))?;
    Ok(d)
}

impl Reader {
    /// `frame(...)` of a Scaffold-GS file.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn scaffold_frame<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        camera: Option<&Bound<'py, PyAny>>,
        language: bool,
        split: bool,
        cull: bool,
        neural: bool,
    ) -> Res<Bound<'py, PyDict>> {
        let Some(camera) = camera else {
            return Err(PyValueError::new_err(
                "a Scaffold-GS file (variant 1) generates its Gaussians per camera: \
                 frame(t, camera=...) needs a camera",
            ));
        };
        if split {
            return Err(request(SCAFFOLD_ONLY_FRAMES));
        }
        let cam = self.resolve(py, camera, t, None, None)?;
        let sdec = self.sdec.as_ref().expect("a Scaffold-GS reader");
        let n = self
            .detach(py, || neural_at(&mut lock(sdec), t, &cam, language, cull))
            .py_err()?;
        if neural {
            neural_to_dict(py, n)
        } else {
            gaussians_to_dict(py, n.to_gaussians())
        }
    }
}
