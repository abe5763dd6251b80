//! Random-access reader + decoder of every GOP (canonical, time features through FFmpeg's
//! HEVC decoder, MLP decoders, a deformed frame), with tiny limits.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(mut dec) = dlgs_decoder::Decoder::new(std::io::Cursor::new(data), dlgs::Limits::tiny()) else { return };
    let _ = dec.reader().verify_all();
    for g in 0..dec.scene().gop_count.min(64) {
        let _ = dec.gop(g);
    }
    let o = dlgs_decoder::FrameOptions { camera_center: [0.0, 0.0, -3.0], language: true };
    let _ = dec.frame_at(0.5, &o);
    let _ = dec.frame_at(0.01, &o);
});
