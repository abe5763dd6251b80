//! Where the render time goes: per-stage milliseconds and work counts on the bench scenes.
//! `cargo run --release -p dlgs-render --example render_timing`

use dlgs_render::{orbit_cameras, render, OrbitSpec, RenderOptions};
use dlgs_testkit::bench_scenes::{big, plant, with_language};

fn main() {
    for (name, g) in [("plant_114k", plant()), ("sidebyside_273k", big())] {
        let cam = orbit_cameras(&g, &OrbitSpec::default()).remove(0);
        for (label, scene, opts) in [
            ("colour", g.clone(), RenderOptions::default()),
            (
                "colour+language",
                with_language(&g),
                RenderOptions {
                    features: true,
                    ..Default::default()
                },
            ),
        ] {
            for threads in [1, 2] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut best = (f64::MAX, 0.0, 0.0, 0, 0);
                for _ in 0..5 {
                    let img = pool.install(|| render(&scene, &cam, &opts).unwrap());
                    let t = img.timings.project_ms + img.timings.raster_ms;
                    if t < best.0 {
                        best = (
                            t,
                            img.timings.project_ms,
                            img.timings.raster_ms,
                            img.visible,
                            img.pairs,
                        );
                    }
                }
                println!(
                    "{name:<16} {label:<16} {threads}t  total {:7.1} ms  project {:6.1} ms  bin+composite {:7.1} ms  visible {:>7}  tile pairs {:>8}",
                    best.0, best.1, best.2, best.3, best.4
                );
            }
        }
    }
}
