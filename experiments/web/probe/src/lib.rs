//! C-ABI probe: JS copies a .dlgs file into wasm memory (`alloc`), calls `digests` or
//! `frames`, then reads `out_ptr()/out_len()`. Panic messages go to the imported `env.log`.
use std::io::Cursor;

#[link(wasm_import_module = "env")]
extern "C" {
    fn log(ptr: *const u8, len: usize);
}

fn js_log(s: &str) {
    unsafe { log(s.as_ptr(), s.len()) }
}

static mut OUT: Vec<u8> = Vec::new();

fn set_out(v: Vec<u8>) {
    unsafe { OUT = v }
}

#[no_mangle]
pub extern "C" fn init() {
    std::panic::set_hook(Box::new(|info| js_log(&format!("panic: {info}"))));
}

#[no_mangle]
pub extern "C" fn alloc(len: usize) -> *mut u8 {
    let mut v = Vec::<u8>::with_capacity(len);
    let p = v.as_mut_ptr();
    std::mem::forget(v);
    p
}

#[no_mangle]
pub extern "C" fn dealloc(ptr: *mut u8, len: usize) {
    unsafe { drop(Vec::from_raw_parts(ptr, 0, len)) }
}

#[no_mangle]
pub extern "C" fn out_ptr() -> *const u8 {
    unsafe { (*std::ptr::addr_of!(OUT)).as_ptr() }
}

#[no_mangle]
pub extern "C" fn out_len() -> usize {
    unsafe { (*std::ptr::addr_of!(OUT)).len() }
}

fn input<'a>(ptr: *const u8, len: usize) -> &'a [u8] {
    unsafe { std::slice::from_raw_parts(ptr, len) }
}

/// mode 0: random access (Decoder::gop_canonical), mode 1: in-order StreamDecoder.
/// Output: one canonical sha256 per GOP, space separated; or "ERR <error>". Returns 0 on Ok.
#[no_mangle]
pub extern "C" fn digests(ptr: *const u8, len: usize, mode: u32) -> i32 {
    let bytes = input(ptr, len);
    let r: dlgs::Result<Vec<String>> = (|| {
        let mut out = Vec::new();
        if mode == 0 {
            let mut dec = dlgs_decoder::Decoder::new(Cursor::new(bytes), dlgs::Limits::default())?;
            for g in 0..dec.scene().gop_count {
                out.push(dlgs::chunks::craw::canonical_digest(&*dec.gop_canonical(g)?));
            }
        } else {
            let mut dec = dlgs_decoder::stream::StreamDecoder::with_limits(bytes, dlgs::Limits::default())?;
            while let Some(g) = dec.next_gop()? {
                out.push(dlgs::chunks::craw::canonical_digest(&g.canonical));
            }
        }
        Ok(out)
    })();
    match r {
        Ok(v) => {
            set_out(v.join(" ").into_bytes());
            0
        }
        Err(e) => {
            set_out(format!("ERR {} {e}", e.name()).into_bytes());
            1
        }
    }
}

/// The dynamic Gaussians at the conformance times (tests/src/vectors/dynamic.rs), f32 LE.
#[no_mangle]
pub extern "C" fn frames(ptr: *const u8, len: usize) -> i32 {
    const TIMES: [f64; 5] = [0.0, 0.5, 1.2345, 2.0, 3.95];
    let bytes = input(ptr, len);
    let r: dlgs::Result<Vec<f32>> = (|| {
        let mut dec = dlgs_decoder::Decoder::new(Cursor::new(bytes), dlgs::Limits::default())?;
        dec.set_read_ahead(false);
        let opts = dlgs_decoder::FrameOptions { camera_center: [0.3, -0.2, -2.5], language: true };
        let mut out = Vec::new();
        for t in TIMES {
            let g = dec.frame_at(t, &opts)?.dynamics;
            out.extend(g.positions.iter().flatten());
            out.extend(g.log_scales.iter().flatten());
            out.extend(g.rotations.iter().flatten());
            out.extend(&g.opacity);
            out.extend(&g.lang_opacity);
            out.extend(&g.sh);
            out.extend(&g.lang);
        }
        Ok(out)
    })();
    match r {
        Ok(v) => {
            set_out(v.iter().flat_map(|x| x.to_le_bytes()).collect());
            0
        }
        Err(e) => {
            set_out(format!("ERR {e}").into_bytes());
            1
        }
    }
}
