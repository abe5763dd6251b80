//! Colour refit for lossy still scenes (`dlgs encode --refit-colours`): after a first coding,
//! the encoder decodes what it stored, fits per-Gaussian colour offsets so the decoded scene
//! renders like the source ([`dlgs_render::colour_fit`]) and codes the scene again with each
//! Gaussian's colour (SH DC) set to its decoded value plus the offset; the other attributes are
//! coded from the same values as before, so they decode the same. The colours then absorb part
//! of the error that quantising positions, shapes and opacities made.
//!
//! The fit can overfit its views (colours that cancel each other's errors from those views
//! only; the donut does), so it is judged on other views of the encoder's own, none the fit
//! saw: the refit coding is kept only if it renders closer to the source there.

use dlgs::Gaussians;
use dlgs_render::colour_fit::fit_colour_offsets;
use dlgs_render::metrics::psnr;
use dlgs_render::sh::C0;
use dlgs_render::{orbit_cameras, render, Camera, OrbitSpec, RenderOptions};
use glam::Vec3;

use crate::importance::importance_views;

/// CGLS steps of the fit.
const ITERATIONS: usize = 4;
/// Damping of the fit, in squared blending weight summed over the fit's pixels: a Gaussian
/// that covers a few pixels of the 320x240 views moves little.
const DAMPING: f64 = 3.0;

/// The views the fit matches: [`importance_views`] at half their size (320x240), 4x faster
/// than full size.
pub fn fit_views(g: &Gaussians) -> Vec<Camera> {
    importance_views(g)
        .iter()
        .map(|c| c.resized(c.width / 2, c.height / 2))
        .collect()
}

/// The views the fit is judged on: orbits around four diagonal up axes (none of
/// [`importance_views`]'s), three azimuths each in the orbit plane, 640x480.
pub fn holdout_views(g: &Gaussians) -> Vec<Camera> {
    let mut cams = Vec::new();
    for up in [
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(0.0, -1.0, 1.0),
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(-1.0, -1.0, 1.0),
    ] {
        cams.extend(orbit_cameras(
            g,
            &OrbitSpec {
                count: 3,
                width: 640,
                height: 480,
                up: up.normalize(),
                elevation_deg: 0.0,
                ..OrbitSpec::default()
            },
        ));
    }
    cams
}

/// Offsets (in colour, the same for every view) that bring `decoded` closer to `source` over
/// [`fit_views`], one per Gaussian of `decoded`.
pub fn fit(source: &Gaussians, decoded: &Gaussians) -> Vec<[f32; 3]> {
    let cams = fit_views(source);
    let opts = RenderOptions::default();
    let targets: Vec<Vec<f32>> = cams
        .iter()
        .map(|c| {
            render(source, c, &opts)
                .map(|i| i.color)
                .unwrap_or_else(|_| vec![0.0; (c.width * c.height * 3) as usize])
        })
        .collect();
    fit_colour_offsets(
        decoded,
        &cams,
        &targets,
        opts.background,
        ITERATIONS,
        DAMPING,
    )
}

/// Sets the SH DC coefficients of Gaussian `i` of `g` to those of Gaussian `k` of `decoded`
/// plus the colour `offset`.
pub fn set_refit_dc(g: &mut Gaussians, i: usize, decoded: &Gaussians, k: usize, offset: [f32; 3]) {
    let (at, from) = (i * g.sh_stride(), k * decoded.sh_stride());
    for (c, o) in offset.iter().enumerate() {
        g.sh[at + c] = decoded.sh[from + c] + o / C0;
    }
}

/// Mean PSNR over [`holdout_views`] of each candidate against `source`.
pub fn holdout_psnr(source: &Gaussians, candidates: &[&Gaussians]) -> Vec<f64> {
    let cams = holdout_views(source);
    let opts = RenderOptions::default();
    let mut sums = vec![0.0; candidates.len()];
    for cam in &cams {
        let Ok(reference) = render(source, cam, &opts) else {
            continue;
        };
        for (sum, g) in sums.iter_mut().zip(candidates) {
            if let Ok(img) = render(g, cam, &opts) {
                // An exact view would be infinite and swamp the mean.
                *sum += psnr(&reference.color, &img.color).min(100.0);
            }
        }
    }
    sums.iter().map(|s| s / cams.len().max(1) as f64).collect()
}
