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
/// (moved only), which SOG codes for 70 % of the first copy's bytes (dlgs: 91 %;
/// docs/benchmarks/canonical-large.md "A larger scene built from the real ones"):
/// [`mosaic`] has no repeats.
pub fn big() -> Gaussians {
    big_with_copy_order(false)
}

/// The same 272,920 Gaussians as [`big`], with the second plant's Gaussians in a fixed shuffled
/// order. The scene renders the same, but no byte-level coder can match the second copy's
/// attribute runs against the first's: SPZ v4's zstd streams do
/// (docs/benchmarks/canonical-large.md "The 273k scene's repeat and SPZ"), our coder sorts every
/// scene into an order of its own anyway.
pub fn big_copy_shuffled() -> Gaussians {
    big_with_copy_order(true)
}

fn big_with_copy_order(shuffle: bool) -> Gaussians {
    let plant = plant();
    let mut out = plant.clone();
    let mut second = plant;
    for p in &mut second.positions {
        p[0] += 0.6;
    }
    if shuffle {
        for i in shuffled_indices(second.len(), 0x5eed_d195) {
            out.push_from(&second, i);
        }
    } else {
        out.extend(&second);
    }
    out.extend(&fit_into(
        load("ply/v3dg_donut_mipsplatting_45624_sh0.ply"),
        [0.3, -0.2, 0.0],
    ));
    out
}

/// `0..n` in an order drawn from `seed` (fastrand's shuffle: the same on every machine).
fn shuffled_indices(n: usize, seed: u64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    fastrand::Rng::with_seed(seed).shuffle(&mut order);
    order
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

    /// The shuffled 273k scene holds the same Gaussians as `big` (as a multiset of records), the
    /// first plant and the donut in place, and the second plant in another order.
    #[test]
    fn shuffled_big_is_big_reordered() {
        let a = big();
        let b = big_copy_shuffled();
        assert_eq!(a.len(), b.len());
        let n = plant().len();
        let record = |g: &Gaussians, i: usize| {
            let mut r: Vec<u32> = g.positions[i].map(f32::to_bits).to_vec();
            r.extend(g.log_scales[i].map(f32::to_bits));
            r.extend(g.rotations[i].map(f32::to_bits));
            r.push(g.opacity[i].to_bits());
            r.extend(g.sh_of(i).iter().map(|v| v.to_bits()));
            r
        };
        for i in (0..n).chain(2 * n..a.len()) {
            assert_eq!(record(&a, i), record(&b, i), "Gaussian {i} moved");
        }
        let mut ra: Vec<Vec<u32>> = (n..2 * n).map(|i| record(&a, i)).collect();
        let mut rb: Vec<Vec<u32>> = (n..2 * n).map(|i| record(&b, i)).collect();
        let unmoved = (0..n).filter(|&k| ra[k] == rb[k]).count();
        assert!(unmoved < n / 100, "{unmoved} of {n} left in place");
        ra.sort_unstable();
        rb.sort_unstable();
        assert_eq!(ra, rb);
    }

    #[test]
    fn shuffled_indices_are_a_permutation() {
        let mut o = shuffled_indices(1000, 1);
        assert_ne!(o, (0..1000).collect::<Vec<_>>());
        o.sort_unstable();
        assert_eq!(o, (0..1000).collect::<Vec<_>>());
        assert!(shuffled_indices(0, 1).is_empty());
        assert_eq!(shuffled_indices(1, 1), vec![0]);
    }

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
