//! A player's own HEVC decoder through `dlgs_set_hevc_decoder`: the conformance vector with
//! intra-only HEVC time features decodes through the callback (counted) to the same floats as
//! through the library's own FFmpeg, and a failing callback is a format error, not a crash.

use std::ffi::c_void;
use std::ptr;
use std::sync::atomic::{AtomicUsize, Ordering};

use dlgs_capi::*;

const VECTOR: &str = "../format-spec/vectors/valid/lod3-dynamic-intra.dlgs";

/// Forwards to FFmpeg (as a player's own decoder would to its own) and counts the calls.
unsafe extern "C" fn forward(
    user: *mut c_void,
    packets: *const *const u8,
    lens: *const usize,
    count: usize,
    width: u32,
    height: u32,
    expect: usize,
    out: *mut u16,
) -> i32 {
    // SAFETY: the library passes `count` valid packets and an output of the promised size.
    let (packets, lens) = unsafe {
        (
            std::slice::from_raw_parts(packets, count),
            std::slice::from_raw_parts(lens, count),
        )
    };
    // SAFETY: each packet pointer is valid for its length for the call.
    let refs: Vec<&[u8]> = (0..count)
        .map(|i| unsafe { std::slice::from_raw_parts(packets[i], lens[i]) })
        .collect();
    let Ok(v) = dlgs_video::decode_gray12(&refs, width, height, expect) else {
        return 1;
    };
    let side = (width * height) as usize;
    // SAFETY: `out` holds `expect * side` samples.
    let out = unsafe { std::slice::from_raw_parts_mut(out, expect * side) };
    for (k, f) in v.frames.iter().enumerate() {
        out[k * side..(k + 1) * side].copy_from_slice(f);
    }
    // SAFETY: `user` is the counter passed below.
    unsafe { &*(user as *const AtomicUsize) }.fetch_add(1, Ordering::SeqCst);
    0
}

unsafe extern "C" fn failing(
    _: *mut c_void,
    _: *const *const u8,
    _: *const usize,
    _: usize,
    _: u32,
    _: u32,
    _: usize,
    _: *mut u16,
) -> i32 {
    -5
}

fn open() -> *mut DlgsDecoder {
    let path = std::ffi::CString::new(format!("{}/{VECTOR}", env!("CARGO_MANIFEST_DIR"))).unwrap();
    let mut d = ptr::null_mut();
    // SAFETY: a valid path and out pointer.
    assert_eq!(
        unsafe { dlgs_open_path(path.as_ptr(), &mut d) },
        DlgsStatus::Ok
    );
    d
}

/// Positions of the frame at `t` (all other attributes follow the same code path).
fn positions(d: *mut DlgsDecoder, t: f64) -> Result<Vec<f32>, DlgsStatus> {
    let mut info = DlgsInfo::default();
    // SAFETY: an open decoder and a writable DlgsInfo.
    assert_eq!(unsafe { dlgs_info(d, &mut info) }, DlgsStatus::Ok);
    let n = info.n_gaussians as usize;
    let mut pos = vec![0f32; n * 3];
    let mut rot = vec![0f32; n * 4];
    let b = DlgsFrameBuffers {
        positions: pos.as_mut_ptr(),
        log_scales: ptr::null_mut(),
        rotations: rot.as_mut_ptr(),
        opacity: ptr::null_mut(),
        sh: ptr::null_mut(),
        lang_opacity: ptr::null_mut(),
        lang: ptr::null_mut(),
        capacity: n,
    };
    let mut written = 0u32;
    // SAFETY: buffers of `n` Gaussians for the attributes asked for.
    let s = unsafe { dlgs_decode_frame(d, t, [0.0f32; 3].as_ptr(), &b, &mut written) };
    if s != DlgsStatus::Ok {
        return Err(s);
    }
    pos.extend(rot);
    Ok(pos)
}

#[test]
fn a_players_hevc_decoder_gives_the_same_frames() {
    let times = [0.0, 0.5, 1.2345, 2.0, 3.95];
    let own = open();
    let want: Vec<Vec<f32>> = times.iter().map(|&t| positions(own, t).unwrap()).collect();
    let calls = AtomicUsize::new(0);
    let plugged = open();
    // SAFETY: `forward` follows the callback contract; `calls` outlives the decoder.
    let s =
        unsafe { dlgs_set_hevc_decoder(plugged, Some(forward), &calls as *const _ as *mut c_void) };
    assert_eq!(s, DlgsStatus::Ok);
    for (t, w) in times.iter().zip(&want) {
        let got = positions(plugged, *t).unwrap();
        assert!(
            got.iter().zip(w).all(|(a, b)| a.to_bits() == b.to_bits()),
            "t = {t}"
        );
    }
    assert!(
        calls.load(Ordering::SeqCst) >= 2,
        "the callback decoded the keys"
    );
    // SAFETY: open decoders, closed once.
    unsafe {
        dlgs_close(own);
        dlgs_close(plugged);
    }
}

#[test]
fn a_failing_hevc_decoder_is_a_format_error() {
    let d = open();
    // SAFETY: `failing` follows the callback contract (it ignores its arguments).
    assert_eq!(
        unsafe { dlgs_set_hevc_decoder(d, Some(failing), ptr::null_mut()) },
        DlgsStatus::Ok
    );
    assert_eq!(positions(d, 0.5), Err(DlgsStatus::Format));
    // SAFETY: NULL callback is refused, not stored.
    assert_eq!(
        unsafe { dlgs_set_hevc_decoder(d, None, ptr::null_mut()) },
        DlgsStatus::NullArgument
    );
    // SAFETY: an open decoder, closed once.
    unsafe { dlgs_close(d) };
}
