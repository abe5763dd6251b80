//! Where the render time goes: per-stage milliseconds and work counts on the bench scenes.
//! `cargo run --release -p dlgs-render --example render_timing`; the last column is a checksum of
//! the image bits, to see that a change leaves every pixel as it was.

use dlgs_render::{metrics, orbit_cameras, render, Accuracy, Image, OrbitSpec, RenderOptions};
use dlgs_testkit::bench_scenes::{big, plant, with_language};

/// Loads one bench scene.
type Loader = fn() -> dlgs::Gaussians;

fn main() {
    // Optional filters: `render_timing [SCENE [WHAT [THREADS [RUNS [fast]]]]]`, e.g.
    // `273k colour 2 20` (SCENE: part of the name; WHAT: `colour` or `colour+language`). With
    // `fast`, each row is timed twice, exact and `Accuracy::Fast` renders in turn, and the fast
    // row adds its PSNR against the exact image (colour; language too when rendered).
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize| args.get(i).map(String::as_str).unwrap_or("");
    let runs: usize = arg(3).parse().unwrap_or(5);
    let modes: &[Accuracy] = if arg(4) == "fast" {
        &[Accuracy::Exact, Accuracy::Fast]
    } else {
        &[Accuracy::Exact]
    };
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
                let mut best = vec![(f64::MAX, 0.0, 0.0, 0, 0); modes.len()];
                let mut sums = vec![0u64; modes.len()];
                let mut last: Vec<Option<Image>> = modes.iter().map(|_| None).collect();
                for _ in 0..runs {
                    for (m, &accuracy) in modes.iter().enumerate() {
                        let o = RenderOptions {
                            accuracy,
                            ..opts.clone()
                        };
                        let img = pool.install(|| render(&scene, &cam, &o).unwrap());
                        sums[m] = checksum(&img);
                        let t = img.timings.project_ms + img.timings.raster_ms;
                        if t < best[m].0 {
                            best[m] = (
                                t,
                                img.timings.project_ms,
                                img.timings.raster_ms,
                                img.visible,
                                img.pairs,
                            );
                        }
                        last[m] = Some(img);
                    }
                }
                for (m, b) in best.iter().enumerate() {
                    let quality = match (&last[0], &last[m]) {
                        (Some(e), Some(f)) if m > 0 => {
                            let lang = match (&e.features, &f.features) {
                                (Some(a), Some(b)) => {
                                    format!("  language PSNR {:.2} dB", metrics::psnr_range(a, b))
                                }
                                _ => String::new(),
                            };
                            format!(
                                "  fast: PSNR vs exact {:.2} dB{lang}",
                                metrics::psnr(&e.color, &f.color)
                            )
                        }
                        _ => String::new(),
                    };
                    println!(
                        "{name:<16} {label:<16} {threads}t  total {:7.1} ms  project {:6.1} ms  bin+composite {:7.1} ms  visible {:>7}  tile pairs {:>8}  image {:016x}{quality}",
                        b.0, b.1, b.2, b.3, b.4, sums[m]
                    );
                }
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
