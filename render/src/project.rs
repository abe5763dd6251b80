//! Per-Gaussian preprocessing: EWA projection to a 2D conic with the 0.3 px low-pass dilation,
//! view-dependent colour, and the screen rectangle where the Gaussian can reach alpha >= 1/255.

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use crate::camera::Camera;
use crate::sh::eval_sh;
use dlgs::model::sigmoid;
use dlgs::Gaussians;

pub const TILE: u32 = 16;
/// Gaussians closer than this (view-space z) are culled, as in 3DGS.
pub const NEAR: f32 = 0.2;
/// The low-pass dilation added to the 2D covariance diagonal.
pub const DILATION: f32 = 0.3;
pub const ALPHA_MIN: f32 = 1.0 / 255.0;

/// A Gaussian projected to the image. 60 bytes, aligned to 64 so each splat is one cache line
/// (with the tile rectangle stored too it was 68 bytes, two lines for most splats: binning and
/// the compositor's gathers read every splat of a tile).
#[derive(Debug, Clone, Copy, Default)]
#[repr(align(64))]
pub struct Splat2d {
    pub mean: [f32; 2],
    /// (a, b, c): power = -0.5 (a dx^2 + c dy^2) - b dx dy.
    pub conic: [f32; 3],
    pub depth: f32,
    pub opacity: f32,
    pub lang_opacity: f32,
    /// The ellipse d^T conic d <= r2 holds every pixel with alpha >= 1/255.
    pub r2: f32,
    pub color: [f32; 3],
    /// Pixel rectangle [x0, y0, x1, y1) that can receive alpha >= 1/255, clipped to the image.
    pub px: [u16; 4],
    /// Index into the source Gaussians.
    pub index: u32,
}

impl Splat2d {
    /// Tile rectangle [x0, y0, x1, y1) in tile units: the tiles `px` touches.
    #[inline]
    pub fn tiles(&self) -> [u16; 4] {
        let [x0, y0, x1, y1] = self.px.map(u32::from);
        let t = TILE;
        [
            x0 / t,
            y0 / t,
            x1.saturating_sub(1) / t + 1,
            y1.saturating_sub(1) / t + 1,
        ]
        .map(|v| v as u16)
    }
}

/// Rotation matrix of a raw w-first quaternion. A zero quaternion yields the identity
/// (what `F.normalize` + `build_rotation` give in the reference code).
pub fn quat_to_mat(q: [f32; 4]) -> Mat3 {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = if n > 0.0 { q.map(|v| v / n) } else { [0.0; 4] };
    Mat3::from_cols(
        Vec3::new(
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y + w * z),
            2.0 * (x * z - w * y),
        ),
        Vec3::new(
            2.0 * (x * y - w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z + w * x),
        ),
        Vec3::new(
            2.0 * (x * z + w * y),
            2.0 * (y * z - w * x),
            1.0 - 2.0 * (x * x + y * y),
        ),
    )
}

/// Project Gaussian `i`; `None` when it cannot contribute to any pixel or has non-finite input.
pub fn project_one(
    g: &Gaussians,
    i: usize,
    cam: &Camera,
    with_lang: bool,
    tiles_x: u32,
    tiles_y: u32,
) -> Option<Splat2d> {
    let p = Vec3::from(g.positions[i]);
    let ls = g.log_scales[i];
    let q = g.rotations[i];
    if !p.is_finite() || !ls.iter().all(|v| v.is_finite()) || !q.iter().all(|v| v.is_finite()) {
        return None;
    }
    let t = cam.to_view(p);
    if !(t.z > NEAR) {
        return None;
    }
    if !g.opacity[i].is_finite() || (with_lang && !g.lang_opacity[i].is_finite()) {
        return None;
    }
    let o = sigmoid(g.opacity[i]);
    let ol = if with_lang {
        sigmoid(g.lang_opacity[i])
    } else {
        0.0
    };
    let omax = o.max(ol);
    if !(omax * 255.0 > 1.0) {
        return None;
    }
    // 3D covariance R S S^T R^T.
    let s = Vec3::new(ls[0].exp(), ls[1].exp(), ls[2].exp());
    let m = quat_to_mat(q) * Mat3::from_diagonal(s);
    let sigma = m * m.transpose();
    // EWA: Jacobian of the perspective map at the mean, with the 3DGS 1.3x FOV clamp.
    let (thx, thy) = cam.tan_half_fov();
    let (limx, limy) = (1.3 * thx, 1.3 * thy);
    let tx = (t.x / t.z).clamp(-limx, limx) * t.z;
    let ty = (t.y / t.z).clamp(-limy, limy) * t.z;
    let j0 = Vec3::new(cam.fx / t.z, 0.0, -cam.fx * tx / (t.z * t.z));
    let j1 = Vec3::new(0.0, cam.fy / t.z, -cam.fy * ty / (t.z * t.z));
    let wt = cam.rotation.transpose();
    let r0 = wt * j0; // row 0 of J W, as a column vector
    let r1 = wt * j1;
    let s0 = sigma * r0;
    let s1 = sigma * r1;
    let a = r0.dot(s0) + DILATION;
    let b = r0.dot(s1);
    let c = r1.dot(s1) + DILATION;
    let det = a * c - b * b;
    if !(det > 0.0) || !det.is_finite() {
        return None;
    }
    let conic = [c / det, -b / det, a / det];
    if !conic.iter().all(|v| v.is_finite()) {
        return None;
    }
    let mean = [
        cam.fx * t.x / t.z + cam.cx - 0.5,
        cam.fy * t.y / t.z + cam.cy - 0.5,
    ];
    // Where o * exp(power) >= 1/255: the ellipse d^T conic d <= r2.
    let r2 = 2.0 * (255.0 * omax).ln();
    let hx = (r2 * a).sqrt();
    let hy = (r2 * c).sqrt();
    if !(mean[0].is_finite() && mean[1].is_finite() && hx.is_finite() && hy.is_finite()) {
        return None;
    }
    // Integer pixel range [lo, hi) inside the ellipse's bounding box, clipped to [0, n).
    let to_px = |lo: f32, hi: f32, n: u32| -> (u32, u32) {
        let lo = lo.ceil().clamp(0.0, n as f32) as u32;
        let hi = (hi.floor() + 1.0).clamp(0.0, n as f32) as u32;
        (lo, hi)
    };
    let (x0, x1) = to_px(mean[0] - hx, mean[0] + hx, cam.width);
    let (y0, y1) = to_px(mean[1] - hy, mean[1] + hy, cam.height);
    if x0 >= x1 || y0 >= y1 {
        return None;
    }
    debug_assert!((x1 - 1) / TILE < tiles_x && (y1 - 1) / TILE < tiles_y);
    let dir = (p - cam.position).normalize_or_zero();
    let color = eval_sh(g.sh_degree, g.sh_of(i), dir.to_array());
    if !color.iter().all(|v| v.is_finite()) {
        return None;
    }
    if with_lang && !g.lang_of(i).iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(Splat2d {
        mean,
        conic,
        depth: t.z,
        opacity: o,
        lang_opacity: ol,
        r2,
        color,
        px: [x0, y0, x1, y1].map(|v| v as u16),
        index: i as u32,
    })
}

/// Project all Gaussians in parallel; the result keeps the source order.
pub fn project_all(g: &Gaussians, cam: &Camera, with_lang: bool) -> Vec<Splat2d> {
    let tiles_x = cam.width.div_ceil(TILE);
    let tiles_y = cam.height.div_ceil(TILE);
    (0..g.len())
        .into_par_iter()
        .with_min_len(4096)
        .filter_map(|i| project_one(g, i, cam, with_lang, tiles_x, tiles_y))
        .collect()
}
