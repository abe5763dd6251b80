//! The fit of an `AHAC` context model to fixed symbols: binary grid entries through a
//! straight-through sign (a real latent per bit; the forward pass uses its sign, the gradient
//! passes where `|latent| <= 1`, as HAC's `STE_binary`) and `mlp_grid` (one hidden ReLU layer),
//! trained by Adam to minimise the symbols' bits under the model (rate only: the symbols and
//! steps are fixed, `adj = 0`).
//!
//! Deterministic on any thread count: anchors are processed in blocks whose number depends only
//! on the anchor count, and the blocks' partial gradients are added in block order.

use rayon::prelude::*;

use dlgs::model::hac_context::{GridShape, HacContext, ATTR_CHANNELS};
use dlgs::model::ntc::{lookup, PLANES};

use super::rate::symbol_rate;
use crate::adam::Adam;

/// Outputs the fit trains: the mean and scale of every channel (the three step adjustments
/// stay 0).
pub(super) const TRAINED_OUT: usize = dlgs::model::hac_context::CONTEXT_OUT - 3;

/// Fixed inputs of a fit: the anchors' grid corners and symbols.
pub(super) struct Problem<'a> {
    pub grid3: &'a GridShape,
    pub grid2: &'a GridShape,
    /// Dequantised positions, normalised to the box (each `u` in [0, 1]).
    pub u: Vec<[f32; 3]>,
    pub symbols: &'a [Vec<i32>; 3],
    pub steps: [f32; 3],
    /// Per trained output: real value = `shift + unit * y`.
    pub shift: Vec<f32>,
    pub unit: Vec<f32>,
}

/// A fitted model in training units.
pub(super) struct Trained {
    pub latent: Vec<f32>,
    /// Start of each level in `latent` (entries x features), and its feature count.
    pub level_at: Vec<(usize, usize)>,
    pub touched: Vec<bool>,
    pub hidden: usize,
    pub w1: Vec<f32>,
    pub b1: Vec<f32>,
    pub w2: Vec<f32>,
    pub b2: Vec<f32>,
    /// Mean bits per anchor at each logged iteration (every tenth and the last).
    pub log: Vec<(usize, f64)>,
}

/// Per anchor, per level: up to 8 kept corners as (latent index of feature 0, weight / sum).
struct Corners {
    cells: usize,
    list: Vec<[(u32, f32); 8]>,
}

fn level_layout(g3: &GridShape, g2: &GridShape) -> Vec<(usize, usize, u32, usize)> {
    // (start in latent, features, resolution, table entries) per level in §6.13.4 order.
    let bits = HacContext::level_bits(g3, g2);
    let n3 = g3.resolutions.len();
    let mut at = 0;
    bits.iter()
        .enumerate()
        .map(|(l, &n)| {
            let (f, r, t) = if l < n3 {
                (
                    g3.features as usize,
                    g3.resolutions[l],
                    1usize << g3.log2_table,
                )
            } else {
                let k = (l - n3) % g2.resolutions.len();
                (
                    g2.features as usize,
                    g2.resolutions[k],
                    1usize << g2.log2_table,
                )
            };
            let start = at;
            at += n;
            (start, f, r, t)
        })
        .collect()
}

fn corners(p: &Problem, layout: &[(usize, usize, u32, usize)]) -> Corners {
    let n3 = p.grid3.resolutions.len();
    let n2 = p.grid2.resolutions.len();
    let cells = layout.len();
    let mut list = Vec::with_capacity(p.u.len() * cells);
    for &u in &p.u {
        for (l, &(start, f, r, table)) in layout.iter().enumerate() {
            let mut c = [(0u32, 0f32); 8];
            let mut k = 0;
            let mut push = |e: usize, w: f32| {
                c[k] = ((start + e * f) as u32, w);
                k += 1;
            };
            let s = if l < n3 {
                lookup::<3>(u, r, table, &mut push)
            } else {
                let (a, b) = PLANES[(l - n3) / n2];
                lookup::<2>([u[a], u[b]], r, table, &mut push)
            };
            for slot in &mut c[..k] {
                slot.1 /= s;
            }
            list.push(c);
        }
    }
    Corners { cells, list }
}

/// Block gradients: of the MLP parameters, and of the latents as (index, value).
type BlockGradients = (Vec<f32>, Vec<(u32, f32)>, f64);

pub(super) struct Schedule {
    pub hidden: usize,
    pub iterations: usize,
    pub batch: usize,
    pub seed: u64,
}

/// Fit the model to the problem. `progress(done, total)` after each iteration.
pub(super) fn fit(p: &Problem, s: &Schedule, progress: &mut dyn FnMut(usize, usize)) -> Trained {
    let layout = level_layout(p.grid3, p.grid2);
    let look = corners(p, &layout);
    let n = p.u.len();
    let ni: usize = layout.iter().map(|l| l.1).sum();
    let nh = s.hidden;
    let no = TRAINED_OUT;
    let latent_len: usize = HacContext::level_bits(p.grid3, p.grid2).iter().sum();
    let mut rng = fastrand::Rng::with_seed(s.seed);
    let mut latent: Vec<f32> = (0..latent_len).map(|_| (rng.f32() - 0.5) * 0.2).collect();
    let mut touched = vec![false; latent_len];
    for (k, cs) in look.list.iter().enumerate() {
        let f = layout[k % look.cells].1;
        for &(e, w) in cs {
            if w > 0.0 {
                touched[e as usize..e as usize + f].fill(true);
            }
        }
    }
    let uni = |rng: &mut fastrand::Rng, scale: f32| (rng.f32() * 2.0 - 1.0) * scale;
    let (o_b1, o_w2, o_b2) = (nh * ni, nh * ni + nh, nh * ni + nh + no * nh);
    let np = o_b2 + no;
    let first_scale = (1.0 / ni.max(1) as f32).sqrt();
    let mut params: Vec<f32> = (0..np)
        .map(|k| match k {
            k if k < o_b1 => uni(&mut rng, first_scale),
            k if k < o_w2 => 0.1,
            k if k < o_b2 => uni(&mut rng, 0.01),
            _ => 0.0,
        })
        .collect();
    // Scale outputs start at one unit (the channel's spread).
    let mut at = 0;
    for &ch in &ATTR_CHANNELS {
        params[o_b2 + at + ch..o_b2 + at + 2 * ch].fill(1.0);
        at += 2 * ch;
    }
    let attr_of: Vec<(usize, usize, usize)> = {
        // Per channel of the 86: (attribute, channel, output of its mean).
        let mut v = Vec::new();
        let mut base = 0;
        for (a, &ch) in ATTR_CHANNELS.iter().enumerate() {
            v.extend((0..ch).map(|c| (a, c, base + c)));
            base += 2 * ch;
        }
        v
    };
    let mut adam_p = Adam::new(np);
    let mut adam_l = Adam::new(latent_len);
    let batch = s.batch.min(n).max(1);
    let blocks_per_batch = 16usize;
    let mut order: Vec<usize> = (0..n).collect();
    let mut log = Vec::new();
    for it in 1..=s.iterations {
        if batch < n && (it - 1) * batch % n < batch {
            rng.shuffle(&mut order);
        }
        let start = (it - 1) * batch % n;
        let ids: Vec<usize> = (0..batch).map(|k| order[(start + k) % n]).collect();
        let frac = it as f32 / s.iterations as f32;
        let lr_grid = 0.02 * 0.05f32.powf(frac);
        let lr_mlp = 0.01 * 0.05f32.powf(frac);
        let scale = 1.0 / ids.len() as f64;
        let logged = it % 10 == 0 || it == s.iterations || it == 1;
        let block = ids.len().div_ceil(blocks_per_batch).max(1);
        let blocks: Vec<BlockGradients> = ids
            .par_chunks(block)
            .map(|ids| {
                let mut gp = vec![0f32; np];
                let mut gl = Vec::new();
                let mut bits = 0f64;
                let mut x = vec![0f32; ni];
                let mut h = vec![0f32; nh];
                let mut dh = vec![0f32; nh];
                let mut dx = vec![0f32; ni];
                for &i in ids {
                    let cs = &look.list[i * look.cells..(i + 1) * look.cells];
                    let mut xi = 0;
                    for (l, corners) in cs.iter().enumerate() {
                        let f = layout[l].1;
                        for ff in 0..f {
                            let mut acc = 0f32;
                            for &(e, w) in corners {
                                let v = latent[e as usize + ff];
                                acc += if v >= 0.0 { w } else { -w };
                            }
                            x[xi + ff] = acc;
                        }
                        xi += f;
                    }
                    for j in 0..nh {
                        let mut a = params[o_b1 + j];
                        for k in 0..ni {
                            a += params[j * ni + k] * x[k];
                        }
                        h[j] = a.max(0.0);
                    }
                    dh.fill(0.0);
                    for &(a, c, om) in &attr_of {
                        let ch = ATTR_CHANNELS[a];
                        let os = om + ch;
                        let (wm, ws) = (o_w2 + om * nh, o_w2 + os * nh);
                        let mut ym = params[o_b2 + om];
                        let mut ys = params[o_b2 + os];
                        for j in 0..nh {
                            ym += params[wm + j] * h[j];
                            ys += params[ws + j] * h[j];
                        }
                        let q = p.steps[a] as f64;
                        let mu = p.shift[om] as f64 + p.unit[om] as f64 * ym as f64;
                        let sigma = p.unit[os] as f64 * ys as f64;
                        let floor = 0.05 * q;
                        let r =
                            symbol_rate(p.symbols[a][i * ch + c], q, mu, sigma.max(floor), logged);
                        bits += r.bits;
                        let gm = (r.d_mu * p.unit[om] as f64 * scale) as f32;
                        let mut gs = (r.d_sigma * p.unit[os] as f64 * scale) as f32;
                        if sigma < floor {
                            gs = gs.min(0.0);
                        }
                        gp[o_b2 + om] += gm;
                        gp[o_b2 + os] += gs;
                        for j in 0..nh {
                            gp[wm + j] += gm * h[j];
                            gp[ws + j] += gs * h[j];
                            dh[j] += gm * params[wm + j] + gs * params[ws + j];
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
                    let mut xi = 0;
                    for (l, corners) in cs.iter().enumerate() {
                        let f = layout[l].1;
                        for &(e, w) in corners {
                            if w > 0.0 {
                                for ff in 0..f {
                                    gl.push((e + ff as u32, dx[xi + ff] * w));
                                }
                            }
                        }
                        xi += f;
                    }
                }
                (gp, gl, bits)
            })
            .collect();
        let mut gp = vec![0f32; np];
        let mut gl = vec![0f32; latent_len];
        let mut bits = 0f64;
        for (p, l, b) in &blocks {
            for (a, b) in gp.iter_mut().zip(p) {
                *a += b;
            }
            for &(at, g) in l {
                gl[at as usize] += g;
            }
            bits += b;
        }
        for (g, l) in gl.iter_mut().zip(&latent) {
            if l.abs() > 1.0 {
                *g = 0.0;
            }
        }
        adam_p.step(&mut params, &gp, lr_mlp, it);
        adam_l.step(&mut latent, &gl, lr_grid, it);
        if logged {
            log.push((it, bits * scale));
        }
        progress(it, s.iterations);
    }
    Trained {
        latent,
        level_at: layout.iter().map(|l| (l.0, l.1)).collect(),
        touched,
        hidden: nh,
        w1: params[..o_b1].to_vec(),
        b1: params[o_b1..o_w2].to_vec(),
        w2: params[o_w2..o_b2].to_vec(),
        b2: params[o_b2..].to_vec(),
        log,
    }
}
