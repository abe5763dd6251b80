//! Tile binning and front-to-back compositing with two opacities.
//!
//! Per pixel, Gaussians are visited in (depth, index) order. For the colour:
//! `a = min(0.99, o * exp(power))`; skip if `a < 1/255`; `T' = T (1 - a)`; if `T' < 1e-4` the
//! pixel is finished and this Gaussian is not added; else `C += c a T`, `T = T'`.
//! The language image uses the language opacity with its own transmittance `Tl` and the same
//! per-Gaussian rule (skip if its own alpha < 1/255), and stops where the colour stops:
//! the paper's "colour transparency accumulation truncation".
//!
//! That is [`Accuracy::Exact`], bit for bit. [`Accuracy::Fast`] approximates it (see there):
//! `exp` by a cheaper `2^x`, and a pixel finishes at `T' < 1e-3`.

use rayon::prelude::*;

use crate::fastexp::{exp2_neg_fast, exp_neg};
use crate::project::{Splat2d, ALPHA_MIN, TILE};
use crate::Accuracy;

pub const T_MIN: f32 = 1e-4;
/// The fast knob's termination threshold.
pub const T_MIN_FAST: f32 = 1e-3;
pub const ALPHA_MAX: f32 = 0.99;
const TP: usize = (TILE * TILE) as usize;

/// Per-frame output buffers.
pub struct Accum {
    pub width: u32,
    pub height: u32,
    /// RGB, row-major, background included.
    pub color: Vec<f32>,
    /// Final colour transmittance per pixel.
    pub transmittance: Vec<f32>,
    /// `lang_width` channels per pixel when language was rendered.
    pub features: Option<Vec<f32>>,
    pub lang_width: usize,
    /// Tile-Gaussian pairs processed (work measure).
    pub pairs: usize,
}

/// Bin splats into tiles (depth order) and composite every tile, exactly.
/// `lang` holds the source Gaussians' language features when the language image is wanted.
pub fn rasterize(
    splats: &[Splat2d],
    width: u32,
    height: u32,
    background: [f32; 3],
    lang: Option<(&[f32], usize)>,
) -> Accum {
    rasterize_with(splats, width, height, background, lang, Accuracy::Exact)
}

/// [`rasterize`] with the compositor's accuracy chosen.
pub fn rasterize_with(
    splats: &[Splat2d],
    width: u32,
    height: u32,
    background: [f32; 3],
    lang: Option<(&[f32], usize)>,
    accuracy: Accuracy,
) -> Accum {
    let fast = accuracy == Accuracy::Fast;
    let tiles_x = width.div_ceil(TILE) as usize;
    let tiles_y = height.div_ceil(TILE) as usize;
    let tile_lists = bin_tiles(splats, width, height);
    let lw = lang.map_or(0, |(_, w)| w);
    let pairs = tile_lists.iter().map(Vec::len).sum();
    let outs: Vec<TileOut> = tile_lists
        .par_iter()
        .enumerate()
        .with_max_len(4)
        .map(|(i, list)| {
            let (tx, ty) = (i % tiles_x, i / tiles_x);
            let x0 = tx as u32 * TILE;
            let y0 = ty as u32 * TILE;
            let w = (width - x0).min(TILE);
            let h = (height - y0).min(TILE);
            match (lang, fast) {
                (Some(l), false) => composite::<true, false>(splats, list, x0, y0, w, h, Some(l)),
                (None, false) => composite::<false, false>(splats, list, x0, y0, w, h, None),
                (Some(l), true) => composite::<true, true>(splats, list, x0, y0, w, h, Some(l)),
                (None, true) => composite::<false, true>(splats, list, x0, y0, w, h, None),
            }
        })
        .collect();
    let n = (width * height) as usize;
    let mut color = vec![0.0; n * 3];
    let mut transmittance = vec![0.0; n];
    let mut features = lang.map(|_| vec![0.0; n * lw]);
    // Copy the tiles out one tile row (16 image rows) at a time, rows in parallel.
    let band = (width * TILE) as usize;
    let feat_bands: Vec<Option<&mut [f32]>> = match &mut features {
        Some(f) if lw > 0 => f.chunks_mut(band * lw).map(Some).collect(),
        _ => (0..tiles_y).map(|_| None).collect(),
    };
    color
        .par_chunks_mut(band * 3)
        .zip(transmittance.par_chunks_mut(band))
        .zip(feat_bands.into_par_iter())
        .zip(outs.par_chunks(tiles_x))
        .for_each(|(((col, trs), mut fb), row)| {
            for (tx, t) in row.iter().enumerate() {
                let x0 = tx as u32 * TILE;
                for ly in 0..t.h {
                    for lx in 0..t.w {
                        let l = (ly * TILE + lx) as usize;
                        let p = (ly * width + x0 + lx) as usize;
                        let tr = t.t[l];
                        for c in 0..3 {
                            col[p * 3 + c] = t.c[l * 3 + c] + tr * background[c];
                        }
                        trs[p] = tr;
                        if let Some(f) = &mut fb {
                            f[p * lw..(p + 1) * lw].copy_from_slice(&t.f[l * lw..(l + 1) * lw]);
                        }
                    }
                }
            }
        });
    Accum {
        width,
        height,
        color,
        transmittance,
        features,
        lang_width: lw,
        pairs,
    }
}

/// Pixel rectangle `(x0, y0, w, h)` of tile `i` (row-major, [`bin_tiles`]'s order) of a
/// `width` x `height` image.
pub fn tile_rect(width: u32, height: u32, i: usize) -> (u32, u32, u32, u32) {
    let tiles_x = width.div_ceil(TILE) as usize;
    let x0 = (i % tiles_x) as u32 * TILE;
    let y0 = (i / tiles_x) as u32 * TILE;
    (x0, y0, (width - x0).min(TILE), (height - y0).min(TILE))
}

/// Per tile (row-major), the splats that reach it, in (depth, index) order.
pub fn bin_tiles(splats: &[Splat2d], width: u32, height: u32) -> Vec<Vec<u32>> {
    let tiles_x = width.div_ceil(TILE) as usize;
    let tiles_y = height.div_ceil(TILE) as usize;
    // Sort by depth (positive finite floats sort like their bit patterns), ties by position.
    let mut order: Vec<u64> = splats
        .iter()
        .enumerate()
        .map(|(k, s)| ((s.depth.to_bits() as u64) << 32) | k as u64)
        .collect();
    order.par_sort_unstable();
    // Per chunk of the depth order, in parallel: per tile row, the splats whose ellipse reaches
    // it and the tiles [a, b) of that row it reaches. Each splat is read once, here.
    let parts: Vec<Vec<Vec<(u32, u16, u16)>>> = order
        .par_chunks(8192)
        .map(|chunk| {
            let mut rows: Vec<Vec<(u32, u16, u16)>> = vec![Vec::new(); tiles_y];
            for key in chunk {
                let k = (*key & 0xffff_ffff) as u32;
                let s = &splats[k as usize];
                let [_, ty0, _, ty1] = s.tiles();
                for ty in ty0..ty1 {
                    let (a, b) = band_tiles(s, ty as u32);
                    if a < b {
                        rows[ty as usize].push((k, a as u16, b as u16));
                    }
                }
            }
            rows
        })
        .collect();
    // Tile lists, built per tile row in parallel from the chunks in order (so in depth order),
    // then every tile composited in parallel (finer than rows, so a few heavy rows do not
    // leave a core idle).
    (0..tiles_y)
        .into_par_iter()
        .flat_map_iter(|ty| {
            let mut lists: Vec<Vec<u32>> = vec![Vec::new(); tiles_x];
            for part in &parts {
                for &(k, a, b) in &part[ty] {
                    for list in &mut lists[a as usize..b as usize] {
                        list.push(k);
                    }
                }
            }
            lists
        })
        .collect()
}

/// Tiles `[a, b)` of tile row `ty` that the splat's ellipse really reaches: its bounding box
/// is loose for thin, tilted ellipses. The x-extent of the ellipse over the row's band of pixel
/// centres is found in closed form (left edge convex, right edge concave in dy), widened by
/// one pixel like the per-row span in `composite`.
fn band_tiles(s: &Splat2d, ty: u32) -> (usize, usize) {
    let [t0, _, t1, _] = s.tiles().map(usize::from);
    let [ca, cb, cc] = s.conic;
    let det = ca * cc - cb * cb;
    if !(det > 0.0) {
        return (t0, t1);
    }
    let hx = (s.r2 * cc / det).sqrt();
    let hy = (s.r2 * ca / det).sqrt();
    let band0 = (ty * TILE) as f32 - s.mean[1];
    let band1 = band0 + (TILE - 1) as f32;
    let (d0, d1) = (band0.max(-hy), band1.min(hy));
    if !(d0 <= d1) {
        return (t0, t0);
    }
    let edge = |dy: f32, sign: f32| {
        (-cb * dy
            + sign
                * (cb * cb * dy * dy - ca * (cc * dy * dy - s.r2))
                    .max(0.0)
                    .sqrt())
            / ca
    };
    // Where the ellipse is widest to the right (+) and to the left (-).
    let d_right = -cb * hx / cc;
    let right = if (d0..=d1).contains(&d_right) {
        hx
    } else {
        edge(d0, 1.0).max(edge(d1, 1.0))
    };
    let left = if (d0..=d1).contains(&-d_right) {
        -hx
    } else {
        edge(d0, -1.0).min(edge(d1, -1.0))
    };
    let lo = ((s.mean[0] + left - 1.0) / TILE as f32).floor();
    let hi = ((s.mean[0] + right + 2.0) / TILE as f32).floor() + 1.0;
    if !(lo.is_finite() && hi.is_finite()) {
        return (t0, t1);
    }
    let a = (lo.max(t0 as f32) as usize).min(t1);
    let b = (hi.max(0.0) as usize).clamp(a, t1);
    (a, b)
}

/// Splats gathered per step of [`composite`].
const CHUNK: usize = 16;

/// Composite one splat over the tile at (x0, y0), size w x h.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn splat_on_tile<const LANG: bool, const FAST: bool>(
    acc: &mut TileAcc,
    s: &Splat2d,
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
    lang: Option<(&[f32], usize)>,
) {
    let xa0 = ((s.px[0] as u32).max(x0) - x0) as f32;
    let xb0 = ((s.px[2] as u32).min(x0 + w) - x0) as f32;
    let ya = (s.px[1] as u32).max(y0) - y0;
    let yb = (s.px[3] as u32).min(y0 + h) - y0;
    let [ca, cbk, cc] = s.conic;
    let cx = s.mean[0] - x0 as f32;
    let feat = match lang {
        Some((all, lw)) if LANG => &all[s.index as usize * lw..(s.index as usize + 1) * lw],
        _ => &[][..],
    };
    // A splat whose box covers only one half of the tile's rows (most splats are a few pixels
    // wide) needs no per-row span: outside the ellipse its alpha is below 1/255 anyway.
    if xb0 <= 8.0 || xa0 >= 8.0 {
        for ly in ya..yb {
            let r = ly as usize;
            if !acc.row_live[r] {
                continue;
            }
            let dy = (y0 + ly) as f32 - s.mean[1];
            if xb0 <= 8.0 {
                row_span::<8, 0, LANG, FAST>(acc, r, s, cx, dy, xa0, xb0, feat)
            } else {
                row_span::<8, 8, LANG, FAST>(acc, r, s, cx, dy, xa0, xb0, feat)
            }
            acc.update_row(r);
        }
        return;
    }
    // Fast: the span's terms set once per splat and tile, a multiplication for the divisions.
    let (inv_a, det, ar2) = (1.0 / ca, ca * cc - cbk * cbk, ca * s.r2);
    for ly in ya..yb {
        let r = ly as usize;
        if !acc.row_live[r] {
            continue;
        }
        let dy = (y0 + ly) as f32 - s.mean[1];
        // Exact span of this row inside the ellipse A dx^2 + 2B dx dy + C dy^2 <= r2, widened by
        // one pixel against rounding; outside it alpha < 1/255 so nothing would be added.
        let disc = if FAST {
            ar2 - det * dy * dy
        } else {
            cbk * cbk * dy * dy - ca * (cc * dy * dy - s.r2)
        };
        if !(disc >= 0.0) {
            continue;
        }
        let sq = disc.sqrt();
        let (l, rt) = if FAST {
            ((-cbk * dy - sq) * inv_a, (-cbk * dy + sq) * inv_a)
        } else {
            ((-cbk * dy - sq) / ca, (-cbk * dy + sq) / ca)
        };
        let xa = ((cx + l).floor() - 1.0).max(xa0);
        let xb = ((cx + rt).ceil() + 2.0).min(xb0);
        if !(xa < xb) {
            continue;
        }
        // Most splats are a few pixels wide: touch only the half-row they cover.
        if xb <= 8.0 {
            row_span::<8, 0, LANG, FAST>(acc, r, s, cx, dy, xa, xb, feat)
        } else if xa >= 8.0 {
            row_span::<8, 8, LANG, FAST>(acc, r, s, cx, dy, xa, xb, feat)
        } else {
            row_span::<16, 0, LANG, FAST>(acc, r, s, cx, dy, xa, xb, feat)
        }
        acc.update_row(r);
    }
}

struct TileOut {
    w: u32,
    h: u32,
    c: Vec<f32>,
    t: Vec<f32>,
    f: Vec<f32>,
}

/// Per-tile accumulators; rows of 16 lanes so the pixel loops vectorise.
struct TileAcc {
    t: [[f32; L]; L],
    cr: [[f32; L]; L],
    cg: [[f32; L]; L],
    cb: [[f32; L]; L],
    /// 1.0 while a pixel still accumulates, 0.0 once its colour transmittance terminated.
    live: [[f32; L]; L],
    tl: [[f32; L]; L],
    /// Whether a tile row still has a live pixel, and how many rows do.
    row_live: [bool; L],
    rows_live: u32,
    /// Language features, channel-planar: `f[c][row][lane]`.
    f: Vec<[[f32; L]; L]>,
}

const L: usize = TILE as usize;

impl TileAcc {
    /// After row `r` was drawn: mark it finished once none of its pixels is live. An OR of the
    /// bits (live is 0.0 or 1.0) rather than a sum, so it vectorises and carries no long chain.
    #[inline(always)]
    fn update_row(&mut self, r: usize) {
        if self.live[r].iter().fold(0u32, |m, v| m | v.to_bits()) == 0 {
            self.row_live[r] = false;
            self.rows_live -= 1;
        }
    }
}

/// One Gaussian on one tile row, lanes `[B, B + N)` of the row (N = 8 or 16): the per-pixel
/// rule of the module comment, written branch-free so it vectorises.
#[inline(always)]
fn row_span<const N: usize, const B: usize, const LANG: bool, const FAST: bool>(
    acc: &mut TileAcc,
    r: usize,
    s: &Splat2d,
    cx: f32,
    dy: f32,
    xa: f32,
    xb: f32,
    feat: &[f32],
) {
    let [ca, cbk, cc] = s.conic;
    let (o, ol) = (s.opacity, s.lang_opacity);
    let [sr, sg, sb] = s.color;
    // power = -0.5 A dx^2 + p1 dx + p0 with the dy terms hoisted out of the lane loop.
    let p0 = -0.5 * cc * dy * dy;
    let p1 = -cbk * dy;
    // Fast: power * log2(e) as a polynomial in the lane's x, (q2 x + q1) x + q0.
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    let q2 = -0.5 * ca * LOG2E;
    let q1 = (ca * cx + p1) * LOG2E;
    let q0 = ((-0.5 * ca * cx - p1) * cx + p0) * LOG2E;
    let mut wl = [0.0f32; N];
    {
        let tr = &mut acc.t[r][B..B + N];
        let lv = &mut acc.live[r][B..B + N];
        let rr = &mut acc.cr[r][B..B + N];
        let rg = &mut acc.cg[r][B..B + N];
        let rb = &mut acc.cb[r][B..B + N];
        let tlr = &mut acc.tl[r][B..B + N];
        for j in 0..N {
            let x = (B + j) as f32;
            // Fast: no span mask; outside the ellipse alpha < 1/255 anyway, up to rounding.
            let span = FAST || (x >= xa && x < xb);
            let inside = if span { lv[j] } else { 0.0 };
            let g = if FAST {
                exp2_neg_fast((q2 * x + q1) * x + q0)
            } else {
                let dx = x - cx;
                exp_neg((-0.5 * ca * dx * dx + p1 * dx + p0).min(0.0))
            };
            let a = (o * g).min(ALPHA_MAX);
            let ok = if a >= ALPHA_MIN { inside } else { 0.0 };
            let test_t = tr[j] * (1.0 - a);
            let t_min = if FAST { T_MIN_FAST } else { T_MIN };
            let term = if test_t < t_min { ok } else { 0.0 };
            let add = ok - term;
            let wgt = add * a * tr[j];
            rr[j] += sr * wgt;
            rg[j] += sg * wgt;
            rb[j] += sb * wgt;
            tr[j] += add * (test_t - tr[j]);
            lv[j] -= term;
            if LANG {
                let al = (ol * g).min(ALPHA_MAX);
                // Language stops where the colour stopped (live after this Gaussian's update).
                let okl = if al >= ALPHA_MIN && span { lv[j] } else { 0.0 };
                wl[j] = okl * al * tlr[j];
                tlr[j] -= wl[j];
            }
        }
    }
    // Rows where the language alpha stays below 1/255 (or the colour finished) add nothing:
    // an OR of the weights' bits (all >= +0.0) skips their nine channel updates.
    if LANG && wl.iter().fold(0u32, |m, v| m | v.to_bits()) != 0 {
        for (c, fc) in feat.iter().enumerate() {
            let dst = &mut acc.f[c][r][B..B + N];
            for j in 0..N {
                dst[j] += fc * wl[j];
            }
        }
    }
}

/// Composite one tile at pixel origin (x0, y0), size w x h. Compiled for AVX2+FMA, SSE4.1 and
/// baseline x86-64, chosen at run time (`multiversion`); all give identical results because
/// the kernel uses no fused multiply-add intrinsics and LLVM does not contract f32 ops
/// (tests/exact_compositing.rs checks the bits). An AVX-512 version was tried: 3 % faster in
/// colour but 18 % slower with language (273k scene, one thread), so it is not built.
#[multiversion::multiversion(targets("x86_64+avx2+fma", "x86_64+sse4.1"))]
fn composite<const LANG: bool, const FAST: bool>(
    splats: &[Splat2d],
    list: &[u32],
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
    lang: Option<(&[f32], usize)>,
) -> TileOut {
    let lw = lang.map_or(0, |(_, w)| w);
    let mut acc = TileAcc {
        t: [[1.0; L]; L],
        cr: [[0.0; L]; L],
        cg: [[0.0; L]; L],
        cb: [[0.0; L]; L],
        live: [[0.0; L]; L],
        tl: [[1.0; L]; L],
        row_live: [false; L],
        rows_live: h,
        f: vec![[[0.0; L]; L]; if LANG { lw } else { 0 }],
    };
    for (row, flag) in acc.live.iter_mut().zip(&mut acc.row_live).take(h as usize) {
        row[..w as usize].fill(1.0);
        *flag = true;
    }
    // The splats are gathered a chunk at a time first: independent loads, so their cache misses
    // overlap instead of stalling one splat after the other.
    let mut buf = [Splat2d::default(); CHUNK];
    for ids in list.chunks(CHUNK) {
        if acc.rows_live == 0 {
            break;
        }
        for (b, &k) in buf.iter_mut().zip(ids) {
            *b = splats[k as usize];
        }
        for s in &buf[..ids.len()] {
            if acc.rows_live == 0 {
                break;
            }
            splat_on_tile::<LANG, FAST>(&mut acc, s, x0, y0, w, h, lang);
        }
    }
    let mut c = vec![0.0f32; TP * 3];
    let mut tt = vec![0.0f32; TP];
    let mut f = vec![0.0f32; if LANG { TP * lw } else { 0 }];
    for i in 0..TP {
        let (y, x) = (i / L, i % L);
        c[i * 3] = acc.cr[y][x];
        c[i * 3 + 1] = acc.cg[y][x];
        c[i * 3 + 2] = acc.cb[y][x];
        tt[i] = acc.t[y][x];
        for (ch, plane) in acc.f.iter().enumerate() {
            f[i * lw + ch] = plane[y][x];
        }
    }
    TileOut { w, h, c, t: tt, f }
}
