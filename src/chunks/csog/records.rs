//! Reading a `CSOG` payload's records (§6.5.2, §6.5.5-6.5.7) without decoding them: every
//! length, range and count is checked against the bytes there and the scene.

use std::borrow::Cow;

use super::channels::Kind;
use super::quantiser::grid_width;
use super::rotation_coarsening::MAX_ROTATION_SHIFT;
use super::MAX_PARTS;
use crate::bytes::{ByteReader, PutLe};
use crate::chunks::csog::adaptive_coder::Mode;
use crate::chunks::csog::grid_coder::GridCodec;
use crate::chunks::csog::octree_positions;
use crate::container::ChunkType;
use crate::error::{Error, Result};

/// How a set's record is laid out (by the `CSOG` layout version).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum SetForm {
    /// Every channel a grid record (layouts 0 and 1, and every dynamic set).
    Grid,
    /// Positions as an octree (layout 2's static parts).
    Octree,
    /// An octree and a rotation coarsening record (layout 3's static parts).
    OctreeCoarse,
}

/// One channel record of a set as read (§6.5.2), its data not yet decoded.
pub(super) struct Record<'a> {
    pub(super) kind: Kind,
    pub(super) bits: u8,
    pub(super) codec: GridCodec,
    pub(super) min: f32,
    pub(super) max: f32,
    /// The data as the codecs read it (layout 4's word count put back, §6.5.7).
    pub(super) data: Cow<'a, [u8]>,
    /// Absolute offset of the data.
    pub(super) at: u64,
    /// Bytes the data takes in the payload.
    pub(super) stored_len: usize,
}

impl Record<'_> {
    /// Codec 5's mode, from the data's first two bytes.
    pub(super) fn mode(&self) -> Option<Mode> {
        (self.codec == GridCodec::Adaptive)
            .then(|| self.data.get(..2))
            .flatten()
            .and_then(|b| Mode::from_bytes(b[0], b[1]))
    }
}

/// A set's records as read: an octree set's positions, its rotation coarsening and one record
/// per channel (the position channels of an octree set with empty data, codec 0).
pub(super) struct SetRecords<'a> {
    pub(super) tree: Option<OctreeRecord<'a>>,
    pub(super) coarsening: Option<(u8, f32)>,
    pub(super) records: Vec<Record<'a>>,
    /// Index of the first record stored as a channel record (after octree positions).
    pub(super) first: usize,
}

/// Read a set's records (§6.5.2, §6.5.5-6.5.7) without decoding them.
pub(super) fn read_set<'a>(
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
            return Err(Error::payload(
                ChunkType::CSOG,
                format!("grid width {stored} for {n} Gaussians, expected {w}"),
                at,
            ));
        }
        let at = r.offset();
        let count = r.u16("CSOG channel count")? as usize;
        if count != kinds.len() {
            return Err(Error::payload(
                ChunkType::CSOG,
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
            return Err(Error::payload(
                ChunkType::CSOG,
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
            return Err(Error::payload(
                ChunkType::CSOG,
                format!("{k:?}: {bits} bits"),
                at,
            ));
        }
        let codec = GridCodec::from_u8(codec).ok_or_else(|| {
            Error::payload(ChunkType::CSOG, format!("unknown grid codec {codec}"), at)
        })?;
        // The records after octree positions start without a previous channel.
        let prev_bits = records
            .last()
            .filter(|_| records.len() > first)
            .map(|p| p.bits);
        if codec == GridCodec::HistogramDelta && prev_bits != Some(bits) {
            return Err(Error::payload(
                ChunkType::CSOG,
                format!("{k:?}: codec 4 needs a previous channel with the same {bits} bits"),
                at,
            ));
        }
        let at = r.offset();
        let (min, max) = match (compact, is_index) {
            (true, true) if half => {
                return Err(Error::payload(
                    ChunkType::CSOG,
                    "the rotation index record has no range to flag",
                    at,
                ))
            }
            (true, true) => (0.0, 3.0),
            _ => read_range(r, half, "CSOG channel min", "CSOG channel max")?,
        };
        if is_index && (min, max) != (0.0, 3.0) {
            return Err(Error::payload(
                ChunkType::CSOG,
                "rotation index channel must have range [0, 3]",
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

/// An octree set's position record (§6.5.5), read but not yet decoded.
pub(super) struct OctreeRecord<'a> {
    pub(super) bits: u8,
    pub(super) ranges: [(f32, f32); 3],
    pub(super) data: Cow<'a, [u8]>,
    pub(super) at: u64,
    /// Bytes the data takes in the payload.
    pub(super) stored_len: usize,
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
        return Err(Error::payload(
            ChunkType::CSOG,
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
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("octree positions of {bits} bits"),
            at,
        ));
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

/// A set stored as parts (layout 1): a part count, then per part its Gaussian count and its
/// set record; the counts must add up to `n`. An empty set may have no parts (since 1.12).
/// `each` reads one part's set record given its Gaussian count.
pub(super) fn read_parts<'a>(
    r: &mut ByteReader<'a>,
    n: usize,
    compact: bool,
    mut each: impl FnMut(&mut ByteReader<'a>, usize) -> Result<()>,
) -> Result<()> {
    let at = r.offset();
    let parts = r.u8("CSOG part count")? as usize;
    if parts > MAX_PARTS || (parts == 0 && n > 0) {
        return Err(Error::payload(
            ChunkType::CSOG,
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
            return Err(Error::payload(
                ChunkType::CSOG,
                format!("part {p} holds {np} Gaussians, only {left} of the set's {n} are left"),
                at,
            ));
        }
        left -= np;
        each(r, np)?;
    }
    if left != 0 {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("the parts hold {} of the set's {n} Gaussians", n - left),
            at,
        ));
    }
    Ok(())
}

/// How `CSOG` layout `version` stores its sets: `None` for layout 0 (one set record each, no
/// parts), else the static parts' form and whether records are compact (§6.5.2, §6.5.7).
pub(super) fn layout_of(version: u8, at: u64) -> Result<Option<(SetForm, bool)>> {
    match version {
        0 => Ok(None),
        1 => Ok(Some((SetForm::Grid, false))),
        2 => Ok(Some((SetForm::Octree, false))),
        3 => Ok(Some((SetForm::OctreeCoarse, false))),
        // Layout 4 is layout 3 in compact records (§6.5.7).
        4 => Ok(Some((SetForm::OctreeCoarse, true))),
        _ => Err(Error::payload(
            ChunkType::CSOG,
            format!("layout version {version} (this reader knows 0 to 4)"),
            at,
        )),
    }
}
