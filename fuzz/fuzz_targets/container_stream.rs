//! In-order stream decoders with tiny limits. 3DGS (`StreamDecoder`): every GOP it yields is
//! built (canonical or residual against its reference, time features incl. HEVC, decoders) and
//! one frame of it is deformed; a language decoder chunk is parsed and run once. Scaffold-GS
//! (`ScaffoldStreamDecoder`, for the streams the 3DGS decoder refuses): every GOP (anchors,
//! residuals, view MLPs, deformation) and one frame of neural Gaussians with language.
#![no_main]
use dlgs_decoder::scaffold::{ScaffoldStreamDecoder, ViewRequest};
use dlgs_decoder::stream::StreamDecoder;
use dlgs_decoder::{DecodedGop, FrameOptions};
use libfuzzer_sys::fuzz_target;

fn scaffold(data: &[u8]) {
    let Ok(mut d) = ScaffoldStreamDecoder::new(data, dlgs::Limits::tiny()) else { return };
    let scene = d.scene().clone();
    let view = ViewRequest { camera_center: [0.0, 0.0, 4.0], language: true, visible: None };
    while let Ok(Some(g)) = d.next_gop() {
        let first = g.index.saturating_mul(scene.gop_length);
        if let Ok(t) = scene.locate((first as f64 + 0.5) / scene.fps()) {
            if t.gop == g.index {
                let _ = g.frame(t.key, t.delta, &view);
            }
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let Ok(mut d) = StreamDecoder::with_limits(data, dlgs::Limits::tiny()) else {
        scaffold(data);
        return;
    };
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
