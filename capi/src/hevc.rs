//! A player's own HEVC decoder for the time features, plugged in through a C callback (the
//! seam that lets a library built without FFmpeg, `--no-default-features`, decode HEVC
//! streams with an LGPL or hardware decoder of the player's choice).

use std::ffi::c_void;
use std::sync::Arc;

use dlgs_decoder::KeyPictureDecoder;

use crate::{decoder, fail, guarded, DlgsDecoder, DlgsStatus};

/// Decodes `packet_count` HEVC Main 12 4:0:0 access units (`packets[i]` of `packet_lens[i]`
/// bytes, in decode order) into exactly `expect` pictures of `width` x `height` 12-bit samples,
/// written row-major, picture after picture, into `out` (`expect * width * height` values).
/// Returns 0 on success, anything else on failure (the frame decode then fails with
/// `DLGS_STATUS_FORMAT`). May be called from any thread, also concurrently.
pub type DlgsHevcDecodeFn = Option<
    unsafe extern "C" fn(
        user: *mut c_void,
        packets: *const *const u8,
        packet_lens: *const usize,
        packet_count: usize,
        width: u32,
        height: u32,
        expect: usize,
        out: *mut u16,
    ) -> i32,
>;

struct Callback {
    f: unsafe extern "C" fn(
        *mut c_void,
        *const *const u8,
        *const usize,
        usize,
        u32,
        u32,
        usize,
        *mut u16,
    ) -> i32,
    user: *mut c_void,
}

// SAFETY: `user` is only handed back to the player's callback, which the C contract of
// `dlgs_set_hevc_decoder` requires to be callable from any thread, also concurrently.
unsafe impl Send for Callback {}
// SAFETY: as above; `Callback` itself holds no interior state.
unsafe impl Sync for Callback {}

impl KeyPictureDecoder for Callback {
    fn decode(
        &self,
        packets: &[&[u8]],
        width: u32,
        height: u32,
        expect: usize,
    ) -> Result<Vec<Vec<u16>>, String> {
        let side = width as usize * height as usize;
        let mut out = vec![0u16; side * expect];
        let ptrs: Vec<*const u8> = packets.iter().map(|p| p.as_ptr()).collect();
        let lens: Vec<usize> = packets.iter().map(|p| p.len()).collect();
        // SAFETY: every pointer is valid for the call: `ptrs[i]` points to `lens[i]` bytes,
        // `out` to `expect * width * height` writable samples, as the callback's contract says.
        let rc = unsafe {
            (self.f)(
                self.user,
                ptrs.as_ptr(),
                lens.as_ptr(),
                packets.len(),
                width,
                height,
                expect,
                out.as_mut_ptr(),
            )
        };
        if rc != 0 {
            return Err(format!("the player's HEVC decoder returned {rc}"));
        }
        // The decoder checks the pictures' count, size and 12-bit range for every key-picture
        // decoder alike (`dlgs-decoder`'s `build::key_pictures`).
        Ok(out.chunks_exact(side.max(1)).map(<[u16]>::to_vec).collect())
    }
}

/// Decode the stream's HEVC time features with `decode` (called with `user`) instead of the
/// library's own decoder (FFmpeg, in builds with it). In a library built without FFmpeg this is
/// how a player decodes files whose time features are HEVC; files with exact time features and
/// still files need no HEVC decoder. GOPs already decoded are decoded again when next needed.
///
/// # Safety
/// `d` is NULL or an open decoder not used by another thread during the call; `decode` is
/// NULL or a function that follows `DlgsHevcDecodeFn`'s contract with `user` for as long as
/// the decoder is open.
#[no_mangle]
pub unsafe extern "C" fn dlgs_set_hevc_decoder(
    d: *mut DlgsDecoder,
    decode: DlgsHevcDecodeFn,
    user: *mut c_void,
) -> DlgsStatus {
    guarded(|| {
        let (Some(d), Some(f)) = (decoder(d), decode) else {
            return fail(
                DlgsStatus::NullArgument,
                "decoder and decode must not be NULL",
            );
        };
        let cb = Arc::new(Callback { f, user });
        match &mut d.inner {
            crate::Inner::Gs(dec) => dec.set_key_picture_decoder(cb),
            crate::Inner::Scaffold(dec, _) => dec.set_key_picture_decoder(cb),
        }
        DlgsStatus::Ok
    })
}
