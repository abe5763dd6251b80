//! Seek latency on a >= 250k-Gaussian scene, both residual modes:
//! `cargo run --release -p dlgs-decoder --example seek_timing [-- exact | intra]` (`intra`:
//! intra-only HEVC time features, `TFEA` codec 3, written to target/seek-{mode}-intra.dlgs).
//!
//! The scene is the 272,920-Gaussian side-by-side capture of `dlgs_testkit::bench_scenes::big`
//! (real scenes), made dynamic by the SYNTHETIC generator (30 % dynamic) over 5 GOPs of 60
//! frames, GOPs 1-4 carrying GENERATED binary voxel residual fields (no trained DLGStream model
//! exists here). Files are written to target/seek-{mode}.dlgs, so `dlgs seek` can be run on
//! them too. For each mode it prints the time of a seek after start (GOP 0 decoded and cached)
//! to each later GOP, split into its parts.

use std::io::Cursor;
use std::time::Instant;

use dlgs::container::header::ResidualMode;
use dlgs::Limits;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::{EncoderConfig, FeatureCodec, HevcSettings};
use dlgs_testkit::bench_scenes::big;
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};

fn main() {
    let hevc = !std::env::args().any(|a| a == "exact");
    let intra = std::env::args().any(|a| a == "intra");
    let scene = big();
    let target = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target");
    for mode in [ResidualMode::Parallel, ResidualMode::Sequential] {
        let spec = SynthSpec {
            gops: 5,
            residual_mode: mode,
            ..Default::default()
        };
        let t0 = Instant::now();
        let m = synth_dynamic(&scene, &spec).unwrap();
        let cfg = EncoderConfig {
            dynamic: dlgs_encoder::DynamicSettings {
                features: if hevc {
                    FeatureCodec::Hevc(HevcSettings {
                        intra_only: intra,
                        ..Default::default()
                    })
                } else {
                    FeatureCodec::Exact
                },
                ..Default::default()
            },
            ..Default::default()
        };
        let bytes = write_model(&m, cfg, Vec::new()).unwrap();
        let suffix = if intra { "-intra" } else { "" };
        let path = target.join(format!("seek-{mode:?}{suffix}.dlgs").to_lowercase());
        std::fs::write(&path, &bytes).unwrap();
        println!(
            "{mode:?}: {} static + {} dynamic, {} bytes ({} features), built in {:.1} s -> {}",
            m.scene.n_static,
            m.scene.n_dynamic,
            bytes.len(),
            match (hevc, intra) {
                (true, false) => "HEVC crf 6",
                (true, true) => "intra-only HEVC crf 6",
                _ => "exact",
            },
            t0.elapsed().as_secs_f64(),
            path.display()
        );
        let opts = FrameOptions {
            camera_center: [0.0, 0.0, 5.0],
            language: false,
        };
        for g in 1..5u32 {
            let mut d = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
            d.gop(0).unwrap();
            let t = (g * 60 + 17) as f64 / 30.0;
            let t0 = Instant::now();
            let canon = d.gop_canonical(g).unwrap();
            let t1 = Instant::now();
            let gop = d.gop(g).unwrap();
            let t2 = Instant::now();
            let f = d.frame_at(t, &opts).unwrap();
            let t3 = Instant::now();
            assert_eq!(canon.len(), gop.canonical.len());
            assert_eq!(f.dynamics.len(), m.scene.n_dynamic as usize);
            let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
            println!(
                "  seek to GOP {g}: {:.1} ms = canonical state {:.1} (residual chain) + features and decoders {:.1} + frame {:.1}",
                ms(t0, t3),
                ms(t0, t1),
                ms(t1, t2),
                ms(t2, t3)
            );
        }
    }
}
