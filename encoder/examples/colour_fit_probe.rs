//! Probe: fit colour offsets to a decoded scene so that it renders like its source from the
//! encoder's 36 importance views (not the benchmark's), and write the result as a PLY:
//! `cargo run --release -p dlgs-encoder --example colour_fit_probe -- SOURCE DECODED.ply OUT.ply [ITERS [DAMPING]]`
//! (`DECODED.ply` from `dlgs export`).
//!
//! The fit is `dlgs_render::colour_fit`; `dlgs encode --refit-colours` runs it inside the
//! encoder and keeps it only where held-out views improve (`dlgs_encoder::colour_refit`).

use dlgs_encoder::importance::importance_views;
use dlgs_render::colour_fit::fit_colour_offsets;
use dlgs_render::sh::C0;
use dlgs_render::{render, RenderOptions};

fn main() {
    let mut args = std::env::args().skip(1);
    let usage = "usage: colour_fit_probe SOURCE DECODED OUT.ply [ITERS [DAMPING]]";
    let src = args.next().expect(usage);
    let dec = args.next().expect(usage);
    let out = args.next().expect(usage);
    let iters: usize = args.next().map_or(8, |s| s.parse().expect("iterations"));
    let damping: f64 = args.next().map_or(10.0, |s| s.parse().expect("damping"));
    let gs = dlgs::interop::read_splat_file(src.as_ref()).expect("readable source");
    let mut gd = dlgs::interop::read_splat_file(dec.as_ref()).expect("readable decoded scene");
    let mut cams = importance_views(&gs);
    // FIT_SCALE=0.5: fit at half the resolution (4x faster).
    if let Ok(f) = std::env::var("FIT_SCALE") {
        let f: f32 = f.parse().expect("a scale");
        for c in &mut cams {
            c.width = (c.width as f32 * f) as u32;
            c.height = (c.height as f32 * f) as u32;
            c.fx *= f;
            c.fy *= f;
            c.cx *= f;
            c.cy *= f;
        }
    }
    let opts = RenderOptions::default();
    let t = std::time::Instant::now();
    let targets: Vec<Vec<f32>> = cams
        .iter()
        .map(|c| render(&gs, c, &opts).unwrap().color)
        .collect();
    // Views the fit never sees: orbits around four diagonal up axes, 640x480.
    let mut held = Vec::new();
    for up in [
        [1.0, -1.0, 0.0],
        [0.0, -1.0, 1.0],
        [1.0, 0.0, 1.0],
        [-1.0, -1.0, 1.0],
    ] {
        held.extend(dlgs_render::orbit_cameras(
            &gs,
            &dlgs_render::OrbitSpec {
                count: 3,
                width: 640,
                height: 480,
                up: glam::Vec3::from(up).normalize(),
                elevation_deg: 0.0,
                ..dlgs_render::OrbitSpec::default()
            },
        ));
    }
    let mean_psnr = |g: &dlgs::Gaussians, cams: &[dlgs_render::Camera]| -> f64 {
        cams.iter()
            .map(|c| {
                let a = render(&gs, c, &opts).unwrap().color;
                dlgs_render::metrics::psnr(&a, &render(g, c, &opts).unwrap().color)
            })
            .sum::<f64>()
            / cams.len() as f64
    };
    let before = mean_psnr(&gd, &cams);
    let held_before = mean_psnr(&gd, &held);
    let off = fit_colour_offsets(&gd, &cams, &targets, opts.background, iters, damping);
    let stride = gd.sh_stride();
    // FIT_SNAP=1: put each fitted DC value on the nearest level the decoded scene uses (what
    // storing it at the same bits would do; the union of every part's levels, so optimistic).
    let snap = std::env::var("FIT_SNAP").is_ok_and(|v| v == "1");
    for c in 0..3 {
        let mut levels: Vec<f32> = (0..gd.len()).map(|i| gd.sh[i * stride + c]).collect();
        levels.sort_by(f32::total_cmp);
        levels.dedup();
        for (i, o) in off.iter().enumerate() {
            let v = gd.sh[i * stride + c] + o[c] / C0;
            gd.sh[i * stride + c] = if snap { nearest(&levels, v) } else { v };
        }
    }
    let after = mean_psnr(&gd, &cams);
    let held_after = mean_psnr(&gd, &held);
    let mean_abs: f64 = off
        .iter()
        .flat_map(|o| o.iter())
        .map(|v| v.abs() as f64)
        .sum::<f64>()
        / (3 * off.len()).max(1) as f64;
    println!(
        "{} Gaussians, {} views, {iters} iterations, damping {damping}, {:.1} s: fit views {before:.2} -> {after:.2} dB, held-out views {held_before:.2} -> {held_after:.2} dB, mean |offset| {mean_abs:.5}",
        gd.len(),
        cams.len(),
        t.elapsed().as_secs_f64()
    );
    std::fs::write(&out, dlgs::interop::ply::write_ply(&gd).unwrap()).unwrap();
}

fn nearest(sorted: &[f32], v: f32) -> f32 {
    let k = sorted.partition_point(|&x| x < v);
    let below = sorted[k.saturating_sub(1)];
    let above = sorted[k.min(sorted.len() - 1)];
    if (v - below).abs() <= (above - v).abs() {
        below
    } else {
        above
    }
}
