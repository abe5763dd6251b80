//! The tiled, vectorised renderer against the independent f64 per-pixel reference
//! (tests/src/reference_render.rs) on real scenes from ../shared/data.

use dlgs_render::{metrics, orbit_cameras, render, OrbitSpec, RenderOptions};
use dlgs_tests::reference_render::render_reference;
use dlgs_tests::{load, with_synthetic_language};

fn psnr64(a: &[f32], b: &[f64]) -> f64 {
    let bf: Vec<f32> = b.iter().map(|v| *v as f32).collect();
    metrics::psnr(a, &bf)
}

fn check(rel: &str, width: u32, height: u32, views: usize) {
    let g = load(rel);
    let spec = OrbitSpec {
        count: views,
        width,
        height,
        ..OrbitSpec::default()
    };
    for cam in orbit_cameras(&g, &spec) {
        let img = render(&g, &cam, &RenderOptions::default()).unwrap();
        let (want, _) = render_reference(&g, &cam, [1.0; 3], false);
        let p = psnr64(&img.color, &want);
        println!(
            "{rel} {}: PSNR vs f64 reference {p:.2} dB ({} visible)",
            cam.name, img.visible
        );
        assert!(p >= 50.0, "{rel} {}: PSNR {p:.2} dB < 50", cam.name);
        // The view must actually show something.
        let covered = img.transmittance.iter().filter(|t| **t < 0.5).count();
        assert!(
            covered > (width * height / 50) as usize,
            "{rel} {}: only {covered} pixels covered",
            cam.name
        );
    }
}

#[test]
fn matches_reference_on_tiny_and_small_real_scenes() {
    check("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply", 160, 120, 3);
    check(
        "ply/supersplat_fruit_drops_minimal_4721_sh3.ply",
        160,
        120,
        3,
    );
    check("ply/gs3d-fork_lod2_tile_0_6831_sh3.ply", 128, 96, 2);
}

#[test]
fn matches_reference_on_larger_real_scenes() {
    check("ply/gsplat_DATA_new_22589_sh3.ply", 96, 72, 2);
    check("ply/v3dg_donut_mipsplatting_45624_sh0.ply", 96, 72, 2);
    check("splat/marcelpadilla_plant.splat", 80, 60, 1);
}

#[test]
fn language_image_matches_reference_with_dual_opacity() {
    let g = with_synthetic_language(&load("ply/supersplat_fruit_drops_minimal_4721_sh3.ply"));
    let spec = OrbitSpec {
        count: 2,
        width: 128,
        height: 96,
        ..OrbitSpec::default()
    };
    for cam in orbit_cameras(&g, &spec) {
        let img = render(
            &g,
            &cam,
            &RenderOptions {
                features: true,
                ..Default::default()
            },
        )
        .unwrap();
        let (rgb, feat) = render_reference(&g, &cam, [1.0; 3], true);
        assert!(psnr64(&img.color, &rgb) >= 50.0);
        let got = img.features.as_ref().unwrap();
        let peak = feat.iter().fold(0f64, |m, v| m.max(v.abs())).max(1e-6);
        let mse = got
            .iter()
            .zip(&feat)
            .map(|(a, b)| (*a as f64 - b).powi(2))
            .sum::<f64>()
            / feat.len() as f64;
        let p = 10.0 * (peak * peak / mse.max(1e-30)).log10();
        println!("features {}: PSNR (peak {peak:.3}) {p:.2} dB", cam.name);
        assert!(p >= 50.0, "feature PSNR {p:.2}");
    }
}

#[test]
fn output_is_identical_on_one_and_two_threads() {
    let g = with_synthetic_language(&load("ply/gs3d-fork_lod1_tile_0_0.5x_14051_sh3.ply"));
    let cam = orbit_cameras(
        &g,
        &OrbitSpec {
            count: 1,
            width: 400,
            height: 300,
            ..OrbitSpec::default()
        },
    )
    .remove(0);
    let opts = RenderOptions {
        features: true,
        ..Default::default()
    };
    let run = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| render(&g, &cam, &opts).unwrap())
    };
    let (a, b) = (run(1), run(2));
    assert!(a.color == b.color, "colour differs between 1 and 2 threads");
    assert!(
        a.features == b.features,
        "features differ between 1 and 2 threads"
    );
}
