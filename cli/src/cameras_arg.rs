//! Camera selection shared by `render`, `compare` and `cameras`.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use dlgs::Gaussians;
use dlgs_render::{cameras_from_json, orbit_cameras, Camera, OrbitSpec};
use glam::Vec3;

#[derive(Args, Debug, Clone)]
pub struct CameraArgs {
    /// 3DGS cameras.json; without it, orbit cameras are generated around the scene.
    #[arg(long, alias = "camera")]
    pub cameras: Option<PathBuf>,
    /// Use only this camera (index into the list, or its name).
    #[arg(long)]
    pub view: Option<String>,
    /// Number of orbit cameras when no cameras.json is given.
    #[arg(long, default_value_t = 8)]
    pub orbit: usize,
    /// Output width (overrides cameras.json, scaling intrinsics).
    #[arg(long)]
    pub width: Option<u32>,
    /// Output height (overrides cameras.json, scaling intrinsics).
    #[arg(long)]
    pub height: Option<u32>,
    /// World up axis for orbit cameras: x, y, z, -x, -y or -z (COLMAP scenes: -y).
    #[arg(long, default_value = "-y", allow_hyphen_values = true)]
    pub up: String,
    /// Orbit distance as a multiple of the scene's robust radius.
    #[arg(long, default_value_t = 1.6)]
    pub distance: f32,
}

fn parse_axis(s: &str) -> Result<Vec3> {
    Ok(match s {
        "x" | "+x" => Vec3::X,
        "y" | "+y" => Vec3::Y,
        "z" | "+z" => Vec3::Z,
        "-x" => Vec3::NEG_X,
        "-y" => Vec3::NEG_Y,
        "-z" => Vec3::NEG_Z,
        _ => bail!("--up must be one of x, y, z, -x, -y, -z (got {s})"),
    })
}

impl CameraArgs {
    /// Cameras to use; orbit cameras are placed around `scene`.
    pub fn resolve(&self, scene: &Gaussians) -> Result<Vec<Camera>> {
        let mut cams = match &self.cameras {
            Some(p) => {
                let text = std::fs::read_to_string(p)
                    .with_context(|| format!("reading {}", p.display()))?;
                cameras_from_json(&text).map_err(anyhow::Error::msg)?
            }
            None => {
                let spec = OrbitSpec {
                    count: self.orbit.max(1),
                    width: self.width.unwrap_or(1352),
                    height: self.height.unwrap_or(1014),
                    up: parse_axis(&self.up)?,
                    distance: self.distance,
                    ..OrbitSpec::default()
                };
                orbit_cameras(scene, &spec)
            }
        };
        if cams.is_empty() {
            bail!("no cameras");
        }
        if let (Some(w), Some(h)) = (self.width, self.height) {
            cams = cams.iter().map(|c| c.resized(w, h)).collect();
        } else if let Some(w) = self.width {
            cams = cams
                .iter()
                .map(|c| {
                    c.resized(
                        w,
                        (c.height as f32 * w as f32 / c.width as f32).round() as u32,
                    )
                })
                .collect();
        }
        if let Some(v) = &self.view {
            let pick = match v.parse::<usize>() {
                Ok(i) => cams.get(i).cloned(),
                Err(_) => cams.iter().find(|c| &c.name == v).cloned(),
            };
            match pick {
                Some(c) => cams = vec![c],
                None => bail!("camera '{v}' not found among {} cameras", cams.len()),
            }
        }
        Ok(cams)
    }
}

/// cameras.json text for a list of cameras (3DGS convention).
pub fn cameras_to_json(cams: &[Camera]) -> String {
    let list: Vec<serde_json::Value> = cams
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let c2w = c.rotation.transpose();
            let rows: Vec<[f32; 3]> = (0..3)
                .map(|r| [c2w.col(0)[r], c2w.col(1)[r], c2w.col(2)[r]])
                .collect();
            serde_json::json!({
                "id": i, "img_name": c.name, "width": c.width, "height": c.height,
                "position": c.position.to_array(), "rotation": rows, "fx": c.fx, "fy": c.fy,
            })
        })
        .collect();
    serde_json::to_string_pretty(&list).expect("json")
}
