//! `dlgs.Writer`: a `.dlgs` written one GOP at a time from arrays, and `dlgs.encode_scene`
//! for still scenes. The file is written to `PATH.partial` and renamed on `close()`.
//! The header holds the GOP count: with `gop_count` given, each GOP is encoded as it is
//! written; without it GOPs are kept until `close()` and encoded then.

use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::Mutex;

use dlgs::container::header::{DeformModel, ResidualMode, Variant};
use dlgs::container::SceneHeader;
use dlgs::model::ntc::NtcField;
use dlgs::model::DynamicGop;
use dlgs::Canonical;
use dlgs_encoder::{EncoderConfig, GopCanonical, StreamEncoder};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::config::CodecOptions;
use crate::errors::{input, request, to_py, IntoPy, Res};
use crate::gop_input::{canonical_from_py, dynamic_from_py};

type Out = BufWriter<File>;
/// A GOP's canonical part: its full state, or a binary voxel residual field (`RNTC`).
enum Canon {
    State(Box<Canonical>),
    Ntc(Box<NtcField>),
}
type Gop = (Canon, Option<DynamicGop>);

/// What the header needs besides what the first GOP tells.
pub struct StreamOptions {
    pub fps: (u32, u32),
    pub gop_length: u32,
    pub residual_mode: ResidualMode,
    pub deform_model: DeformModel,
    pub gop_count: Option<u32>,
    pub frame_count: Option<u32>,
}

enum State {
    Open {
        pending: Vec<Gop>,
    },
    Streaming {
        enc: Box<StreamEncoder<Out>>,
        done: u32,
        total: u32,
    },
    Closed,
}

#[pyclass(module = "dlgs._dlgs", name = "Writer", frozen)]
pub struct Writer {
    path: PathBuf,
    opts: StreamOptions,
    cfg: EncoderConfig,
    progress: Option<PyObject>,
    state: Mutex<State>,
}

pub fn parse_residual_mode(s: &str) -> Res<ResidualMode> {
    Ok(match s {
        "intra" => ResidualMode::Intra,
        "sequential" => ResidualMode::Sequential,
        "parallel" => ResidualMode::Parallel,
        _ => {
            return Err(request(format!(
                "residual_mode `{s}`: intra, sequential or parallel"
            )))
        }
    })
}

pub fn parse_deform_model(s: &str) -> Res<DeformModel> {
    Ok(match s {
        "reference" => DeformModel::Reference,
        "lerp" => DeformModel::PaperLerp,
        _ => return Err(request(format!("deform_model `{s}`: reference or lerp"))),
    })
}

fn partial(path: &std::path::Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

/// The header for `gops` GOPs shaped like `first`.
fn header(o: &StreamOptions, first: &Gop, gops: u32) -> Res<SceneHeader> {
    let (c, dy) = first;
    let Canon::State(c) = c else {
        return Err(input(
            "GOP 0 needs its full canonical state, not a residual field",
        ));
    };
    let lw = c.statics.lang_width.max(c.dynamics.lang_width);
    let (lang_levels, lang_dims) = match lw {
        0 => (0, 0),
        w if w % 3 == 0 => (w / 3, 3),
        w => (1, w),
    };
    let key_interval = match dy {
        Some(d) if d.features.keys >= 2 => {
            let k = d.features.keys as u32 - 1;
            if !o.gop_length.is_multiple_of(k) {
                return Err(input(format!(
                    "time_features have {} keys: gop_length {} is not a multiple of {k}",
                    d.features.keys, o.gop_length
                )));
            }
            o.gop_length / k
        }
        Some(_) => return Err(input("time_features need at least 2 keys")),
        None => 1,
    };
    Ok(SceneHeader {
        variant: Variant::Gaussians3d,
        residual_mode: o.residual_mode,
        deform_model: o.deform_model,
        sh_degree: c.statics.sh_degree,
        lang_levels: u8::try_from(lang_levels).map_err(|_| input("language too wide"))?,
        lang_dims: u8::try_from(lang_dims).map_err(|_| input("language too wide"))?,
        time_channels: dy.as_ref().map_or(0, |d| d.features.channels as u8),
        fps_num: o.fps.0,
        fps_den: o.fps.1,
        gop_length: o.gop_length,
        key_interval,
        gop_count: gops,
        frame_count: o.frame_count.unwrap_or(gops * o.gop_length),
        n_static: c.statics.len() as u32,
        n_dynamic: c.dynamics.len() as u32,
        refresh_interval: 0,
    })
}

impl Writer {
    pub fn new(
        path: PathBuf,
        opts: StreamOptions,
        codec: &CodecOptions,
        progress: Option<PyObject>,
    ) -> Res<Self> {
        if opts.gop_length == 0 || opts.fps.0 == 0 || opts.fps.1 == 0 {
            return Err(request("fps and gop_length must be positive"));
        }
        Ok(Writer {
            path,
            opts,
            cfg: codec.config()?,
            progress,
            state: Mutex::new(State::Open {
                pending: Vec::new(),
            }),
        })
    }

    fn start(&self, first: &Gop, total: u32) -> Res<StreamEncoder<Out>> {
        let scene = header(&self.opts, first, total)?;
        let f = File::create(partial(&self.path)).map_err(|e| {
            to_py(dlgs::Error::io(
                format!("creating {}", self.path.display()),
                e,
                0,
            ))
        })?;
        StreamEncoder::new(BufWriter::new(f), scene, self.cfg.clone()).py_err()
    }

    /// The state, locked: the lock is held across calls that release the GIL (encoding), so a
    /// thread waits for it without the GIL.
    fn lock_state(&self, py: Python<'_>) -> std::sync::MutexGuard<'_, State> {
        loop {
            match self.state.try_lock() {
                Ok(g) => return g,
                Err(std::sync::TryLockError::Poisoned(e)) => return e.into_inner(),
                // Wait without the GIL until the holder lets go, then try again.
                Err(std::sync::TryLockError::WouldBlock) => {
                    py.allow_threads(|| drop(self.state.lock()))
                }
            }
        }
    }

    fn report(&self, py: Python<'_>, done: u32, total: u32) -> Res<()> {
        if let Some(cb) = &self.progress {
            cb.call1(py, (done, total))?;
        }
        Ok(())
    }
}

fn push(py: Python<'_>, enc: &mut StreamEncoder<Out>, gop: &Gop) -> Res<()> {
    let canonical = match &gop.0 {
        Canon::State(c) => GopCanonical::State(c),
        Canon::Ntc(f) => GopCanonical::Ntc(f),
    };
    py.allow_threads(|| enc.push(canonical, gop.1.as_ref()))
        .py_err()
}

#[pymethods]
impl Writer {
    #[new]
    #[pyo3(signature = (path, fps=30.0, gop_length=1, quality="lossless", crf=6, preset="medium",
        exact_features=false, lossless_features=false, intra_features=false, per_gop_range=false,
        mlp_f16=false, zstd_level=9, residual_mode="intra", deform_model="reference",
        gop_count=None, frame_count=None, meta=None, lang_decoder=None, negatives=None,
        progress=None, fast_start="first", max_compression=false, quantised_features=None))]
    fn py_new(
        py: Python<'_>,
        path: PathBuf,
        fps: f64,
        gop_length: u32,
        quality: &str,
        crf: u8,
        preset: &str,
        exact_features: bool,
        lossless_features: bool,
        intra_features: bool,
        per_gop_range: bool,
        mlp_f16: bool,
        zstd_level: i32,
        residual_mode: &str,
        deform_model: &str,
        gop_count: Option<u32>,
        frame_count: Option<u32>,
        meta: Option<&Bound<'_, PyAny>>,
        lang_decoder: Option<PathBuf>,
        negatives: Option<&Bound<'_, PyAny>>,
        progress: Option<PyObject>,
        fast_start: &str,
        max_compression: bool,
        quantised_features: Option<u8>,
    ) -> Res<Self> {
        if let Some(b) = quantised_features.filter(|b| !(6..=12).contains(b)) {
            return Err(request(format!(
                "quantised_features={b}: must be 6 to 12 bits"
            )));
        }
        let codec = CodecOptions {
            quality: quality.to_owned(),
            crf,
            preset: preset.to_owned(),
            exact_features,
            quantised_features,
            lossless_features,
            intra_features,
            fast_start: crate::config::parse_fast_start(fast_start)?,
            per_gop_range,
            mlp_f16,
            max_compression,
            zstd_level,
            meta: crate::config::meta_from_py(py, meta)?,
            lang_decoder: crate::config::lang_decoder_from_py(lang_decoder, negatives)?,
        };
        let opts = StreamOptions {
            fps: crate::config::fps_fraction(fps)?,
            gop_length,
            residual_mode: parse_residual_mode(residual_mode)?,
            deform_model: parse_deform_model(deform_model)?,
            gop_count,
            frame_count,
        };
        Writer::new(path, opts, &codec, progress)
    }

    /// Append the next GOP (see docs/python.md for the arrays).
    #[pyo3(signature = (static_set=None, dynamic=None, time_features=None, decoders=None,
        scale_offsets=None, residual_field=None))]
    fn write_gop(
        &self,
        py: Python<'_>,
        static_set: Option<&Bound<'_, PyDict>>,
        dynamic: Option<&Bound<'_, PyDict>>,
        time_features: Option<&Bound<'_, PyAny>>,
        decoders: Option<&Bound<'_, PyDict>>,
        scale_offsets: Option<bool>,
        residual_field: Option<&Bound<'_, PyDict>>,
    ) -> Res<()> {
        let canonical = match (static_set, residual_field) {
            (Some(s), None) => Canon::State(Box::new(canonical_from_py(s, dynamic)?)),
            (None, Some(f)) if dynamic.is_none() => {
                Canon::Ntc(Box::new(crate::ntc_input::ntc_from_dict(f)?))
            }
            _ => {
                return Err(input(
                    "give the canonical sets (static, dynamic) or a residual_field, not both",
                ))
            }
        };
        let mut state = self.lock_state(py);
        let index = match &*state {
            State::Open { pending } => pending.len() as u32,
            State::Streaming { done, .. } => *done,
            State::Closed => return Err(request("the writer is closed")),
        };
        let dynamic_gop = match (time_features, decoders) {
            (Some(f), Some(d)) => Some(dynamic_from_py(f, d, scale_offsets.unwrap_or(index > 0))?),
            (None, None) => None,
            _ => return Err(input("give time_features and decoders together")),
        };
        if let Canon::State(c) = &canonical {
            if dynamic_gop.is_some() == c.dynamics.is_empty() {
                return Err(input(
                    "a GOP with dynamic Gaussians needs time_features and decoders (and only then)",
                ));
            }
        }
        let gop = (canonical, dynamic_gop);
        match &mut *state {
            State::Open { pending } => match self.opts.gop_count {
                Some(total) if pending.is_empty() => {
                    let mut enc = self.start(&gop, total)?;
                    push(py, &mut enc, &gop)?;
                    *state = State::Streaming {
                        enc: Box::new(enc),
                        done: 1,
                        total,
                    };
                    drop(state);
                    self.report(py, 1, total)?;
                }
                _ => pending.push(gop),
            },
            State::Streaming { enc, done, total } => {
                if *done >= *total {
                    return Err(request(format!("gop_count is {total}: no GOP left")));
                }
                push(py, enc, &gop)?;
                *done += 1;
                let (d, t) = (*done, *total);
                drop(state);
                self.report(py, d, t)?;
            }
            State::Closed => unreachable!("checked above"),
        }
        Ok(())
    }

    /// Finish the file (index, tail) and move it to `path`; returns its size in bytes.
    fn close(&self, py: Python<'_>) -> Res<u64> {
        let mut state = self.lock_state(py);
        let taken = std::mem::replace(&mut *state, State::Closed);
        drop(state);
        let enc = match taken {
            State::Closed => return Err(request("the writer is closed")),
            State::Open { pending } => {
                let Some(first) = pending.first() else {
                    return Err(request("no GOP was written"));
                };
                let total = pending.len() as u32;
                let mut enc = self.start(first, total)?;
                for (i, gop) in pending.iter().enumerate() {
                    push(py, &mut enc, gop)?;
                    self.report(py, i as u32 + 1, total)?;
                }
                enc
            }
            State::Streaming { enc, done, total } => {
                if done != total {
                    return Err(request(format!(
                        "{done} of gop_count={total} GOPs were written"
                    )));
                }
                *enc
            }
        };
        let out = py.allow_threads(|| enc.finish()).py_err()?;
        let f = out
            .into_inner()
            .map_err(|e| to_py(dlgs::Error::io("flushing", e.into_error(), 0)))?;
        let io = |e| {
            to_py(dlgs::Error::io(
                format!("writing {}", self.path.display()),
                e,
                0,
            ))
        };
        f.sync_all().map_err(io)?;
        std::fs::rename(partial(&self.path), &self.path).map_err(io)?;
        Ok(std::fs::metadata(&self.path).map_err(io)?.len())
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    /// Close on success; on an exception, drop the partial file.
    fn __exit__(
        &self,
        py: Python<'_>,
        exc_type: Option<&Bound<'_, PyAny>>,
        _exc: Option<&Bound<'_, PyAny>>,
        _tb: Option<&Bound<'_, PyAny>>,
    ) -> Res<bool> {
        if exc_type.is_none() {
            self.close(py)?;
        } else {
            *self.lock_state(py) = State::Closed;
            let _ = std::fs::remove_file(partial(&self.path));
        }
        Ok(false)
    }
}

/// Encode one still scene as `dlgs encode SCENE` does (lossy `high` by default).
pub fn encode_still(
    py: Python<'_>,
    g: &dlgs::Gaussians,
    path: PathBuf,
    cfg: EncoderConfig,
) -> Res<u64> {
    let tmp = partial(&path);
    let io = |e| to_py(dlgs::Error::io(format!("writing {}", path.display()), e, 0));
    py.allow_threads(|| {
        let f = File::create(&tmp).map_err(io)?;
        let out = dlgs_encoder::encode_still(g, cfg, BufWriter::new(f)).map_err(to_py)?;
        let f = out
            .into_inner()
            .map_err(|e| to_py(dlgs::Error::io("flushing", e.into_error(), 0)))?;
        f.sync_all().map_err(io)?;
        std::fs::rename(&tmp, &path).map_err(io)
    })?;
    Ok(std::fs::metadata(&path).map_err(io)?.len())
}
