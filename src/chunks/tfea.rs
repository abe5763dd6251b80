//! `TFEA`: the key time features of one GOP (format-spec §6.2). Either exact `f32` (zstd) or
//! tiled into `4 side x (C/4) side` 12-bit gray images that an HEVC encoder codes as one
//! K-frame sequence. This module owns the framing, tiling and quantisation; the HEVC bitstream
//! itself is produced and decoded by `dlgs-video` (FFmpeg), outside this crate.

use crate::bytes::{zstd_exact, ByteReader, PutLe};
pub use crate::chunks::tfea_quantised::Quantised;
use crate::chunks::tfea_quantised::{self, CODEC as QUANTISED};
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, FormatErrorKind, Result};
use crate::model::TimeFeatures;
use crate::Limits;

/// Largest value of a 12-bit sample.
pub const Q_MAX: u16 = 4095;
/// Tiles per image row (the reference's 4 x 4 layout for 16 channels).
pub const TILE_COLUMNS: usize = 4;

/// How the features are stored.
#[derive(Debug, Clone, PartialEq)]
pub enum TfeaBody {
    /// Exact f32, `(N, K, C)` order, one zstd frame.
    Exact(TimeFeatures),
    /// Codec 4 (since 1.19): quantised to 6-12 bits per channel, zstd, no video codec.
    Quantised(Quantised),
    /// Quantised 12-bit tiles coded as an HEVC stream, packets in decode order.
    Hevc {
        tiling: Tiling,
        /// One (lo, hi) per channel (codec 1); empty for codec 2.
        ranges: Vec<(f32, f32)>,
        /// Codec 2: the reference implementation's dequantisation with its one f64 range
        /// (see [`untile_reference`]); `ranges` is then unused.
        reference: Option<(f64, f64)>,
        packets: Vec<Vec<u8>>,
        /// Codec 3 (since 1.7): packet `k` is picture `k` alone, an intra picture with its own
        /// parameter sets, so any key decodes without the others (seeking). Never with
        /// `reference`.
        intra: bool,
    },
}

/// Geometry of the tiled images.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tiling {
    pub n: usize,
    pub keys: usize,
    pub channels: usize,
    /// Tile side; `side * side >= n`.
    pub side: usize,
}

impl Tiling {
    /// The smallest tiling for `n` Gaussians whose image sides are even and at least 64
    /// (libx265 refuses smaller pictures).
    pub fn for_count(n: usize, keys: usize, channels: usize) -> Self {
        let mut side = (n as f64).sqrt().ceil() as usize;
        while side * side < n {
            side += 1;
        }
        let mut t = Tiling {
            n,
            keys,
            channels,
            side,
        };
        // Both sides >= 64: the shorter of 4 tile columns and `tile_rows` tile rows decides.
        t.side = side.max(64usize.div_ceil(TILE_COLUMNS.min(t.tile_rows()).max(1)));
        if t.height() % 2 == 1 || t.width() % 2 == 1 {
            t.side += 1;
        }
        t
    }
    pub fn tile_rows(&self) -> usize {
        self.channels.div_ceil(TILE_COLUMNS)
    }
    pub fn width(&self) -> usize {
        TILE_COLUMNS * self.side
    }
    pub fn height(&self) -> usize {
        self.tile_rows() * self.side
    }
    /// Pixel index of Gaussian `i`'s channel `c`: `frame[(c/4) side + i/side][(c%4) side + i%side]`.
    #[inline]
    pub fn pixel(&self, i: usize, c: usize) -> usize {
        let (row, col) = (
            (c / TILE_COLUMNS) * self.side + i / self.side,
            (c % TILE_COLUMNS) * self.side + i % self.side,
        );
        row * self.width() + col
    }
}

/// Per-channel (lo, hi) of the features over all keys; `per_gop` gives every channel the
/// global range instead (the reference's single min/max).
pub fn ranges(f: &TimeFeatures, per_gop: bool) -> Vec<(f32, f32)> {
    let mut r = vec![(f32::INFINITY, f32::NEG_INFINITY); f.channels];
    for chunk in f.data.chunks_exact(f.channels.max(1)) {
        for (c, &v) in chunk.iter().enumerate() {
            r[c].0 = r[c].0.min(v);
            r[c].1 = r[c].1.max(v);
        }
    }
    for x in &mut r {
        if x.0 > x.1 {
            *x = (0.0, 0.0);
        }
    }
    if per_gop {
        let lo = r.iter().map(|x| x.0).fold(f32::INFINITY, f32::min);
        let hi = r.iter().map(|x| x.1).fold(f32::NEG_INFINITY, f32::max);
        r.iter_mut().for_each(|x| *x = (lo, hi));
    }
    r
}

/// `round((x - lo) / (hi - lo) * 4095)` clamped; a constant channel (`hi <= lo`) gives 0.
#[inline]
pub fn quantise(x: f32, (lo, hi): (f32, f32)) -> u16 {
    if !(hi > lo) {
        return 0;
    }
    let q = ((x - lo) / (hi - lo) * Q_MAX as f32).round();
    q.clamp(0.0, Q_MAX as f32) as u16
}

/// `lo + q * ((hi - lo) / 4095)`, evaluated in f32 exactly in this order (§6.2).
#[inline]
pub fn dequantise(q: u16, (lo, hi): (f32, f32)) -> f32 {
    if !(hi > lo) {
        return lo;
    }
    lo + q as f32 * ((hi - lo) / Q_MAX as f32)
}

/// Tile and quantise every key into one image. Padding pixels repeat the last Gaussian's value
/// (smoother than zeros for the video coder); decoders ignore them.
pub fn tile(f: &TimeFeatures, t: &Tiling, ranges: &[(f32, f32)]) -> Vec<Vec<u16>> {
    (0..f.keys)
        .map(|k| {
            let mut img = vec![0u16; t.width() * t.height()];
            for c in 0..t.tile_rows() * TILE_COLUMNS {
                for i in 0..t.side * t.side {
                    let v = if c < f.channels && f.n > 0 {
                        quantise(f.at(i.min(f.n - 1), k)[c], ranges[c])
                    } else {
                        0
                    };
                    img[t.pixel(i, c)] = v;
                }
            }
            img
        })
        .collect()
}

/// Inverse of [`tile`]: dequantised features from decoded images.
pub fn untile(images: &[Vec<u16>], t: &Tiling, ranges: &[(f32, f32)]) -> TimeFeatures {
    let value = sample_value(ranges);
    let mut f = TimeFeatures::zeros(t.n, t.keys, t.channels);
    for (k, img) in images.iter().enumerate().take(t.keys) {
        for i in 0..t.n {
            let dst = f.at_mut(i, k);
            for c in 0..t.channels {
                dst[c] = value(c, img[t.pixel(i, c)]);
            }
        }
    }
    f
}

/// The features of decoded images key- and channel-major, `(K, C, N)`: column `(k, c)` is
/// channel c's tile of key k read row by row, so each column is a few contiguous copies of
/// image rows (no per-sample index arithmetic). `value(c, q)` dequantises sample `q` of channel
/// c. Columns fill in parallel; every value depends on its own sample only, so the result does
/// not depend on the thread count.
pub fn untile_columns(
    images: &[Vec<u16>],
    t: &Tiling,
    value: impl Fn(usize, u16) -> f32 + Sync,
) -> Vec<f32> {
    use rayon::prelude::*;
    let mut data = vec![0f32; t.keys * t.channels * t.n];
    data.par_chunks_mut(t.n.max(1))
        .enumerate()
        .for_each(|(kc, col)| {
            let (k, c) = (kc / t.channels, kc % t.channels);
            untile_column(&images[k], t, c, &value, col);
        });
    data
}

/// [`untile_columns`] of one key's image, `(C, N)`, on the calling thread only (for callers
/// that hold a lock and must not wait on other threads' work).
pub fn untile_key(image: &[u16], t: &Tiling, value: impl Fn(usize, u16) -> f32) -> Vec<f32> {
    let mut data = vec![0f32; t.channels * t.n];
    for (c, col) in data.chunks_mut(t.n.max(1)).enumerate() {
        untile_column(image, t, c, &value, col);
    }
    data
}

/// Channel c's tile of `image`, row by row, into `col` (`n` values).
fn untile_column(
    image: &[u16],
    t: &Tiling,
    c: usize,
    value: &impl Fn(usize, u16) -> f32,
    col: &mut [f32],
) {
    for (r, dst) in col.chunks_mut(t.side).enumerate() {
        let start = t.pixel(r * t.side, c);
        let src = &image[start..start + dst.len()];
        for (d, &q) in dst.iter_mut().zip(src) {
            *d = value(c, q);
        }
    }
}

/// Codec 1 sample value (what [`untile`] stores).
pub fn sample_value(ranges: &[(f32, f32)]) -> impl Fn(usize, u16) -> f32 + Sync + '_ {
    move |c, q| dequantise(q, ranges[c])
}

/// Codec 2 sample value (what [`untile_reference`] stores).
pub fn reference_sample_value((lo, hi): (f64, f64)) -> impl Fn(usize, u16) -> f32 + Sync {
    move |_, q| {
        let v12 = q as u32;
        let v16 = (v12 << 4) | (v12 >> 8);
        ((v16 as f64 / 65535.0) * (hi - lo) + lo) as f32
    }
}

/// Codec 2 (the reference implementation's decoder, `test_fdsd.py`): each 12-bit sample `v`
/// is expanded to 16 bits as FFmpeg's `gray16` output does (`v << 4 | v >> 8`), then
/// `f32((v16 / 65535) * (hi - lo) + lo)` evaluated in f64 in this order.
pub fn untile_reference(images: &[Vec<u16>], t: &Tiling, range: (f64, f64)) -> TimeFeatures {
    let value = reference_sample_value(range);
    let mut f = TimeFeatures::zeros(t.n, t.keys, t.channels);
    for (k, img) in images.iter().enumerate().take(t.keys) {
        for i in 0..t.n {
            let dst = f.at_mut(i, k);
            for c in 0..t.channels {
                dst[c] = value(c, img[t.pixel(i, c)]);
            }
        }
    }
    f
}

/// Serialise a `TFEA` payload.
pub fn encode(body: &TfeaBody, zstd_level: i32) -> Result<Vec<u8>> {
    let mut b = Vec::new();
    match body {
        TfeaBody::Exact(f) => {
            crate::model::dynamic::check_finite("time features", &f.data)?;
            b.put_u8(0);
            b.put_u8(0);
            b.put_u16(f.channels as u16);
            b.put_u32(f.n as u32);
            b.put_u32(f.keys as u32);
            b.put_u32(0);
            let mut raw = Vec::with_capacity(f.data.len() * 4);
            raw.put_f32s(&f.data);
            let z = crate::bytes::zstd_compress(&raw, zstd_level)?;
            b.extend_from_slice(&z);
        }
        TfeaBody::Quantised(q) => {
            b.put_u8(QUANTISED);
            b.put_u8(q.bits);
            b.put_u16(q.channels as u16);
            b.put_u32(q.n as u32);
            b.put_u32(q.keys as u32);
            b.put_u32(0);
            tfea_quantised::encode_body(q, zstd_level, &mut b)?;
        }
        TfeaBody::Hevc {
            tiling,
            ranges,
            reference,
            packets,
            intra,
        } => {
            let codec = match (reference, intra) {
                (None, false) => 1,
                (Some(_), false) => 2,
                (None, true) => 3,
                (Some(_), true) => {
                    return Err(Error::input(
                        "intra-only time features use per-channel ranges (codec 3)",
                    ))
                }
            };
            if *intra && packets.len() != tiling.keys {
                return Err(Error::input(format!(
                    "intra-only time features need one packet per key: {} packets, {} keys",
                    packets.len(),
                    tiling.keys
                )));
            }
            b.put_u8(codec);
            b.put_u8(12);
            b.put_u16(tiling.channels as u16);
            b.put_u32(tiling.n as u32);
            b.put_u32(tiling.keys as u32);
            b.put_u32(tiling.side as u32);
            if let Some((lo, hi)) = *reference {
                if !lo.is_finite() || !hi.is_finite() {
                    return Err(Error::input("time-feature range not finite"));
                }
                b.extend_from_slice(&lo.to_le_bytes());
                b.extend_from_slice(&hi.to_le_bytes());
            }
            for &(lo, hi) in ranges.iter().filter(|_| reference.is_none()) {
                if !lo.is_finite() || !hi.is_finite() {
                    return Err(Error::input("time-feature range not finite"));
                }
                b.put_f32(lo);
                b.put_f32(hi);
            }
            b.put_u32(packets.len() as u32);
            for p in packets {
                b.put_u32(p.len() as u32);
                b.extend_from_slice(p);
            }
        }
    }
    Ok(b)
}

/// Parse a `TFEA` payload starting at absolute `offset`, checked against the scene and limits.
/// HEVC packets are returned as they are; decode them with `dlgs-video` and [`untile`].
pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<TfeaBody> {
    let mut r = ByteReader::new(p, offset);
    let at = r.offset();
    let codec = r.u8("TFEA codec")?;
    let depth = r.u8("TFEA bit depth")?;
    let channels = r.u16("TFEA channels")? as usize;
    let n = r.u32("TFEA n_dynamic")? as usize;
    let keys = r.u32("TFEA keys")? as usize;
    let side = r.u32("TFEA side")? as usize;
    if channels != scene.time_channels as usize
        || n != scene.n_dynamic as usize
        || keys != scene.keys_per_gop() as usize
    {
        return Err(Error::payload(
            ChunkType::TFEA,
            format!(
                "shape ({n}, {keys}, {channels}) differs from HEAD ({}, {}, {})",
                scene.n_dynamic,
                scene.keys_per_gop(),
                scene.time_channels
            ),
            at,
        ));
    }
    // Bounded by HEAD, which the reader checked against the Gaussian limit: no overflow.
    let floats = n as u64 * keys as u64 * channels as u64;
    match (codec, depth) {
        (0, 0) => {
            let len = floats * 4;
            limits.check_alloc("TFEA features", len, at)?;
            let body_at = r.offset();
            let raw = zstd_exact(r.rest(), len, body_at)?;
            let data = raw
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            Ok(TfeaBody::Exact(TimeFeatures {
                n,
                keys,
                channels,
                data,
            }))
        }
        (QUANTISED, 6..=12) => Ok(TfeaBody::Quantised(tfea_quantised::decode_body(
            &mut r,
            (n, keys, channels, depth),
            limits,
            at,
        )?)),
        (1..=3, 12) => {
            let tiling = Tiling {
                n,
                keys,
                channels,
                side,
            };
            let ok = side > 0
                && (side as u64) * (side as u64) >= n as u64
                && tiling.width() <= 16384
                && tiling.height() <= 16384;
            if !ok {
                return Err(Error::format(
                    FormatErrorKind::InvalidField {
                        field: "TFEA side",
                        value: side as u64,
                        reason: "side^2 must cover n_dynamic and images must fit 16384^2",
                    },
                    at + 12,
                ));
            }
            let pixels = (tiling.width() * tiling.height()) as u64 * keys as u64 * 2;
            limits.check_alloc("TFEA decoded images", pixels, at)?;
            let mut ranges = Vec::with_capacity(channels);
            let mut reference = None;
            if codec == 2 {
                let lo = f64::from_le_bytes(r.take(8, "TFEA reference lo")?.try_into().expect("8"));
                let hi = f64::from_le_bytes(r.take(8, "TFEA reference hi")?.try_into().expect("8"));
                if !lo.is_finite() || !hi.is_finite() {
                    return Err(Error::format(
                        FormatErrorKind::NonFinite {
                            field: "TFEA reference range",
                        },
                        at + 16,
                    ));
                }
                reference = Some((lo, hi));
            } else {
                for _ in 0..channels {
                    let lo = r.finite_f32("TFEA range lo")?;
                    let hi = r.finite_f32("TFEA range hi")?;
                    ranges.push((lo, hi));
                }
            }
            let count = r.u32("TFEA packet count")? as usize;
            // Every packet needs at least its 4-byte length: bounds the loop by the bytes present.
            if count as u64 * 4 > r.remaining() as u64 {
                return Err(r.err(FormatErrorKind::Truncated {
                    what: "TFEA packets",
                    needed: count as u64 * 4,
                    available: r.remaining() as u64,
                }));
            }
            if codec == 3 && count != keys {
                return Err(Error::payload(
                    ChunkType::TFEA,
                    format!("intra-only codec 3 with {count} packets for {keys} keys"),
                    r.offset() - 4,
                ));
            }
            let mut packets = Vec::with_capacity(count);
            for _ in 0..count {
                let len = r.u32("TFEA packet length")? as usize;
                packets.push(r.take(len, "TFEA packet")?.to_vec());
            }
            if r.remaining() != 0 {
                return Err(Error::payload(
                    ChunkType::TFEA,
                    format!("{} bytes after the last packet", r.remaining()),
                    r.offset(),
                ));
            }
            Ok(TfeaBody::Hevc {
                tiling,
                ranges,
                reference,
                packets,
                intra: codec == 3,
            })
        }
        _ => Err(Error::payload(
            ChunkType::TFEA,
            format!("unknown codec {codec} / bit depth {depth}"),
            at,
        )),
    }
}

#[cfg(test)]
#[allow(clippy::disallowed_methods)] // the platform libm as a reference or test data
mod tests {
    use super::*;

    fn feats(n: usize) -> TimeFeatures {
        let mut f = TimeFeatures::zeros(n, 7, 16);
        for (j, v) in f.data.iter_mut().enumerate() {
            *v = ((j as f32) * 0.37).sin() * 2.0;
        }
        f
    }

    #[test]
    fn tiling_round_trip_is_within_half_a_step() {
        for n in [1, 2, 7, 100, 101, 1000] {
            let f = feats(n);
            let t = Tiling::for_count(n, 7, 16);
            assert!(t.side * t.side >= n && t.width() & 1 == 0 && t.height() & 1 == 0);
            let r = ranges(&f, false);
            let back = untile(&tile(&f, &t, &r), &t, &r);
            for (a, b) in f.data.iter().zip(&back.data) {
                assert!((a - b).abs() <= 4.0 / 4095.0 * 0.5 + 1e-6, "{a} {b}");
            }
        }
    }

    #[test]
    fn column_untiling_is_the_row_untiling_transposed() {
        for n in [0, 1, 7, 101, 1000] {
            let f = feats(n);
            let t = Tiling::for_count(n, 7, 16);
            let r = ranges(&f, false);
            let images = tile(&f, &t, &r);
            for (rows, cols) in [
                (
                    untile(&images, &t, &r),
                    untile_columns(&images, &t, sample_value(&r)),
                ),
                (
                    untile_reference(&images, &t, (-2.0, 2.0)),
                    untile_columns(&images, &t, reference_sample_value((-2.0, 2.0))),
                ),
            ] {
                assert_eq!(cols.len(), n * 7 * 16);
                for i in 0..n {
                    for k in 0..7 {
                        for c in 0..16 {
                            let a = rows.at(i, k)[c];
                            let b = cols[(k * 16 + c) * n + i];
                            assert_eq!(a.to_bits(), b.to_bits(), "n {n} i {i} k {k} c {c}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn constant_channels_decode_exactly() {
        let mut f = feats(10);
        for i in 0..10 {
            for k in 0..7 {
                f.at_mut(i, k)[3] = 1.25;
            }
        }
        let r = ranges(&f, false);
        let t = Tiling::for_count(10, 7, 16);
        let back = untile(&tile(&f, &t, &r), &t, &r);
        assert!((0..10).all(|i| (0..7).all(|k| back.at(i, k)[3] == 1.25)));
    }

    #[test]
    fn reference_pixel_layout() {
        let t = Tiling {
            n: 9,
            keys: 1,
            channels: 16,
            side: 3,
        };
        // frame[(c//4)*side + i, (c%4)*side + j] = F[i*side + j, c]
        assert_eq!(t.pixel(4, 5), (3 + 1) * 12 + (3 + 1));
    }

    /// A 60-frame GOP of 5 dynamic Gaussians, 16 channels, a key every 10 frames.
    fn five_dynamic() -> SceneHeader {
        let mut s = SceneHeader::still(0, 0);
        s.n_dynamic = 5;
        s.time_channels = 16;
        s.gop_length = 60;
        s.key_interval = 10;
        s.frame_count = 60;
        s
    }

    #[test]
    fn exact_payload_round_trip() {
        let s = five_dynamic();
        let f = feats(5);
        let p = encode(&TfeaBody::Exact(f.clone()), 3).unwrap();
        assert_eq!(
            decode(&p, 0, &s, &Limits::tiny()).unwrap(),
            TfeaBody::Exact(f)
        );
        let mut nan = feats(5);
        nan.data[3] = f32::NAN;
        assert!(encode(&TfeaBody::Exact(nan), 3).is_err());
    }

    #[test]
    fn intra_only_payload_needs_one_packet_per_key() {
        let s = five_dynamic();
        let tiling = Tiling::for_count(5, 7, 16);
        let body = |packets: usize, intra: bool| TfeaBody::Hevc {
            tiling,
            ranges: vec![(0.0, 1.0); 16],
            reference: None,
            packets: (0..packets).map(|k| vec![k as u8; 3]).collect(),
            intra,
        };
        let p = encode(&body(7, true), 3).unwrap();
        assert_eq!(p[0], 3, "codec 3");
        assert_eq!(decode(&p, 0, &s, &Limits::tiny()).unwrap(), body(7, true));
        // The writer refuses another count; a reader reports one as a payload error.
        assert!(encode(&body(6, true), 3).is_err());
        let mut q = encode(&body(6, false), 3).unwrap();
        q[0] = 3;
        let e = decode(&q, 100, &s, &Limits::tiny()).unwrap_err();
        assert!(e.to_string().contains("6 packets for 7 keys"), "{e}");
        // Intra-only with the reference's dequantisation is not a codec.
        let mut r = body(7, true);
        if let TfeaBody::Hevc { reference, .. } = &mut r {
            *reference = Some((0.0, 1.0));
        }
        assert!(encode(&r, 3).is_err());
    }
}
