//! `RNTC`: a GOP's binary-voxel residual field (format-spec §6.6): grid shapes, normalisation
//! box, the binary grids entropy-coded per segment with the stored frequency of +1, and the
//! MLP weights.

use bitvec::prelude::*;
use rayon::prelude::*;

use crate::bytes::{ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::entropy::binary_bits;
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::ntc::{NtcConfig, NtcField, NtcMlp, RowLayout};

/// Largest plane level count, log2 table size and feature count a reader accepts (bounds the
/// work a file can ask for: at most 3 * 8 * 2^20 * 8 bits).
pub const MAX_LEVELS: usize = 8;
pub const MAX_LOG2_TABLE: u8 = 20;
pub const MAX_FEATURES: u8 = 8;
pub const MAX_HIDDEN: usize = 1024;

/// Where a segment's probability of a 1 bit comes from (§6.6.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrequencyScope {
    /// Each segment's own count of ones.
    Segment = 0,
    /// The count summed over the segment's grid (all plane levels, or the gate).
    Grid = 1,
}

/// Segment sizes in bits: `3 * levels` plane levels then the gate.
fn segment_lengths(c: &NtcConfig) -> Vec<usize> {
    let mut v = vec![c.level_bits(); 3 * c.levels()];
    v.push(c.gate_table());
    v
}

/// The shared-count groups of scope 1: the plane levels, then the gate.
fn grid_groups(n: usize) -> Vec<u8> {
    let mut g = vec![0u8; n - 1];
    g.push(1);
    g
}

/// Per segment probability of a 1 bit under `scope`.
fn probabilities(ones: &[u64], lens: &[usize], scope: FrequencyScope) -> Vec<u32> {
    match scope {
        FrequencyScope::Segment => binary_bits::segment_probabilities(ones, lens, None),
        FrequencyScope::Grid => {
            binary_bits::segment_probabilities(ones, lens, Some(&grid_groups(lens.len())))
        }
    }
}

fn code_segments(
    segs: &[&BitSlice<u64, Lsb0>],
    ones: &[u64],
    scope: FrequencyScope,
) -> Vec<Vec<u32>> {
    match scope {
        FrequencyScope::Segment => binary_bits::encode_segments(segs, ones, None),
        FrequencyScope::Grid => {
            binary_bits::encode_segments(segs, ones, Some(&grid_groups(segs.len())))
        }
    }
}

/// One row of [`grid_report`].
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentReport {
    pub bits: usize,
    pub ones: u64,
    /// Coded bytes with the segment's own frequency and with its grid's.
    pub bytes_segment: usize,
    pub bytes_grid: usize,
    /// `n H(ones / n)` in bits.
    pub entropy_bits: f64,
}

/// The field's segments in storage order (plane levels, then the gate) and their counts of ones.
fn segments(f: &NtcField) -> (Vec<&BitSlice<u64, Lsb0>>, Vec<u64>) {
    let segs: Vec<&BitSlice<u64, Lsb0>> = f
        .planes
        .iter()
        .map(|p| p.as_bitslice())
        .chain([f.gate.as_bitslice()])
        .collect();
    let ones = segs.iter().map(|s| s.count_ones() as u64).collect();
    (segs, ones)
}

/// Coded size of every segment under both frequency scopes, and the entropy bound.
pub fn grid_report(f: &NtcField) -> Vec<SegmentReport> {
    let (segs, ones) = segments(f);
    let a = code_segments(&segs, &ones, FrequencyScope::Segment);
    let b = code_segments(&segs, &ones, FrequencyScope::Grid);
    segs.iter()
        .enumerate()
        .map(|(i, s)| SegmentReport {
            bits: s.len(),
            ones: ones[i],
            bytes_segment: a[i].len() * 4,
            bytes_grid: b[i].len() * 4,
            entropy_bits: binary_bits::entropy_bits(ones[i], s.len() as u64),
        })
        .collect()
}

fn best_coding(segs: &[&BitSlice<u64, Lsb0>], ones: &[u64]) -> (FrequencyScope, Vec<Vec<u32>>) {
    let a = code_segments(segs, ones, FrequencyScope::Segment);
    let b = code_segments(segs, ones, FrequencyScope::Grid);
    let size = |v: &Vec<Vec<u32>>| v.iter().map(Vec::len).sum::<usize>();
    if size(&b) < size(&a) {
        (FrequencyScope::Grid, b)
    } else {
        (FrequencyScope::Segment, a)
    }
}

/// Encode a field. The weights are stored as f32, zstd-compressed.
pub fn encode(f: &NtcField, scene: &SceneHeader, zstd_level: i32) -> Result<Vec<u8>> {
    f.validate_layout(RowLayout::of(scene))
        .map_err(|e| Error::input(format!("RNTC: {e}")))?;
    let c = &f.config;
    if c.levels() > MAX_LEVELS
        || c.log2_table > MAX_LOG2_TABLE
        || c.gate_log2_table > MAX_LOG2_TABLE
        || c.features > MAX_FEATURES
        || f.mlp.hidden > MAX_HIDDEN
    {
        return Err(Error::input("RNTC: grid or MLP larger than §6.6 allows"));
    }
    let (segs, ones) = segments(f);
    let (scope, coded) = best_coding(&segs, &ones);

    let mut out = Vec::new();
    out.put_u8(f.groups);
    out.put_u8(f.sets);
    out.put_u8(c.features);
    out.put_u8(c.log2_table);
    out.put_u8(c.gate_log2_table);
    out.put_u8(c.levels() as u8);
    out.put_u8(scope as u8);
    out.put_u8(0);
    out.put_f32s(&f.bound_min);
    out.put_f32s(&f.bound_max);
    out.put_u32(c.gate_resolution);
    for &r in &c.resolutions {
        out.put_u32(r);
    }
    out.put_u16(f.mlp.hidden as u16);
    out.put_u16(f.mlp.outputs as u16);
    for (o, w) in ones.iter().zip(&coded) {
        out.put_u32(*o as u32);
        out.put_u32((w.len() * 4) as u32);
    }
    for w in &coded {
        for &x in w {
            out.put_u32(x);
        }
    }
    let mut raw = Vec::new();
    for v in f.mlp.params() {
        raw.put_f32(*v);
    }
    let z = crate::bytes::zstd_compress(&raw, zstd_level)?;
    out.put_u32(z.len() as u32);
    out.extend_from_slice(&z);
    Ok(out)
}

/// Decode an `RNTC` payload that starts at file offset `offset`.
pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<NtcField> {
    let mut r = ByteReader::new(p, offset);
    let groups = r.u8("RNTC groups")?;
    let sets = r.u8("RNTC sets")?;
    let at = r.offset();
    let features = r.u8("RNTC features")?;
    let log2_table = r.u8("RNTC log2 table")?;
    let gate_log2_table = r.u8("RNTC gate log2 table")?;
    let levels = r.u8("RNTC levels")? as usize;
    if !(1..=MAX_FEATURES).contains(&features)
        || !(1..=MAX_LOG2_TABLE).contains(&log2_table)
        || !(1..=MAX_LOG2_TABLE).contains(&gate_log2_table)
        || !(1..=MAX_LEVELS).contains(&levels)
    {
        return Err(Error::payload(
            ChunkType::RNTC,
            format!(
                "grid shape out of range: {features} features, log2 table {log2_table}, \
                 gate log2 table {gate_log2_table}, {levels} levels"
            ),
            at,
        ));
    }
    let at = r.offset();
    let scope = match r.u8("RNTC frequency scope")? {
        0 => FrequencyScope::Segment,
        1 => FrequencyScope::Grid,
        v => {
            return Err(Error::payload(
                ChunkType::RNTC,
                format!("unknown frequency scope {v}"),
                at,
            ))
        }
    };
    r.u8("RNTC reserved")?;
    let mut bmin = [0f32; 3];
    let mut bmax = [0f32; 3];
    for v in bmin.iter_mut().chain(bmax.iter_mut()) {
        *v = r.finite_f32("RNTC bounds")?;
    }
    let gate_resolution = r.u32("RNTC gate resolution")?;
    let mut resolutions = Vec::with_capacity(levels);
    for _ in 0..levels {
        resolutions.push(r.u32("RNTC resolution")?);
    }
    let at = r.offset();
    let hidden = r.u16("RNTC hidden width")? as usize;
    let outputs = r.u16("RNTC output width")? as usize;
    if hidden == 0 || hidden > MAX_HIDDEN {
        return Err(Error::payload(
            ChunkType::RNTC,
            format!("hidden width {hidden} (1..={MAX_HIDDEN})"),
            at,
        ));
    }
    let config = NtcConfig {
        resolutions,
        features,
        log2_table,
        gate_resolution,
        gate_log2_table,
    };
    let lens = segment_lengths(&config);
    let total_bits: u64 = lens.iter().map(|&n| n as u64).sum();
    limits.check_alloc("RNTC grid bits", total_bits / 8, at)?;
    let mut ones = Vec::with_capacity(lens.len());
    let mut sizes = Vec::with_capacity(lens.len());
    for &n in &lens {
        let at = r.offset();
        let o = r.u32("RNTC segment ones")? as u64;
        let s = r.u32("RNTC segment bytes")? as usize;
        if o > n as u64 {
            return Err(Error::payload(
                ChunkType::RNTC,
                format!("{o} ones in a segment of {n} bits"),
                at,
            ));
        }
        let constant = o == 0 || o == n as u64;
        if !s.is_multiple_of(4) || (constant && s != 0) || (!constant && s == 0) {
            return Err(Error::payload(
                ChunkType::RNTC,
                format!("segment of {s} bytes for {o} ones of {n} bits"),
                at,
            ));
        }
        ones.push(o);
        sizes.push(s);
    }
    let probs = probabilities(&ones, &lens, scope);
    let mut streams = Vec::with_capacity(lens.len());
    for &s in &sizes {
        let at = r.offset();
        let b = r.take(s, "RNTC segment words")?;
        streams.push((at, b));
    }
    let segs: Vec<BitVec<u64, Lsb0>> = streams
        .par_iter()
        .enumerate()
        .map(|(i, &(at, b))| {
            binary_bits::decode_segment(b, lens[i], ones[i], probs[i])
                .map_err(|e| Error::payload(ChunkType::RNTC, format!("segment {i}: {e}"), at))
        })
        .collect::<Result<_>>()?;
    // The output width follows from the groups (of Gaussians or, in a Scaffold-GS scene, of
    // anchors): check it before sizing the weights.
    let width = RowLayout::of(scene)
        .row_width(groups)
        .map_err(|e| Error::payload(ChunkType::RNTC, e, offset))?;
    if outputs != width {
        return Err(Error::payload(
            ChunkType::RNTC,
            format!("output width {outputs}, the selected groups take {width}"),
            at,
        ));
    }
    let inputs = config.input_width();
    let params = inputs * hidden + hidden + hidden * outputs + outputs;
    let at = r.offset();
    let zlen = r.u32("RNTC weights length")? as usize;
    let z = r.take(zlen, "RNTC weights")?;
    limits.check_alloc("RNTC weights", params as u64 * 4, at)?;
    let raw = crate::bytes::zstd_exact(z, params as u64 * 4, at + 4)?;
    let mut w = ByteReader::new(&raw, at + 4);
    let mut take = |n| w.f32_vec(n, "RNTC weights");
    let mlp = NtcMlp {
        inputs,
        hidden,
        outputs,
        w1: take(inputs * hidden)?,
        b1: take(hidden)?,
        w2: take(hidden * outputs)?,
        b2: take(outputs)?,
    };
    let mut segs = segs;
    let gate = segs.pop().expect("gate segment");
    let field = NtcField {
        config,
        bound_min: bmin,
        bound_max: bmax,
        planes: segs,
        gate,
        mlp,
        groups,
        sets,
    };
    field
        .validate_layout(RowLayout::of(scene))
        .map_err(|e| Error::payload(ChunkType::RNTC, e, offset))?;
    Ok(field)
}
