//! A binary-voxel residual field (`RNTC`, format-spec §6.6) fitted by gradient descent: the
//! offsets that carry one GOP's canonical state to the next, as a function of position.
//!
//! The field is the reference's `NTC_encoding` at a small size: three planes (xy, xz, yz) of a
//! few dense levels, binary entries trained through a straight-through sign (each bit has a
//! real-valued latent; the forward pass uses its sign, the gradient passes where
//! `|latent| <= 1`, as the reference's `STE_binary`), and an MLP with one hidden ReLU layer.
//! The gate grid is left constant (all +1: a gate of about 0.73 everywhere) and codes to
//! nothing. Adam updates the latents and the MLP on the whole set every step.
//!
//! Written by hand rather than with an autodiff crate: the model is one lookup and a two-layer
//! MLP, whose gradients take a few dozen lines, and the hand-written loop is deterministic by
//! construction (per-block partial sums added in block order, whatever the thread count).
//!
//! The fit only has to be good, not exact: the encoder applies the decoded field to the
//! decoder's reference state and fits the GOP's time features to what that gives, so what the
//! field misses the time features carry.

use bitvec::prelude::*;
use rayon::prelude::*;

use dlgs::model::ntc::{groups_in, lookup, NtcConfig, NtcField, NtcMlp, PLANES};
use dlgs::model::residual::SET_DYNAMIC;
use dlgs::model::Gaussians;

use crate::adam::Adam;

/// Size and schedule of a fitted field.
#[derive(Debug, Clone, PartialEq)]
pub struct NtcFitSettings {
    /// Plane level resolutions (dense: `resolution^2 <= 2^log2_table`).
    pub resolutions: Vec<u32>,
    pub features: u8,
    pub log2_table: u8,
    pub hidden: usize,
    pub iterations: usize,
    /// Attribute groups the field offsets (§6.6.1 mask). Positions only by default: on the
    /// wave sequence the field then leaves 10 % of the position change instead of 20 %, and
    /// the time features carry the rest of the attributes' change at no measurable cost
    /// (docs/benchmarks/sequences.md).
    pub groups: u8,
    pub seed: u64,
}

impl Default for NtcFitSettings {
    fn default() -> Self {
        use dlgs::model::residual::AttrGroup::Position;
        NtcFitSettings {
            resolutions: vec![8, 16, 32],
            features: 2,
            log2_table: 10,
            hidden: 32,
            iterations: 600,
            groups: Position.bit(),
            seed: 0x005e_ed0f_4e7c,
        }
    }
}

/// How well the field fits, before coding (relative to the offsets it is fitted to).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NtcFitReport {
    /// Root-mean-square of the offsets per output column, and of what the field leaves.
    pub target_rms: Vec<f64>,
    pub residual_rms: Vec<f64>,
}

/// Per Gaussian: for each (plane, level), up to 4 kept corners as (entry, weight / sum).
struct Lookups {
    corners: Vec<[(u32, f32); 4]>,
}

/// The kept corners of a 2D lookup at `u` with weights divided by their sum, as the decoder
/// looks the grid up ([`lookup`], §6.6.4).
fn corners_2d(u: [f32; 2], r: u32, table: usize) -> [(u32, f32); 4] {
    let mut out = [(0u32, 0f32); 4];
    let mut n = 0;
    let sum = lookup::<2>(u, r, table, |e, w| {
        out[n] = (e as u32, w);
        n += 1;
    });
    for slot in &mut out[..n] {
        slot.1 /= sum;
    }
    out
}

fn normalised(p: [f32; 3], lo: [f32; 3], hi: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|a| ((p[a] - lo[a]) / (hi[a] - lo[a])).clamp(0.0, 1.0))
}

/// The box the field is defined on: the positions' bounds widened by 1 % (and at least 1e-6)
/// so that every Gaussian is inside.
pub fn field_box(positions: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in positions {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    for a in 0..3 {
        if !lo[a].is_finite() {
            (lo[a], hi[a]) = (0.0, 1.0);
        }
        let pad = (0.01 * (hi[a] - lo[a])).max(1e-6);
        lo[a] -= pad;
        hi[a] += pad;
    }
    (lo, hi)
}

/// The offset rows from `reference` to `target` (the same Gaussians in the same order) for the
/// groups of `mask`. Rotations are compared as unit quaternions on the same hemisphere, scaled
/// to the reference's length (the decoder normalises their sum).
pub fn offset_rows(reference: &Gaussians, target: &Gaussians, mask: u8) -> Vec<f32> {
    use dlgs::model::residual::AttrGroup;
    let mut rows = Vec::new();
    for i in 0..reference.len() {
        for g in groups_in(mask) {
            let r = g.values(reference, i);
            let t = g.values(target, i);
            if g == AttrGroup::Rotation {
                let nr = r.iter().map(|v| v * v).sum::<f32>().sqrt();
                let nt = t.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
                let dot: f32 = (0..4).map(|c| r[c] * t[c]).sum();
                let s = if dot < 0.0 { -nr / nt } else { nr / nt };
                rows.extend((0..4).map(|c| t[c] * s - r[c]));
            } else {
                rows.extend(r.iter().zip(t).map(|(a, b)| b - a));
            }
        }
    }
    rows
}

/// One block's gradients: of the MLP parameters, and of the latents as (index, value) pairs.
type BlockGradients = (Vec<f32>, Vec<(u32, f32)>);

/// Fit a field whose rows carry `positions` (of the reference state) to `targets` (`outputs`
/// values per Gaussian), applied to the dynamic set. `progress(done, total)` after each step.
pub fn fit(
    positions: &[[f32; 3]],
    targets: &[f32],
    s: &NtcFitSettings,
    sh_degree: u8,
    mut progress: impl FnMut(usize, usize),
) -> (NtcField, NtcFitReport) {
    let n = positions.len();
    let no = groups_in(s.groups)
        .map(|g| g.width(sh_degree, 0))
        .sum::<usize>();
    assert_eq!(targets.len(), n * no, "one target row per Gaussian");
    let levels = s.resolutions.len();
    let nf = s.features as usize;
    let ni = 3 * levels * nf;
    let nh = s.hidden;
    let table = 1usize << s.log2_table;
    let (lo, hi) = field_box(positions);
    // Gate: all entries +1, so it is one constant (the decoder's exact value is what the
    // closed loop uses; here the plain sigmoid of 1).
    let gate = 1.0 / (1.0 + (-1.0f32).exp());
    let look = Lookups {
        corners: positions
            .iter()
            .flat_map(|&p| {
                let u = normalised(p, lo, hi);
                PLANES.iter().flat_map(move |&(a, b)| {
                    s.resolutions
                        .iter()
                        .map(move |&r| corners_2d([u[a], u[b]], r, table))
                })
            })
            .collect(),
    };
    // Targets standardised per column: the loss weighs every attribute alike.
    let mut mean = vec![0f64; no];
    let mut sd = vec![0f64; no];
    for row in targets.chunks(no) {
        for o in 0..no {
            mean[o] += row[o] as f64 / n.max(1) as f64;
        }
    }
    for row in targets.chunks(no) {
        for o in 0..no {
            sd[o] += (row[o] as f64 - mean[o]).powi(2) / n.max(1) as f64;
        }
    }
    let target_rms: Vec<f64> = (0..no)
        .map(|o| (sd[o] + mean[o] * mean[o]).sqrt())
        .collect();
    let sd: Vec<f32> = sd.iter().map(|v| v.sqrt().max(1e-12) as f32).collect();
    let norm: Vec<f32> = targets
        .iter()
        .enumerate()
        .map(|(k, &v)| ((v as f64 - mean[k % no]) / sd[k % no] as f64) as f32)
        .collect();

    let mut rng = fastrand::Rng::with_seed(s.seed);
    let planes_len = 3 * levels * table * nf;
    let mut latent: Vec<f32> = (0..planes_len).map(|_| (rng.f32() - 0.5) * 2e-4).collect();
    let mut touched = vec![false; 3 * levels * table];
    for (k, c) in look.corners.iter().enumerate() {
        let pl = k % (3 * levels);
        for &(e, w) in c {
            if w > 0.0 {
                touched[pl * table + e as usize] = true;
            }
        }
    }
    let uni = |rng: &mut fastrand::Rng, fan_in: usize| {
        (rng.f32() * 2.0 - 1.0) * (1.0 / fan_in as f32).sqrt()
    };
    // Parameters: w1 (nh x ni), b1, w2 (no x nh), b2, in one vector for Adam.
    let (o_b1, o_w2, o_b2) = (nh * ni, nh * ni + nh, nh * ni + nh + no * nh);
    let np = o_b2 + no;
    let mut params: Vec<f32> = (0..np)
        .map(|k| match k {
            k if k < o_b1 => uni(&mut rng, ni),
            k if (o_w2..o_b2).contains(&k) => uni(&mut rng, nh),
            _ => 0.0,
        })
        .collect();
    let mut adam_p = Adam::new(np);
    let mut adam_l = Adam::new(planes_len);
    const BLOCK: usize = 512;
    let cells = 3 * levels;
    for it in 1..=s.iterations {
        let frac = it as f32 / s.iterations as f32;
        // Learning rates decay tenfold (grid) and hundredfold over the run, as the reference's
        // exponential schedules.
        let lr_grid = 0.01 * 0.01f32.powf(frac);
        let lr_mlp = 0.005 * 0.1f32.powf(frac);
        // Per block: gradients of the parameters and of the latents (as sparse (index, g)).
        let blocks: Vec<BlockGradients> = (0..n)
            .collect::<Vec<_>>()
            .par_chunks(BLOCK)
            .map(|ids| {
                let mut gp = vec![0f32; np];
                let mut gl = Vec::with_capacity(ids.len() * cells * 4 * nf);
                let mut x = vec![0f32; ni];
                let mut h = vec![0f32; nh];
                let mut dh = vec![0f32; nh];
                let mut dx = vec![0f32; ni];
                for &i in ids {
                    let cs = &look.corners[i * cells..(i + 1) * cells];
                    for (c, corners) in cs.iter().enumerate() {
                        let base = c * table;
                        for f in 0..nf {
                            let mut acc = 0f32;
                            for &(e, w) in corners {
                                let l = latent[(base + e as usize) * nf + f];
                                acc += if l >= 0.0 { w } else { -w };
                            }
                            x[c * nf + f] = acc * gate;
                        }
                    }
                    for j in 0..nh {
                        let mut a = params[o_b1 + j];
                        for k in 0..ni {
                            a += params[j * ni + k] * x[k];
                        }
                        h[j] = a.max(0.0);
                    }
                    dh.fill(0.0);
                    for o in 0..no {
                        let mut y = params[o_b2 + o];
                        for j in 0..nh {
                            y += params[o_w2 + o * nh + j] * h[j];
                        }
                        let d = 2.0 * (y - norm[i * no + o]) / (n * no) as f32;
                        gp[o_b2 + o] += d;
                        for j in 0..nh {
                            gp[o_w2 + o * nh + j] += d * h[j];
                            dh[j] += d * params[o_w2 + o * nh + j];
                        }
                    }
                    dx.fill(0.0);
                    for j in 0..nh {
                        if h[j] <= 0.0 {
                            continue;
                        }
                        gp[o_b1 + j] += dh[j];
                        for k in 0..ni {
                            gp[j * ni + k] += dh[j] * x[k];
                            dx[k] += dh[j] * params[j * ni + k];
                        }
                    }
                    for (c, corners) in cs.iter().enumerate() {
                        let base = c * table;
                        for &(e, w) in corners {
                            if w > 0.0 {
                                for f in 0..nf {
                                    let at = (base + e as usize) * nf + f;
                                    gl.push((at as u32, dx[c * nf + f] * gate * w));
                                }
                            }
                        }
                    }
                }
                (gp, gl)
            })
            .collect();
        let mut gp = vec![0f32; np];
        let mut gl = vec![0f32; planes_len];
        for (p, l) in &blocks {
            for (a, b) in gp.iter_mut().zip(p) {
                *a += b;
            }
            for &(at, g) in l {
                gl[at as usize] += g;
            }
        }
        // Straight-through: no gradient where the latent is outside [-1, 1].
        for (g, l) in gl.iter_mut().zip(&latent) {
            if l.abs() > 1.0 {
                *g = 0.0;
            }
        }
        adam_p.step(&mut params, &gp, lr_mlp, it);
        adam_l.step(&mut latent, &gl, lr_grid, it);
        progress(it, s.iterations);
    }

    // Back to real units: out = sd * y + mean.
    let mut w2 = params[o_w2..o_b2].to_vec();
    let mut b2 = params[o_b2..].to_vec();
    for o in 0..no {
        for j in 0..nh {
            w2[o * nh + j] *= sd[o];
        }
        b2[o] = (b2[o] as f64 * sd[o] as f64 + mean[o]) as f32;
    }
    // Entries no Gaussian reads take the more common value: they cost the least that way.
    let bits: Vec<bool> = latent.iter().map(|&l| l >= 0.0).collect();
    let used_ones = bits
        .iter()
        .enumerate()
        .filter(|&(k, &b)| b && touched[k / nf])
        .count();
    let used = touched.iter().filter(|&&t| t).count() * nf;
    let filler = 2 * used_ones > used;
    let planes: Vec<BitVec<u64, Lsb0>> = (0..cells)
        .map(|c| {
            (0..table * nf)
                .map(|k| {
                    if touched[c * table + k / nf] {
                        bits[c * table * nf + k]
                    } else {
                        filler
                    }
                })
                .collect()
        })
        .collect();
    let config = NtcConfig {
        resolutions: s.resolutions.clone(),
        features: s.features,
        log2_table: s.log2_table,
        gate_resolution: 3,
        gate_log2_table: 1,
    };
    let gate_bits = bitvec![u64, Lsb0; 1; config.gate_table()];
    let field = NtcField {
        config,
        bound_min: lo,
        bound_max: hi,
        planes,
        gate: gate_bits,
        mlp: NtcMlp {
            inputs: ni,
            hidden: nh,
            outputs: no,
            w1: params[..o_b1].to_vec(),
            b1: params[o_b1..o_w2].to_vec(),
            w2,
            b2,
        },
        groups: s.groups,
        sets: SET_DYNAMIC,
    };
    let rows = field.residuals_at(positions);
    let mut res = vec![0f64; no];
    for (k, (&r, &t)) in rows.iter().zip(targets).enumerate() {
        res[k % no] += ((r - t) as f64).powi(2) / n.max(1) as f64;
    }
    let report = NtcFitReport {
        target_rms,
        residual_rms: res.iter().map(|v| v.sqrt()).collect(),
    };
    (field, report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dlgs::model::residual::AttrGroup;

    #[test]
    fn a_smooth_position_field_is_learnt_and_deterministic() {
        // A wave over a 40 x 40 sheet: the offset is a smooth function of position.
        let mut pos = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                pos.push([i as f32 / 39.0, 0.0, j as f32 / 39.0]);
            }
        }
        let targets: Vec<f32> = pos
            .iter()
            .flat_map(|p| [0.0, 0.05 * (6.0 * p[0] + 2.0 * p[2]).sin(), 0.0])
            .collect();
        let s = NtcFitSettings {
            groups: AttrGroup::Position.bit(),
            iterations: 300,
            ..Default::default()
        };
        let (field, report) = fit(&pos, &targets, &s, 0, |_, _| {});
        let rms_y = report.residual_rms[1];
        assert!(
            rms_y < 0.25 * report.target_rms[1],
            "fit leaves {rms_y} of {}",
            report.target_rms[1]
        );
        let (again, _) = fit(&pos, &targets, &s, 0, |_, _| {});
        assert_eq!(field, again);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let (single, _) = one.install(|| fit(&pos, &targets, &s, 0, |_, _| {}));
        assert_eq!(field, single);
    }
}
