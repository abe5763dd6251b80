//! C ABI of the dlgs decoder: open a `.dlgs` stream from a path or from memory, read its
//! description, decode the Gaussians of any time t into caller-owned buffers, close. Scaffold-GS
//! files (variant 1) decode per camera with `dlgs_decode_frame_view` (module `view`).
//! The header `include/dlgs.h` is generated from this file by cbindgen.
//!
//! Conventions: every function returns a [`DlgsStatus`]; on failure the message of the last
//! error on the calling thread is available from [`dlgs_last_error`]. No Rust panic crosses
//! the boundary (it becomes `DLGS_STATUS_PANIC`). A decoder may be used from one thread at a
//! time; different decoders are independent.

use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom};
use std::panic::{catch_unwind, AssertUnwindSafe};

use dlgs::container::header::Variant;
use dlgs::model::Gaussians;
use dlgs_decoder::scaffold::ScaffoldDecoder;
use dlgs_decoder::{Decoder, FrameOptions};

mod hevc;
mod read_ahead;
mod view;
pub use hevc::{dlgs_set_hevc_decoder, DlgsHevcDecodeFn};
pub use read_ahead::{dlgs_read_ahead_hits, dlgs_set_read_ahead};
pub use view::{dlgs_decode_frame_view, DlgsView};

/// Result of every call.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DlgsStatus {
    Ok = 0,
    /// A required pointer argument was NULL.
    NullArgument = 1,
    /// The file could not be opened or read.
    Io = 2,
    /// The bytes are not a valid `.dlgs` stream (see `dlgs_last_error` for what and where).
    Format = 3,
    /// The time is outside `[0, duration]` or not finite.
    TimeOutOfRange = 4,
    /// A buffer is smaller than the frame (`capacity` < Gaussians in the frame).
    BufferTooSmall = 5,
    /// An internal error (a bug): the decoder must not be used again.
    Panic = 6,
    /// The stream's time features are HEVC and this library has no HEVC decoder (built
    /// without FFmpeg): set one with `dlgs_set_hevc_decoder`.
    NoHevcDecoder = 7,
    /// The call does not apply to the file's variant: a Scaffold-GS file (variant 1) generates
    /// its Gaussians per camera, decode it with `dlgs_decode_frame_view`.
    WrongVariant = 8,
    /// A bad argument (e.g. a camera with a zero size or a non-finite value).
    BadArgument = 9,
}

/// What a stream holds. Counts are per frame and the same for every frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct DlgsInfo {
    pub version_major: u16,
    pub version_minor: u16,
    pub gop_count: u32,
    pub gop_length: u32,
    pub frame_count: u32,
    pub fps: f64,
    /// Seconds; valid times are `0 <= t <= duration`.
    pub duration: f64,
    pub n_static: u32,
    pub n_dynamic: u32,
    /// `n_static + n_dynamic`: the size every frame buffer must hold.
    pub n_gaussians: u32,
    pub sh_degree: u32,
    /// SH coefficients per colour channel: `(sh_degree + 1)^2`.
    pub sh_coeffs: u32,
    /// Language feature width per Gaussian (0 = no language; DLGStream: 9 = 3 levels x 3).
    pub lang_width: u32,
    /// 0: 3D Gaussians (`dlgs_decode_frame`); 1: Scaffold-GS anchors, whose Gaussians are
    /// generated per camera (`dlgs_decode_frame_view`). For variant 1, `n_static` and
    /// `n_dynamic` count anchors and `n_gaussians` is the most Gaussians a frame can have
    /// (10 per anchor): a frame has as many as the camera makes visible.
    pub variant: u32,
}

/// Caller-owned output buffers for one frame, `capacity` Gaussians each. Any pointer may be
/// NULL: that attribute is not written (and language is not evaluated unless `lang` or
/// `lang_opacity` is set). Gaussians are written static set first, then the dynamic set.
/// Values are the model's own, as in an INRIA PLY: activations are left to the player.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct DlgsFrameBuffers {
    /// `capacity * 3`: x, y, z.
    pub positions: *mut f32,
    /// `capacity * 3`: natural log of the scale per axis (apply `exp`).
    pub log_scales: *mut f32,
    /// `capacity * 4`: quaternion w, x, y, z, not normalised (normalise; zero = identity).
    pub rotations: *mut f32,
    /// `capacity`: colour opacity before the sigmoid.
    pub opacity: *mut f32,
    /// `capacity * sh_coeffs * 3`: per Gaussian, per coefficient, r, g, b (coefficient 0 is
    /// the DC term `f_dc`; 1.. are `f_rest` in coefficient-major order).
    pub sh: *mut f32,
    /// `capacity`: language opacity before the sigmoid (ignored if the stream has no language).
    pub lang_opacity: *mut f32,
    /// `capacity * lang_width`: language features (ignored if the stream has no language).
    pub lang: *mut f32,
    /// How many Gaussians each buffer holds.
    pub capacity: usize,
}

/// An open stream. Opaque to C.
pub struct DlgsDecoder {
    inner: Inner,
    /// The previous frame's dynamic set, reused so playback allocates nothing per frame.
    reuse: Option<Gaussians>,
}

/// The decoder of the file's variant.
enum Inner {
    Gs(Box<Decoder<Box<dyn Source>>>),
    /// With the file's format version (the Scaffold-GS decoder does not expose its reader).
    Scaffold(Box<ScaffoldDecoder<Box<dyn Source>>>, (u16, u16)),
}

impl Inner {
    fn scene(&self) -> &dlgs::container::SceneHeader {
        match self {
            Inner::Gs(d) => d.scene(),
            Inner::Scaffold(d, _) => d.scene(),
        }
    }
}

trait Source: Read + Seek + Send {}
impl<T: Read + Seek + Send> Source for T {}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_error(msg: String) {
    let c = CString::new(msg.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

fn fail(status: DlgsStatus, msg: impl Into<String>) -> DlgsStatus {
    set_error(msg.into());
    status
}

fn format_error(e: dlgs::Error) -> DlgsStatus {
    let status = match e {
        dlgs::Error::Io(_) => DlgsStatus::Io,
        dlgs::Error::NoHevcDecoder => DlgsStatus::NoHevcDecoder,
        _ => DlgsStatus::Format,
    };
    fail(status, e.to_string())
}

/// Run `f`, turning a panic into `DLGS_STATUS_PANIC` with its message.
fn guarded(f: impl FnOnce() -> DlgsStatus) -> DlgsStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(s) => s,
        Err(p) => {
            let msg = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            fail(DlgsStatus::Panic, format!("internal error: {msg}"))
        }
    }
}

/// The decoder for the variant `src` holds.
fn open_inner(mut src: Box<dyn Source>) -> dlgs::Result<Inner> {
    let limits = dlgs::Limits::default();
    let r = dlgs::container::FileReader::open_with_limits(&mut src, limits.clone())?;
    let (variant, version) = (r.scene().variant, r.version());
    drop(r);
    src.seek(SeekFrom::Start(0))
        .map_err(|e| dlgs::Error::io("rewinding the stream", e, 0))?;
    Ok(match variant {
        Variant::Scaffold => Inner::Scaffold(Box::new(ScaffoldDecoder::new(src, limits)?), version),
        _ => Inner::Gs(Box::new(Decoder::new(src, limits)?)),
    })
}

fn open(src: Box<dyn Source>, out: *mut *mut DlgsDecoder) -> DlgsStatus {
    match open_inner(src) {
        Ok(inner) => {
            let d = Box::new(DlgsDecoder { inner, reuse: None });
            // SAFETY: `out` was checked non-NULL by the caller of `open`, and the C contract
            // is that it points to writable storage for one pointer.
            unsafe { *out = Box::into_raw(d) };
            DlgsStatus::Ok
        }
        Err(e) => format_error(e),
    }
}

/// Open a `.dlgs` file. On success `*out` receives a decoder to release with `dlgs_close`.
///
/// # Safety
/// `path` is NULL or a NUL-terminated string; `out` is NULL or writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn dlgs_open_path(
    path: *const c_char,
    out: *mut *mut DlgsDecoder,
) -> DlgsStatus {
    guarded(|| {
        if path.is_null() || out.is_null() {
            return fail(DlgsStatus::NullArgument, "path and out must not be NULL");
        }
        // SAFETY: non-NULL, and the C contract is a NUL-terminated string that stays valid
        // for the duration of the call.
        let path = unsafe { CStr::from_ptr(path) };
        let Ok(path) = path.to_str() else {
            return fail(DlgsStatus::Io, "the path is not valid UTF-8");
        };
        match File::open(path) {
            Ok(f) => open(Box::new(BufReader::new(f)), out),
            Err(e) => fail(DlgsStatus::Io, format!("{path}: {e}")),
        }
    })
}

/// Open a `.dlgs` stream held in memory. The bytes are copied: the caller may free them as
/// soon as this returns.
///
/// # Safety
/// `data` is NULL or `len` readable bytes; `out` is NULL or writable storage for one pointer.
#[no_mangle]
pub unsafe extern "C" fn dlgs_open_memory(
    data: *const u8,
    len: usize,
    out: *mut *mut DlgsDecoder,
) -> DlgsStatus {
    guarded(|| {
        if data.is_null() || out.is_null() {
            return fail(DlgsStatus::NullArgument, "data and out must not be NULL");
        }
        // SAFETY: non-NULL, and the C contract is `len` readable bytes at `data` for the
        // duration of the call; they are copied before returning.
        let bytes = unsafe { std::slice::from_raw_parts(data, len) }.to_vec();
        open(Box::new(Cursor::new(bytes)), out)
    })
}

/// Borrow the decoder behind a C pointer.
fn decoder<'a>(d: *mut DlgsDecoder) -> Option<&'a mut DlgsDecoder> {
    // SAFETY: the C contract: `d` is NULL or a pointer returned by `dlgs_open_*` and not yet
    // closed, used by one thread at a time, so no other reference to it exists.
    unsafe { d.as_mut() }
}

/// Describe the stream.
///
/// # Safety
/// `d` is NULL or an open decoder not used by another thread during the call; `out` is NULL or writable storage for one DlgsInfo.
#[no_mangle]
pub unsafe extern "C" fn dlgs_info(d: *mut DlgsDecoder, out: *mut DlgsInfo) -> DlgsStatus {
    guarded(|| {
        let Some(d) = decoder(d) else {
            return fail(DlgsStatus::NullArgument, "decoder must not be NULL");
        };
        if out.is_null() {
            return fail(DlgsStatus::NullArgument, "out must not be NULL");
        }
        let (major, minor) = match &mut d.inner {
            Inner::Gs(g) => g.reader().version(),
            Inner::Scaffold(_, v) => *v,
        };
        let s = d.inner.scene();
        let scaffold = s.variant == Variant::Scaffold;
        let n_gaussians = if scaffold {
            (s.n_static + s.n_dynamic).saturating_mul(dlgs::model::scaffold::N_OFFSETS as u32)
        } else {
            s.n_static + s.n_dynamic
        };
        let info = DlgsInfo {
            version_major: major,
            version_minor: minor,
            gop_count: s.gop_count,
            gop_length: s.gop_length,
            frame_count: s.frame_count,
            fps: s.fps(),
            duration: s.duration_seconds(),
            n_static: s.n_static,
            n_dynamic: s.n_dynamic,
            n_gaussians,
            sh_degree: s.sh_degree as u32,
            sh_coeffs: dlgs::model::sh_coeffs(s.sh_degree) as u32,
            lang_width: s.lang_width() as u32,
            variant: u32::from(scaffold),
        };
        // SAFETY: non-NULL; the C contract is writable storage for one DlgsInfo.
        unsafe { *out = info };
        DlgsStatus::Ok
    })
}

/// Copy `src` into the caller's buffer at `dst` (skipped when NULL).
fn put(dst: *mut f32, src: &[f32]) {
    if dst.is_null() {
        return;
    }
    // SAFETY: the caller checked that `capacity` covers the frame, and the C contract is
    // that a non-NULL buffer holds `capacity` times this attribute's width in floats, so
    // `src.len()` floats are writable at `dst`; the regions cannot overlap Rust memory.
    unsafe { std::ptr::copy_nonoverlapping(src.as_ptr(), dst, src.len()) };
}

/// Decode the Gaussians shown at time `t` seconds (any time in `[0, duration]`, between
/// frames included) into `buffers`. `camera_center` (3 floats, may be NULL = origin) is the
/// viewpoint for view-dependent decoders. `*written` (may be NULL) receives the count.
///
/// # Safety
/// `d` is NULL or an open decoder not used by another thread during the call; `camera_center` is NULL or three readable floats; `buffers` is NULL or a DlgsFrameBuffers whose non-NULL pointers hold `capacity` Gaussians of their attribute; `written` is NULL or writable storage for one uint32_t.
#[no_mangle]
pub unsafe extern "C" fn dlgs_decode_frame(
    d: *mut DlgsDecoder,
    t: f64,
    camera_center: *const f32,
    buffers: *const DlgsFrameBuffers,
    written: *mut u32,
) -> DlgsStatus {
    guarded(|| {
        let Some(d) = decoder(d) else {
            return fail(DlgsStatus::NullArgument, "decoder must not be NULL");
        };
        // SAFETY: NULL or, by the C contract, a valid DlgsFrameBuffers for the call.
        let Some(b) = (unsafe { buffers.as_ref() }) else {
            return fail(DlgsStatus::NullArgument, "buffers must not be NULL");
        };
        let centre = if camera_center.is_null() {
            [0.0; 3]
        } else {
            // SAFETY: non-NULL; the C contract is three readable floats.
            unsafe { std::slice::from_raw_parts(camera_center, 3) }
                .try_into()
                .expect("three floats")
        };
        decode_gs(d, t, centre, b, written)
    })
}

/// `dlgs_decode_frame` of a 3DGS file (also `dlgs_decode_frame_view`'s).
fn decode_gs(
    d: &mut DlgsDecoder,
    t: f64,
    centre: [f32; 3],
    b: &DlgsFrameBuffers,
    written: *mut u32,
) -> DlgsStatus {
    {
        let Inner::Gs(dec) = &mut d.inner else {
            return fail(
                DlgsStatus::WrongVariant,
                "a Scaffold-GS file (variant 1): its Gaussians are generated per camera; \
                 decode them with dlgs_decode_frame_view",
            );
        };
        let scene = dec.scene();
        let n = (scene.n_static + scene.n_dynamic) as usize;
        if b.capacity < n {
            return fail(
                DlgsStatus::BufferTooSmall,
                format!("buffers hold {} Gaussians, the frame has {n}", b.capacity),
            );
        }
        if !(t.is_finite() && (0.0..=scene.duration_seconds()).contains(&t)) {
            return fail(
                DlgsStatus::TimeOutOfRange,
                format!("t = {t} is outside [0, {}] s", scene.duration_seconds()),
            );
        }
        let has_lang = scene.lang_width() > 0;
        let opts = FrameOptions {
            camera_center: centre,
            language: has_lang && !(b.lang.is_null() && b.lang_opacity.is_null()),
        };
        let reuse = d.reuse.take().unwrap_or_default();
        let frame = match dec.frame_at_reusing(t, &opts, reuse) {
            Ok(f) => f,
            Err(e) => return format_error(e),
        };
        let (st, dy) = (frame.statics(), &frame.dynamics);
        write_part(b, st, 0, has_lang);
        write_part(b, dy, st.len(), has_lang);
        d.reuse = Some(frame.dynamics);
        set_written(written, n);
        DlgsStatus::Ok
    }
}

/// Copy `part` into rows `at..` of the caller's buffers (the NULL ones skipped).
fn write_part(b: &DlgsFrameBuffers, part: &Gaussians, at: usize, has_lang: bool) {
    let offset = |w: usize, p: *mut f32| {
        if p.is_null() {
            p
        } else {
            p.wrapping_add(at * w)
        }
    };
    put(offset(3, b.positions), part.positions.as_flattened());
    put(offset(3, b.log_scales), part.log_scales.as_flattened());
    put(offset(4, b.rotations), part.rotations.as_flattened());
    put(offset(1, b.opacity), &part.opacity);
    put(offset(part.sh_stride(), b.sh), &part.sh);
    if has_lang {
        put(offset(1, b.lang_opacity), &part.lang_opacity);
        put(offset(part.lang_width, b.lang), &part.lang);
    }
}

fn set_written(written: *mut u32, n: usize) {
    if !written.is_null() {
        // SAFETY: non-NULL; the C contract is writable storage for one u32.
        unsafe { *written = n as u32 };
    }
}

/// The message of the last failed call on this thread ("" if none). Valid until the next
/// call on this thread; do not free.
#[no_mangle]
pub extern "C" fn dlgs_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// A static name for a status code, e.g. "DLGS_STATUS_FORMAT" ("unknown status" for values
/// that are not a DlgsStatus; taken as an int so any value is safe to pass).
#[no_mangle]
pub extern "C" fn dlgs_status_name(status: i32) -> *const c_char {
    let s: &'static CStr = match status {
        0 => c"DLGS_STATUS_OK",
        1 => c"DLGS_STATUS_NULL_ARGUMENT",
        2 => c"DLGS_STATUS_IO",
        3 => c"DLGS_STATUS_FORMAT",
        4 => c"DLGS_STATUS_TIME_OUT_OF_RANGE",
        5 => c"DLGS_STATUS_BUFFER_TOO_SMALL",
        6 => c"DLGS_STATUS_PANIC",
        7 => c"DLGS_STATUS_NO_HEVC_DECODER",
        8 => c"DLGS_STATUS_WRONG_VARIANT",
        9 => c"DLGS_STATUS_BAD_ARGUMENT",
        _ => c"unknown status",
    };
    s.as_ptr()
}

/// Release a decoder (NULL is ignored).
///
/// # Safety
/// `d` is NULL or a decoder from `dlgs_open_*` that is not used after this call.
#[no_mangle]
pub unsafe extern "C" fn dlgs_close(d: *mut DlgsDecoder) {
    if d.is_null() {
        return;
    }
    // SAFETY: the C contract: `d` came from `dlgs_open_*` and is closed once; ownership
    // returns to Rust here and the box is dropped.
    let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(d) })));
}

/// The library version, e.g. "0.1.0".
#[no_mangle]
pub extern "C" fn dlgs_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}
