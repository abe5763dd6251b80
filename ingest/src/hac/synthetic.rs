//! A large synthetic `AHAC` content for decode benchmarks: **real positions, synthetic
//! symbols**. Anchor positions are voxelised (Scaffold-GS's `unique(round(p / v))`) from points
//! sampled inside the Gaussians of a real scene (a PLY of `../shared/data`), with the voxel size
//! chosen for the requested count; the context model is a real one (the fixture's grids and
//! `mlp_grid`) over the new box; each symbol is drawn from its own anchor's predicted
//! distribution (`round(N(μ, σ) / Q)`, seeded, normal by the sum of 12 uniforms).

use dlgs::chunks::ahac::HacAnchors;
use dlgs::model::hac_context::{dequantize, AnchorParams, ATTR_CHANNELS};

/// `n` anchors voxelised from points sampled in the Gaussians of `ply` (PLY bytes), with the
/// context model of `model`; `None` if the scene cannot give `n` distinct voxels.
#[allow(clippy::disallowed_methods)] // benchmark data, not decoded data
pub fn synthetic_anchors(
    model: &HacAnchors,
    ply: &[u8],
    n: usize,
    seed: u64,
) -> Option<HacAnchors> {
    let g = dlgs::interop::ply::read_ply(ply, &dlgs::Limits::default()).ok()?;
    let mut rng = fastrand::Rng::with_seed(seed);
    let normal = |r: &mut fastrand::Rng| (0..12).map(|_| r.f32()).sum::<f32>() - 6.0;
    // Samples per Gaussian: enough for n voxels at a fine voxel size.
    let per = (4 * n).div_ceil(g.positions.len().max(1)).max(1);
    let mut pts = Vec::with_capacity(per * g.positions.len());
    for (p, s) in g.positions.iter().zip(&g.log_scales) {
        for _ in 0..per {
            pts.push(std::array::from_fn::<f32, 3, _>(|d| {
                p[d] + s[d].exp().min(0.05) * normal(&mut rng)
            }));
        }
    }
    let voxels = |v: f32| {
        let mut k: Vec<[i64; 3]> = pts
            .iter()
            .map(|p| p.map(|x| (x / v).round() as i64))
            .collect();
        k.sort_unstable();
        k.dedup();
        k
    };
    // Largest voxel (bisection on a log scale) that still gives at least n voxels.
    let (mut lo, mut hi) = (1e-6f32, 10.0f32);
    for _ in 0..40 {
        let mid = (lo * hi).sqrt();
        if voxels(mid).len() >= n {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let v = lo;
    let all = voxels(v);
    if all.len() < n {
        return None;
    }
    let pos: Vec<[f32; 3]> = (0..n)
        .map(|i| all[i * all.len() / n].map(|k| k as f32 * v))
        .collect();
    let mut bmin = [f32::MAX; 3];
    let mut bmax = [f32::MIN; 3];
    for p in &pos {
        for d in 0..3 {
            bmin[d] = bmin[d].min(p[d]);
            bmax[d] = bmax[d].max(p[d]);
        }
    }
    let interval: [f32; 3] =
        std::array::from_fn(|d| (bmax[d] - bmin[d]) * (1.0f64 / 65535.0) as f32 + 1e-6f32);
    let quantized: Vec<[u16; 3]> = pos
        .iter()
        .map(|p| {
            std::array::from_fn(|d| {
                ((p[d] - bmin[d]) / interval[d]).round().clamp(0.0, 65535.0) as u16
            })
        })
        .collect();
    let mut context = model.context.clone();
    context.bound_min = bmin;
    context.bound_max = bmax;
    let params = context.prepare().eval(&dequantize(&quantized, bmin, bmax));
    let mut symbols: [Vec<i32>; 3] = Default::default();
    for p in &params {
        for (a, s) in symbols.iter_mut().enumerate() {
            let m = AnchorParams::mean_at(a);
            let c = ATTR_CHANNELS[a];
            for ch in 0..c {
                let (mu, sigma) = (p.out[m + ch], p.out[m + c + ch].max(1e-9));
                let x = mu + sigma * normal(&mut rng);
                let xi = if p.q[a] > 0.0 {
                    (x / p.q[a]).round()
                } else {
                    0.0
                };
                s.push(xi.clamp(-30000.0, 30000.0) as i32);
            }
        }
    }
    Some(HacAnchors {
        n_static: n as u32,
        n_dynamic: 0,
        batch: model.batch,
        context,
        quantized,
        symbols,
    })
}
