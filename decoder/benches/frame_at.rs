//! `frame_at` throughput: 80,000 dynamic Gaussians of the real plant scene animated by the
//! synthetic generator (no real DLGStream model exists here), with and without language,
//! 1 and 2 threads. `cargo bench -p dlgs-decoder --bench frame_at`
//!
//! Also prints the achieved GFLOP/s of the per-frame MLP work.

use std::io::Cursor;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion};
use dlgs::Limits;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::{EncoderConfig, FeatureCodec};
use dlgs_testkit::bench_scenes::plant;
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};

fn bench(c: &mut Criterion) {
    let spec = SynthSpec {
        dynamic_fraction: 0.75,
        max_dynamic: 80_000,
        language: true,
        ..Default::default()
    };
    let model = synth_dynamic(&plant(), &spec).unwrap();
    let cfg = EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: FeatureCodec::Exact,
            ..Default::default()
        },
        ..Default::default()
    };
    let bytes = write_model(&model, cfg, Vec::new()).unwrap();
    let n = model.scene.n_dynamic as f64;
    let mut group = c.benchmark_group("frame_at_80k_dynamic");
    group.sample_size(20);
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let mut dec = Decoder::new(Cursor::new(bytes.as_slice()), Limits::default()).unwrap();
        pool.install(|| dec.gop(0).unwrap());
        let macs = model.gops[0].mlps.per_frame_macs(false) as f64;
        let macs_lang = model.gops[0].mlps.per_frame_macs(true) as f64;
        for (label, language, macs) in [
            ("colour", false, macs),
            ("colour+language", true, macs_lang),
        ] {
            let o = FrameOptions {
                camera_center: [0.0, 0.0, -3.0],
                language,
            };
            let mut t = 0.0f64;
            group.bench_function(format!("{label}/{threads}t/new-buffers"), |b| {
                b.iter(|| {
                    t = (t + 0.0123) % 1.9;
                    pool.install(|| dec.frame_at(t, &o).unwrap())
                })
            });
            // A player: the previous frame's buffers are reused.
            let mut buf = Some(dlgs::model::Gaussians::default());
            group.bench_function(format!("{label}/{threads}t/reused-buffers"), |b| {
                b.iter(|| {
                    t = (t + 0.0123) % 1.9;
                    let f = pool
                        .install(|| dec.frame_at_reusing(t, &o, buf.take().unwrap()))
                        .unwrap();
                    buf = Some(f.dynamics);
                })
            });
            // A plain timing (reused buffers, median of 60 frames) for the FLOP rate line.
            let mut times: Vec<f64> = (0..60)
                .map(|i| {
                    let start = Instant::now();
                    let f = pool
                        .install(|| dec.frame_at_reusing(i as f64 * 0.031, &o, buf.take().unwrap()))
                        .unwrap();
                    buf = Some(f.dynamics);
                    start.elapsed().as_secs_f64()
                })
                .collect();
            times.sort_by(f64::total_cmp);
            let s = times[times.len() / 2];
            println!(
                "{label}/{threads}t: {:.2} ms/frame = {:.0} frames/s; MLP work {:.3} GFLOP/frame -> {:.1} GFLOP/s",
                s * 1e3,
                1.0 / s,
                2.0 * macs * n / 1e9,
                2.0 * macs * n / 1e9 / s
            );
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
