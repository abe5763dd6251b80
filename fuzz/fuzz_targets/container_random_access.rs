//! Random-access reader + decoder of every GOP, with tiny limits.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(mut dec) = dlgs_decoder::Decoder::new(std::io::Cursor::new(data), dlgs::Limits::tiny()) else { return };
    let _ = dec.reader().verify_all();
    for g in 0..dec.scene().gop_count.min(64) {
        let _ = dec.gop_canonical(g);
    }
    let _ = dec.frame_at(0.5);
});
