//! Sequential 10-GOP streams of a >= 250k-Gaussian scene with periodic refresh (format-spec
//! §4.1 `refresh_interval`), for `dlgs seek`:
//! `cargo run --release -p dlgs-decoder --example refresh_files [-- K ...]` writes
//! target/refresh-{K}.dlgs for each K (default 0 3 5; 0 = no refresh) and prints their bytes.
//!
//! The scene is the 272,920-Gaussian side-by-side capture of `dlgs_testkit::bench_scenes::big`
//! (real scenes), made dynamic by the SYNTHETIC generator (30 % dynamic) over 10 GOPs of 60
//! frames, GOPs 1-9 carrying GENERATED binary voxel residual fields (no trained DLGStream model
//! exists here); lossless canonical states (`CRAW`), intra-only HEVC time features (crf 6).

use std::time::Instant;

use dlgs::container::header::ResidualMode;
use dlgs_encoder::{EncoderConfig, FeatureCodec, HevcSettings};
use dlgs_testkit::bench_scenes::big;
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};

fn main() {
    let ks: Vec<u32> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("K: an integer"))
        .collect();
    let ks = if ks.is_empty() { vec![0, 3, 5] } else { ks };
    let scene = big();
    let target = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target");
    for k in ks {
        let spec = SynthSpec {
            gops: 10,
            residual_mode: ResidualMode::Sequential,
            refresh_interval: k,
            ..Default::default()
        };
        let t0 = Instant::now();
        let m = synth_dynamic(&scene, &spec).unwrap();
        let cfg = EncoderConfig {
            dynamic: dlgs_encoder::DynamicSettings {
                features: FeatureCodec::Hevc(HevcSettings {
                    intra_only: true,
                    ..Default::default()
                }),
                ..Default::default()
            },
            ..Default::default()
        };
        let bytes = write_model(&m, cfg, Vec::new()).unwrap();
        let path = target.join(format!("refresh-{k}.dlgs"));
        std::fs::write(&path, &bytes).unwrap();
        println!(
            "K = {k}: {} static + {} dynamic, 10 GOPs, {} bytes ({:.1} KB/frame), built in {:.1} s -> {}",
            m.scene.n_static,
            m.scene.n_dynamic,
            bytes.len(),
            bytes.len() as f64 / 600.0 / 1024.0,
            t0.elapsed().as_secs_f64(),
            path.display()
        );
    }
}
