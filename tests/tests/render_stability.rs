//! Degenerate Gaussians: the renderer never panics and never writes NaN, and each case does
//! what format-spec/renderer.md documents.

use dlgs::Gaussians;
use dlgs_render::{render, Camera, RenderOptions};
use glam::Vec3;

fn cam() -> Camera {
    // At the origin looking down +z (x right, y down).
    Camera::look_at(Vec3::ZERO, Vec3::Z, Vec3::NEG_Y, 64, 48, 60.0)
}

/// One red Gaussian at depth 3 in front of the camera, with optional language.
fn one(pos: [f32; 3], log_scale: [f32; 3], rot: [f32; 4], opacity: f32) -> Gaussians {
    let mut g = Gaussians::new(0, 9);
    g.positions.push(pos);
    g.log_scales.push(log_scale);
    g.rotations.push(rot);
    g.opacity.push(opacity);
    g.sh.extend([1.5, -1.5, -1.5]);
    g.lang_opacity.push(opacity);
    g.lang.extend([0.5; 9]);
    g
}

fn draw(g: &Gaussians) -> dlgs_render::Image {
    let img = render(
        g,
        &cam(),
        &RenderOptions {
            features: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(img.color.iter().all(|v| v.is_finite()), "NaN/Inf in colour");
    assert!(
        img.features.as_ref().unwrap().iter().all(|v| v.is_finite()),
        "NaN/Inf in features"
    );
    img
}

fn covered(img: &dlgs_render::Image) -> usize {
    img.transmittance.iter().filter(|t| **t < 0.999).count()
}

const ID: [f32; 4] = [1.0, 0.0, 0.0, 0.0];
const C: [f32; 3] = [0.0, 0.0, 3.0];

#[test]
fn a_normal_gaussian_is_drawn() {
    let img = draw(&one(C, [-2.0; 3], ID, 2.0));
    assert!(covered(&img) > 20);
}

#[test]
fn zero_and_tiny_scales_become_the_dilation_footprint() {
    // exp(-inf) = 0 is non-finite input (culled); exp(-100) ~ 0 and ln(1e-8) are drawn as
    // 0.3 px low-pass blobs.
    assert_eq!(covered(&draw(&one(C, [f32::NEG_INFINITY; 3], ID, 2.0))), 0);
    for ls in [-100.0f32, (1e-8f32).ln()] {
        let img = draw(&one(C, [ls; 3], ID, 5.0));
        let n = covered(&img);
        assert!((1..=16).contains(&n), "log-scale {ls}: {n} pixels");
    }
}

#[test]
fn huge_scales_are_culled_or_drawn_finite() {
    // exp(50) overflows the 2D covariance in f32: culled. exp(5) covers the whole image.
    assert_eq!(covered(&draw(&one(C, [50.0; 3], ID, 2.0))), 0);
    assert_eq!(covered(&draw(&one(C, [1e6; 3], ID, 2.0))), 0);
    assert_eq!(covered(&draw(&one(C, [5.0; 3], ID, 2.0))), 64 * 48);
}

#[test]
fn zero_quaternion_is_identity_and_unnormalised_is_normalised() {
    let base = draw(&one(C, [-2.0, -3.0, -2.5], ID, 2.0)).color;
    assert!(
        draw(&one(C, [-2.0, -3.0, -2.5], [0.0; 4], 2.0)).color == base,
        "zero quaternion is not the identity"
    );
    let scaled = draw(&one(C, [-2.0, -3.0, -2.5], [7.0, 0.0, 0.0, 0.0], 2.0)).color;
    let d = base
        .iter()
        .zip(&scaled)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(d < 1e-5, "unnormalised quaternion differs by {d}");
}

#[test]
fn extreme_opacity_logits() {
    // +50: alpha clamps at 0.99; -50: invisible.
    let img = draw(&one(C, [-1.5; 3], ID, 50.0));
    // The mean sits between pixel centres, so the brightest pixel is a bit below the clamp.
    let t = img.transmittance.iter().copied().fold(1f32, f32::min);
    assert!((0.01 - 1e-6..0.03).contains(&t), "min transmittance {t}");
    assert_eq!(covered(&draw(&one(C, [-1.5; 3], ID, -50.0))), 0);
}

#[test]
fn gaussians_behind_or_on_the_camera_plane_are_culled() {
    for z in [-3.0f32, 0.0, 0.1, 0.2] {
        assert_eq!(
            covered(&draw(&one([0.0, 0.0, z], [-1.0; 3], ID, 2.0))),
            0,
            "z = {z}"
        );
    }
}

#[test]
fn nan_and_inf_anywhere_cull_that_gaussian_only() {
    let good = one([0.5, 0.0, 3.0], [-2.0; 3], ID, 2.0);
    let reference = draw(&good);
    type Poison = Box<dyn Fn(&mut Gaussians)>;
    let cases: Vec<Poison> = vec![
        Box::new(|g| g.positions[0][1] = f32::NAN),
        Box::new(|g| g.positions[0][2] = f32::INFINITY),
        Box::new(|g| g.log_scales[0][0] = f32::NAN),
        Box::new(|g| g.rotations[0][3] = f32::NAN),
        Box::new(|g| g.opacity[0] = f32::NAN),
        Box::new(|g| g.sh[1] = f32::INFINITY),
        Box::new(|g| g.lang[4] = f32::NAN),
        Box::new(|g| g.lang_opacity[0] = f32::NAN),
    ];
    for (k, poison) in cases.iter().enumerate() {
        let mut bad = one([-0.5, 0.0, 2.0], [-2.0; 3], ID, 2.0);
        poison(&mut bad);
        let mut both = good.clone();
        both.extend(&bad);
        let img = draw(&both);
        assert!(
            img.color == reference.color,
            "case {k}: the poisoned Gaussian changed the image"
        );
    }
    // Infinite opacity logits are non-finite input too: culled, not drawn as opaque.
    assert_eq!(covered(&draw(&one(C, [-1.5; 3], ID, f32::INFINITY))), 0);
}

#[test]
fn empty_scene_and_bad_sizes() {
    let g = Gaussians::new(0, 0);
    let img = render(&g, &cam(), &RenderOptions::default()).unwrap();
    assert!(img.color.iter().all(|v| *v == 1.0));
    let mut c = cam();
    c.width = 0;
    assert!(render(&g, &c, &RenderOptions::default()).is_err());
    assert!(render(
        &g,
        &cam(),
        &RenderOptions {
            features: true,
            ..Default::default()
        }
    )
    .is_err());
}
