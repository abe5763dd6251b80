//! Tests of `colour_fit`.

use super::*;
use crate::camera::{orbit_cameras, OrbitSpec};
use crate::contribution::tests::blob;
use crate::metrics::psnr;
use crate::RenderOptions;

fn cams(g: &Gaussians, count: usize) -> Vec<Camera> {
    orbit_cameras(
        g,
        &OrbitSpec {
            count,
            width: 96,
            height: 72,
            ..OrbitSpec::default()
        },
    )
}

/// Per-Gaussian colours and a 3-channel image of `v`'s size, varied, for the passes' tests.
fn test_colours(n: usize) -> Vec<[f32; 3]> {
    (0..n)
        .map(|i| [(i as f32).sin(), (i as f32 * 0.3).cos(), 0.5])
        .collect()
}

fn test_image(v: &View) -> Vec<f32> {
    (0..(v.width * v.height * 3) as usize)
        .map(|k| ((k * 7919) % 101) as f32 / 100.0)
        .collect()
}

#[test]
fn backward_is_the_adjoint_of_forward() {
    // <A x, r> = <x, A^T r> for any x and r: the solver's two passes walk the same
    // weights.
    let g = blob(150);
    let v = View::new(&g, &cams(&g, 1)[0]);
    let x = test_colours(g.len());
    let r: Vec<f32> = test_image(&v).iter().map(|v| v - 0.5).collect();
    let ax = v.forward(&x);
    let lhs: f64 = ax
        .iter()
        .zip(&r)
        .map(|(a, b)| (*a as f64) * (*b as f64))
        .sum();
    let mut atr = vec![[0.0f64; 3]; g.len()];
    v.backward(&r, &mut atr, None);
    let rhs: f64 = x
        .iter()
        .zip(&atr)
        .map(|(a, b)| (0..3).map(|c| a[c] as f64 * b[c]).sum::<f64>())
        .sum();
    assert!(lhs.abs() > 1.0, "{lhs}");
    assert!((lhs - rhs).abs() < 1e-4 * lhs.abs(), "{lhs} vs {rhs}");
}

#[test]
fn the_fused_pass_gives_the_floats_of_forward_then_backward() {
    let g = blob(150);
    let v = View::new(&g, &cams(&g, 1)[0]);
    let x = test_colours(g.len());
    let b = test_image(&v);
    let ax = v.forward(&x);
    let r: Vec<f32> = b.iter().zip(&ax).map(|(b, a)| b - a).collect();
    let (mut grad, mut diag) = (vec![[0.0f64; 3]; g.len()], vec![0.0f64; g.len()]);
    v.backward(&r, &mut grad, Some(&mut diag));
    let (mut grad2, mut diag2) = (vec![[0.0f64; 3]; g.len()], vec![0.0f64; g.len()]);
    let r2 = v.residual_and_backward(&x, &b, &mut grad2, Some(&mut diag2));
    assert_eq!(r, r2);
    assert_eq!(grad, grad2);
    assert_eq!(diag, diag2);
    assert!(diag.iter().filter(|&&d| d > 0.0).count() > 100);
}

#[test]
fn the_fit_recovers_colour_changes_and_is_deterministic() {
    // Targets rendered with every colour moved; the fit from the unmoved colours brings
    // the renders much closer, and gives the same offsets on one thread.
    let g = blob(150);
    let cams = cams(&g, 6);
    let targets = moved_targets(&g, &cams, |i| 0.1 * ((i % 5) as f32 - 2.0));
    let opts = RenderOptions::default();
    let off = fit_colour_offsets(&g, &cams, &targets, opts.background, 8, 0.01);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| fit_colour_offsets(&g, &cams, &targets, opts.background, 8, 0.01));
    assert_eq!(off, one);
    let mut fitted = g.clone();
    for (i, o) in off.iter().enumerate() {
        for c in 0..3 {
            fitted.sh[i * 3 + c] += o[c] / crate::sh::C0;
        }
    }
    let mean = |g: &Gaussians| mean_psnr(g, &cams, &targets);
    let (before, after) = (mean(&g), mean(&fitted));
    println!("{before:.2} -> {after:.2} dB");
    assert!(after > before + 10.0, "{before:.2} -> {after:.2} dB");
}

#[test]
fn the_lattice_search_beats_rounding_keeps_its_bounds_and_is_deterministic() {
    // Targets with every colour moved by about a third of a wide step: rounding each fitted
    // offset alone leaves them where they are; the search moves some by a whole step.
    let g = blob(150);
    let cams = cams(&g, 6);
    let targets = moved_targets(&g, &cams, |i| 0.12 * ((i % 3) as f32 - 1.0));
    let bg = RenderOptions::default().background;
    let off = fit_colour_offsets(&g, &cams, &targets, bg, 8, 0.01);
    let step = 0.36 * crate::sh::C0;
    // Gaussian 0 may not move at all, channel 2 of every Gaussian only up by one step.
    let steps: Vec<[f32; 3]> = (0..g.len())
        .map(|i| if i == 0 { [0.0; 3] } else { [step; 3] })
        .collect();
    let moves = vec![[(-3, 3), (-3, 3), (0, 1)]; g.len()];
    let snap =
        |sweeps| snap_colour_offsets(&g, &cams, &targets, bg, &off, &steps, &moves, sweeps, 0.01);
    let (rounded, searched) = (snap(0), snap(2));
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| snap(2));
    assert_eq!(searched, one);
    assert_eq!(searched[0], [0; 3]);
    for m in &searched {
        assert!((-3..=3).contains(&m[0]) && (-3..=3).contains(&m[1]) && (0..=1).contains(&m[2]));
    }
    let apply = |m: &[[i32; 3]]| {
        let mut out = g.clone();
        for (i, mi) in m.iter().enumerate() {
            for c in 0..3 {
                out.sh[i * 3 + c] += mi[c] as f32 * steps[i][c] / crate::sh::C0;
            }
        }
        out
    };
    let mean = |g: &Gaussians| mean_psnr(g, &cams, &targets);
    let (before, at_rounding, at_search) =
        (mean(&g), mean(&apply(&rounded)), mean(&apply(&searched)));
    println!("{before:.2} dB, rounded {at_rounding:.2}, searched {at_search:.2}");
    assert_ne!(rounded, searched);
    assert!(
        at_search > at_rounding + 0.5,
        "{at_rounding:.2} -> {at_search:.2} dB"
    );
}

/// Renders from `cams` of `g` with SH coefficient `i` moved by `shift(i)`.
fn moved_targets(g: &Gaussians, cams: &[Camera], shift: impl Fn(usize) -> f32) -> Vec<Vec<f32>> {
    let mut moved = g.clone();
    for (i, v) in moved.sh.iter_mut().enumerate() {
        *v += shift(i);
    }
    let opts = RenderOptions::default();
    cams.iter()
        .map(|c| render(&moved, c, &opts).unwrap().color)
        .collect()
}

/// Mean PSNR of `g`'s renders from `cams` against `targets`.
fn mean_psnr(g: &Gaussians, cams: &[Camera], targets: &[Vec<f32>]) -> f64 {
    let opts = RenderOptions::default();
    cams.iter()
        .zip(targets)
        .map(|(c, t)| psnr(t, &render(g, c, &opts).unwrap().color))
        .sum::<f64>()
        / cams.len() as f64
}

fn render(
    g: &Gaussians,
    c: &Camera,
    o: &crate::RenderOptions,
) -> Result<crate::Image, crate::RenderError> {
    crate::render(g, c, o)
}
