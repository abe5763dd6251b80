//! Render time per 1352x1014 frame on real scenes, colour only and colour + language,
//! 1 and 2 threads. `cargo bench -p dlgs-render`.

use criterion::{criterion_group, criterion_main, Criterion};
use dlgs_render::{orbit_cameras, render, OrbitSpec, RenderOptions};
use dlgs_testkit::bench_scenes::{big, plant, with_language};

fn bench(c: &mut Criterion) {
    let scenes = [("plant_114k", plant()), ("sidebyside_273k", big())];
    let mut group = c.benchmark_group("render_1352x1014");
    group.sample_size(10);
    for (name, g) in &scenes {
        let cam = orbit_cameras(g, &OrbitSpec::default()).remove(0);
        let lang = with_language(g);
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let colour = RenderOptions::default();
            let both = RenderOptions {
                features: true,
                ..Default::default()
            };
            // Check once before timing that the frame shows the scene.
            let img = pool.install(|| render(g, &cam, &colour).unwrap());
            assert!(
                img.visible > g.len() / 2,
                "{name}: only {} visible",
                img.visible
            );
            group.bench_function(format!("{name}/colour/{threads}t"), |b| {
                b.iter(|| pool.install(|| render(g, &cam, &colour).unwrap()))
            });
            group.bench_function(format!("{name}/colour+language/{threads}t"), |b| {
                b.iter(|| pool.install(|| render(&lang, &cam, &both).unwrap()))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
