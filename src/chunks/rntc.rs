//! `RNTC`: a GOP's binary-voxel residual field (format-spec §6.6): grid shapes, normalisation
//! box, the binary grids entropy-coded per segment with the stored frequency of +1, and the
//! MLP weights.

use bitvec::prelude::*;
use rayon::prelude::*;

use crate::bytes::{ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::entropy::binary_bits;
use crate::entropy::binary_bits::BitWord;
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::ntc::{NtcConfig, NtcField, NtcMlp, RowLayout};
use crate::model::residual::{SET_DYNAMIC, SET_STATIC};

/// Largest plane level count, log2 table size and feature count a reader accepts (bounds the
/// work a file can ask for: at most 3 * 8 * 2^20 * 8 bits).
pub const MAX_LEVELS: usize = 8;
pub const MAX_LOG2_TABLE: u8 = 20;
pub const MAX_FEATURES: u8 = 8;
pub const MAX_HIDDEN: usize = 1024;
/// Grid resolutions (gate and plane levels) a reader accepts (§6.6.2).
pub const MIN_RESOLUTION: u32 = 3;
pub const MAX_RESOLUTION: u32 = 1 << 20;

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
    segs: &[&BitSlice<BitWord, Lsb0>],
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
fn segments(f: &NtcField) -> (Vec<&BitSlice<BitWord, Lsb0>>, Vec<u64>) {
    let segs: Vec<&BitSlice<BitWord, Lsb0>> = f
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

fn best_coding(segs: &[&BitSlice<BitWord, Lsb0>], ones: &[u64]) -> (FrequencyScope, Vec<Vec<u32>>) {
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
    // The output width follows from the groups (of Gaussians or, in a Scaffold-GS scene, of
    // anchors): every field is checked where it is read, before anything is sized from it.
    let width = RowLayout::of(scene)
        .row_width(groups)
        .map_err(|e| Error::payload(ChunkType::RNTC, e, offset))?;
    let sets = r.u8("RNTC sets")?;
    if sets == 0 || sets & !(SET_STATIC | SET_DYNAMIC) != 0 {
        return Err(Error::payload(
            ChunkType::RNTC,
            format!("set mask {sets:#x} (bit 0 static, bit 1 dynamic, not 0)"),
            offset + 1,
        ));
    }
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
    let at = r.offset();
    for v in bmin.iter_mut().chain(bmax.iter_mut()) {
        *v = r.finite_f32("RNTC bounds")?;
    }
    if let Some(a) = (0..3).find(|&a| bmax[a] <= bmin[a]) {
        return Err(Error::payload(
            ChunkType::RNTC,
            format!("box axis {a}: bmax {} not above bmin {}", bmax[a], bmin[a]),
            at + 12 + 4 * a as u64,
        ));
    }
    let mut resolution = |what| {
        let at = r.offset();
        let v = r.u32(what)?;
        if !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&v) {
            return Err(Error::payload(
                ChunkType::RNTC,
                format!("{what} {v} ({MIN_RESOLUTION}..={MAX_RESOLUTION})"),
                at,
            ));
        }
        Ok(v)
    };
    let gate_resolution = resolution("RNTC gate resolution")?;
    let resolutions = (0..levels)
        .map(|_| resolution("RNTC plane resolution"))
        .collect::<Result<Vec<u32>>>()?;
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
    if outputs != width {
        return Err(Error::payload(
            ChunkType::RNTC,
            format!("output width {outputs}, the selected groups take {width}"),
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
    let segs: Vec<BitVec<BitWord, Lsb0>> = streams
        .par_iter()
        .enumerate()
        .map(|(i, &(at, b))| {
            binary_bits::decode_segment(b, lens[i], ones[i], probs[i])
                .map_err(|e| Error::payload(ChunkType::RNTC, format!("segment {i}: {e}"), at))
        })
        .collect::<Result<_>>()?;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene of 4 static and 2 dynamic Gaussians at SH degree 0, no language.
    fn scene() -> SceneHeader {
        let mut s = SceneHeader::still(4, 0);
        s.n_dynamic = 2;
        s
    }

    /// Two plane levels (R 6 dense, R 12 hashed; 2^5 entries of 2 features), gate R 5 of 2^6,
    /// MLP 12 -> 4 -> 4 over position and opacity; bits and weights from a fixed seed.
    fn field() -> NtcField {
        let config = NtcConfig {
            resolutions: vec![6, 12],
            features: 2,
            log2_table: 5,
            gate_resolution: 5,
            gate_log2_table: 6,
        };
        let mut rng = fastrand::Rng::with_seed(9);
        let mut bits = |n: usize| {
            (0..n)
                .map(|_| rng.bool())
                .collect::<BitVec<BitWord, Lsb0>>()
        };
        let planes = (0..6).map(|_| bits(config.level_bits())).collect();
        let gate = bits(config.gate_table());
        let mut w = |n: usize| (0..n).map(|_| rng.f32() - 0.5).collect::<Vec<f32>>();
        NtcField {
            mlp: NtcMlp {
                inputs: 12,
                hidden: 4,
                outputs: 4,
                w1: w(48),
                b1: w(4),
                w2: w(16),
                b2: w(4),
            },
            config,
            bound_min: [-1.0, -2.0, -3.0],
            bound_max: [1.0, 2.0, 3.0],
            planes,
            gate,
            groups: 0b10_0001,
            sets: SET_STATIC | SET_DYNAMIC,
        }
    }

    /// Decode `p` at offset 1000: the error's name and offset.
    fn fault(p: &[u8]) -> (&'static str, u64) {
        let e = decode(p, 1000, &scene(), &Limits::default()).unwrap_err();
        assert!(
            e.name() != "Payload" || e.to_string().contains("RNTC"),
            "{e}"
        );
        (e.name(), e.offset().unwrap())
    }

    #[test]
    fn every_field_is_checked_where_it_stands() {
        let f = field();
        let p = encode(&f, &scene(), 3).unwrap();
        assert_eq!(decode(&p, 1000, &scene(), &Limits::default()).unwrap(), f);
        let edit = |at: usize, v: &[u8]| {
            let mut q = p.clone();
            q[at..at + v.len()].copy_from_slice(v);
            q
        };
        let payload = |at: usize, v: &[u8]| {
            assert_eq!(
                fault(&edit(at, v)),
                ("Payload", 1000 + at as u64),
                "byte {at} = {v:?}"
            );
        };
        // groups: none, a group of width 0 here (sh_rest at degree 0, language without it).
        for g in [0u8, 0b1_0000, 0b100_0000] {
            assert_eq!(fault(&edit(0, &[g])), ("Payload", 1000), "groups {g:#x}");
        }
        // sets: none, an undefined bit.
        payload(1, &[0]);
        payload(1, &[4]);
        // F 1..=8, T2 and T3 1..=20, Lv 1..=8 (reported at F).
        for (at, v) in [
            (2, 0u8),
            (2, 9),
            (3, 0),
            (3, 21),
            (4, 0),
            (4, 21),
            (5, 0),
            (5, 9),
        ] {
            assert_eq!(fault(&edit(at, &[v])), ("Payload", 1002), "byte {at} = {v}");
        }
        payload(6, &[2]);
        // The box: finite, bmax > bmin per axis.
        assert_eq!(
            fault(&edit(8, &f32::NAN.to_le_bytes())),
            ("NonFinite", 1008)
        );
        assert_eq!(
            fault(&edit(28, &f32::INFINITY.to_le_bytes())),
            ("NonFinite", 1028)
        );
        payload(24, &(-2.0f32).to_le_bytes());
        payload(20, &(-1.5f32).to_le_bytes());
        // Resolutions 3..=2^20: the gate's, then each plane level's.
        payload(32, &2u32.to_le_bytes());
        payload(36, &0u32.to_le_bytes());
        payload(40, &((1u32 << 20) + 1).to_le_bytes());
        // H 1..=1024; O the selected groups' width (4), reported at H.
        payload(44, &0u16.to_le_bytes());
        payload(44, &1025u16.to_le_bytes());
        assert_eq!(fault(&edit(46, &5u16.to_le_bytes())), ("Payload", 1044));
        // Segment 0 (2^5 x 2 bits): more ones than bits; a length not a multiple of 4, or 0
        // for a segment that is not constant.
        payload(48, &65u32.to_le_bytes());
        for bytes in [6u32, 0] {
            assert_eq!(fault(&edit(52, &bytes.to_le_bytes())), ("Payload", 1048));
        }
        // The weights: cut short (Truncated), another size (Decompress), not finite (Payload).
        let coded: usize = (0..7)
            .map(|k| u32::from_le_bytes(p[52 + 8 * k..56 + 8 * k].try_into().unwrap()) as usize)
            .sum();
        let wlen_at = 48 + 7 * 8 + coded;
        assert_eq!(fault(&p[..p.len() - 1]).0, "Truncated");
        let with_weights = |raw: &[u8]| {
            let z = crate::bytes::zstd_compress(raw, 3).unwrap();
            let mut q = p[..wlen_at].to_vec();
            q.put_u32(z.len() as u32);
            q.extend_from_slice(&z);
            q
        };
        let mut raw: Vec<u8> = f.mlp.params().flat_map(|v| v.to_le_bytes()).collect();
        assert_eq!(with_weights(&raw), p);
        assert_eq!(fault(&with_weights(&raw[4..])).0, "Decompress");
        raw[..4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert_eq!(fault(&with_weights(&raw)), ("Payload", 1000));
        // The grid bits and the weights are drawn from the budget first.
        let tight = Limits {
            max_alloc: 32,
            ..Limits::default()
        };
        let e = decode(&p, 0, &scene(), &tight).unwrap_err();
        assert_eq!(e.name(), "LimitExceeded", "{e}");
    }

    #[test]
    fn no_byte_change_panics_in_decoding_or_evaluating() {
        let p = encode(&field(), &scene(), 3).unwrap();
        let at = [
            [0.1, 0.2, 0.3],
            [-1.0, -2.0, -3.0],
            [1.0, 2.0, 3.0],
            [0.9, -1.9, 2.9],
        ];
        let mut decoded = 0;
        for i in 0..p.len() {
            for v in [0, 1, 3, 0x7f, 0x80, 0xff, p[i] ^ 0x10] {
                let mut q = p.clone();
                q[i] = v;
                if let Ok(f) = decode(&q, 0, &scene(), &Limits::default()) {
                    decoded += 1;
                    assert_eq!(f.residuals_at(&at).len(), 4 * at.len());
                    for x in at {
                        assert_eq!(f.residual_at(x).len(), 4);
                    }
                }
            }
        }
        assert!(decoded > 0);
    }
}
