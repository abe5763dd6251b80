//! Shared helpers for the integration tests: paths to the real data in `../shared/data`,
//! small real scenes, and an independent reference renderer.

pub mod reference_render;

use std::path::PathBuf;

use dlgs::Gaussians;

/// `../shared/data` relative to the workspace root (override with `DLGS_DATA`).
pub fn data_dir() -> PathBuf {
    if let Ok(d) = std::env::var("DLGS_DATA") {
        return PathBuf::from(d);
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data")
}

pub fn data(rel: &str) -> PathBuf {
    data_dir().join(rel)
}

/// Load a real scene from `../shared/data` by relative path.
pub fn load(rel: &str) -> Gaussians {
    let p = data(rel);
    dlgs::interop::read_splat_file(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Real scenes used across tests: (relative path, Gaussian count, SH degree).
pub const REAL_SCENES: &[(&str, usize, u8)] = &[
    ("tiny/metalsplatter_3-points-from-train.ply", 3, 3),
    ("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply", 1971, 3),
    ("ply/supersplat_fruit_drops_minimal_4721_sh3.ply", 4721, 3),
    ("ply/gs3d-fork_lod2_tile_0_6831_sh3.ply", 6831, 3),
    ("ply/gs3d-fork_lod1_tile_0_0.5x_14051_sh3.ply", 14051, 3),
    ("ply/gsplat_DATA_new_22589_sh3.ply", 22589, 3),
    ("ply/v3dg_donut_mipsplatting_45624_sh0.ply", 45624, 0),
    ("splat/marcelpadilla_plant.splat", 113648, 0),
];

/// Give a real scene DLGStream's language channels: a language opacity equal to the colour
/// opacity plus a smooth 9-dim feature derived from position (there is no real language
/// model here; this only exercises the second opacity and the feature image).
pub fn with_synthetic_language(g: &Gaussians) -> Gaussians {
    let mut out = g.clone();
    out.lang_width = 9;
    out.lang_opacity = g.opacity.iter().map(|o| o - 0.5).collect();
    out.lang = g
        .positions
        .iter()
        .flat_map(|p| {
            let s = |k: f32| (p[0] * k).sin() + (p[1] * k * 0.7).cos() * 0.5 + p[2] * 0.1;
            [
                s(1.0),
                s(2.0),
                s(3.0),
                s(0.5),
                s(1.5),
                s(2.5),
                s(0.3),
                s(0.7),
                s(1.1),
            ]
        })
        .collect();
    out
}
