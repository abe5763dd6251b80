//! In-order stream reader, decoding every canonical payload (CRAW, CSOG) it yields, with tiny
//! limits.
#![no_main]
use dlgs::container::{StreamEvent, StreamReader};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let limits = dlgs::Limits::tiny();
    let Ok(mut r) = StreamReader::with_limits(data, limits) else { return };
    let scene = r.scene().clone();
    while let Ok(Some(ev)) = r.next_event() {
        if let StreamEvent::GopChunk(c, p) = ev {
            let _ = dlgs::payload::decode_canonical(c.ty, &p, c.payload_offset(), &scene, &limits);
        }
    }
});
