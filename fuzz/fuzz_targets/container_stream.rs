//! In-order stream decoder (`StreamDecoder`) with tiny limits: every GOP it yields is built
//! (canonical or residual against its reference, time features incl. HEVC, decoders) and one
//! frame of it is deformed; a language decoder chunk is parsed and run once.
#![no_main]
use dlgs_decoder::stream::StreamDecoder;
use dlgs_decoder::{DecodedGop, FrameOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(mut d) = StreamDecoder::with_limits(data, dlgs::Limits::tiny()) else { return };
    if let Ok(Some(ld)) = d.lang_decoder() {
        let mut out = vec![0.0; ld.embed_dims()];
        ld.decode_one(&vec![0.5; ld.input_dims()], &mut out);
    }
    let scene = d.scene().clone();
    let opts = FrameOptions { camera_center: [0.0; 3], language: true };
    while let Ok(Some(g)) = d.next_gop() {
        let first = g.index.saturating_mul(scene.gop_length);
        if let Ok(t) = scene.locate((first as f64 + 0.5) / scene.fps()) {
            if t.gop == g.index {
                let _ = DecodedGop::frame(&g, t, &opts, Default::default());
            }
        }
    }
});
