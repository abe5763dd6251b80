//! `AHAC`: canonical anchors of a Scaffold-GS GOP, HAC-coded (format-spec §6.13): quantised
//! positions, the context model (binary hash grids coded as `RNTC` segments, `mlp_grid`), and
//! the anchors' feature, log-scaling and offset integers range-coded in batches with a
//! Gaussian model per symbol. Batches decode in parallel; the result does not depend on the
//! thread count.

use bitvec::prelude::*;
use constriction::stream::queue::{DefaultRangeDecoder, DefaultRangeEncoder};
use constriction::stream::{Decode, Encode};
use rayon::prelude::*;

use crate::bytes::{zstd_compress, zstd_exact, ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::entropy::binary_bits;
use crate::entropy::binary_bits::BitWord;
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::hac_cdf::{GaussModel, MAX_ALPHABET, MAX_SYMBOL_MAGNITUDE};
use crate::model::hac_context::{
    dequantize, AnchorParams, GridShape, HacContext, Prepared, ATTR_CHANNELS, CONTEXT_OUT,
};
use crate::model::scaffold::{Anchors, ScaffoldCanonical};

/// Largest batch a reader accepts.
pub const MAX_BATCH: u32 = 1 << 20;
/// The reference's batch size.
pub const REFERENCE_BATCH: u32 = 1000;

/// What an `AHAC` chunk holds: the context model, the quantised positions and the integers.
#[derive(Debug, Clone, PartialEq)]
pub struct HacAnchors {
    pub n_static: u32,
    pub n_dynamic: u32,
    /// Anchors per batch.
    pub batch: u32,
    pub context: HacContext,
    /// Static anchors, then dynamic ones.
    pub quantized: Vec<[u16; 3]>,
    /// Per attribute (feature, log-scaling, offsets) the integers `round(x / Q)`,
    /// anchor-major, `ATTR_CHANNELS[a]` per anchor.
    pub symbols: [Vec<i32>; 3],
}

/// Bytes of each part of an encoded payload.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AhacSizes {
    pub header: usize,
    pub positions: usize,
    pub grids: usize,
    pub mlp: usize,
    /// Batch headers (lo, hi, bytes).
    pub batch_headers: usize,
    /// Coded streams of feature, log-scaling, offsets.
    pub streams: [usize; 3],
}

fn n_anchors(h: &HacAnchors) -> usize {
    h.n_static as usize + h.n_dynamic as usize
}

/// Segment group labels of scope 1: the 3D grid's levels share a count, the planes' levels
/// another.
fn groups(c: &HacContext) -> Vec<u8> {
    let n3 = c.grid3.resolutions.len();
    (0..c.levels.len()).map(|l| (l >= n3) as u8).collect()
}

/// The canonical anchors: positions dequantised, values `f32(x) * Q`.
fn values(
    positions: Vec<[f32; 3]>,
    symbols: &[Vec<i32>; 3],
    q: &[[f32; 3]],
    n_static: usize,
) -> ScaffoldCanonical {
    let scaled = |a: usize| -> Vec<f32> {
        let c = ATTR_CHANNELS[a];
        symbols[a]
            .iter()
            .enumerate()
            .map(|(k, &x)| x as f32 * q[k / c][a])
            .collect()
    };
    let all = Anchors {
        features: scaled(0),
        log_scalings: scaled(1),
        offsets: scaled(2),
        positions,
    };
    ScaffoldCanonical::split_at(all, n_static)
}

impl HacAnchors {
    /// The decoded anchors (the decoder's arithmetic: context, steps, values).
    pub fn canonical(&self) -> ScaffoldCanonical {
        let positions = dequantize(
            &self.quantized,
            self.context.bound_min,
            self.context.bound_max,
        );
        let params = self.context.prepare().eval(&positions);
        let q: Vec<[f32; 3]> = params.iter().map(|p| p.q).collect();
        values(positions, &self.symbols, &q, self.n_static as usize)
    }
}

impl HacAnchors {
    /// Near-lossless: the same anchors with every step `k` times larger (`Q_BASE × k`, so
    /// `Q' = k Q` up to rounding) and the integers requantised, `x' = round(x Q / Q')` (0 where
    /// `Q'` is 0). Each value moves by at most `Q' / 2` (plus rounding); `k = 1` changes nothing.
    pub fn requantized(&self, k: f32) -> Result<HacAnchors> {
        if !(k.is_finite() && k > 0.0) {
            return Err(Error::input(format!("AHAC: step scale {k} (finite, > 0)")));
        }
        if k == 1.0 {
            return Ok(self.clone());
        }
        let positions = dequantize(
            &self.quantized,
            self.context.bound_min,
            self.context.bound_max,
        );
        let old = self.context.prepare().eval(&positions);
        let mut out = self.clone();
        out.context.q_base = self.context.q_base.map(|q| q * k);
        let new = out.context.prepare().eval(&positions);
        for a in 0..3 {
            let c = ATTR_CHANNELS[a];
            for (i, x) in out.symbols[a].iter_mut().enumerate() {
                let (q0, q1) = (old[i / c].q[a], new[i / c].q[a]);
                let v = *x as f32 * q0;
                *x = if q1 > 0.0 { (v / q1).round() as i32 } else { 0 };
            }
        }
        Ok(out)
    }
}

/// The model of symbol `k` (anchor `k / c`, channel `k % c`) of attribute `a`.
#[inline]
fn model(p: &AnchorParams, a: usize, ch: usize, lo: i32, len: u32) -> GaussModel {
    let m = AnchorParams::mean_at(a);
    let c = ATTR_CHANNELS[a];
    GaussModel::new(lo, len, p.out[m + ch], p.out[m + c + ch], p.q[a])
}

/// Range-code one batch's symbols of attribute `a`: `(lo, hi, words)`.
fn encode_stream(params: &[AnchorParams], syms: &[i32], a: usize) -> Result<(i32, i32, Vec<u32>)> {
    let lo = *syms.iter().min().expect("a batch is not empty");
    let hi = *syms.iter().max().expect("a batch is not empty");
    if lo < -MAX_SYMBOL_MAGNITUDE || hi > MAX_SYMBOL_MAGNITUDE {
        return Err(Error::input(format!(
            "AHAC: symbol range [{lo}, {hi}] outside ±{MAX_SYMBOL_MAGNITUDE}"
        )));
    }
    let len = (hi as i64 - lo as i64 + 1) as u32;
    if len > MAX_ALPHABET {
        return Err(Error::input(format!(
            "AHAC: alphabet of {len} symbols (at most {MAX_ALPHABET})"
        )));
    }
    if len == 1 {
        return Ok((lo, hi, Vec::new()));
    }
    let c = ATTR_CHANNELS[a];
    let mut enc = DefaultRangeEncoder::new();
    for (k, &x) in syms.iter().enumerate() {
        let m = model(&params[k / c], a, k % c, lo, len);
        enc.encode_symbol((x - lo) as u32, m)
            .map_err(|e| Error::input(format!("AHAC: range coder: {e:?}")))?;
    }
    let words = enc
        .into_compressed()
        .map_err(|_| Error::input("AHAC: range coder backend"))?;
    Ok((lo, hi, words))
}

/// Serialise. The scene must agree on the anchor counts.
pub fn encode(
    h: &HacAnchors,
    scene: &SceneHeader,
    zstd_level: i32,
) -> Result<(Vec<u8>, AhacSizes)> {
    if h.n_static != scene.n_static || h.n_dynamic != scene.n_dynamic {
        return Err(Error::input("AHAC: anchor counts differ from the scene's"));
    }
    encode_payload(h, zstd_level)
}

/// Serialise without a scene: the payload [`encode`] writes for a scene with these counts.
pub fn encode_payload(h: &HacAnchors, zstd_level: i32) -> Result<(Vec<u8>, AhacSizes)> {
    let c = &h.context;
    c.validate()
        .map_err(|e| Error::input(format!("AHAC: {e}")))?;
    let n = n_anchors(h);
    if h.quantized.len() != n
        || (0..3).any(|a| h.symbols[a].len() != n * ATTR_CHANNELS[a])
        || !(1..=MAX_BATCH).contains(&h.batch)
        || c.grid3.resolutions.len() > 255
    {
        return Err(Error::input(
            "AHAC: positions, symbols or batch size do not fit",
        ));
    }
    let mut sizes = AhacSizes::default();
    let mut out = Vec::new();
    out.put_u32(h.n_static);
    out.put_u32(h.n_dynamic);
    out.put_u32(h.batch);
    out.put_f32s(&c.bound_min);
    out.put_f32s(&c.bound_max);
    out.put_f32s(&c.q_base);
    let (g3, g2) = (&c.grid3, &c.grid2);
    let (segs, ones): (Vec<&BitSlice<BitWord, Lsb0>>, Vec<u64>) = c
        .levels
        .iter()
        .map(|l| (l.as_bitslice(), l.count_ones() as u64))
        .unzip();
    let g = groups(c);
    let a = binary_bits::encode_segments(&segs, &ones, None);
    let b = binary_bits::encode_segments(&segs, &ones, Some(&g));
    let total = |v: &Vec<Vec<u32>>| v.iter().map(Vec::len).sum::<usize>();
    let (scope, coded) = if total(&b) < total(&a) {
        (1u8, b)
    } else {
        (0u8, a)
    };
    for v in [
        g3.resolutions.len() as u8,
        g3.log2_table,
        g3.features,
        g2.resolutions.len() as u8,
        g2.log2_table,
        g2.features,
        scope,
        0,
    ] {
        out.put_u8(v);
    }
    for &r in g3.resolutions.iter().chain(&g2.resolutions) {
        out.put_u32(r);
    }
    out.put_u16(c.hidden as u16);
    out.put_u16(CONTEXT_OUT as u16);
    sizes.header = out.len();

    let mut raw = Vec::with_capacity(6 * n);
    for d in 0..3 {
        for q in &h.quantized {
            raw.put_u16(q[d]);
        }
    }
    let z = zstd_compress(&raw, zstd_level)?;
    out.put_u32(z.len() as u32);
    out.extend_from_slice(&z);
    sizes.positions = 4 + z.len();

    let at = out.len();
    for (o, w) in ones.iter().zip(&coded) {
        out.put_u32(*o as u32);
        out.put_u32((w.len() * 4) as u32);
    }
    for w in &coded {
        for &x in w {
            out.put_u32(x);
        }
    }
    sizes.grids = out.len() - at;

    let mut raw = Vec::new();
    for v in [&c.w1, &c.b1, &c.w2, &c.b2] {
        raw.put_f32s(v);
    }
    let z = zstd_compress(&raw, zstd_level)?;
    out.put_u32(z.len() as u32);
    out.extend_from_slice(&z);
    sizes.mlp = 4 + z.len();

    let positions = dequantize(&h.quantized, c.bound_min, c.bound_max);
    let prepared = c.prepare();
    let bsz = h.batch as usize;
    let streams: Vec<[(i32, i32, Vec<u32>); 3]> = (0..n.div_ceil(bsz))
        .into_par_iter()
        .map(|b| {
            let (a0, a1) = (b * bsz, ((b + 1) * bsz).min(n));
            let params = prepared.eval(&positions[a0..a1]);
            let one = |a: usize| {
                let ch = ATTR_CHANNELS[a];
                encode_stream(&params, &h.symbols[a][a0 * ch..a1 * ch], a)
            };
            Ok([one(0)?, one(1)?, one(2)?])
        })
        .collect::<Result<_>>()?;
    for s in streams.iter().flatten() {
        out.put_u32(s.0 as u32);
        out.put_u32(s.1 as u32);
        out.put_u32((s.2.len() * 4) as u32);
    }
    sizes.batch_headers = 12 * 3 * streams.len();
    for s in &streams {
        for (a, (_, _, w)) in s.iter().enumerate() {
            for &x in w {
                out.put_u32(x);
            }
            sizes.streams[a] += w.len() * 4;
        }
    }
    Ok((out, sizes))
}

fn bad(reason: impl Into<String>, at: u64) -> Error {
    Error::payload(ChunkType::AHAC, reason, at)
}

fn read_shape(r: &mut ByteReader, levels: u8, log2: u8, features: u8) -> Result<GridShape> {
    let mut resolutions = Vec::with_capacity(levels as usize);
    for _ in 0..levels {
        resolutions.push(r.u32("AHAC resolution")?);
    }
    Ok(GridShape {
        resolutions,
        log2_table: log2,
        features,
    })
}

/// A decoded batch: each anchor's steps and the batch's integers per attribute.
type BatchOut = (Vec<[f32; 3]>, [Vec<i32>; 3]);

/// Decode one batch's stream of attribute `a`.
fn decode_stream(
    params: &[AnchorParams],
    a: usize,
    lo: i32,
    hi: i32,
    words: &[u8],
    at: u64,
) -> Result<Vec<i32>> {
    let c = ATTR_CHANNELS[a];
    let count = params.len() * c;
    if lo == hi {
        return Ok(vec![lo; count]);
    }
    let len = (hi - lo + 1) as u32;
    let w: Vec<u32> = words
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect();
    let mut dec = DefaultRangeDecoder::from_compressed(w)
        .map_err(|_| bad("invalid range-coder stream", at))?;
    let mut out = Vec::with_capacity(count);
    for k in 0..count {
        let m = model(&params[k / c], a, k % c, lo, len);
        let s = dec
            .decode_symbol(m)
            .map_err(|_| bad(format!("invalid range-coder stream (symbol {k})"), at))?;
        out.push(lo + s as i32);
    }
    Ok(out)
}

/// Decode a payload at file offset `offset`: the chunk's content and the anchors.
pub fn decode_full(
    p: &[u8],
    offset: u64,
    scene: &SceneHeader,
    limits: &Limits,
) -> Result<(HacAnchors, ScaffoldCanonical)> {
    let mut r = ByteReader::new(p, offset);
    let ns = r.u32("AHAC n_static")?;
    let nd = r.u32("AHAC n_dynamic")?;
    if ns != scene.n_static || nd != scene.n_dynamic {
        return Err(bad(
            format!(
                "{ns} + {nd} anchors, the scene header says {} + {}",
                scene.n_static, scene.n_dynamic
            ),
            offset,
        ));
    }
    let n = ns as usize + nd as usize;
    limits.check_gaussians("AHAC anchors", n as u64, offset)?;
    let at = r.offset();
    let batch = r.u32("AHAC batch")?;
    if !(1..=MAX_BATCH).contains(&batch) {
        return Err(bad(format!("batch of {batch} anchors (1..=2^20)"), at));
    }
    let mut f = [0f32; 9];
    for v in f.iter_mut() {
        *v = r.finite_f32("AHAC box and steps")?;
    }
    let at = r.offset();
    let g = r.take(8, "AHAC grid shapes")?;
    if g[7] != 0 || g[6] > 1 {
        return Err(bad(format!("scope {} / reserved {}", g[6], g[7]), at + 6));
    }
    let scope = g[6];
    let grid3 = read_shape(&mut r, g[0], g[1], g[2])?;
    let grid2 = read_shape(&mut r, g[3], g[4], g[5])?;
    grid3.check("3D grid").map_err(|e| bad(e, at))?;
    grid2.check("planes").map_err(|e| bad(e, at))?;
    let at = r.offset();
    let hidden = r.u16("AHAC hidden width")? as usize;
    let outputs = r.u16("AHAC output width")? as usize;
    if !(1..=crate::model::hac_context::MAX_HIDDEN).contains(&hidden) || outputs != CONTEXT_OUT {
        return Err(bad(
            format!("mlp_grid hidden {hidden} (1..=1024), outputs {outputs} ({CONTEXT_OUT})"),
            at,
        ));
    }

    // Positions.
    let at = r.offset();
    let plen = r.u32("AHAC positions length")? as usize;
    let z = r.take(plen, "AHAC positions")?;
    limits.check_alloc("AHAC positions", 6 * n as u64, at)?;
    let raw = zstd_exact(z, 6 * n as u64, at + 4)?;
    let comp =
        |d: usize, i: usize| u16::from_le_bytes([raw[2 * (d * n + i)], raw[2 * (d * n + i) + 1]]);
    let quantized: Vec<[u16; 3]> = (0..n)
        .map(|i| [comp(0, i), comp(1, i), comp(2, i)])
        .collect();

    // Grid bits.
    let lens = HacContext::level_bits(&grid3, &grid2);
    let total_bits: u64 = lens.iter().map(|&b| b as u64).sum();
    // The bits, and the decoder's lookup tables (at most one byte per bit).
    limits.check_alloc(
        "AHAC grid bits and tables",
        total_bits / 8 + total_bits + 8 * lens.len() as u64,
        at,
    )?;
    let mut ones = Vec::with_capacity(lens.len());
    let mut sizes = Vec::with_capacity(lens.len());
    for &nb in &lens {
        let at = r.offset();
        let o = r.u32("AHAC segment ones")? as u64;
        let s = r.u32("AHAC segment bytes")? as usize;
        let constant = o == 0 || o == nb as u64;
        if o > nb as u64 || !s.is_multiple_of(4) || constant != (s == 0) {
            return Err(bad(
                format!("segment of {s} bytes for {o} ones of {nb} bits"),
                at,
            ));
        }
        ones.push(o);
        sizes.push(s);
    }
    let grp: Vec<u8> = (0..lens.len())
        .map(|l| (l >= grid3.resolutions.len()) as u8)
        .collect();
    let probs = binary_bits::segment_probabilities(&ones, &lens, (scope == 1).then_some(&grp[..]));
    let mut streams = Vec::with_capacity(lens.len());
    for &s in &sizes {
        let at = r.offset();
        streams.push((at, r.take(s, "AHAC segment words")?));
    }
    let levels: Vec<BitVec<BitWord, Lsb0>> = streams
        .par_iter()
        .enumerate()
        .map(|(i, &(at, b))| {
            binary_bits::decode_segment(b, lens[i], ones[i], probs[i])
                .map_err(|e| bad(format!("grid segment {i}: {e}"), at))
        })
        .collect::<Result<_>>()?;

    // mlp_grid.
    let inputs = grid3.resolutions.len() * grid3.features as usize
        + 3 * grid2.resolutions.len() * grid2.features as usize;
    let params = HacContext::param_count(inputs, hidden);
    let at = r.offset();
    let wlen = r.u32("AHAC mlp_grid length")? as usize;
    let z = r.take(wlen, "AHAC mlp_grid")?;
    // The weights, and their transposed copy.
    limits.check_alloc("AHAC mlp_grid", params as u64 * 8, at)?;
    let raw = zstd_exact(z, params as u64 * 4, at + 4)?;
    let mut w = ByteReader::new(&raw, at + 4);
    let mut take = |k| w.f32_vec(k, "AHAC mlp_grid");
    let context = HacContext {
        grid3,
        grid2,
        bound_min: [f[0], f[1], f[2]],
        bound_max: [f[3], f[4], f[5]],
        q_base: [f[6], f[7], f[8]],
        levels,
        hidden,
        w1: take(inputs * hidden)?,
        b1: take(hidden)?,
        w2: take(hidden * CONTEXT_OUT)?,
        b2: take(CONTEXT_OUT)?,
    };
    context.validate().map_err(|e| bad(e, offset))?;

    // Batches.
    let bsz = batch as usize;
    let nb = n.div_ceil(bsz);
    let at = r.offset();
    let heads = r.take(
        nb.checked_mul(36).ok_or_else(|| bad("batch count", at))?,
        "AHAC batch headers",
    )?;
    let word = |k: usize| u32::from_le_bytes(heads[4 * k..4 * k + 4].try_into().expect("4"));
    let mut jobs = Vec::with_capacity(3 * nb);
    for k in 0..3 * nb {
        let hat = at + 12 * k as u64;
        let (lo, hi, bytes) = (
            word(3 * k) as i32,
            word(3 * k + 1) as i32,
            word(3 * k + 2) as usize,
        );
        if lo < -MAX_SYMBOL_MAGNITUDE || hi > MAX_SYMBOL_MAGNITUDE || hi < lo {
            return Err(bad(format!("symbol range [{lo}, {hi}]"), hat));
        }
        if (hi - lo) as u32 >= MAX_ALPHABET {
            return Err(bad(format!("alphabet of {} symbols", hi - lo + 1), hat));
        }
        if !bytes.is_multiple_of(4) || (lo == hi) != (bytes == 0) {
            return Err(bad(
                format!("stream of {bytes} bytes for [{lo}, {hi}]"),
                hat,
            ));
        }
        jobs.push((lo, hi, bytes));
    }
    let mut data = Vec::with_capacity(3 * nb);
    for &(lo, hi, bytes) in &jobs {
        let sat = r.offset();
        data.push((lo, hi, sat, r.take(bytes, "AHAC stream")?));
    }
    if r.remaining() != 0 {
        return Err(bad(
            format!("{} bytes after the streams", r.remaining()),
            r.offset(),
        ));
    }
    let syms_total: u64 = ATTR_CHANNELS.iter().map(|&c| (c * n) as u64).sum();
    limits.check_alloc("AHAC symbols", 8 * syms_total + 12 * n as u64, at)?;
    let positions = dequantize(&quantized, context.bound_min, context.bound_max);
    let prepared: Prepared = context.prepare();
    let decoded: Vec<BatchOut> = (0..nb)
        .into_par_iter()
        .map(|b| {
            let (a0, a1) = (b * bsz, ((b + 1) * bsz).min(n));
            let params = prepared.eval(&positions[a0..a1]);
            let one = |a: usize| {
                let (lo, hi, sat, words) = data[3 * b + a];
                decode_stream(&params, a, lo, hi, words, sat)
            };
            let syms = [one(0)?, one(1)?, one(2)?];
            Ok((params.iter().map(|p| p.q).collect(), syms))
        })
        .collect::<Result<_>>()?;
    let mut q = Vec::with_capacity(n);
    let mut symbols: [Vec<i32>; 3] = Default::default();
    for (qs, s) in decoded {
        q.extend(qs);
        for (all, part) in symbols.iter_mut().zip(s) {
            all.extend(part);
        }
    }
    let canonical = values(positions, &symbols, &q, ns as usize);
    Ok((
        HacAnchors {
            n_static: ns,
            n_dynamic: nd,
            batch,
            context,
            quantized,
            symbols,
        },
        canonical,
    ))
}

/// Decode a payload at file offset `offset` to the canonical anchors.
pub fn decode(
    p: &[u8],
    offset: u64,
    scene: &SceneHeader,
    limits: &Limits,
) -> Result<ScaffoldCanonical> {
    decode_full(p, offset, scene, limits).map(|(_, c)| c)
}
