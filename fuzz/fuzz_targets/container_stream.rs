//! In-order stream reader, decoding every canonical payload (CRAW, CSOG) it yields and applying
//! every residual payload (RNTC, RDLT) to the last decoded state, with tiny limits.
#![no_main]
use dlgs::container::{StreamEvent, StreamReader};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let limits = dlgs::Limits::tiny();
    let Ok(mut r) = StreamReader::with_limits(data, limits) else { return };
    let scene = r.scene().clone();
    let mut state = None;
    while let Ok(Some(ev)) = r.next_event() {
        if let StreamEvent::GopChunk(c, p) = ev {
            let at = c.payload_offset();
            if let Some(Ok(g)) = dlgs::payload::decode_canonical(c.ty, &p, at, &scene, &limits) {
                state = Some(g);
            } else if let Some(base) = &state {
                if let Some(Ok((g, _))) =
                    dlgs::payload::decode_residual(c.ty, &p, at, &scene, &limits, base)
                {
                    state = Some(g);
                }
            }
        }
    }
});
