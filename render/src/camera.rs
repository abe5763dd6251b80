//! Pinhole cameras in the 3DGS convention (x right, y down, z forward), the 3DGS
//! `cameras.json` reader, and an orbit generator for scenes that come without cameras.

use glam::{Mat3, Vec3};
use serde::Deserialize;

use dlgs::Gaussians;

use crate::RenderError;

#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    /// Principal point in pixels (continuous coordinates, pixel i covers [i, i+1)).
    pub cx: f32,
    pub cy: f32,
    /// World-to-camera rotation.
    pub rotation: Mat3,
    /// Camera centre in world coordinates.
    pub position: Vec3,
    pub name: String,
}

impl Camera {
    /// World -> camera coordinates.
    pub fn to_view(&self, p: Vec3) -> Vec3 {
        self.rotation * (p - self.position)
    }

    /// Horizontal and vertical tan(fov/2).
    pub fn tan_half_fov(&self) -> (f32, f32) {
        (
            self.width as f32 * 0.5 / self.fx,
            self.height as f32 * 0.5 / self.fy,
        )
    }

    /// A camera at `eye` looking at `target`, with `up` roughly the image's upward direction.
    pub fn look_at(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        width: u32,
        height: u32,
        fov_x_deg: f32,
    ) -> Camera {
        let f = (target - eye).normalize_or(Vec3::Z);
        // Image y points down, so the camera's y axis is -up projected off the forward axis.
        let mut down = -up - f * f.dot(-up);
        if down.length_squared() < 1e-12 {
            down = f.any_orthonormal_vector();
        }
        let down = down.normalize();
        let right = down.cross(f);
        let rotation = Mat3::from_cols(right, down, f).transpose();
        let fx = width as f32 * 0.5 / (fov_x_deg.to_radians() * 0.5).tan();
        Camera {
            width,
            height,
            fx,
            fy: fx,
            cx: width as f32 * 0.5,
            cy: height as f32 * 0.5,
            rotation,
            position: eye,
            name: String::new(),
        }
    }

    /// Same camera at a different resolution (intrinsics scaled).
    pub fn resized(&self, width: u32, height: u32) -> Camera {
        let sx = width as f32 / self.width as f32;
        let sy = height as f32 / self.height as f32;
        Camera {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
            ..self.clone()
        }
    }
}

#[derive(Deserialize)]
struct JsonCamera {
    #[serde(default)]
    id: i64,
    #[serde(default)]
    img_name: String,
    width: u32,
    height: u32,
    position: [f32; 3],
    /// Camera-to-world rotation, row-major.
    rotation: [[f32; 3]; 3],
    fx: f32,
    fy: f32,
}

/// Parse a 3DGS `cameras.json` (list of {width, height, position, rotation (camera-to-world,
/// rows), fx, fy}).
pub fn cameras_from_json(text: &str) -> Result<Vec<Camera>, RenderError> {
    let list: Vec<JsonCamera> =
        serde_json::from_str(text).map_err(|e| RenderError::Cameras(e.to_string()))?;
    list.into_iter()
        .map(|c| {
            if c.width == 0 || c.height == 0 || !(c.fx > 0.0) || !(c.fy > 0.0) {
                return Err(RenderError::Cameras(format!(
                    "camera {}: width, height, fx and fy must be positive",
                    c.id
                )));
            }
            let r = c.rotation;
            let c2w = Mat3::from_cols(
                Vec3::new(r[0][0], r[1][0], r[2][0]),
                Vec3::new(r[0][1], r[1][1], r[2][1]),
                Vec3::new(r[0][2], r[1][2], r[2][2]),
            );
            Ok(Camera {
                width: c.width,
                height: c.height,
                fx: c.fx,
                fy: c.fy,
                cx: c.width as f32 * 0.5,
                cy: c.height as f32 * 0.5,
                rotation: c2w.transpose(),
                position: Vec3::from(c.position),
                name: if c.img_name.is_empty() {
                    format!("cam{}", c.id)
                } else {
                    c.img_name
                },
            })
        })
        .collect()
}

/// Parameters of [`orbit_cameras`].
#[derive(Debug, Clone)]
pub struct OrbitSpec {
    pub count: usize,
    pub width: u32,
    pub height: u32,
    pub fov_x_deg: f32,
    /// World up direction. Scenes from COLMAP pipelines usually have -Y up.
    pub up: Vec3,
    /// Elevation above the orbit plane, degrees.
    pub elevation_deg: f32,
    /// Orbit radius as a multiple of the scene's robust radius.
    pub distance: f32,
}

impl Default for OrbitSpec {
    fn default() -> Self {
        OrbitSpec {
            count: 8,
            width: 1352,
            height: 1014,
            fov_x_deg: 60.0,
            up: Vec3::NEG_Y,
            elevation_deg: 20.0,
            distance: 1.6,
        }
    }
}

/// Robust centre (per-axis median) and radius (80th percentile of distances) of the Gaussians,
/// so a few far-away floaters do not push the cameras out.
pub fn robust_bounds(g: &Gaussians) -> (Vec3, f32) {
    let pts: Vec<Vec3> = g
        .positions
        .iter()
        .map(|p| Vec3::from(*p))
        .filter(|p| p.is_finite())
        .collect();
    if pts.is_empty() {
        return (Vec3::ZERO, 1.0);
    }
    let median = |a: usize| {
        let mut v: Vec<f32> = pts.iter().map(|p| p[a]).collect();
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let c = Vec3::new(median(0), median(1), median(2));
    let mut d: Vec<f32> = pts.iter().map(|p| (*p - c).length()).collect();
    d.sort_by(f32::total_cmp);
    (c, d[(d.len() * 8 / 10).min(d.len() - 1)].max(1e-3))
}

/// `count` cameras evenly spaced on a circle around the scene, looking at its centre.
pub fn orbit_cameras(g: &Gaussians, spec: &OrbitSpec) -> Vec<Camera> {
    let (center, radius) = robust_bounds(g);
    let up = spec.up.normalize_or(Vec3::NEG_Y);
    let a = up.any_orthonormal_vector();
    let b = up.cross(a);
    let el = spec.elevation_deg.to_radians();
    let r = radius * spec.distance / (spec.fov_x_deg.to_radians() * 0.5).tan().max(0.1);
    (0..spec.count)
        .map(|i| {
            let th = i as f32 / spec.count as f32 * std::f32::consts::TAU;
            let dir = (a * th.cos() + b * th.sin()) * el.cos() + up * el.sin();
            let mut cam = Camera::look_at(
                center + dir * r,
                center,
                up,
                spec.width,
                spec.height,
                spec.fov_x_deg,
            );
            cam.name = format!("orbit{i:02}");
            cam
        })
        .collect()
}
