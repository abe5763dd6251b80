//! Quantising and coding one set's channels (the encoder's side): octree positions and the
//! order they give, level shaping, coarse rotations, then each channel's best grid codec.

use rayon::prelude::*;

use super::channels::{channels, values, Kind, FIRST_ROTATION};
use super::quantiser::{
    dequantise, grid_width, levels, position_steps, quantise, range, robust_radius,
};
use super::rotation_coarsening::{
    cells_by_shift, coarsening_record, halvings, rotation_shift, RotationCoarsening,
};
use super::QuantBits;
use super::{grid_shaping, kd_layout, octree_positions};
use crate::chunks::csog::grid_coder::{self, GridCodec};
use crate::model::Gaussians;

/// One channel as stored.
pub(super) struct Channel {
    pub(super) bits: u8,
    pub(super) min: f32,
    pub(super) max: f32,
    pub(super) codec: GridCodec,
    pub(super) data: Vec<u8>,
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
pub(super) struct CodedSet {
    pub(super) channels: Vec<Channel>,
    pub(super) octree: Option<Vec<u8>>,
    /// Layout 3's (max shift, threshold) of rotation coarsening (§6.5.6).
    pub(super) coarsening: Option<(u8, f32)>,
    /// `order[k]` = index in the given set of the Gaussian stored `k`-th.
    pub(super) order: Vec<u32>,
}

/// How one set is quantised and coded: everything [`code_set`] takes besides the set.
#[derive(Clone, Copy)]
pub(super) struct SetCoding<'a> {
    pub(super) bits: &'a QuantBits,
    pub(super) zstd_level: i32,
    /// One per Gaussian: bits one squared quantisation step of its error is worth; the
    /// channels are then shaped first ([`shape_channels`]).
    pub(super) weight: Option<&'a [f32]>,
    /// Positions as an octree, the set stored in the order readers derive from them
    /// ([`kd_layout`]), not the order given.
    pub(super) octree: bool,
    /// Layout 3's coarse rotations (octree sets only).
    pub(super) coarsen: Option<RotationCoarsening>,
    /// Codec 5's mixed modes where they save this fraction; `None` leaves them out.
    pub(super) mixed_margin: Option<f64>,
}

impl<'a> SetCoding<'a> {
    /// A grid set (no octree, shaping or coarse rotations) at the default mixed margin.
    pub(super) fn grid(bits: &'a QuantBits, zstd_level: i32) -> SetCoding<'a> {
        SetCoding {
            bits,
            zstd_level,
            weight: None,
            octree: false,
            coarsen: None,
            mixed_margin: Some(grid_coder::MIXED_MARGIN),
        }
    }
}

/// Quantise and code every channel of a set, in payload order.
pub(super) fn code_set(g: &Gaussians, how: &SetCoding) -> CodedSet {
    let SetCoding {
        bits,
        zstd_level,
        weight,
        octree,
        coarsen,
        mixed_margin,
    } = *how;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chunks::csog::half_range;

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
