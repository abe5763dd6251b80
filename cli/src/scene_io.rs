//! Loading renderable Gaussians from any supported file: a `.dlgs` stream at time t (with the
//! view-dependent decoders evaluated for a given camera) or a PLY / .splat / SPZ / SOG scene.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use anyhow::{Context, Result};
use dlgs::Gaussians;
use dlgs_decoder::scaffold::{ScaffoldDecoder, ViewRequest};
use dlgs_decoder::{Decoder, FrameOptions};

pub fn is_dlgs(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dlgs"))
}

/// A scene file opened once and asked for Gaussians per time and camera.
pub enum Source {
    Dlgs(Box<Decoder<BufReader<File>>>, String),
    /// A Scaffold-GS `.dlgs`: its Gaussians are generated per camera.
    Scaffold(Box<ScaffoldDecoder<BufReader<File>>>, String),
    Splat(Gaussians),
}

/// Whether a `.dlgs` file is of the Scaffold-GS variant (`HEAD.variant = 1`).
pub fn is_scaffold(path: &Path) -> Result<bool> {
    let f = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let r = dlgs::container::FileReader::open(BufReader::new(f))
        .with_context(|| format!("opening {}", path.display()))?;
    Ok(r.scene().variant == dlgs::container::header::Variant::Scaffold)
}

impl Source {
    pub fn open(path: &Path) -> Result<Self> {
        if is_dlgs(path) && is_scaffold(path)? {
            let f = File::open(path).with_context(|| format!("opening {}", path.display()))?;
            let dec = ScaffoldDecoder::new(BufReader::new(f), dlgs::Limits::default())
                .with_context(|| format!("opening {}", path.display()))?;
            Ok(Source::Scaffold(Box::new(dec), path.display().to_string()))
        } else if is_dlgs(path) {
            let dec =
                Decoder::open_path(path).with_context(|| format!("opening {}", path.display()))?;
            Ok(Source::Dlgs(Box::new(dec), path.display().to_string()))
        } else {
            let g = dlgs::interop::read_splat_file(path)
                .with_context(|| format!("reading {}", path.display()))?;
            Ok(Source::Splat(g))
        }
    }

    /// The undeformed Gaussians of the GOP shown at `t` (for camera placement).
    pub fn canonical(&mut self, t: f64) -> Result<Gaussians> {
        match self {
            Source::Splat(g) => Ok(g.clone()),
            Source::Dlgs(dec, name) => {
                let tp = dec
                    .scene()
                    .locate(t)
                    .with_context(|| format!("{name} at t = {t} s"))?;
                Ok(dec
                    .gop_canonical(tp.gop)
                    .with_context(|| format!("decoding GOP {} of {name}", tp.gop))?
                    .merged())
            }
            Source::Scaffold(dec, name) => {
                // The anchors themselves stand for the scene (bounds, camera placement).
                dec.anchor_stand_ins(t)
                    .with_context(|| format!("the anchors of {name} at t = {t} s"))
            }
        }
    }

    /// The Gaussians at `t` seen from `camera_center` (view-dependent dynamic decoders).
    pub fn at(&mut self, t: f64, camera_center: [f32; 3], language: bool) -> Result<Gaussians> {
        match self {
            Source::Splat(g) => Ok(g.clone()),
            Source::Dlgs(dec, name) => {
                let f = dec
                    .frame_at(
                        t,
                        &FrameOptions {
                            camera_center,
                            language,
                        },
                    )
                    .with_context(|| format!("decoding {name} at t = {t} s"))?;
                Ok(f.merged())
            }
            Source::Scaffold(dec, name) => {
                let view = ViewRequest {
                    camera_center,
                    language,
                    visible: None,
                };
                let f = dec
                    .frame_at(t, &view)
                    .with_context(|| format!("decoding {name} at t = {t} s"))?;
                Ok(f.to_gaussians())
            }
        }
    }
}

impl Source {
    /// The Gaussians at `t` seen by `camera`. For Scaffold-GS files, with `cull`, only the
    /// anchors whose children can reach into the camera's frustum are decoded (the image is the
    /// same; the time is not).
    pub fn at_camera(
        &mut self,
        t: f64,
        camera: &dlgs_render::Camera,
        language: bool,
        cull: bool,
    ) -> Result<Gaussians> {
        match self {
            Source::Scaffold(dec, name) if cull => {
                let in_view =
                    |p: &[[f32; 3]], r: &[f32]| dlgs_render::cull::spheres_in_view(camera, p, r);
                let (f, _) = dec
                    .frame_in_view(t, camera.position.to_array(), language, &in_view)
                    .with_context(|| format!("decoding {name} at t = {t} s"))?;
                Ok(f.to_gaussians())
            }
            _ => self.at(t, camera.position.to_array(), language),
        }
    }

    /// Frame rate and frame count of a `.dlgs` stream (`None` for a still scene file).
    pub fn timing(&self) -> Option<(f64, u32)> {
        match self {
            Source::Splat(_) => None,
            Source::Dlgs(dec, _) => Some((dec.scene().fps(), dec.scene().frame_count)),
            Source::Scaffold(dec, _) => Some((dec.scene().fps(), dec.scene().frame_count)),
        }
    }

    /// The GOP shown at `t` (`None` for a still scene file or a time outside the stream).
    pub fn gop_at(&self, t: f64) -> Option<u32> {
        match self {
            Source::Splat(_) => None,
            Source::Dlgs(dec, _) => dec.scene().locate(t).ok().map(|p| p.gop),
            Source::Scaffold(dec, _) => dec.scene().locate(t).ok().map(|p| p.gop),
        }
    }

    /// The file's language decoder (`.dlgs` with a `LAED` chunk), if any.
    pub fn lang_decoder(&mut self) -> Result<Option<dlgs::model::lang_decoder::LangDecoder>> {
        match self {
            Source::Splat(_) | Source::Scaffold(..) => Ok(None),
            Source::Dlgs(dec, name) => dec
                .lang_decoder()
                .with_context(|| format!("reading the language decoder of {name}")),
        }
    }

    /// Language levels and dims per level, from the `.dlgs` header.
    pub fn language_shape(&self) -> Option<(usize, usize)> {
        match self {
            Source::Splat(_) => None,
            Source::Dlgs(dec, _) => {
                let s = dec.scene();
                (s.lang_levels > 0).then_some((s.lang_levels as usize, s.lang_dims as usize))
            }
            Source::Scaffold(dec, _) => {
                let s = dec.scene();
                (s.lang_levels > 0).then_some((s.lang_levels as usize, s.lang_dims as usize))
            }
        }
    }
}
