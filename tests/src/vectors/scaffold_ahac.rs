//! The Scaffold-GS vectors whose anchors are HAC-coded (`AHAC`, format-spec §6.13, since 1.17):
//! the tiny model's 3 anchors with generated context grids, `mlp_grid` weights and integers, as
//! one-level hashed grids, with one grid-bit frequency per group (scope 1), and dense grids.

use dlgs::chunks::tfea::TfeaBody;
use dlgs::model::scaffold::{FEAT_DIM, N_OFFSETS, SCALING_DIM};
use dlgs_encoder::scaffold::{scaffold_scene, ScaffoldWriter};

use super::scaffold::model;

pub const AHAC_VALID: &str = "scaffold-ahac-tiny";

/// `AHAC` content (§6.13) for the tiny model's 3 anchors: positions quantised from the 3 real
/// points in a box around them, one-level grids (3D: R 5, 2^4 entries; planes: R 6, 2^5; 2
/// features), `mlp_grid` 8 -> 4 -> 175, generated weights and integers, batches of 2.
pub fn hac_anchors() -> dlgs::chunks::ahac::HacAnchors {
    hac_anchors_with((5, 4), (6, 5), 53)
}

/// As [`hac_anchors`] with one-level grids of (resolution, log2 entries) `g3` (3D) and `g2`
/// (planes), grid bits, weights and integers drawn from `seed`.
fn hac_anchors_with(g3: (u32, u8), g2: (u32, u8), seed: u64) -> dlgs::chunks::ahac::HacAnchors {
    use dlgs::model::hac_context::{GridShape, HacContext, CONTEXT_OUT};
    let (c, _, d, _) = model();
    let mut rng = fastrand::Rng::with_seed(seed);
    let shape = |(r, log2): (u32, u8)| GridShape {
        resolutions: vec![r],
        log2_table: log2,
        features: 2,
    };
    let (grid3, grid2) = (shape(g3), shape(g2));
    let levels = HacContext::level_bits(&grid3, &grid2)
        .into_iter()
        .map(|n| (0..n).map(|_| rng.bool()).collect())
        .collect();
    let (inputs, hidden) = (8, 4);
    let mut w = |n: usize, s: f32, b: f32| (0..n).map(|_| (rng.f32() - 0.5) * s + b).collect();
    let (bmin, bmax) = (d.bound_min, d.bound_max);
    let quantized = c
        .statics
        .positions
        .iter()
        .chain(&c.dynamics.positions)
        .map(|p| std::array::from_fn(|a| ((p[a] - bmin[a]) / (bmax[a] - bmin[a]) * 65535.0) as u16))
        .collect();
    let context = HacContext {
        grid3,
        grid2,
        bound_min: bmin,
        bound_max: bmax,
        q_base: [0.25, 0.001, 0.05],
        levels,
        hidden,
        w1: w(inputs * hidden, 2.0, 0.0),
        b1: w(hidden, 0.5, 0.2),
        w2: w(hidden * CONTEXT_OUT, 0.5, 0.0),
        b2: w(CONTEXT_OUT, 0.5, 0.5),
    };
    let mut s = |n: usize, lo: i32, hi: i32| (0..3 * n).map(|_| rng.i32(lo..=hi)).collect();
    dlgs::chunks::ahac::HacAnchors {
        n_static: 2,
        n_dynamic: 1,
        batch: 2,
        context,
        quantized,
        symbols: [
            s(FEAT_DIM, -4, 4),
            s(SCALING_DIM, -3100, -2900),
            s(3 * N_OFFSETS, -9, 9),
        ],
    }
}

/// The tiny model with its anchors in `AHAC` instead of `ANCR`.
pub fn ahac_bytes() -> Vec<u8> {
    ahac_file(&hac_anchors())
}

/// The tiny model's one-GOP file with these anchors in `AHAC`.
fn ahac_file(h: &dlgs::chunks::ahac::HacAnchors) -> Vec<u8> {
    let (_, m, d, f) = model();
    let scene = scaffold_scene(2, 1, true, 30, 60, 10, 60);
    let mut w = ScaffoldWriter::new(Vec::new(), scene, 19).unwrap();
    w.push_gop_hac(h, &m, Some((&d, &TfeaBody::Exact(f))))
        .unwrap();
    w.finish().unwrap()
}

/// The `AHAC` payload's `scope` byte (§6.13.1, offset 54).
fn ahac_scope(h: &dlgs::chunks::ahac::HacAnchors) -> u8 {
    let scene = scaffold_scene(2, 1, true, 30, 60, 10, 60);
    dlgs::chunks::ahac::encode(h, &scene, 19).unwrap().0[54]
}

/// `AHAC` whose grid bits code smaller with one frequency per grid group (scope 1, §6.13.4)
/// than with each segment's own: the first seed from 0 for which that holds (the encoder codes
/// both ways and keeps the smaller).
pub const AHAC_SCOPE: &str = "scaffold-ahac-scope";
pub(super) fn ahac_scope_bytes() -> Vec<u8> {
    let h = (0..1000)
        .map(|seed| hac_anchors_with((5, 4), (6, 5), seed))
        .find(|h| ahac_scope(h) == 1)
        .expect("a seed where scope 1 wins");
    ahac_file(&h)
}

/// `AHAC` whose grids are dense (§6.13.5 reads them as §6.6.4: `sum k_d R^d` when
/// `R^D <= 2^T`): the 3D level R 4 in 2^6 entries (64), the planes R 5 in 2^5 (25 <= 32).
pub const AHAC_DENSE: &str = "scaffold-ahac-dense";
pub(super) fn ahac_dense_bytes() -> Vec<u8> {
    ahac_file(&hac_anchors_with((4, 6), (5, 5), 53))
}

/// Offset of batch header `k` (batches x attributes) in the `AHAC` payload: the headers end
/// where the streams start, and the streams end the payload.
pub(super) fn ahac_batch_header(payload_len: usize, k: usize) -> usize {
    let h = hac_anchors();
    let scene = scaffold_scene(2, 1, true, 30, 60, 10, 60);
    let (_, sizes) = dlgs::chunks::ahac::encode(&h, &scene, 19).unwrap();
    let nb = 2; // 3 anchors in batches of 2
    payload_len - sizes.streams.iter().sum::<usize>() - 36 * nb + 12 * k
}
