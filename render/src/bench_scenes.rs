//! Real scenes for benchmarks: the 114k-Gaussian plant capture, a >= 250k scene made of real
//! scenes placed side by side, and a mosaic of every real scene once (../shared/data; override
//! with DLGS_DATA).

use std::path::PathBuf;

use dlgs::Gaussians;

pub fn data_dir() -> PathBuf {
    std::env::var("DLGS_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"))
}

fn load(rel: &str) -> Gaussians {
    let p = data_dir().join(rel);
    dlgs::interop::read_splat_file(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The 113,648-Gaussian phone capture (SH 0).
pub fn plant() -> Gaussians {
    load("splat/marcelpadilla_plant.splat")
}

/// 272,920 Gaussians: the plant twice side by side (x offset 0.6) plus the 45,624-Gaussian
/// donut scaled into the gap, all at SH 0. The second plant is an exact repeat of the first
/// (moved only), which SOG codes for 70 % of the first copy's bytes (dlgs: 91 %; BENCHMARKS.md):
/// [`mosaic`] has no repeats.
pub fn big() -> Gaussians {
    let plant = plant();
    let mut out = plant.clone();
    let mut second = plant;
    for p in &mut second.positions {
        p[0] += 0.6;
    }
    out.extend(&second);
    out.extend(&fit_into(
        load("ply/v3dg_donut_mipsplatting_45624_sh0.ply"),
        [0.3, -0.2, 0.0],
    ));
    out
}

/// 209,435 Gaussians: every real scene of the data set once (no repeats), at SH 0: the plant
/// where it is, the six others each scaled into a 0.3 box around it.
pub fn mosaic() -> Gaussians {
    let mut out = plant();
    for (rel, centre) in [
        (
            "ply/v3dg_donut_mipsplatting_45624_sh0.ply",
            [0.45, -0.2, 0.0],
        ),
        ("ply/gsplat_DATA_new_22589_sh3.ply", [-0.45, -0.2, 0.0]),
        (
            "ply/gs3d-fork_lod1_tile_0_0.5x_14051_sh3.ply",
            [0.0, -0.2, 0.5],
        ),
        ("ply/gs3d-fork_lod2_tile_0_6831_sh3.ply", [0.0, -0.2, -0.5]),
        (
            "ply/supersplat_fruit_drops_minimal_4721_sh3.ply",
            [0.45, -0.2, 0.5],
        ),
        (
            "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply",
            [-0.45, -0.2, -0.5],
        ),
    ] {
        out.extend(&fit_into(load(rel).with_sh_degree(0), centre));
    }
    out
}

/// `g` scaled uniformly so its largest extent is 0.3 and moved to `centre` (log-scales follow
/// the scale; rotations are unchanged by a uniform scale).
fn fit_into(mut g: Gaussians, centre: [f32; 3]) -> Gaussians {
    let (lo, hi) = g.bounds().expect("a real scene has positions");
    let size = (0..3).map(|a| hi[a] - lo[a]).fold(0f32, f32::max).max(1e-6);
    let s = 0.3 / size;
    for (p, ls) in g.positions.iter_mut().zip(g.log_scales.iter_mut()) {
        for a in 0..3 {
            p[a] = (p[a] - (lo[a] + hi[a]) * 0.5) * s;
            ls[a] += s.ln();
            p[a] += centre[a];
        }
    }
    g
}

/// Add DLGStream-shaped language channels (no real language model exists here).
pub fn with_language(g: &Gaussians) -> Gaussians {
    let mut out = g.clone();
    out.lang_width = 9;
    out.lang_opacity = g.opacity.clone();
    out.lang = g
        .positions
        .iter()
        .flat_map(|p| {
            [
                p[0],
                p[1],
                p[2],
                -p[0],
                -p[1],
                -p[2],
                p[0] * p[1],
                p[1] * p[2],
                p[0] * p[2],
            ]
        })
        .collect();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mosaic holds every real scene once: its size is their sum, nothing repeats, and
    /// each of the six fitted scenes lies in its 0.3 box (the plant keeps its own place).
    #[test]
    fn mosaic_is_every_real_scene_once() {
        let g = mosaic();
        assert_eq!(g.len(), 209_435);
        assert_eq!(g.sh_degree, 0);
        assert!(g.positions.iter().flatten().all(|v| v.is_finite()));
        let plant_len = plant().len();
        assert_eq!(&g.positions[..plant_len], &plant().positions[..]);
        let mut keys: Vec<[u32; 3]> = g.positions.iter().map(|p| p.map(f32::to_bits)).collect();
        keys.sort_unstable();
        keys.dedup();
        assert!(keys.len() > 209_000, "{} distinct positions", keys.len());
        let fitted = fit_into(
            load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply"),
            [1.0, 2.0, 3.0],
        );
        let (lo, hi) = fitted.bounds().unwrap();
        let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0f32, f32::max);
        assert!((extent - 0.3).abs() < 1e-4, "{extent}");
        for (a, c) in [1.0f32, 2.0, 3.0].iter().enumerate() {
            assert!(((lo[a] + hi[a]) * 0.5 - c).abs() < 1e-4);
        }
    }
}
