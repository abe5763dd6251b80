//! Cold seek into a residual GOP, time features as one HEVC stream per GOP (default) or as
//! intra-only pictures (`TFEA` codec 3, a seek decodes 2 keys): the real plant scene, 80,000 of
//! its Gaussians animated by the SYNTHETIC generator (no real DLGStream model exists here), 2
//! GOPs in parallel mode with a generated binary voxel residual.
//! `cargo bench -p dlgs-decoder --bench seek`

use std::io::Cursor;

use criterion::{criterion_group, criterion_main, Criterion};
use dlgs::container::header::ResidualMode;
use dlgs::Limits;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::{EncoderConfig, FeatureCodec, HevcSettings};
use dlgs_testkit::bench_scenes::plant;
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};

fn bench(c: &mut Criterion) {
    let spec = SynthSpec {
        dynamic_fraction: 0.75,
        max_dynamic: 80_000,
        gops: 2,
        residual_mode: ResidualMode::Parallel,
        ..Default::default()
    };
    let model = synth_dynamic(&plant(), &spec).unwrap();
    let mut group = c.benchmark_group("seek_cold_plant_80k_dynamic");
    group.sample_size(10);
    let o = FrameOptions {
        camera_center: [0.0, 0.0, -3.0],
        language: false,
    };
    for (label, intra_only) in [("one-stream", false), ("intra-only", true)] {
        let cfg = EncoderConfig {
            dynamic: dlgs_encoder::DynamicSettings {
                features: FeatureCodec::Hevc(HevcSettings {
                    intra_only,
                    ..Default::default()
                }),
                ..Default::default()
            },
            ..Default::default()
        };
        let bytes = write_model(&model, cfg, Vec::new()).unwrap();
        println!("{label}: {} bytes", bytes.len());
        let mut k = 0u32;
        group.bench_function(label, |b| {
            b.iter(|| {
                // A different time of GOP 1 each run (2.0 s .. 4.0 s), from a fresh decoder.
                k = (k + 7) % 59;
                let t = 2.0 + k as f64 / 30.0;
                let mut dec =
                    Decoder::new(Cursor::new(bytes.as_slice()), Limits::default()).unwrap();
                dec.seek(t, &o).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
