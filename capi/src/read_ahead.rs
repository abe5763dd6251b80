//! Read-ahead control: while a player asks for frames in time order, the decoder decodes the
//! next GOP on a thread of its own (on by default; `dlgs_decoder::Decoder::set_read_ahead`).

use crate::{decoder, fail, guarded, DlgsDecoder, DlgsStatus, Inner};

/// Turn read-ahead on (`enabled` non-zero, the default) or off. With it on, once two frames
/// of a GOP have been asked for in time order, the next GOP is decoded on a background thread
/// (one GOP of extra memory), so playback does not stall at GOP boundaries; frames are the
/// same bits either way. Scaffold-GS files (variant 1) decode without read-ahead: the call
/// succeeds and changes nothing.
///
/// # Safety
/// `d` is NULL or an open decoder not used by another thread during the call.
#[no_mangle]
pub unsafe extern "C" fn dlgs_set_read_ahead(d: *mut DlgsDecoder, enabled: i32) -> DlgsStatus {
    guarded(|| {
        let Some(d) = decoder(d) else {
            return fail(DlgsStatus::NullArgument, "decoder must not be NULL");
        };
        if let Inner::Gs(dec) = &mut d.inner {
            dec.set_read_ahead(enabled != 0);
        }
        DlgsStatus::Ok
    })
}

/// `*hits` receives how many GOPs were taken ready from the read-ahead thread since the
/// decoder was opened or `dlgs_set_read_ahead` was last called (0 for Scaffold-GS files).
///
/// # Safety
/// `d` is NULL or an open decoder not used by another thread during the call; `hits` is
/// NULL or writable storage for one uint64_t.
#[no_mangle]
pub unsafe extern "C" fn dlgs_read_ahead_hits(d: *mut DlgsDecoder, hits: *mut u64) -> DlgsStatus {
    guarded(|| {
        let Some(d) = decoder(d) else {
            return fail(DlgsStatus::NullArgument, "decoder must not be NULL");
        };
        if hits.is_null() {
            return fail(DlgsStatus::NullArgument, "hits must not be NULL");
        }
        let n = match &d.inner {
            Inner::Gs(dec) => dec.read_ahead_hits(),
            Inner::Scaffold(..) => 0,
        };
        // SAFETY: non-NULL; the C contract is writable storage for one u64.
        unsafe { *hits = n };
        DlgsStatus::Ok
    })
}
