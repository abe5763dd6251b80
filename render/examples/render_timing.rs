//! Where the render time goes: per-stage milliseconds and work counts on the bench scenes.
//! `cargo run --release -p dlgs-render --example render_timing`; the last column is a checksum of
//! the image bits, to see that a change leaves every pixel as it was.

use dlgs_render::{orbit_cameras, render, Image, OrbitSpec, RenderOptions};
use dlgs_testkit::bench_scenes::{big, plant, with_language};

/// Loads one bench scene.
type Loader = fn() -> dlgs::Gaussians;

fn main() {
    // Optional filters: `render_timing [SCENE [WHAT [THREADS [RUNS]]]]`, e.g. `273k colour 2 20`
    // (SCENE: part of the name; WHAT: `colour` or `colour+language`).
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize| args.get(i).map(String::as_str).unwrap_or("");
    let runs: usize = arg(3).parse().unwrap_or(5);
    let scenes: [(&str, Loader); 2] = [("plant_114k", plant), ("sidebyside_273k", big)];
    for (name, load) in scenes {
        if !name.contains(arg(0)) {
            continue;
        }
        let g = load();
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
            if !arg(1).is_empty() && label != arg(1) {
                continue;
            }
            for threads in [1, 2] {
                if !arg(2).is_empty() && arg(2) != threads.to_string() {
                    continue;
                }
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut best = (f64::MAX, 0.0, 0.0, 0, 0);
                let mut sum = 0u64;
                for _ in 0..runs {
                    let img = pool.install(|| render(&scene, &cam, &opts).unwrap());
                    sum = checksum(&img);
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
                    "{name:<16} {label:<16} {threads}t  total {:7.1} ms  project {:6.1} ms  bin+composite {:7.1} ms  visible {:>7}  tile pairs {:>8}  image {sum:016x}",
                    best.0, best.1, best.2, best.3, best.4
                );
            }
        }
    }
}

/// FNV-1a over the image's bits (colour, transmittance, features): equal sums, equal images.
fn checksum(img: &Image) -> u64 {
    let feats = img.features.as_deref().unwrap_or(&[]);
    let all = img.color.iter().chain(&img.transmittance).chain(feats);
    all.fold(0xcbf2_9ce4_8422_2325, |h, v| {
        (h ^ u64::from(v.to_bits())).wrapping_mul(0x100_0000_01b3)
    })
}
