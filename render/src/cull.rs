//! View-frustum culling of bounding spheres (e.g. Scaffold-GS anchors with the reach of their
//! children): a sphere is kept unless it lies wholly outside one of the frustum's five planes
//! (the four sides through the image borders widened by [`MARGIN_PX`], and the near plane at
//! z = 0.2, the renderer's).

use glam::Vec3;

use crate::camera::Camera;

/// The renderer's near plane (view-space z), as `project`.
pub const NEAR: f32 = 0.2;
/// Pixels the image borders are widened by: the renderer's low-pass dilation (0.3 px² added
/// to every 2D covariance) lets a splat reach about 1.6 px further than its 3σ sphere.
pub const MARGIN_PX: f32 = 3.0;

/// For each sphere (`centres[i]`, `radii[i]`), whether any of it can be in `camera`'s view.
pub fn spheres_in_view(camera: &Camera, centres: &[[f32; 3]], radii: &[f32]) -> Vec<bool> {
    // Side planes through the camera centre and the image borders, as unit inward normals in
    // view space (x right, y down, z forward).
    let l = (camera.cx + MARGIN_PX) / camera.fx;
    let r = (camera.width as f32 - camera.cx + MARGIN_PX) / camera.fx;
    let t = (camera.cy + MARGIN_PX) / camera.fy;
    let b = (camera.height as f32 - camera.cy + MARGIN_PX) / camera.fy;
    let planes = [
        Vec3::new(1.0, 0.0, l).normalize(),
        Vec3::new(-1.0, 0.0, r).normalize(),
        Vec3::new(0.0, 1.0, t).normalize(),
        Vec3::new(0.0, -1.0, b).normalize(),
    ];
    centres
        .iter()
        .zip(radii)
        .map(|(&c, &rad)| {
            let v = camera.to_view(Vec3::from_array(c));
            v.z + rad >= NEAR && planes.iter().all(|n| n.dot(v) >= -rad)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spheres_behind_or_beside_the_camera_are_culled() {
        let cam = Camera::look_at(
            Vec3::new(0.0, 0.0, -5.0),
            Vec3::ZERO,
            Vec3::new(0.0, -1.0, 0.0),
            100,
            100,
            90.0,
        );
        let centres = [
            [0.0, 0.0, 0.0],
            [0.0, 0.0, -10.0],
            [50.0, 0.0, 0.0],
            [5.5, 0.0, 0.0],
        ];
        // In front; behind; far to the side; just outside the 90° frustum but reaching in.
        let got = spheres_in_view(&cam, &centres, &[0.1, 0.1, 0.1, 1.0]);
        assert_eq!(got, vec![true, false, false, true]);
        assert!(!spheres_in_view(&cam, &centres[3..], &[0.1])[0]);
    }
}
