//! `CSOG`: canonical Gaussians as quantised attribute grids (format-spec §6.5). The encoder
//! sorts each set so that grid neighbours are similar (`dlgs-encoder`'s grid sort); this module
//! only quantises, lays every channel out as a `width`-wide grid in set order and codes it
//! losslessly with [`grid_coder`]. Decoding restores the quantised values exactly.

use std::borrow::Cow;

use rayon::prelude::*;

use crate::bytes::{ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, ErrorKind, Result};
use crate::limits::Limits;
use crate::model::{sigmoid, Canonical, Gaussians};
use crate::payload::adaptive_coder::Mode;
use crate::payload::grid_coder::{self, GridCodec};
use crate::payload::{
    colour_lattice, grid_shaping, half_range, kd_layout, octree_positions, task_queue,
};

/// Bits per attribute (1..=16 each; the rotation's dropped-component index always uses 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct QuantBits {
    pub position: u8,
    pub log_scale: u8,
    /// Each of the three smallest quaternion components.
    pub rotation: u8,
    /// Colour and language opacity, after the sigmoid.
    pub opacity: u8,
    pub sh_dc: u8,
    /// SH band 1 (coefficients 1-3).
    pub sh_rest: u8,
    /// SH bands 2 and 3 (coefficients 4-15): on real scenes their effect on the image is
    /// scene-dependent and mostly small (BENCHMARKS.md "SH bands").
    pub sh_high: u8,
    pub lang: u8,
}

impl QuantBits {
    /// Renders within ~65 dB of the unquantised model (measured on the reference-run fixture,
    /// BENCHMARKS.md "Ingest"): for re-packing trained models at a fraction of their bytes.
    pub const NEAR_LOSSLESS: QuantBits = QuantBits {
        position: 16,
        log_scale: 11,
        rotation: 12,
        opacity: 11,
        sh_dc: 11,
        sh_rest: 9,
        sh_high: 9,
        lang: 11,
    };
    pub const HIGH: QuantBits = QuantBits {
        position: 14,
        log_scale: 8,
        rotation: 9,
        opacity: 8,
        sh_dc: 8,
        sh_rest: 6,
        sh_high: 5,
        lang: 8,
    };
    pub const MEDIUM: QuantBits = QuantBits {
        position: 13,
        log_scale: 7,
        rotation: 8,
        opacity: 7,
        sh_dc: 7,
        sh_rest: 5,
        sh_high: 4,
        lang: 7,
    };
    pub const LOW: QuantBits = QuantBits {
        position: 12,
        log_scale: 6,
        rotation: 7,
        opacity: 6,
        sh_dc: 6,
        sh_rest: 4,
        sh_high: 3,
        lang: 6,
    };
    pub fn preset(name: &str) -> Option<QuantBits> {
        match name {
            "near-lossless" => Some(Self::NEAR_LOSSLESS),
            "high" => Some(Self::HIGH),
            "medium" => Some(Self::MEDIUM),
            "low" => Some(Self::LOW),
            _ => None,
        }
    }
    /// The attribute group called `name` (`position`, `log_scale`, `rotation`, `opacity`,
    /// `sh_dc`, `sh_rest`, `sh_high`, `lang`: the `--bits` keys).
    pub fn field_mut(&mut self, name: &str) -> Option<&mut u8> {
        Some(match name {
            "position" => &mut self.position,
            "log_scale" => &mut self.log_scale,
            "rotation" => &mut self.rotation,
            "opacity" => &mut self.opacity,
            "sh_dc" => &mut self.sh_dc,
            "sh_rest" => &mut self.sh_rest,
            "sh_high" => &mut self.sh_high,
            "lang" => &mut self.lang,
            _ => return None,
        })
    }

    /// Every group `by` bits coarser, at least 1 bit.
    pub fn coarser(&self, by: u8) -> QuantBits {
        let c = |b: u8| b.saturating_sub(by).max(1);
        QuantBits {
            position: c(self.position),
            log_scale: c(self.log_scale),
            rotation: c(self.rotation),
            opacity: c(self.opacity),
            sh_dc: c(self.sh_dc),
            sh_rest: c(self.sh_rest),
            sh_high: c(self.sh_high),
            lang: c(self.lang),
        }
    }

    fn all(&self) -> [u8; 8] {
        [
            self.position,
            self.log_scale,
            self.rotation,
            self.opacity,
            self.sh_dc,
            self.sh_rest,
            self.sh_high,
            self.lang,
        ]
    }
}

/// What a channel holds, in payload order (§6.5.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Position(usize),
    LogScale(usize),
    RotIndex,
    Rotation(usize),
    Opacity,
    Sh(usize),
    LangOpacity,
    Lang(usize),
}

/// Index of `Kind::Rotation(0)` in every set's channel list.
const FIRST_ROTATION: usize = 7;

fn channels(g: &Gaussians) -> Vec<Kind> {
    let mut k: Vec<Kind> = (0..3).map(Kind::Position).collect();
    k.extend((0..3).map(Kind::LogScale));
    k.push(Kind::RotIndex);
    k.extend((0..3).map(Kind::Rotation));
    k.push(Kind::Opacity);
    k.extend((0..g.sh_stride()).map(Kind::Sh));
    if g.has_language() {
        k.push(Kind::LangOpacity);
        k.extend((0..g.lang_width).map(Kind::Lang));
    }
    k
}

impl Kind {
    fn bits(self, b: &QuantBits) -> u8 {
        match self {
            Kind::Position(_) => b.position,
            Kind::LogScale(_) => b.log_scale,
            Kind::RotIndex => 2,
            Kind::Rotation(_) => b.rotation,
            Kind::Opacity | Kind::LangOpacity => b.opacity,
            Kind::Sh(j) if j < 3 => b.sh_dc,
            Kind::Sh(j) if j < 12 => b.sh_rest,
            Kind::Sh(_) => b.sh_high,
            Kind::Lang(_) => b.lang,
        }
    }
}

/// Normalised quaternion, identity for a zero one, sign so the largest |component| is positive;
/// returns (index of the largest, the other three in order).
fn smallest_three(q: [f32; 4]) -> (usize, [f32; 3]) {
    let n = (q.iter().map(|v| v * v).sum::<f32>()).sqrt();
    let q = if n > 0.0 && n.is_finite() {
        q.map(|v| v / n)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    };
    let m = (0..4)
        .max_by(|&a, &b| q[a].abs().total_cmp(&q[b].abs()).then(b.cmp(&a)))
        .expect("four components");
    let s = if q[m] < 0.0 { -1.0 } else { 1.0 };
    let mut rest = [0.0; 3];
    let mut j = 0;
    for (i, v) in q.iter().enumerate() {
        if i != m {
            rest[j] = v * s;
            j += 1;
        }
    }
    (m, rest)
}

/// The channel's values before quantisation.
fn values(g: &Gaussians, k: Kind) -> Vec<f32> {
    let n = g.len();
    match k {
        Kind::Position(a) => g.positions.iter().map(|p| p[a]).collect(),
        Kind::LogScale(a) => g.log_scales.iter().map(|p| p[a]).collect(),
        Kind::RotIndex => g
            .rotations
            .iter()
            .map(|&q| smallest_three(q).0 as f32)
            .collect(),
        Kind::Rotation(a) => g
            .rotations
            .iter()
            .map(|&q| smallest_three(q).1[a])
            .collect(),
        Kind::Opacity => g.opacity.iter().map(|&o| sigmoid(o)).collect(),
        Kind::LangOpacity => g.lang_opacity.iter().map(|&o| sigmoid(o)).collect(),
        Kind::Sh(j) => (0..n).map(|i| g.sh[i * g.sh_stride() + j]).collect(),
        Kind::Lang(j) => (0..n).map(|i| g.lang[i * g.lang_width + j]).collect(),
    }
}

/// Log-scales more than this below the channel's largest are raised to it before
/// quantisation: an axis under e^-14 (~1e-6) of the largest Gaussian's is far below a pixel at
/// any practical resolution, while trained scenes hold collapsed axes near e^-23 that would
/// otherwise take half the range (format-spec §6.5.2; measured in BENCHMARKS.md).
pub const LOG_SCALE_SPAN: f32 = 14.0;

/// Log-scales are also raised to `ln(R) - LOG_SCALE_BELOW_RADIUS`, `R` the set's robust
/// radius ([`robust_radius`]): with the whole scene 4,000 pixels across, a pixel is about
/// e^-7.6 R, so the floor is a twentieth of a pixel there, while the quantisation step shrinks
/// by the span it no longer covers (on the real lod2 tile at `medium`: 48.8 dB instead of 46.9
/// for 0.3 % fewer bytes; BENCHMARKS.md).
pub const LOG_SCALE_BELOW_RADIUS: f32 = 10.0;

/// 80th percentile of the distances of the finite positions from their per-axis median
/// (what the renderer's orbit cameras frame); `None` for an empty or degenerate set.
pub fn robust_radius(positions: &[[f32; 3]]) -> Option<f32> {
    let pts: Vec<[f32; 3]> = positions
        .iter()
        .copied()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    if pts.is_empty() {
        return None;
    }
    let mut c = [0f32; 3];
    for (a, ca) in c.iter_mut().enumerate() {
        let mut v: Vec<f32> = pts.iter().map(|p| p[a]).collect();
        let mid = v.len() / 2;
        *ca = *v.select_nth_unstable_by(mid, f32::total_cmp).1;
    }
    let mut d: Vec<f32> = pts
        .iter()
        .map(|p| {
            let (x, y, z) = (p[0] - c[0], p[1] - c[1], p[2] - c[2]);
            (x * x + y * y + z * z).sqrt()
        })
        .collect();
    let k = (d.len() * 8 / 10).min(d.len() - 1);
    let r = *d.select_nth_unstable_by(k, f32::total_cmp).1;
    (r > 0.0 && r.is_finite()).then_some(r)
}

/// Quantisation range at `bits`: fixed for opacities, rotation components and the index; the
/// data's min/max otherwise (log-scales: raised to `max - LOG_SCALE_SPAN` and to
/// `ln(radius) - LOG_SCALE_BELOW_RADIUS`, never above the max; SH bands 1-3: widened to put a
/// level at zero where that is cheaper, [`zero_on_level`]). Every range but a position, rotation
/// or zero-on-level one is then widened to binary16 ends where that coarsens its step by at most
/// a 256th and moves each end by under half a step ([`half_range::snap`]): layout 4 stores such
/// a range in half the bytes (§6.5.7).
fn range(k: Kind, v: &[f32], radius: Option<f32>, bits: u8) -> (f32, f32) {
    let min_max = || {
        v.iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            })
    };
    let (lo, hi) = match k {
        Kind::Opacity | Kind::LangOpacity => (0.0, 1.0),
        Kind::Rotation(_) => (
            -std::f32::consts::FRAC_1_SQRT_2,
            std::f32::consts::FRAC_1_SQRT_2,
        ),
        Kind::RotIndex => (0.0, 3.0),
        _ if v.is_empty() => (0.0, 0.0),
        Kind::LogScale(_) => {
            let (lo, hi) = min_max();
            let floor = radius.map_or(f32::NEG_INFINITY, |r| r.ln() - LOG_SCALE_BELOW_RADIUS);
            (lo.max(hi - LOG_SCALE_SPAN).max(floor.min(hi)), hi)
        }
        Kind::Sh(j) if j >= 3 => {
            let (lo, hi) = min_max();
            let plain = half_range::snap(lo, hi, bits);
            return cheaper_range(v, plain, zero_on_level(lo, hi, bits), bits);
        }
        // SH DC from 8-bit colours: levels on the colours, not snapped to binary16 ends
        // (that would move them off the colours again).
        Kind::Sh(_) => match colour_lattice::range(v, bits) {
            Some(r) => return r,
            None => min_max(),
        },
        _ => min_max(),
    };
    match k {
        // Positions keep the data's ends: moving a position lattice by up to half a step
        // measurably moves the image (gsplat at 11 bits: -0.17 dB) for 12 bytes per part.
        // Rotation components keep their fixed range (-0.06 dB there for 4 bytes).
        Kind::Position(_) | Kind::Rotation(_) => (lo, hi),
        _ => half_range::snap(lo, hi, bits),
    }
}

/// A range around zero widened (by at most one step in all) so that zero is one of its
/// levels: SH bands 1-3 of trained scenes gather at zero, and on a range that merely spans the
/// data's min and max zero falls between two levels, shifting every such coefficient by up to
/// half a step. The encoder keeps this range only where it is the cheaper one
/// ([`cheaper_range`]): real gsplat at `low`, 7 % fewer bytes at the same PSNR; fruit at its
/// presets, no change (BENCHMARKS.md "SH bands"). Ranges not around zero, and 1-bit channels,
/// are returned as they are.
fn zero_on_level(lo: f32, hi: f32, bits: u8) -> (f32, f32) {
    let l = levels(bits);
    if !(lo < 0.0 && hi > 0.0) || l < 2.0 {
        return (lo, hi);
    }
    let (lo64, hi64, l64) = (lo as f64, hi as f64, l as f64);
    // Zero's level: of the two around where zero falls, the one that widens the range least.
    let step_at = |m: f64| (-lo64 / m).max(hi64 / (l64 - m));
    let at = -lo64 / (hi64 - lo64) * l64;
    let (below, above) = (
        at.floor().clamp(1.0, l64 - 1.0),
        at.ceil().clamp(1.0, l64 - 1.0),
    );
    let m = if step_at(below) <= step_at(above) {
        below
    } else {
        above
    };
    let step = step_at(m);
    // f32 rounding must not narrow the range below the data.
    let widened = (
        ((-m * step) as f32).min(lo),
        (((l64 - m) * step) as f32).max(hi),
    );
    // Near f32::MAX the widened ends overflow: stored ranges must be finite (§6.5.2).
    if widened.0.is_finite() && widened.1.is_finite() {
        widened
    } else {
        (lo, hi)
    }
}

/// Of two ranges, the one with the lower estimated rate-distortion cost for `v` (ties: `a`):
/// squared error plus `λ` times the order-0 entropy of the levels, `λ = 2 ln 2 / 12 · step²`
/// (the slope of uniform quantisation at high rate: one bit more quarters the error `step²/12`).
fn cheaper_range(v: &[f32], a: (f32, f32), b: (f32, f32), bits: u8) -> (f32, f32) {
    if a == b {
        return a;
    }
    let cost = |(lo, hi): (f32, f32)| -> f64 {
        let mut counts = vec![0u32; 1 << bits];
        let mut sse = 0.0;
        for &x in v {
            let q = quantise(x, lo, hi, bits);
            counts[q as usize] += 1;
            let e = (x - dequantise(q, lo, hi, bits)) as f64;
            sse += e * e;
        }
        let n = v.len() as f64;
        let rate: f64 = counts
            .iter()
            .filter(|&&c| c > 0)
            .map(|&c| -(c as f64) * (c as f64 / n).log2())
            .sum();
        let step = (hi as f64 - lo as f64) / levels(bits) as f64;
        sse + 2.0 * std::f64::consts::LN_2 / 12.0 * step * step * rate
    };
    if cost(b) < cost(a) {
        b
    } else {
        a
    }
}

fn levels(bits: u8) -> f32 {
    ((1u32 << bits) - 1) as f32
}

/// `q = round((v - min) / (max - min) * (2^bits - 1))`, clamped; 0 when the range is empty.
pub fn quantise(v: f32, min: f32, max: f32, bits: u8) -> u16 {
    if !(max > min) {
        return 0;
    }
    let t = ((v - min) / (max - min) * levels(bits)).round();
    t.clamp(0.0, levels(bits)) as u16
}

/// `v = min + q * ((max - min) / (2^bits - 1))` in f32 (§6.5.2).
pub fn dequantise(q: u16, min: f32, max: f32, bits: u8) -> f32 {
    min + q as f32 * ((max - min) / levels(bits))
}

/// Largest rotation shift a layout-3 set may give (§6.5.6).
pub const MAX_ROTATION_SHIFT: u8 = 8;

/// How many bits coarser a Gaussian's three stored rotation components are (§6.5.6): the
/// number of halvings from `exp(threshold)` down to its largest scale, at most `max_shift`.
/// A rotation error turns a Gaussian by an angle that moves its surface by about the angle
/// times its largest scale: a small Gaussian may turn more for the same displacement.
/// f32 arithmetic in this order, so every reader gets the same shifts from the same file.
pub fn rotation_shift(log_scale: [f32; 3], threshold: f32, max_shift: u8) -> u8 {
    let largest = log_scale[0].max(log_scale[1]).max(log_scale[2]);
    let x = (threshold - largest) * std::f32::consts::LOG2_E;
    if x >= 1.0 {
        x.floor().min(max_shift as f32) as u8
    } else {
        0
    }
}

/// Encoder setting for layout 3 (§6.5.6): rotations of Gaussians smaller than `factor`
/// position steps per rotation step are stored up to `max_shift` bits coarser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationCoarsening {
    /// Surface displacement allowed by one (coarsened) rotation step, in position steps.
    pub factor: f32,
    pub max_shift: u8,
}

impl RotationCoarsening {
    /// The reference encoder's default (`dlgs encode` without `--coarse-rotations`): on the
    /// real SH 0 scenes and gsplat 1-4 % fewer bytes for 0.00-0.33 dB (BENCHMARKS.md).
    pub const DEFAULT: RotationCoarsening = RotationCoarsening {
        factor: 1.0,
        max_shift: 4,
    };
}

/// The stored (max shift, threshold) of a set whose channels hold `chans` (positions
/// quantised): `exp(threshold)` is the largest scale whose one-step turn moves its surface by
/// `factor` position steps. Shift 0 (no coarsening) when that is not finite.
fn coarsening_record(chans: &[(u8, f32, f32, Vec<u16>)], c: RotationCoarsening) -> (u8, f32) {
    let step = position_steps(chans).into_iter().fold(0.0f64, f64::max);
    let rot_bits = chans[FIRST_ROTATION].0;
    // One rotation step turns by about twice the component step, 2 * sqrt(2) / levels.
    let turn = 2.0 * std::f64::consts::SQRT_2 / levels(rot_bits) as f64;
    let t = (c.factor as f64 * step / turn).ln() as f32;
    if t.is_finite() && c.max_shift > 0 {
        (c.max_shift.min(MAX_ROTATION_SHIFT), t)
    } else {
        (0, 0.0)
    }
}

/// Layout 3 stores the rotation index and components of the cells with shift 0 first, then
/// those with shift 1, and so on, each class in grid order (§6.5.6): the coders' adaptive
/// models then learn one class's narrower values at a time. `order[j]` = grid cell stored
/// `j`-th.
pub fn cells_by_shift(shifts: &[u8]) -> Vec<u32> {
    // A counting sort: stable and linear (at most 256 classes).
    let mut start = [0usize; 257];
    for &s in shifts {
        start[s as usize + 1] += 1;
    }
    for k in 1..start.len() {
        start[k] += start[k - 1];
    }
    let mut order = vec![0u32; shifts.len()];
    for (i, &s) in shifts.iter().enumerate() {
        order[start[s as usize]] = i as u32;
        start[s as usize] += 1;
    }
    order
}

/// `2^-shift` (exact in f32).
fn halvings(shift: u8) -> f32 {
    1.0 / (1u32 << shift) as f32
}

/// Grid width for `n` cells: `ceil(sqrt(n))` (0 for an empty set).
pub fn grid_width(n: usize) -> usize {
    if n == 0 {
        return 0;
    }
    let mut w = (n as f64).sqrt() as usize;
    while w * w < n {
        w += 1;
    }
    w
}

/// One channel as stored.
struct Channel {
    bits: u8,
    min: f32,
    max: f32,
    codec: GridCodec,
    data: Vec<u8>,
}

/// A set's quantised channels in payload order: bits, range, cells.
pub struct QuantisedSet {
    pub channels: Vec<(u8, f32, f32, Vec<u16>)>,
}

/// Quantise every channel of a set (for the encoder, tests and tools).
pub fn quantise_set(g: &Gaussians, bits: &QuantBits) -> QuantisedSet {
    let radius = robust_radius(&g.positions);
    let channels = channels(g)
        .into_par_iter()
        .map(|k| {
            let v = values(g, k);
            let b = k.bits(bits);
            let (lo, hi) = range(k, &v, radius, b);
            (
                b,
                lo,
                hi,
                v.iter().map(|&x| quantise(x, lo, hi, b)).collect(),
            )
        })
        .collect();
    QuantisedSet { channels }
}

/// A set's channels as coded, and with positions as an octree (§6.5.5) the octree, whose
/// channel records are then left out of `channels`' payload (they are still listed first).
struct CodedSet {
    channels: Vec<Channel>,
    octree: Option<Vec<u8>>,
    /// Layout 3's (max shift, threshold) of rotation coarsening (§6.5.6).
    coarsening: Option<(u8, f32)>,
    /// `order[k]` = index in the given set of the Gaussian stored `k`-th.
    order: Vec<u32>,
}

/// Quantise and code every channel of a set, in payload order. With `weight` (one per
/// Gaussian: bits one squared quantisation step of its error is worth) the channels are shaped
/// first ([`shape_channels`]). With `octree`, positions are coded as an octree and the set is
/// stored in the order readers derive from them ([`kd_layout`]), not the order given.
fn code_set(
    g: &Gaussians,
    bits: &QuantBits,
    zstd_level: i32,
    weight: Option<&[f32]>,
    octree: bool,
    coarsen: Option<RotationCoarsening>,
    mixed_margin: Option<f64>,
) -> CodedSet {
    let w = grid_width(g.len()).max(1);
    let mut chans = quantise_set(g, bits).channels;
    let mut order: Vec<u32> = (0..g.len() as u32).collect();
    let mut tree = None;
    let reordered;
    let (g, weight) = if octree {
        let points: Vec<[u16; 3]> = (0..g.len())
            .map(|i| [chans[0].3[i], chans[1].3[i], chans[2].3[i]])
            .collect();
        let (data, morton) = octree_positions::encode(&points, bits.position);
        let in_morton: Vec<[u16; 3]> = morton.iter().map(|&i| points[i as usize]).collect();
        let step = position_steps(&chans);
        order = kd_layout::kd_layout(&in_morton, step)
            .into_iter()
            .map(|k| morton[k as usize])
            .collect();
        for c in chans.iter_mut() {
            c.3 = order.iter().map(|&i| c.3[i as usize]).collect();
        }
        let mut r = Gaussians::new(g.sh_degree, g.lang_width);
        for &i in &order {
            r.push_from(g, i as usize);
        }
        reordered = (
            r,
            weight.map(|w| order.iter().map(|&i| w[i as usize]).collect::<Vec<f32>>()),
        );
        tree = Some(data);
        (&reordered.0, reordered.1.as_deref())
    } else {
        (g, weight)
    };
    // Octree positions are final: shaping starts after them.
    let first = if octree { 3 } else { 0 };
    let coarsening = coarsen
        .filter(|_| octree)
        .map(|c| coarsening_record(&chans, c));
    // Rotation shifts follow the final log-scale levels: shape up to the rotations, requantise
    // them coarsened, then shape the rest.
    let rot0 = FIRST_ROTATION;
    if let Some(weight) = weight {
        shape_channels(g, &mut chans, weight, w, zstd_level, first..rot0, None);
    }
    let shifts = coarsening.filter(|c| c.0 > 0).map(|(max_shift, t)| {
        let ls: Vec<Vec<f32>> = chans[3..6]
            .iter()
            .map(|(b, lo, hi, q)| q.iter().map(|&v| dequantise(v, *lo, *hi, *b)).collect())
            .collect();
        let shifts: Vec<u8> = (0..g.len())
            .map(|i| rotation_shift([ls[0][i], ls[1][i], ls[2][i]], t, max_shift))
            .collect();
        for a in 0..3 {
            let (b, lo, hi, ref mut q) = chans[rot0 + a];
            *q = values(g, Kind::Rotation(a))
                .iter()
                .zip(&shifts)
                .map(|(&v, &s)| quantise(v * halvings(s), lo, hi, b))
                .collect();
        }
        shifts
    });
    if let Some(weight) = weight {
        let all = rot0..chans.len();
        shape_channels(g, &mut chans, weight, w, zstd_level, all, shifts.as_deref());
    }
    if let Some(shifts) = &shifts {
        let by_shift = cells_by_shift(shifts);
        for (_, _, _, q) in &mut chans[rot0 - 1..rot0 + 3] {
            *q = by_shift.iter().map(|&i| q[i as usize]).collect();
        }
    }
    let channels = (0..chans.len())
        .into_par_iter()
        .map(|j| {
            let (b, min, max, q) = &chans[j];
            if j < first {
                return Channel {
                    bits: *b,
                    min: *min,
                    max: *max,
                    codec: GridCodec::Constant,
                    data: Vec::new(),
                };
            }
            // Codecs 4 and 5 may code against the previous channel; not against octree
            // positions, so that readers decode the octree beside the other channels.
            let earlier = |back: usize| {
                j.checked_sub(back)
                    .filter(|&p| p >= first)
                    .map(|p| (chans[p].3.as_slice(), chans[p].0))
            };
            let (codec, data) =
                grid_coder::encode_best(q, earlier(1), earlier(2), w, *b, zstd_level, mixed_margin);
            Channel {
                bits: *b,
                min: *min,
                max: *max,
                codec,
                data,
            }
        })
        .collect();
    CodedSet {
        channels,
        octree: tree,
        coarsening,
        order,
    }
}

/// Scene distance of one quantisation step of each position channel (the first three).
fn position_steps(chans: &[(u8, f32, f32, Vec<u16>)]) -> [f64; 3] {
    let step =
        |c: &(u8, f32, f32, Vec<u16>)| (c.2 as f64 - c.1 as f64).max(0.0) / (levels(c.0) as f64);
    [step(&chans[0]), step(&chans[1]), step(&chans[2])]
}

/// Replace each channel's nearest levels (but the rotation index's) by the [`grid_shaping`]
/// variant, or the nearest levels themselves, that codes smallest, for the channels `which`. In
/// payload order: codec 4 and its shaper need the previous channel's final cells. `shifts`:
/// the rotation shifts of a layout-3 set (§6.5.6).
fn shape_channels(
    g: &Gaussians,
    chans: &mut [(u8, f32, f32, Vec<u16>)],
    weight: &[f32],
    width: usize,
    zstd_level: i32,
    which: std::ops::Range<usize>,
    shifts: Option<&[u8]>,
) {
    assert_eq!(weight.len(), g.len(), "one weight per Gaussian");
    let kinds = channels(g);
    for j in which {
        let (b, min, max, ref q0) = chans[j];
        if kinds[j] == Kind::RotIndex || !(max > min) {
            continue;
        }
        let prev = j
            .checked_sub(1)
            .map(|p| (chans[p].3.as_slice(), chans[p].0));
        let scale = levels(b) / (max - min);
        let mut v = values(g, kinds[j]);
        if let (Kind::Rotation(_), Some(s)) = (kinds[j], shifts) {
            for (x, &s) in v.iter_mut().zip(s) {
                *x *= halvings(s);
            }
        }
        let exact: Vec<f32> = v
            .iter()
            .map(|&v| ((v - min) * scale).clamp(0.0, levels(b)))
            .collect();
        let cells = grid_shaping::Cells {
            exact: &exact,
            nearest: q0,
            weight,
            bits: b,
        };
        let mut variants = vec![
            q0.clone(),
            grid_shaping::for_prediction(&cells, width),
            grid_shaping::for_histogram(&cells, None),
        ];
        if let Some((p, _)) = prev.filter(|p| p.1 == b) {
            variants.push(grid_shaping::for_histogram(&cells, Some(p)));
        }
        // Judged by the tabled codecs the variants were shaped for (codec 5's modes would
        // multiply the passes); the final coding still tries codec 5.
        let best = variants
            .into_par_iter()
            .min_by_key(|q| {
                grid_coder::encode_best_tabled(q, prev, width, b, zstd_level)
                    .1
                    .len()
            })
            .expect("at least the nearest levels");
        chans[j].3 = best;
    }
}

/// Bytes of a channel record before its data in layouts 0-3: bits, codec, min, max, len
/// (§6.5.2); [`breakdown`] counts records this way (layout 4's take 3-10, §6.5.7).
const CHANNEL_HEADER_LEN: usize = 14;
/// Bytes of an octree set's position record before the octree: bits, three ranges, len.
const OCTREE_HEADER_LEN: usize = 29;

/// Write a set (or, with `octree`, an octree set, §6.5.5), in layout 4's compact records
/// (§6.5.7) when `compact`; returns the stored order (indices into `g`).
#[allow(clippy::too_many_arguments)]
fn encode_set(
    out: &mut Vec<u8>,
    g: &Gaussians,
    bits: &QuantBits,
    zstd_level: i32,
    weight: Option<&[f32]>,
    octree: bool,
    coarsen: Option<RotationCoarsening>,
    compact: bool,
    mixed_margin: Option<f64>,
) -> Vec<u32> {
    let coded = code_set(g, bits, zstd_level, weight, octree, coarsen, mixed_margin);
    if !compact {
        out.put_u32(grid_width(g.len()) as u32);
        out.put_u16(coded.channels.len() as u16);
    }
    let mut chans = coded.channels.iter();
    if let Some(tree) = &coded.octree {
        let pos: Vec<&Channel> = chans.by_ref().take(3).collect();
        let ranges: Vec<f32> = pos.iter().flat_map(|c| [c.min, c.max]).collect();
        let half = compact && ranges.iter().all(|&v| half_range::is_f16(v));
        out.put_u8(pos[0].bits | (half as u8) << 7);
        put_range_values(out, &ranges, half);
        if compact {
            // The stream's word count follows from the length (§6.5.7).
            out.put_varint((tree.len() - 4) as u32);
            out.extend_from_slice(&tree[4..]);
        } else {
            out.put_u32(tree.len() as u32);
            out.extend_from_slice(tree);
        }
    }
    match (coded.coarsening, compact && octree) {
        (Some((max_shift, threshold)), _) => {
            out.put_u8(max_shift);
            out.put_f32(threshold);
        }
        // Layout 4's octree sets always carry the record: shift 0 turns it off.
        (None, true) => {
            out.put_u8(0);
            out.put_f32(0.0);
        }
        (None, false) => {}
    }
    let first = coded.channels.len() - chans.len();
    for (c, k) in chans.zip(&channels(g)[first..]) {
        if compact {
            put_compact_record(out, c, *k == Kind::RotIndex);
        } else {
            out.put_u8(c.bits);
            out.put_u8(c.codec as u8);
            out.put_f32(c.min);
            out.put_f32(c.max);
            out.put_u32(c.data.len() as u32);
            out.extend_from_slice(&c.data);
        }
    }
    coded.order
}

fn put_range_values(out: &mut Vec<u8>, values: &[f32], half: bool) {
    for &v in values {
        if half {
            out.put_u16(half::f16::from_f32(v).to_bits());
        } else {
            out.put_f32(v);
        }
    }
}

/// Layout 4's channel record (§6.5.7): one byte for bits, codec and the range's width; no
/// range for the rotation index; a varint length; codec 5 data without its word count.
fn put_compact_record(out: &mut Vec<u8>, c: &Channel, is_index: bool) {
    let half = half_range::is_f16(c.min) && half_range::is_f16(c.max);
    out.put_u8((c.bits - 1) | (c.codec as u8) << 4 | ((half && !is_index) as u8) << 7);
    if !is_index {
        put_range_values(out, &[c.min, c.max], half);
    }
    if c.codec == GridCodec::Adaptive {
        // Mode, k, [word count], words: the count follows from the length.
        out.put_varint((c.data.len() - 4) as u32);
        out.extend_from_slice(&c.data[..2]);
        out.extend_from_slice(&c.data[6..]);
    } else {
        out.put_varint(c.data.len() as u32);
        out.extend_from_slice(&c.data);
    }
}

/// Coded bytes per attribute group of one set, for reports: (group name, bytes), each record
/// with its layout 0-3 header. With `octree`, the octree is counted as the first position
/// channel.
pub fn breakdown(
    g: &Gaussians,
    bits: &QuantBits,
    zstd_level: i32,
    octree: bool,
) -> Vec<(&'static str, usize)> {
    let kinds = channels(g);
    let coded = code_set(
        g,
        bits,
        zstd_level,
        None,
        octree,
        None,
        Some(grid_coder::MIXED_MARGIN),
    );
    let tree = coded
        .octree
        .as_ref()
        .map_or(0, |t| t.len() + OCTREE_HEADER_LEN);
    let sizes = coded
        .channels
        .into_iter()
        .enumerate()
        .map(|(j, c)| match j {
            0 if octree => tree,
            0..3 if octree => 0,
            _ => c.data.len() + CHANNEL_HEADER_LEN,
        });
    let mut out: Vec<(&'static str, usize)> = Vec::new();
    for (k, s) in kinds.iter().zip(sizes) {
        let name = match k {
            Kind::Position(_) => "position",
            Kind::LogScale(_) => "log_scale",
            Kind::RotIndex | Kind::Rotation(_) => "rotation",
            Kind::Opacity => "opacity",
            Kind::Sh(j) if *j < 3 => "sh_dc",
            Kind::Sh(_) => "sh_rest",
            Kind::LangOpacity => "lang_opacity",
            Kind::Lang(_) => "lang",
        };
        match out.last_mut() {
            Some((n, total)) if *n == name => *total += s,
            _ => out.push((name, s)),
        }
    }
    out
}

/// Encode a canonical GOP. Sets are stored in the order given (sort them first).
pub fn encode(c: &Canonical, bits: &QuantBits, zstd_level: i32) -> Result<Vec<u8>> {
    encode_shaped(c, bits, zstd_level, None)
}

/// [`encode`], choosing each static Gaussian's levels by estimated bits plus
/// `static_weight[i]` times the squared error in quantisation steps ([`grid_shaping`]) in every
/// channel but the rotation index.
pub fn encode_shaped(
    c: &Canonical,
    bits: &QuantBits,
    zstd_level: i32,
    static_weight: Option<&[f32]>,
) -> Result<Vec<u8>> {
    let bad = |m: String| Error::new(ErrorKind::InvalidInput(m), 0);
    for &b in &bits.all() {
        if !(1..=16).contains(&b) {
            return Err(bad(format!("quantisation bits must be 1..=16, got {b}")));
        }
    }
    if let Some(s) = static_weight {
        if s.len() != c.statics.len() || s.iter().any(|w| !(*w >= 0.0)) {
            return Err(bad(format!(
                "{} shaping weights (each >= 0) for {} static Gaussians",
                s.len(),
                c.statics.len()
            )));
        }
    }
    c.statics.check_shapes()?;
    c.dynamics.check_shapes()?;
    c.statics.check_finite()?;
    c.dynamics.check_finite()?;
    let mut out = vec![0u8]; // layout version
    encode_set(
        &mut out,
        &c.statics,
        bits,
        zstd_level,
        static_weight,
        false,
        None,
        false,
        Some(grid_coder::MIXED_MARGIN),
    );
    encode_set(
        &mut out,
        &c.dynamics,
        bits,
        zstd_level,
        None,
        false,
        None,
        false,
        Some(grid_coder::MIXED_MARGIN),
    );
    Ok(out)
}

/// Largest number of parts a set may be stored in (layout 1).
pub const MAX_PARTS: usize = 16;

/// Encode a canonical GOP in layout 1 (§6.5.2): the static set as the given parts, each a
/// sorted grid with its own bits, stored in order (the decoded set is their concatenation);
/// the dynamic set as one part with `dynamic_bits`.
pub fn encode_parts(
    static_parts: &[(Gaussians, QuantBits)],
    dynamics: &Gaussians,
    dynamic_bits: &QuantBits,
    zstd_level: i32,
) -> Result<Vec<u8>> {
    let parts = PartedGop {
        static_parts,
        static_weight: None,
        dynamics,
        dynamic_bits,
        rotation_coarsening: None,
        compact_records: false,
        mixed_margin: Some(grid_coder::MIXED_MARGIN),
    };
    encode_grid_parts(&parts, zstd_level)
}

/// [`encode_parts`] from a [`PartedGop`]: with its shaping weights (`rotation_coarsening`
/// does not apply to grid positions).
pub fn encode_grid_parts(gop: &PartedGop, zstd_level: i32) -> Result<Vec<u8>> {
    Ok(encode_parted(gop, zstd_level, false)?.0)
}

/// A canonical GOP to store as parts (layouts 1, 2 and 3).
pub struct PartedGop<'a> {
    /// The static set's parts, each with its bits, in stored order.
    pub static_parts: &'a [(Gaussians, QuantBits)],
    /// Shaping weights (§6.5.4), one per static Gaussian of all parts in order.
    pub static_weight: Option<&'a [f32]>,
    pub dynamics: &'a Gaussians,
    pub dynamic_bits: &'a QuantBits,
    /// With octree positions: store the static parts in layout 3, rotations of small
    /// Gaussians coarser (§6.5.6). Ignored without octree positions.
    pub rotation_coarsening: Option<RotationCoarsening>,
    /// With octree positions: layout 4's compact records (§6.5.7, since 1.14) instead of
    /// layouts 2 and 3's.
    pub compact_records: bool,
    /// Let channels take codec 5's mixed-context modes (5 and 6, since 1.13) where they are
    /// smaller than any other coding by this fraction (usually [`grid_coder::MIXED_MARGIN`]);
    /// `None` leaves them out for faster decoding (`dlgs encode --fast-decode`).
    pub mixed_margin: Option<f64>,
}

/// Encode a canonical GOP in layout 2 (§6.5.2, since 1.10): as [`encode_parts`], but each
/// static part's positions are an octree and its Gaussians are stored in the order readers
/// derive from them (§6.5.5); in layout 3 (since 1.11) when `gop.rotation_coarsening` is set,
/// with the rotations of small Gaussians coarser (§6.5.6). Returns the payload and that order: `order[k]` = index, in the
/// parts' concatenation, of the `k`-th static Gaussian stored.
pub fn encode_octree(gop: &PartedGop, zstd_level: i32) -> Result<(Vec<u8>, Vec<u32>)> {
    encode_parted(gop, zstd_level, true)
}

fn encode_parted(gop: &PartedGop, zstd_level: i32, octree: bool) -> Result<(Vec<u8>, Vec<u32>)> {
    let bad = |m: String| Error::new(ErrorKind::InvalidInput(m), 0);
    let static_parts = gop.static_parts;
    if !(1..=MAX_PARTS).contains(&static_parts.len()) {
        return Err(bad(format!(
            "{} static parts (1..={MAX_PARTS})",
            static_parts.len()
        )));
    }
    let all = static_parts
        .iter()
        .map(|(g, b)| (g, b))
        .chain([(gop.dynamics, gop.dynamic_bits)]);
    for (g, b) in all {
        if let Some(x) = b.all().into_iter().find(|x| !(1..=16).contains(x)) {
            return Err(bad(format!("quantisation bits must be 1..=16, got {x}")));
        }
        g.check_shapes()?;
        g.check_finite()?;
    }
    let n_static: usize = static_parts.iter().map(|p| p.0.len()).sum();
    if let Some(s) = gop.static_weight {
        if s.len() != n_static || s.iter().any(|w| !(*w >= 0.0)) {
            return Err(bad(format!(
                "{} shaping weights (each >= 0) for {n_static} static Gaussians",
                s.len()
            )));
        }
    }
    let coarsen = gop.rotation_coarsening.filter(|_| octree);
    let compact = octree && gop.compact_records;
    let layout = match (octree, coarsen, compact) {
        (false, _, _) => 1u8,
        (true, _, true) => 4,
        (true, None, false) => 2,
        (true, Some(_), false) => 3,
    };
    let mut out = vec![layout];
    out.put_u8(static_parts.len() as u8);
    let mut order = Vec::with_capacity(n_static);
    let mut start = 0;
    let put_count = |out: &mut Vec<u8>, n: usize| match compact {
        true => out.put_varint(n as u32),
        false => out.put_u32(n as u32),
    };
    for (g, b) in static_parts {
        put_count(&mut out, g.len());
        let weight = gop.static_weight.map(|w| &w[start..start + g.len()]);
        let local = encode_set(
            &mut out,
            g,
            b,
            zstd_level,
            weight,
            octree,
            coarsen,
            compact,
            gop.mixed_margin,
        );
        order.extend(local.into_iter().map(|i| i + start as u32));
        start += g.len();
    }
    if gop.dynamics.is_empty() {
        // Since 1.12 an empty set is no parts: a part's set record would carry every channel's
        // record (837 bytes in all at SH 3) to say nothing.
        out.put_u8(0);
    } else {
        out.put_u8(1);
        put_count(&mut out, gop.dynamics.len());
        encode_set(
            &mut out,
            gop.dynamics,
            gop.dynamic_bits,
            zstd_level,
            None,
            false,
            None,
            compact,
            gop.mixed_margin,
        );
    }
    Ok((out, order))
}

fn bad_at(reason: String, at: u64) -> Error {
    Error::new(
        ErrorKind::Payload {
            chunk: ChunkType::CSOG,
            reason,
        },
        at,
    )
}

/// How a set's record is laid out (by the `CSOG` layout version).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SetForm {
    /// Every channel a grid record (layouts 0 and 1, and every dynamic set).
    Grid,
    /// Positions as an octree (layout 2's static parts).
    Octree,
    /// An octree and a rotation coarsening record (layout 3's static parts).
    OctreeCoarse,
}

/// One channel record of a set as read (§6.5.2), its data not yet decoded.
struct Record<'a> {
    kind: Kind,
    bits: u8,
    codec: GridCodec,
    min: f32,
    max: f32,
    /// The data as the codecs read it (layout 4's word count put back, §6.5.7).
    data: Cow<'a, [u8]>,
    /// Absolute offset of the data.
    at: u64,
    /// Bytes the data takes in the payload.
    stored_len: usize,
}

impl Record<'_> {
    /// Codec 5's mode, from the data's first two bytes.
    fn mode(&self) -> Option<Mode> {
        (self.codec == GridCodec::Adaptive)
            .then(|| self.data.get(..2))
            .flatten()
            .and_then(|b| Mode::from_bytes(b[0], b[1]))
    }
}

/// A set's records as read: an octree set's positions, its rotation coarsening and one record
/// per channel (the position channels of an octree set with empty data, codec 0).
struct SetRecords<'a> {
    tree: Option<OctreeRecord<'a>>,
    coarsening: Option<(u8, f32)>,
    records: Vec<Record<'a>>,
    /// Index of the first record stored as a channel record (after octree positions).
    first: usize,
}

/// Read a set's records (§6.5.2, §6.5.5-6.5.7) without decoding them.
fn read_set<'a>(
    r: &mut ByteReader<'a>,
    n: usize,
    kinds: &[Kind],
    form: SetForm,
    compact: bool,
) -> Result<SetRecords<'a>> {
    let at = r.offset();
    let w = grid_width(n);
    // Layout 4 leaves out the width and channel count: both follow from the scene (§6.5.7).
    if !compact {
        let stored = r.u32("CSOG grid width")? as usize;
        if stored != w {
            return Err(bad_at(
                format!("grid width {stored} for {n} Gaussians, expected {w}"),
                at,
            ));
        }
        let at = r.offset();
        let count = r.u16("CSOG channel count")? as usize;
        if count != kinds.len() {
            return Err(bad_at(
                format!("{count} channels, the layout has {}", kinds.len()),
                at,
            ));
        }
    }
    // An octree set's positions come first, already in grid order (§6.5.5).
    let mut records: Vec<Record> = Vec::with_capacity(kinds.len());
    let tree = if form != SetForm::Grid {
        let t = read_octree_record(r, compact)?;
        for (a, &(min, max)) in t.ranges.iter().enumerate() {
            records.push(Record {
                kind: kinds[a],
                bits: t.bits,
                codec: GridCodec::Constant,
                min,
                max,
                data: Cow::Borrowed(&[]),
                at: 0,
                stored_len: 0,
            });
        }
        Some(t)
    } else {
        None
    };
    let coarsening = if form == SetForm::OctreeCoarse {
        let at = r.offset();
        let max_shift = r.u8("CSOG rotation max shift")?;
        if max_shift > MAX_ROTATION_SHIFT {
            return Err(bad_at(
                format!("rotation max shift {max_shift} (at most {MAX_ROTATION_SHIFT})"),
                at,
            ));
        }
        Some((max_shift, r.finite_f32("CSOG rotation threshold")?))
    } else {
        None
    };
    let first = records.len();
    for &k in &kinds[first..] {
        let at = r.offset();
        let is_index = k == Kind::RotIndex;
        let (bits, codec, half) = if compact {
            // bits - 1, codec, binary16 range (§6.5.7).
            let head = r.u8("CSOG channel head")?;
            (head & 15, head >> 4 & 7, head >> 7 == 1)
        } else {
            let bits = r.u8("CSOG channel bits")?;
            (bits, r.u8("CSOG channel codec")?, false)
        };
        let bits = bits + compact as u8;
        if !(1..=16).contains(&bits) || (is_index && bits != 2) {
            return Err(bad_at(format!("{k:?}: {bits} bits"), at));
        }
        let codec = GridCodec::from_u8(codec)
            .ok_or_else(|| bad_at(format!("unknown grid codec {codec}"), at))?;
        // The records after octree positions start without a previous channel.
        let prev_bits = records
            .last()
            .filter(|_| records.len() > first)
            .map(|p| p.bits);
        if codec == GridCodec::HistogramDelta && prev_bits != Some(bits) {
            return Err(bad_at(
                format!("{k:?}: codec 4 needs a previous channel with the same {bits} bits"),
                at,
            ));
        }
        let at = r.offset();
        let (min, max) = match (compact, is_index) {
            (true, true) if half => {
                return Err(bad_at(
                    "the rotation index record has no range to flag".into(),
                    at,
                ))
            }
            (true, true) => (0.0, 3.0),
            _ => read_range(r, half, "CSOG channel min", "CSOG channel max")?,
        };
        if is_index && (min, max) != (0.0, 3.0) {
            return Err(bad_at(
                "rotation index channel must have range [0, 3]".into(),
                at,
            ));
        }
        let len = match compact {
            true => r.varint_u32("CSOG channel length")?,
            false => r.u32("CSOG channel length")?,
        } as usize;
        let at = r.offset();
        let stored = r.take(len, "CSOG channel data")?;
        let data = match (compact, codec) {
            (true, GridCodec::Adaptive) => with_word_count(stored, 2, at)?,
            _ => Cow::Borrowed(stored),
        };
        records.push(Record {
            kind: k,
            bits,
            codec,
            min,
            max,
            data,
            at,
            stored_len: len,
        });
    }
    Ok(SetRecords {
        tree,
        coarsening,
        records,
        first,
    })
}

/// A set's records, read and split into chains, not yet decoded.
struct SetPlan<'a> {
    n: usize,
    sh_degree: u8,
    lang_width: usize,
    tree: Option<OctreeRecord<'a>>,
    coarsening: Option<(u8, f32)>,
    stored: Vec<Record<'a>>,
    /// Runs of records that decode in order, each after the one before it.
    chains: Vec<std::ops::Range<usize>>,
}

/// Read one set's records (§6.5.2) and split them into chains.
fn plan_set<'a>(
    r: &mut ByteReader<'a>,
    n: usize,
    sh_degree: u8,
    lang_width: usize,
    limits: &Limits,
    form: SetForm,
    compact: bool,
) -> Result<SetPlan<'a>> {
    let kinds = channels(&Gaussians::new(sh_degree, lang_width));
    limits.check_alloc(
        "CSOG channel cells",
        (n as u64) * 2 * kinds.len() as u64,
        r.offset(),
    )?;
    let SetRecords {
        tree,
        coarsening,
        records: stored,
        first,
    } = read_set(r, n, &kinds, form, compact)?;
    // Codec 4 and codec 5 modes 1-3 need the previous channel's final cells:
    // split the records into chains that start at an independent channel, decode the chains in
    // parallel and each chain in order (same cells whatever the thread count). The first
    // record after octree positions starts a chain: it has no previous channel (§6.5.2).
    let needs_previous = |s: &Record| match s.codec {
        GridCodec::HistogramDelta => true,
        GridCodec::Adaptive => s.mode().is_none_or(|m| m.needs_previous()),
        _ => false,
    };
    let needs_two = |s: &Record| s.mode().is_some_and(|m| m.needs_two_previous());
    let mut chains: Vec<std::ops::Range<usize>> = Vec::new();
    for j in first..stored.len() {
        match chains.last_mut() {
            Some(c) if needs_previous(&stored[j]) => c.end = j + 1,
            _ => chains.push(j..j + 1),
        }
        // Codec 5 mode 6 also reads the record before the previous one: when the previous
        // record starts a chain, this chain joins the one before it (whose last record that
        // is). Without such a record the chain stays as it is and decoding reports it.
        let k = chains.len();
        if needs_two(&stored[j]) && k >= 2 && chains[k - 1].start + 1 == j {
            let last = chains.pop().expect("two chains");
            chains[k - 2].end = last.end;
        }
    }
    Ok(SetPlan {
        n,
        sh_degree,
        lang_width,
        tree,
        coarsening,
        stored,
        chains,
    })
}

/// One unit of parallel decoding: a set's octree positions or one of its chains.
#[derive(Clone, Copy)]
enum Task {
    Octree(usize),
    Chain(usize, usize),
}

/// Decode sets (the parts of a `CSOG` payload) together. Every set's octree and chains go
/// into one pool, the costliest first, so that no long chain of one part is left to run alone
/// while the other thread idles, as when the parts decoded one after another. Each task's cells
/// depend only on its bytes: the same cells whatever the thread count or order.
fn decode_sets(plans: &[SetPlan]) -> Result<Vec<Gaussians>> {
    // Estimated cost, in units of a tree mode's byte: mixed modes take about twice as long per
    // byte (0.23 against 0.11 ms per KB on the 273k goal row); octrees about as long.
    let record_cost = |s: &Record| {
        let mixed = s
            .mode()
            .is_some_and(|m| matches!(m, Mode::Mixed(_) | Mode::MixedTwo(..)));
        s.data.len() * if mixed { 2 } else { 1 }
    };
    let mut tasks: Vec<(Task, usize)> = Vec::new();
    for (set, plan) in plans.iter().enumerate() {
        if let Some(t) = &plan.tree {
            tasks.push((Task::Octree(set), t.data.len()));
        }
        for (c, range) in plan.chains.iter().enumerate() {
            let cost = plan.stored[range.clone()].iter().map(record_cost).sum();
            tasks.push((Task::Chain(set, c), cost));
        }
    }
    tasks.sort_by_key(|&(_, cost)| std::cmp::Reverse(cost));
    let done: Vec<(Task, Vec<Vec<u16>>)> = task_queue::in_list_order(&tasks, |&(t, _)| match t {
        Task::Chain(set, c) => Ok((t, plans[set].decode_chain(c)?)),
        Task::Octree(set) => Ok((t, plans[set].decode_octree()?)),
    })
    .into_iter()
    .collect::<Result<_>>()?;
    let mut positions: Vec<Vec<Vec<u16>>> = vec![Vec::new(); plans.len()];
    let mut chains: Vec<Vec<Vec<Vec<u16>>>> = plans
        .iter()
        .map(|p| vec![Vec::new(); p.chains.len()])
        .collect();
    for (t, cells) in done {
        match t {
            Task::Octree(set) => positions[set] = cells,
            Task::Chain(set, c) => chains[set][c] = cells,
        }
    }
    Ok(plans
        .par_iter()
        .zip(positions)
        .zip(chains)
        .map(|((plan, positions), chains)| {
            // Back to record order: positions, then the chains in order.
            let cells = positions.into_iter().chain(chains.into_iter().flatten());
            plan.finish(cells.collect())
        })
        .collect())
}

impl SetPlan<'_> {
    /// The octree's cells, one channel per axis.
    fn decode_octree(&self) -> Result<Vec<Vec<u16>>> {
        let cells = self
            .tree
            .as_ref()
            .map(|r| octree_cells(r, self.n))
            .transpose()?;
        Ok(cells.map(Vec::from).unwrap_or_default())
    }

    /// The cells of chain `c`'s channels, in order.
    fn decode_chain(&self, c: usize) -> Result<Vec<Vec<u16>>> {
        let (stored, n, w) = (&self.stored, self.n, grid_width(self.n));
        let range = &self.chains[c];
        let mut out: Vec<Vec<u16>> = Vec::with_capacity(range.len());
        for j in range.clone() {
            let Record {
                bits,
                codec,
                ref data,
                at,
                ..
            } = stored[j];
            let prev = out.last().map(|p| (p.as_slice(), stored[j - 1].bits));
            let prev2 = out
                .len()
                .checked_sub(2)
                .map(|p| (out[p].as_slice(), stored[j - 2].bits));
            let r = ByteReader::new(data, at);
            let mut q = grid_coder::decode(codec, r, n, w.max(1), bits, prev, prev2)?;
            if codec == GridCodec::HistogramDelta {
                let (p, _) = prev.expect("codec 4 continues a chain (checked above)");
                grid_coder::undo_delta(&mut q, p, bits);
            }
            out.push(q);
        }
        Ok(out)
    }

    /// Dequantise a set's cells (positions first, then every channel record in order) into
    /// Gaussians.
    fn finish(&self, cells: Vec<Vec<u16>>) -> Gaussians {
        let (n, stored, coarsening) = (self.n, &self.stored, self.coarsening);
        let mut g = Gaussians::new(self.sh_degree, self.lang_width);
        let lang_width = self.lang_width;
        let mut decoded: Vec<(u8, Vec<f32>)> = stored
            .par_iter()
            .zip(cells)
            .map(|(s, q)| {
                let v = match s.kind {
                    Kind::RotIndex => q.iter().map(|&v| v as f32).collect(),
                    _ => q
                        .iter()
                        .map(|&v| dequantise(v, s.min, s.max, s.bits))
                        .collect(),
                };
                (s.bits, v)
            })
            .collect();
        // Layout 3: shifts from the decoded log-scales; rotation cells back to grid order.
        let shifts = coarsening.filter(|c| c.0 > 0).map(|(max_shift, t)| {
            let ls = &decoded[3..6];
            let shifts: Vec<u8> = (0..n)
                .into_par_iter()
                .map(|i| rotation_shift([ls[0].1[i], ls[1].1[i], ls[2].1[i]], t, max_shift))
                .collect();
            let by_shift = cells_by_shift(&shifts);
            decoded[FIRST_ROTATION - 1..FIRST_ROTATION + 3]
                .par_iter_mut()
                .for_each(|(_, v)| {
                    let mut grid = vec![0.0f32; n];
                    for (&i, &x) in by_shift.iter().zip(v.iter()) {
                        grid[i as usize] = x;
                    }
                    *v = grid;
                });
            shifts
        });
        let mut ch = decoded.into_iter();
        let mut next = || ch.next().expect("one decoded channel per kind");
        let zip3 = |a: Vec<f32>, b: Vec<f32>, c: Vec<f32>| -> Vec<[f32; 3]> {
            (0..n).map(|i| [a[i], b[i], c[i]]).collect()
        };
        g.positions = zip3(next().1, next().1, next().1);
        g.log_scales = zip3(next().1, next().1, next().1);
        let idx = next().1;
        let rest = zip3(next().1, next().1, next().1);
        g.rotations = (0..n)
            .map(|i| {
                let mut r = rest[i];
                if let Some(s) = &shifts {
                    // Exact: a power of two (§6.5.6).
                    let up = (1u32 << s[i]) as f32;
                    r = r.map(|v| v * up);
                }
                let big = (1.0 - (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]))
                    .max(0.0)
                    .sqrt();
                let m = idx[i] as usize;
                let mut q = [0.0; 4];
                let mut j = 0;
                for (a, v) in q.iter_mut().enumerate() {
                    if a == m {
                        *v = big;
                    } else {
                        *v = r[j];
                        j += 1;
                    }
                }
                q
            })
            .collect();
        let (ob, o) = next();
        g.opacity = logit(o, ob);
        let stride = g.sh_stride();
        let sh: Vec<Vec<f32>> = (0..stride).map(|_| next().1).collect();
        g.sh = (0..n * stride)
            .map(|x| sh[x % stride][x / stride])
            .collect();
        if lang_width > 0 {
            let (lb, lo) = next();
            g.lang_opacity = logit(lo, lb);
            let l: Vec<Vec<f32>> = (0..lang_width).map(|_| next().1).collect();
            g.lang = (0..n * lang_width)
                .map(|x| l[x % lang_width][x / lang_width])
                .collect();
        }
        g
    }
}

/// An octree set's position record (§6.5.5), read but not yet decoded.
struct OctreeRecord<'a> {
    bits: u8,
    ranges: [(f32, f32); 3],
    data: Cow<'a, [u8]>,
    at: u64,
    /// Bytes the data takes in the payload.
    stored_len: usize,
}

/// A channel range: two f32, or in layout 4 when flagged two binary16 values (§6.5.7).
fn read_range(
    r: &mut ByteReader,
    half: bool,
    min: &'static str,
    max: &'static str,
) -> Result<(f32, f32)> {
    Ok(match half {
        true => (r.finite_f16(min)?, r.finite_f16(max)?),
        false => (r.finite_f32(min)?, r.finite_f32(max)?),
    })
}

/// Layout 4 leaves a range-coded stream's word count out (§6.5.7): the stream as the codecs
/// read it, the count put back after the first `at_byte` bytes. The words must be whole.
fn with_word_count(data: &[u8], at_byte: usize, at: u64) -> Result<Cow<'_, [u8]>> {
    if data.len() < at_byte || !(data.len() - at_byte).is_multiple_of(4) {
        return Err(bad_at(
            format!(
                "{} bytes of stream after its {at_byte}-byte head: not whole 32-bit words",
                data.len().saturating_sub(at_byte)
            ),
            at,
        ));
    }
    let mut v = Vec::with_capacity(data.len() + 4);
    v.extend_from_slice(&data[..at_byte]);
    v.put_u32(((data.len() - at_byte) / 4) as u32);
    v.extend_from_slice(&data[at_byte..]);
    Ok(Cow::Owned(v))
}

fn read_octree_record<'a>(r: &mut ByteReader<'a>, compact: bool) -> Result<OctreeRecord<'a>> {
    let at = r.offset();
    let head = r.u8("CSOG octree bits")?;
    // Layout 4: the top bit flags binary16 ranges (§6.5.7).
    let (bits, half) = match compact {
        true => (head & 0x7f, head >> 7 == 1),
        false => (head, false),
    };
    if !(1..=octree_positions::MAX_BITS).contains(&bits) {
        return Err(bad_at(format!("octree positions of {bits} bits"), at));
    }
    let mut ranges = [(0.0f32, 0.0f32); 3];
    for range in ranges.iter_mut() {
        *range = read_range(r, half, "CSOG position min", "CSOG position max")?;
    }
    let len = match compact {
        true => r.varint_u32("CSOG octree length")?,
        false => r.u32("CSOG octree length")?,
    } as usize;
    let at = r.offset();
    let data = r.take(len, "CSOG octree data")?;
    let data = match compact {
        true => with_word_count(data, 0, at)?,
        false => Cow::Borrowed(data),
    };
    Ok(OctreeRecord {
        bits,
        ranges,
        data,
        at,
        stored_len: len,
    })
}

/// The octree's `n` points laid out in grid order: the three position channels' cells.
fn octree_cells(t: &OctreeRecord, n: usize) -> Result<[Vec<u16>; 3]> {
    let points = octree_positions::decode(ByteReader::new(&t.data, t.at), n, t.bits)?;
    let step = t
        .ranges
        .map(|(min, max)| (max as f64 - min as f64).max(0.0) / levels(t.bits) as f64);
    let order = kd_layout::kd_layout(&points, step);
    let axis = |a: usize| order.iter().map(|&i| points[i as usize][a]).collect();
    Ok([axis(0), axis(1), axis(2)])
}

/// A set stored as parts (layout 1): a part count, then per part its Gaussian count and its
/// set record; the counts must add up to `n`. An empty set may have no parts (since 1.12).
/// `each` reads one part's set record given its Gaussian count.
fn read_parts<'a>(
    r: &mut ByteReader<'a>,
    n: usize,
    compact: bool,
    mut each: impl FnMut(&mut ByteReader<'a>, usize) -> Result<()>,
) -> Result<()> {
    let at = r.offset();
    let parts = r.u8("CSOG part count")? as usize;
    if parts > MAX_PARTS || (parts == 0 && n > 0) {
        return Err(bad_at(
            format!("{parts} parts for {n} Gaussians (1..={MAX_PARTS}; 0 only for none)"),
            at,
        ));
    }
    let mut left = n;
    for p in 0..parts {
        let at = r.offset();
        let np = match compact {
            true => r.varint_u32("CSOG part Gaussian count")?,
            false => r.u32("CSOG part Gaussian count")?,
        } as usize;
        if np > left {
            return Err(bad_at(
                format!("part {p} holds {np} Gaussians, only {left} of the set's {n} are left"),
                at,
            ));
        }
        left -= np;
        each(r, np)?;
    }
    if left != 0 {
        return Err(bad_at(
            format!("the parts hold {} of the set's {n} Gaussians", n - left),
            at,
        ));
    }
    Ok(())
}

/// Read a set stored as parts (§6.5.7) into one plan per part.
fn plan_parts<'a>(
    r: &mut ByteReader<'a>,
    n: usize,
    sh_degree: u8,
    lang_width: usize,
    limits: &Limits,
    form: SetForm,
    compact: bool,
) -> Result<Vec<SetPlan<'a>>> {
    let mut plans = Vec::new();
    read_parts(r, n, compact, |r, np| {
        plans.push(plan_set(
            r, np, sh_degree, lang_width, limits, form, compact,
        )?);
        Ok(())
    })?;
    Ok(plans)
}

/// One set from its parts' Gaussians, in part order.
fn join_parts(parts: Vec<Gaussians>, sh_degree: u8, lang_width: usize) -> Gaussians {
    let mut parts = parts.into_iter();
    let mut g = parts
        .next()
        .unwrap_or_else(|| Gaussians::new(sh_degree, lang_width));
    for part in parts {
        g.extend(&part);
    }
    g
}

/// Back to pre-sigmoid opacity; alpha is kept half a step away from 0 and 1 so the logit is
/// finite (§6.5.2).
fn logit(alpha: Vec<f32>, bits: u8) -> Vec<f32> {
    let eps = 0.5 / levels(bits);
    alpha
        .into_iter()
        .map(|a| {
            let a = a.clamp(eps, 1.0 - eps);
            (a / (1.0 - a)).ln()
        })
        .collect()
}

/// How `CSOG` layout `version` stores its sets: `None` for layout 0 (one set record each, no
/// parts), else the static parts' form and whether records are compact (§6.5.2, §6.5.7).
fn layout_of(version: u8, at: u64) -> Result<Option<(SetForm, bool)>> {
    match version {
        0 => Ok(None),
        1 => Ok(Some((SetForm::Grid, false))),
        2 => Ok(Some((SetForm::Octree, false))),
        3 => Ok(Some((SetForm::OctreeCoarse, false))),
        // Layout 4 is layout 3 in compact records (§6.5.7).
        4 => Ok(Some((SetForm::OctreeCoarse, true))),
        _ => Err(bad_at(
            format!("layout version {version} (this reader knows 0 to 4)"),
            at,
        )),
    }
}

/// One record of a `CSOG` payload: what it holds, how it is coded and how many bytes its data
/// takes (for `dlgs info --channels`). Record heads, ranges and counts are not in `bytes`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RecordSummary {
    /// `"static"` or `"dynamic"`.
    pub set: &'static str,
    pub part: usize,
    /// Gaussians in the part.
    pub gaussians: usize,
    /// The channel, e.g. `"log_scale y"`, `"sh 1 g"`; octree positions are one record.
    pub channel: String,
    /// The channel's attribute as `dlgs encode --bits` names it.
    pub attribute: &'static str,
    pub bits: u8,
    /// Codec and, for codec 5, its mode (§6.5.3), or `"octree"` (§6.5.5).
    pub coding: String,
    pub bytes: usize,
}

/// Where the bytes of a `CSOG` payload go, record by record.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CsogSummary {
    pub layout: u8,
    pub payload_bytes: usize,
    pub records: Vec<RecordSummary>,
}

impl Kind {
    fn name(self) -> String {
        const AXIS: [&str; 3] = ["x", "y", "z"];
        const RGB: [&str; 3] = ["r", "g", "b"];
        match self {
            Kind::Position(a) => format!("position {}", AXIS[a]),
            Kind::LogScale(a) => format!("log_scale {}", AXIS[a]),
            Kind::RotIndex => "rotation index".into(),
            Kind::Rotation(j) => format!("rotation {j}"),
            Kind::Opacity => "opacity".into(),
            // `[coef][rgb]` per Gaussian (coefficient 0 is DC).
            Kind::Sh(j) => format!("sh {} {}", j / 3, RGB[j % 3]),
            Kind::LangOpacity => "language opacity".into(),
            Kind::Lang(j) => format!("language {j}"),
        }
    }

    /// The `--bits` name of the attribute ([`Kind::bits`]'s field).
    fn attribute(self) -> &'static str {
        match self {
            Kind::Position(_) => "position",
            Kind::LogScale(_) => "log_scale",
            Kind::RotIndex | Kind::Rotation(_) => "rotation",
            Kind::Opacity | Kind::LangOpacity => "opacity",
            Kind::Sh(j) if j < 3 => "sh_dc",
            Kind::Sh(j) if j < 12 => "sh_rest",
            Kind::Sh(_) => "sh_high",
            Kind::Lang(_) => "lang",
        }
    }
}

fn coding_name(r: &Record) -> String {
    match r.codec {
        GridCodec::Constant => "constant (codec 0)".into(),
        GridCodec::Zstd => "zstd (codec 1)".into(),
        GridCodec::Predictive => "predictive (codec 2)".into(),
        GridCodec::Histogram => "histogram (codec 3)".into(),
        GridCodec::HistogramDelta => "histogram of the difference (codec 4)".into(),
        GridCodec::Adaptive => match r.mode() {
            Some(m) => format!("adaptive (codec 5), {}", m.describe()),
            None => "adaptive (codec 5), unknown mode".into(),
        },
    }
}

/// Read a `CSOG` payload's records without decoding them (no cells are allocated): which
/// channel each holds, its bits, codec and bytes. Errors as [`decode`] for what it reads.
pub fn describe(p: &[u8], offset: u64, scene: &SceneHeader) -> Result<CsogSummary> {
    let mut r = ByteReader::new(p, offset);
    let at = r.offset();
    let layout = r.u8("CSOG layout version")?;
    let kinds = channels(&Gaussians::new(scene.sh_degree, scene.lang_width()));
    let (ns, nd) = (scene.n_static as usize, scene.n_dynamic as usize);
    let mut records = Vec::new();
    let mut summarise = |set: &'static str, part: usize, n: usize, s: SetRecords| {
        let row = |channel, attribute, bits, coding, bytes| RecordSummary {
            set,
            part,
            gaussians: n,
            channel,
            attribute,
            bits,
            coding,
            bytes,
        };
        if let Some(t) = &s.tree {
            let bytes = t.stored_len;
            records.push(row(
                "positions".into(),
                "position",
                t.bits,
                "octree".into(),
                bytes,
            ));
        }
        for rec in &s.records[s.first..] {
            let (name, attribute) = (rec.kind.name(), rec.kind.attribute());
            records.push(row(
                name,
                attribute,
                rec.bits,
                coding_name(rec),
                rec.stored_len,
            ));
        }
    };
    match layout_of(layout, at)? {
        None => {
            for (set, n) in [("static", ns), ("dynamic", nd)] {
                summarise(
                    set,
                    0,
                    n,
                    read_set(&mut r, n, &kinds, SetForm::Grid, false)?,
                );
            }
        }
        Some((form, compact)) => {
            for (set, n, form) in [("static", ns, form), ("dynamic", nd, SetForm::Grid)] {
                let mut part = 0;
                read_parts(&mut r, n, compact, |r, np| {
                    summarise(set, part, np, read_set(r, np, &kinds, form, compact)?);
                    part += 1;
                    Ok(())
                })?;
            }
        }
    }
    if r.remaining() != 0 {
        return Err(bad_at(
            format!("{} bytes after the last channel", r.remaining()),
            r.offset(),
        ));
    }
    Ok(CsogSummary {
        layout,
        payload_bytes: p.len(),
        records,
    })
}

/// Decode a `CSOG` payload that starts at absolute `offset`, checking it against the scene.
pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<Canonical> {
    let mut r = ByteReader::new(p, offset);
    let at = r.offset();
    let version = r.u8("CSOG layout version")?;
    let (sh, lw) = (scene.sh_degree, scene.lang_width());
    let (ns, nd) = (scene.n_static as usize, scene.n_dynamic as usize);
    // Both sets and all their parts are read first and then decoded together (`decode_sets`).
    let (static_plans, dynamic_plans) = match layout_of(version, at)? {
        None => (
            vec![plan_set(&mut r, ns, sh, lw, limits, SetForm::Grid, false)?],
            vec![plan_set(&mut r, nd, sh, lw, limits, SetForm::Grid, false)?],
        ),
        Some((form, compact)) => (
            plan_parts(&mut r, ns, sh, lw, limits, form, compact)?,
            plan_parts(&mut r, nd, sh, lw, limits, SetForm::Grid, compact)?,
        ),
    };
    if r.remaining() != 0 {
        return Err(bad_at(
            format!("{} bytes after the last channel", r.remaining()),
            r.offset(),
        ));
    }
    let split = static_plans.len();
    let plans: Vec<SetPlan> = static_plans.into_iter().chain(dynamic_plans).collect();
    // Every part's cells are held at once until the parts are dequantised.
    let kinds = channels(&Gaussians::new(sh, lw)).len() as u64;
    limits.check_alloc("CSOG channel cells", ((ns + nd) as u64) * 2 * kinds, at)?;
    let mut sets = decode_sets(&plans)?;
    let dynamics = join_parts(sets.split_off(split), sh, lw);
    Ok(Canonical {
        statics: join_parts(sets, sh, lw),
        dynamics,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_radius_of_degenerate_sets() {
        assert_eq!(robust_radius(&[]), None);
        assert_eq!(
            robust_radius(&[[1.0, 2.0, 3.0]; 5]),
            None,
            "all at one point"
        );
        assert_eq!(robust_radius(&[[f32::NAN, 0.0, 0.0]]), None);
        // Non-finite positions are ignored; the 80th percentile distance from the median.
        let mut p: Vec<[f32; 3]> = (0..10).map(|i| [i as f32, 0.0, 0.0]).collect();
        p.push([f32::INFINITY, 0.0, 0.0]);
        assert_eq!(robust_radius(&p), Some(4.0));
    }

    #[test]
    fn quaternions_survive_smallest_three() {
        for q in [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0],
            [-0.2, 0.9, -0.3, 0.1],
            [0.5, -0.5, 0.5, -0.5],
            [0.0, 0.0, -3.0, 0.0],
        ] {
            let (m, r) = smallest_three(q);
            assert!(r
                .iter()
                .all(|v| v.abs() <= std::f32::consts::FRAC_1_SQRT_2 + 1e-6));
            let big = (1.0 - r.iter().map(|v| v * v).sum::<f32>()).sqrt();
            let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            if n > 0.0 {
                // Same rotation up to sign.
                let mut back = [0.0; 4];
                let mut j = 0;
                for a in 0..4 {
                    back[a] = if a == m {
                        big
                    } else {
                        j += 1;
                        r[j - 1]
                    };
                }
                let dot: f32 = back.iter().zip(q).map(|(a, b)| a * b / n).sum();
                assert!((dot.abs() - 1.0).abs() < 1e-5, "{q:?}");
            }
        }
    }

    #[test]
    fn rotation_shifts_count_halvings_and_survive_degenerate_scales() {
        let t = 0.0f32; // exp(threshold) = 1
        let ln2 = std::f32::consts::LN_2;
        // Largest scale 1: no shift; 1/2 (one halving): 1; 1/4: 2; far below: the max.
        assert_eq!(rotation_shift([0.0, -5.0, -9.0], t, 4), 0);
        assert_eq!(rotation_shift([-ln2 * 1.0001, -9.0, -9.0], t, 4), 1);
        assert_eq!(rotation_shift([-9.0, -ln2 * 2.0001, -9.0], t, 4), 2);
        assert_eq!(rotation_shift([-30.0; 3], t, 4), 4);
        assert_eq!(rotation_shift([-30.0; 3], t, 0), 0, "max shift 0 = off");
        // Larger than exp(threshold), NaN or infinite: defined, never a panic.
        assert_eq!(rotation_shift([3.0; 3], t, 4), 0);
        assert_eq!(rotation_shift([f32::NAN; 3], t, 4), 0);
        assert_eq!(rotation_shift([f32::NAN, -30.0, f32::NAN], t, 4), 4);
        assert_eq!(rotation_shift([f32::INFINITY; 3], t, 4), 0);
        assert_eq!(rotation_shift([f32::NEG_INFINITY; 3], t, 8), 8);
    }

    #[test]
    fn cells_by_shift_is_a_stable_grouping() {
        assert_eq!(cells_by_shift(&[2, 0, 1, 0, 2]), vec![1, 3, 2, 0, 4]);
        assert!(cells_by_shift(&[]).is_empty());
    }

    #[test]
    fn quantisation_hits_ends_and_constant_ranges() {
        assert_eq!(quantise(-1.0, -1.0, 3.0, 8), 0);
        assert_eq!(quantise(3.0, -1.0, 3.0, 8), 255);
        assert_eq!(dequantise(255, -1.0, 3.0, 8), 3.0);
        assert_eq!(quantise(5.0, 2.0, 2.0, 8), 0);
        assert_eq!(dequantise(0, 2.0, 2.0, 8), 2.0);
        assert_eq!(quantise(1e30, 0.0, 1.0, 16), 65535);
    }

    #[test]
    fn zero_on_level_covers_the_range_and_codes_zero_exactly() {
        for (lo, hi) in [(-0.3f32, 0.7f32), (-5.0, 0.001), (-1e-6, 40.0), (-0.5, 0.5)] {
            for bits in 2..=16u8 {
                let (a, b) = zero_on_level(lo, hi, bits);
                assert!(a <= lo && b >= hi, "{lo}..{hi} at {bits} bits -> {a}..{b}");
                // Widened by at most one step of the new range in all (f32 rounding aside).
                let step = (b - a) / levels(bits);
                assert!(
                    (lo - a) + (b - hi) <= step * 1.01,
                    "{lo}..{hi} at {bits} bits -> {a}..{b}"
                );
                let back = dequantise(quantise(0.0, a, b, bits), a, b, bits);
                assert!(
                    back.abs() <= 1e-6 * (hi - lo),
                    "zero -> {back} at {bits} bits"
                );
            }
        }
        // Ranges not around zero, empty ranges and 1-bit channels are left as they are.
        assert_eq!(zero_on_level(0.2, 0.9, 8), (0.2, 0.9));
        assert_eq!(zero_on_level(-0.9, -0.2, 8), (-0.9, -0.2));
        assert_eq!(zero_on_level(0.0, 0.0, 8), (0.0, 0.0));
        assert_eq!(zero_on_level(-1.0, 1.0, 1), (-1.0, 1.0));
        // Ends that would overflow f32 keep the data's range.
        assert_eq!(zero_on_level(-f32::MAX, f32::MAX, 8), (-f32::MAX, f32::MAX));
    }

    #[test]
    fn sh_bands_above_dc_keep_their_zeros_and_dc_keeps_its_range() {
        let mut g = Gaussians::new(1, 0);
        for i in 0..64 {
            g.positions.push([i as f32, 0.0, 0.0]);
            g.log_scales.push([-3.0; 3]);
            g.rotations.push([1.0, 0.0, 0.0, 0.0]);
            g.opacity.push(0.0);
            // DC from -0.3 to 0.4, band 1 zero for most, with a lopsided range.
            let x = i as f32 / 63.0;
            let rest = if i % 4 == 0 { 0.7 * x - 0.3 } else { 0.0 };
            g.sh.extend([-0.3 + 0.7 * x; 3]);
            g.sh.extend([rest; 9]);
        }
        let set = quantise_set(&g, &QuantBits::LOW);
        let sh0 = FIRST_ROTATION + 4;
        for (c, (bits, lo, hi, q)) in set.channels[sh0..sh0 + 12].iter().enumerate() {
            if c < 3 {
                // The data's range, widened to binary16 ends (§6.5.7).
                assert_eq!(
                    (*lo, *hi),
                    half_range::snap(-0.3, -0.3 + 0.7, QuantBits::LOW.sh_dc),
                    "DC channel {c}: the data's range"
                );
                assert!(*lo <= -0.3 && *hi >= 0.4 && half_range::is_f16(*lo));
                continue;
            }
            for (i, &cell) in q.iter().enumerate() {
                if i % 4 != 0 {
                    let v = dequantise(cell, *lo, *hi, *bits);
                    assert!(v.abs() < 1e-6, "band-1 channel {c}, Gaussian {i}: {v}");
                }
            }
        }
    }
}
