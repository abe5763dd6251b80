//! The 273k playback stream of issue 55: `cargo run --release -p dlgs-decoder --example
//! play_file` writes target/play-273k.dlgs for `dlgs play` and `dlgs seek`.
//!
//! The scene is the 272,920-Gaussian side-by-side capture of `dlgs_testkit::bench_scenes::big`
//! (real scenes), made dynamic by the SYNTHETIC generator (30 % dynamic, synthetic 9-dim
//! language) over 5 sequential GOPs of 60 frames, GOPs 1-4 carrying GENERATED binary voxel
//! residual fields (no trained DLGStream model exists here); canonical state as `CSOG` at the
//! `high` preset, time features as 12-bit HEVC (crf 6), as `dlgs encode` writes by default.

use std::time::Instant;

use dlgs::chunks::csog::QuantBits;
use dlgs::container::header::ResidualMode;
use dlgs_encoder::{CanonicalCodec, EncoderConfig, SortSpec};
use dlgs_testkit::bench_scenes::big;
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};

fn main() {
    let t0 = Instant::now();
    let spec = SynthSpec {
        gops: 5,
        residual_mode: ResidualMode::Sequential,
        language: true,
        ..Default::default()
    };
    let m = synth_dynamic(&big(), &spec).unwrap();
    let mut cfg = EncoderConfig::default();
    cfg.coding.codec = CanonicalCodec::Sorted {
        bits: QuantBits::HIGH,
        sort: SortSpec::NONE,
    };
    let bytes = write_model(&m, cfg, Vec::new()).unwrap();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/play-273k.dlgs");
    std::fs::write(&path, &bytes).unwrap();
    println!(
        "{} static + {} dynamic, 5 GOPs, {} bytes, built in {:.1} s -> {}",
        m.scene.n_static,
        m.scene.n_dynamic,
        bytes.len(),
        t0.elapsed().as_secs_f64(),
        path.display()
    );
}
