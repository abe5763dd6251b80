//! `dlgs.open(...)`: a `.dlgs` stream opened for frames, renders, queries and GOPs. The
//! decoder sits behind a mutex so that every long call releases the GIL; two readers decode in
//! parallel, two threads on one reader take turns.

use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek};
use std::sync::{Mutex, MutexGuard};

use dlgs::container::SceneHeader;
use dlgs::model::lang_decoder::LangDecoder;
use dlgs::Gaussians;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_render::Camera;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

use crate::arrays::{gaussians_to_dict, owned_array, read_f32};
use crate::camera;
use crate::errors::{request, to_py, IntoPy, Res};
use crate::gop_dict::gop_to_dict;
use crate::scaffold::{self, ScaffoldDec};
use crate::timing::since_epoch;
use crate::view::{self, QueryParams};

pub trait Source: Read + Seek + Send {}
impl<T: Read + Seek + Send> Source for T {}

type Dec = Decoder<Box<dyn Source>>;

/// An open `.dlgs` stream (see `dlgs.open`).
#[pyclass(module = "dlgs._dlgs", name = "Reader", frozen)]
pub struct Reader {
    /// The decoder of a 3DGS file (variant 0); `None` for a Scaffold-GS file.
    dec: Option<Mutex<Dec>>,
    /// The decoder of a Scaffold-GS file (variant 1), whose frames need a camera.
    pub(crate) sdec: Option<Mutex<ScaffoldDec>>,
    pub(crate) scene: SceneHeader,
    version: (u16, u16),
    /// The static set of the last GOP asked for with `split=True`, shared between frames.
    statics: Mutex<Option<(u32, Py<PyDict>)>>,
    /// This reader's own worker threads (`open(..., threads=N)`); `None`: the global pool.
    pool: Option<rayon::ThreadPool>,
    /// The default orbit of the last GOP a camera index was resolved in.
    orbit: Mutex<Option<(u32, Vec<Camera>)>>,
    /// The arrays of the last merged frames, decoded into again once Python lets go of them.
    pub(crate) recycler: crate::recycle::Recycler,
}

pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic inside the decoder poisons the lock; its state is still a valid decoder.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

pub(crate) const SCAFFOLD_ONLY_FRAMES: &str = "a Scaffold-GS file (variant 1) has no canonical \
     static/dynamic Gaussians: its Gaussians are generated per camera (frame(t, camera=...))";

/// Open a path (str or os.PathLike) or bytes-like object.
#[pyfunction]
#[pyo3(name = "open", signature = (source, threads=None, read_ahead=true))]
pub fn open_reader(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    threads: Option<usize>,
    read_ahead: bool,
) -> Res<Reader> {
    let src: Box<dyn Source> = if let Ok(b) = source.downcast::<PyBytes>() {
        Box::new(Cursor::new(b.as_bytes().to_vec()))
    } else if let Ok(path) = source.extract::<std::path::PathBuf>() {
        let f = File::open(&path)
            .map_err(|e| to_py(dlgs::Error::io(format!("opening {}", path.display()), e, 0)))?;
        Box::new(BufReader::new(f))
    } else {
        // bytearray, memoryview, numpy uint8 arrays: anything `bytes()` takes.
        let b: Vec<u8> = py
            .import("builtins")?
            .getattr("bytes")?
            .call1((source,))
            .map_err(|_| request("open: expected a path or a bytes-like object"))?
            .extract()?;
        Box::new(Cursor::new(b))
    };
    let (dec, sdec, scene, version) = py
        .allow_threads(|| {
            let mut src = src;
            let limits = dlgs::Limits::default();
            let (is_scaffold, version) = scaffold::sniff(&mut src, &limits)?;
            if is_scaffold {
                let d = ScaffoldDec::new(src, limits)?;
                let scene = d.scene().clone();
                Ok((None, Some(Mutex::new(d)), scene, version))
            } else {
                let mut d = Decoder::new(src, limits)?;
                d.set_read_ahead(read_ahead);
                let scene = d.scene().clone();
                let version = d.reader().version();
                Ok((Some(Mutex::new(d)), None, scene, version))
            }
        })
        .py_err()?;
    Ok(Reader {
        dec,
        sdec,
        scene,
        version,
        statics: Mutex::new(None),
        orbit: Mutex::new(None),
        recycler: Default::default(),
        pool: match threads {
            None => None,
            Some(n) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n.max(1))
                    .build()
                    .map_err(|e| request(format!("threads={n}: {e}")))?,
            ),
        },
    })
}

fn gaussians_at(
    dec: &mut Dec,
    t: f64,
    centre: [f32; 3],
    language: bool,
) -> dlgs::Result<Gaussians> {
    dec.frame_at_merged(
        t,
        &FrameOptions {
            camera_center: centre,
            language,
        },
    )
}

impl Reader {
    /// The 3DGS decoder; a request error for a Scaffold-GS file.
    pub(crate) fn dec(&self) -> dlgs::Result<MutexGuard<'_, Dec>> {
        match &self.dec {
            Some(d) => Ok(lock(d)),
            None => Err(dlgs::Error::request(SCAFFOLD_ONLY_FRAMES)),
        }
    }

    pub fn is_scaffold(&self) -> bool {
        self.sdec.is_some()
    }

    /// The Gaussians at `t` as `camera` sees them (static then dynamic; for a Scaffold-GS
    /// file the neural Gaussians as 3D Gaussians, only the anchors in view with `cull`).
    /// Called without the GIL.
    fn gaussians_for(
        &self,
        t: f64,
        camera: &Camera,
        language: bool,
        cull: bool,
    ) -> dlgs::Result<Gaussians> {
        match &self.sdec {
            Some(s) => {
                Ok(scaffold::neural_at(&mut lock(s), t, camera, language, cull)?.to_gaussians())
            }
            None => gaussians_at(&mut *self.dec()?, t, camera.position.to_array(), language),
        }
    }

    /// Run `f` without the GIL, on this reader's pool when it has one.
    pub(crate) fn detach<T: Send>(&self, py: Python<'_>, f: impl FnOnce() -> T + Send) -> T {
        py.allow_threads(|| match &self.pool {
            Some(p) => p.install(f),
            None => f(),
        })
    }

    /// The 8 orbit views `dlgs render` places around the GOP shown at `t` (cached per GOP:
    /// placing them takes medians over the canonical Gaussians).
    fn default_orbit(&self, py: Python<'_>, t: f64) -> Res<Vec<Camera>> {
        let gop = self.scene.locate(t).py_err()?.gop;
        // Not held while the GIL is released below (a thread waiting for it with the GIL
        // would keep this one from taking the GIL back).
        if let Some((g, cams)) = self
            .orbit
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .as_ref()
        {
            if *g == gop {
                return Ok(cams.clone());
            }
        }
        let g = self.canonical(py, t)?;
        let cams = camera::orbit(&g, 8, 1352, 1014);
        *self.orbit.lock().unwrap_or_else(|e| e.into_inner()) = Some((gop, cams.clone()));
        Ok(cams)
    }

    /// The undeformed Gaussians of the GOP shown at `t` (for a Scaffold-GS file, its anchors
    /// at `t` as stand-ins, as the CLI places its orbit around them).
    pub fn canonical(&self, py: Python<'_>, t: f64) -> Res<Gaussians> {
        self.detach(py, || {
            if let Some(s) = &self.sdec {
                return scaffold::anchor_stand_ins(&mut lock(s), t);
            }
            let mut d = self.dec()?;
            let gop = d.scene().locate(t)?.gop;
            Ok(d.gop_canonical(gop)?.merged())
        })
        .py_err()
    }

    pub(crate) fn resolve(
        &self,
        py: Python<'_>,
        cam: &Bound<'_, PyAny>,
        t: f64,
        width: Option<u32>,
        height: Option<u32>,
    ) -> Res<Camera> {
        camera::resolve(cam, width, height, || self.default_orbit(py, t))
    }

    /// The Gaussians at `t` (static then dynamic) seen by `camera` (every anchor of a
    /// Scaffold-GS file decoded).
    pub fn gaussians(
        &self,
        py: Python<'_>,
        t: f64,
        camera: &Camera,
        language: bool,
    ) -> Res<Gaussians> {
        self.detach(py, || self.gaussians_for(t, camera, language, false))
            .py_err()
    }

    /// The frame at `t` as one dict (static then dynamic) or split.
    pub fn frame_impl<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        centre: [f32; 3],
        language: bool,
        split: bool,
    ) -> Res<Bound<'py, PyDict>> {
        let opts = FrameOptions {
            camera_center: centre,
            language: language && self.scene.lang_width() > 0,
        };
        if !split {
            // Into the arrays of an earlier frame Python has released, if any (warm memory:
            // the static rows copied, the dynamic rows decoded in place) ...
            if let Some(d) = self.decode_into_free(py, t, &opts)? {
                return Ok(d);
            }
            // ... else the static set is copied once into new merged buffers and the dynamic
            // set is decoded straight into their tail; numpy then takes the buffers over.
            let g = self
                .detach(py, || self.dec()?.frame_at_merged(t, &opts))
                .py_err()?;
            let d = gaussians_to_dict(py, g)?;
            self.recycler.remember(&d)?;
            return Ok(d);
        }
        let frame = self
            .detach(py, || self.dec()?.frame_at(t, &opts))
            .py_err()?;
        let gop = frame.time.gop;
        // The lock is never held while Python runs (another thread could then wait for it
        // holding the GIL).
        let cached = {
            let cache = self.statics.lock().unwrap_or_else(|e| e.into_inner());
            match cache.as_ref() {
                Some((g, d)) if *g == gop => Some(d.clone_ref(py)),
                _ => None,
            }
        };
        let statics = match cached {
            Some(d) => d.into_bound(py),
            None => {
                let d = gaussians_to_dict(py, frame.statics().clone())?;
                for v in d.values() {
                    v.call_method1("setflags", (false,))?;
                }
                let keep = d.clone().unbind();
                *self.statics.lock().unwrap_or_else(|e| e.into_inner()) = Some((gop, keep));
                d
            }
        };
        let out = PyDict::new(py);
        out.set_item("static", statics)?;
        out.set_item("dynamic", gaussians_to_dict(py, frame.dynamics)?)?;
        Ok(out)
    }
}

fn centre_of(
    reader: &Reader,
    py: Python<'_>,
    t: f64,
    cam: Option<&Bound<'_, PyAny>>,
) -> Res<[f32; 3]> {
    match cam {
        None => Ok([0.0; 3]),
        Some(c) => Ok(reader.resolve(py, c, t, None, None)?.position.to_array()),
    }
}

#[pymethods]
impl Reader {
    /// What the stream holds: GOPs, frames, fps, counts, SH degree, language, variant.
    #[getter]
    fn info<'py>(&self, py: Python<'py>) -> Res<Bound<'py, PyDict>> {
        let s = &self.scene;
        let d = PyDict::new(py);
        d.set_item("version", format!("{}.{}", self.version.0, self.version.1))?;
        d.set_item("gop_count", s.gop_count)?;
        d.set_item("gop_length", s.gop_length)?;
        d.set_item("key_interval", s.key_interval)?;
        d.set_item("frame_count", s.frame_count)?;
        d.set_item("fps", s.fps())?;
        d.set_item("duration", s.duration_seconds())?;
        d.set_item("n_static", s.n_static)?;
        d.set_item("n_dynamic", s.n_dynamic)?;
        d.set_item("n_gaussians", s.n_static + s.n_dynamic)?;
        d.set_item("sh_degree", s.sh_degree)?;
        d.set_item("lang_levels", s.lang_levels)?;
        d.set_item("lang_dims", s.lang_dims)?;
        d.set_item("lang_width", s.lang_width())?;
        d.set_item("language", s.lang_width() > 0)?;
        d.set_item("time_channels", s.time_channels)?;
        d.set_item(
            "variant",
            match s.variant {
                dlgs::container::header::Variant::Scaffold => "scaffold",
                _ => "3dgs",
            },
        )?;
        d.set_item("residual_mode", format!("{:?}", s.residual_mode))?;
        d.set_item("deform_model", format!("{:?}", s.deform_model))?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let s = &self.scene;
        format!(
            "<dlgs.Reader {} GOPs x {} frames at {} fps, {} static + {} dynamic, SH {}, language {}>",
            s.gop_count,
            s.gop_length,
            s.fps(),
            s.n_static,
            s.n_dynamic,
            s.sh_degree,
            s.lang_width()
        )
    }

    /// Frames in the stream.
    fn __len__(&self) -> usize {
        self.scene.frame_count as usize
    }

    /// The Gaussians shown at time `t` seconds (between frames too). A Scaffold-GS file
    /// needs `camera`; `cull` then decodes only the anchors in its view, `neural` returns the
    /// MLP outputs as they are (see docs/python.md).
    #[pyo3(signature = (t, camera=None, language=false, split=false, cull=false, neural=false))]
    fn frame<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        camera: Option<&Bound<'py, PyAny>>,
        language: bool,
        split: bool,
        cull: bool,
        neural: bool,
    ) -> Res<Bound<'py, PyDict>> {
        if self.is_scaffold() {
            return self.scaffold_frame(py, t, camera, language, split, cull, neural);
        }
        if cull || neural {
            return Err(request(
                "cull and neural are for Scaffold-GS files (variant 1); this one is 3DGS",
            ));
        }
        let centre = centre_of(self, py, t, camera)?;
        self.frame_impl(py, t, centre, language, split)
    }

    /// Render the frame at `t` from `camera`: HxWx3 float32, and HxWxL features when asked.
    /// `cull` (Scaffold-GS files): decode only the anchors whose children reach into the
    /// view (the same image, less time; `dlgs render` without `--no-cull`). `fast`: the
    /// renderer's faster compositing (`--fast-render`; at least 60 dB from the exact image).
    #[pyo3(signature = (t, camera, width=None, height=None, features=false, background=(1.0, 1.0, 1.0), cull=true, fast=false))]
    fn render<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        camera: &Bound<'py, PyAny>,
        width: Option<u32>,
        height: Option<u32>,
        features: bool,
        background: (f32, f32, f32),
        cull: bool,
        fast: bool,
    ) -> Res<Bound<'py, PyAny>> {
        let cam = self.resolve(py, camera, t, width, height)?;
        let bg = [background.0, background.1, background.2];
        let img = self.detach(py, || {
            let g = self.gaussians_for(t, &cam, features, cull).map_err(to_py)?;
            view::render_arrays(&g, &cam, features, bg, fast)
        })?;
        let color = owned_array(py, img.color, &[img.height, img.width, 3])?;
        match img.features {
            None => Ok(color),
            Some((f, lw)) => {
                let feats = owned_array(py, f, &[img.height, img.width, lw])?;
                Ok((color, feats).into_pyobject(py)?.into_any())
            }
        }
    }

    /// Open-vocabulary query of the frame at `t` seen from `camera`.
    #[pyo3(signature = (text_embedding, t, camera, width=None, height=None, negatives=None,
        lang_decoder=None, threshold=0.4, mean_kernel=29, smooth_kernel=7, min_score=0.5,
        level=None, temperature=10.0, exact=false))]
    fn query<'py>(
        &self,
        py: Python<'py>,
        text_embedding: &Bound<'py, PyAny>,
        t: f64,
        camera: &Bound<'py, PyAny>,
        width: Option<u32>,
        height: Option<u32>,
        negatives: Option<&Bound<'py, PyAny>>,
        lang_decoder: Option<std::path::PathBuf>,
        threshold: f32,
        mean_kernel: usize,
        smooth_kernel: usize,
        min_score: f32,
        level: Option<usize>,
        temperature: f32,
        exact: bool,
    ) -> Res<Bound<'py, PyAny>> {
        if self.scene.lang_levels == 0 {
            return Err(request("the stream has no language features"));
        }
        let cam = self.resolve(py, camera, t, width, height)?;
        let (pv, ps) = read_f32(text_embedding, "text_embedding")?;
        let single = ps.len() == 1;
        let positives = view::embeddings(pv, &ps, "text_embedding")?;
        let dec: LangDecoder = match lang_decoder {
            Some(p) => {
                dlgs_query::decoder_io::load_lang_decoder(&p).map_err(crate::errors::other)?
            }
            None => self
                .detach(py, || match self.is_scaffold() {
                    // The Scaffold-GS decoder reads no LAED chunk (the HAC ingest writes none).
                    true => Ok(None),
                    false => self.dec()?.lang_decoder(),
                })
                .py_err()?
                .ok_or_else(|| {
                    request("the stream has no language decoder (LAED): pass lang_decoder")
                })?,
        };
        let negatives = match negatives {
            Some(n) => {
                let (v, s) = read_f32(n, "negatives")?;
                view::embeddings(v, &s, "negatives")?
            }
            None if !dec.negatives.is_empty() => {
                dlgs_query::Embeddings::from_named(&dec.negatives).map_err(request)?
            }
            None => {
                return Err(request(
                    "no negatives: the language decoder stores none, pass negatives",
                ))
            }
        };
        let params = QueryParams {
            threshold,
            mean_kernel,
            smooth_kernel,
            min_score,
            level,
            temperature,
            exact,
        };
        let shape = (
            self.scene.lang_levels as usize,
            self.scene.lang_dims as usize,
        );
        let answers = self.detach(py, || {
            // Scaffold-GS: only the anchors in view (the same image).
            let g = self.gaussians_for(t, &cam, true, true).map_err(to_py)?;
            view::query_arrays(&g, &cam, &dec, &positives, &negatives, shape, &params)
        })?;
        let list = view::answers_to_list(py, answers)?;
        if single {
            Ok(list.get_item(0)?)
        } else {
            Ok(list.into_any())
        }
    }

    /// GOP `g` as a trained model holds it: canonical static and dynamic sets, key time
    /// features (N_dyn, K, 16) and decoder weights (what `Writer.write_gop` takes).
    fn gop<'py>(&self, py: Python<'py>, g: u32) -> Res<Bound<'py, PyDict>> {
        let (gop, dynamic) = self
            .detach(py, || {
                let gop = self.dec()?.gop(g)?;
                let dynamic = gop.dynamic()?;
                Ok((gop, dynamic))
            })
            .py_err()?;
        gop_to_dict(py, &gop.canonical, dynamic, gop.ntc.as_deref())
    }

    /// The orbit cameras `dlgs render`/`dlgs cameras` place around the scene at `t`, as 3DGS
    /// cameras.json entries.
    #[pyo3(signature = (count=8, width=1352, height=1014, t=0.0))]
    fn cameras<'py>(
        &self,
        py: Python<'py>,
        count: usize,
        width: u32,
        height: u32,
        t: f64,
    ) -> Res<Bound<'py, PyList>> {
        let g = self.canonical(py, t)?;
        let cams = camera::orbit(&g, count, width, height);
        let list = PyList::empty(py);
        for (i, c) in cams.iter().enumerate() {
            list.append(camera::to_json_entry(py, i, c)?)?;
        }
        Ok(list)
    }

    /// Seconds each `frame_at(t)` of the Rust decoder takes for `times` (new buffers, no
    /// merge, no numpy: the baseline `frame` is measured against; see docs/benchmarks/python.md).
    #[pyo3(signature = (times, language=false))]
    fn time_frame_at(&self, py: Python<'_>, times: Vec<f64>, language: bool) -> Res<Vec<f64>> {
        self.detach(py, || self.time_frames(&times, language))
            .py_err()
    }

    /// As [`Self::time_frame_at`], and when the decoding ran: seconds on a clock shared by
    /// every thread of the process, read inside the call with the GIL released (the threads
    /// test checks that two threads' calls overlap).
    #[pyo3(signature = (times, language=false))]
    fn time_frame_span(
        &self,
        py: Python<'_>,
        times: Vec<f64>,
        language: bool,
    ) -> Res<(f64, f64, Vec<f64>)> {
        since_epoch();
        self.detach(py, || {
            let start = since_epoch();
            let each = self.time_frames(&times, language)?;
            Ok((start, since_epoch(), each))
        })
        .py_err()
    }

    /// Iterate over `(t, frame)` for every frame of the stream.
    fn __iter__(slf: Py<Self>, py: Python<'_>) -> FrameIter {
        let end = slf.get().scene.frame_count;
        let _ = py;
        FrameIter {
            reader: slf,
            next: 0,
            end,
        }
    }
}

/// Iterator over the frames of a [`Reader`].
#[pyclass(module = "dlgs._dlgs")]
pub struct FrameIter {
    reader: Py<Reader>,
    next: u32,
    end: u32,
}

#[pymethods]
impl FrameIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }
    fn __next__<'py>(&mut self, py: Python<'py>) -> Res<Option<(f64, Bound<'py, PyDict>)>> {
        if self.next >= self.end {
            return Ok(None);
        }
        let r = self.reader.get();
        let t = self.next as f64 / r.scene.fps();
        self.next += 1;
        Ok(Some((t, r.frame_impl(py, t, [0.0; 3], false, false)?)))
    }
}
