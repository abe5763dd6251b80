//! In-order stream reader, decoding every CRAW payload it yields, with tiny limits.
#![no_main]
use dlgs::container::{ChunkType, StreamEvent, StreamReader};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let limits = dlgs::Limits::tiny();
    let Ok(mut r) = StreamReader::with_limits(data, limits) else { return };
    let scene = r.scene().clone();
    while let Ok(Some(ev)) = r.next_event() {
        if let StreamEvent::GopChunk(c, p) = ev {
            if c.ty == ChunkType::CRAW {
                let _ = dlgs::payload::raw_canonical::decode(&p, c.payload_offset(), &scene, &limits);
            }
        }
    }
});
