//! Writing a `CSOG` payload (§6.5.2, §6.5.5-6.5.7): the layouts' set and channel records
//! around what [`set_coder`](super::set_coder) coded, and the encoder's entry points.

use super::channels::{channels, Kind};
use super::quantiser::grid_width;
use super::rotation_coarsening::RotationCoarsening;
use super::set_coder::{code_set, Channel, SetCoding};
use super::{QuantBits, MAX_PARTS};
use crate::bytes::PutLe;
use crate::chunks::csog::grid_coder::{self, GridCodec};
use crate::chunks::csog::half_range;
use crate::error::{Error, Result};
use crate::model::{Canonical, Gaussians};

/// Bytes of a channel record before its data in layouts 0-3: bits, codec, min, max, len
/// (§6.5.2); [`breakdown`] counts records this way (layout 4's take 3-10, §6.5.7).
const CHANNEL_HEADER_LEN: usize = 14;
/// Bytes of an octree set's position record before the octree: bits, three ranges, len.
const OCTREE_HEADER_LEN: usize = 29;

/// Write a set (or, with `octree`, an octree set, §6.5.5), in layout 4's compact records
/// (§6.5.7) when `compact`; returns the stored order (indices into `g`).
fn encode_set(out: &mut Vec<u8>, g: &Gaussians, how: &SetCoding, compact: bool) -> Vec<u32> {
    let (coded, octree) = (code_set(g, how), how.octree);
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
    let how = SetCoding {
        octree,
        ..SetCoding::grid(bits, zstd_level)
    };
    let coded = code_set(g, &how);
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
    for &b in &bits.all() {
        if !(1..=16).contains(&b) {
            return Err(Error::input(format!(
                "quantisation bits must be 1..=16, got {b}"
            )));
        }
    }
    if let Some(s) = static_weight {
        if s.len() != c.statics.len() || s.iter().any(|w| !(*w >= 0.0)) {
            return Err(Error::input(format!(
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
    let grid = SetCoding::grid(bits, zstd_level);
    let statics = SetCoding {
        weight: static_weight,
        ..grid
    };
    encode_set(&mut out, &c.statics, &statics, false);
    encode_set(&mut out, &c.dynamics, &grid, false);
    Ok(out)
}

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
    let static_parts = gop.static_parts;
    if !(1..=MAX_PARTS).contains(&static_parts.len()) {
        return Err(Error::input(format!(
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
            return Err(Error::input(format!(
                "quantisation bits must be 1..=16, got {x}"
            )));
        }
        g.check_shapes()?;
        g.check_finite()?;
    }
    let n_static: usize = static_parts.iter().map(|p| p.0.len()).sum();
    if let Some(s) = gop.static_weight {
        if s.len() != n_static || s.iter().any(|w| !(*w >= 0.0)) {
            return Err(Error::input(format!(
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
        let how = SetCoding {
            bits: b,
            zstd_level,
            weight,
            octree,
            coarsen,
            mixed_margin: gop.mixed_margin,
        };
        let local = encode_set(&mut out, g, &how, compact);
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
        let how = SetCoding {
            mixed_margin: gop.mixed_margin,
            ..SetCoding::grid(gop.dynamic_bits, zstd_level)
        };
        encode_set(&mut out, gop.dynamics, &how, compact);
    }
    Ok((out, order))
}
