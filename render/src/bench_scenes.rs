//! Real scenes for benchmarks: the 114k-Gaussian plant capture and a >= 250k scene made of
//! real scenes placed side by side (../shared/data; override with DLGS_DATA).

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
/// donut scaled into the gap, all at SH 0.
pub fn big() -> Gaussians {
    let plant = plant();
    let mut out = plant.clone();
    let mut second = plant;
    for p in &mut second.positions {
        p[0] += 0.6;
    }
    out.extend(&second);
    let donut = load("ply/v3dg_donut_mipsplatting_45624_sh0.ply");
    let (lo, hi) = donut.bounds().expect("donut has positions");
    let size = (0..3).map(|a| hi[a] - lo[a]).fold(0f32, f32::max).max(1e-6);
    let s = 0.3 / size;
    let mut d = donut;
    for (p, ls) in d.positions.iter_mut().zip(d.log_scales.iter_mut()) {
        for a in 0..3 {
            p[a] = (p[a] - (lo[a] + hi[a]) * 0.5) * s;
            ls[a] += s.ln();
        }
        p[0] += 0.3;
        p[1] -= 0.2;
    }
    out.extend(&d);
    out
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
