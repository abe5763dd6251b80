//! `TFEA` codec 4 (since 1.19, format-spec §6.2): the key time features quantised per channel to
//! `b` bits (6-12; 12 is codec 1's quantisation) and coded losslessly with zstd, no video codec.
//! A decoder any platform has (the web player: HEVC is not decodable in a browser GPL-free).
//!
//! Body after the 16-byte `TFEA` header: `predictor` (u8: 0 none, 1 previous key), `C` ranges
//! (f32 `lo`, f32 `hi`), then one zstd frame of `2 K C N` bytes: the low bytes of the `K C N`
//! stored values in `(k, c, i)` order, then their high bytes. A stored value `z` is the sample
//! `q` itself (predictor 0, and key 0 always) or the zigzag of `q - q_prev` taken modulo `2^b`
//! (predictor 1: `q_prev` is the same Gaussian and channel at the previous key).

use crate::bytes::{zstd_compress, zstd_exact, ByteReader, PutLe};
use crate::chunks::tfea::ranges;
use crate::error::{Error, FormatErrorKind, Result};
use crate::model::TimeFeatures;
use crate::Limits;

/// Codec number in `TFEA`'s first byte.
pub const CODEC: u8 = 4;
/// Allowed sample depths.
pub const BITS: std::ops::RangeInclusive<u8> = 6..=12;

/// Codec 4 features as stored: per-channel ranges and the samples, `(K, C, N)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Quantised {
    pub n: usize,
    pub keys: usize,
    pub channels: usize,
    pub bits: u8,
    /// Writing: `Some(p)` stores with predictor `p`, `None` with the one that codes smaller.
    /// Read: the file's.
    pub predictor: Option<u8>,
    pub ranges: Vec<(f32, f32)>,
    /// `q[(k * C + c) * N + i]`, each below `2^bits`.
    pub q: Vec<u16>,
}

impl Quantised {
    /// Quantise `f` to `bits` bits per channel (the ranges of [`ranges`], per channel).
    pub fn from_features(f: &TimeFeatures, bits: u8, predictor: Option<u8>) -> Result<Self> {
        if !BITS.contains(&bits) {
            return Err(Error::input(format!(
                "time-feature bits {bits}: must be 6 to 12"
            )));
        }
        if predictor.is_some_and(|p| p > 1) {
            return Err(Error::input(
                "time-feature predictor: 0 (none) or 1 (previous key)",
            ));
        }
        crate::model::dynamic::check_finite("time features", &f.data)?;
        let r = ranges(f, false);
        let max = ((1u32 << bits) - 1) as f32;
        let mut q = vec![0u16; f.keys * f.channels * f.n];
        for k in 0..f.keys {
            for i in 0..f.n {
                let v = f.at(i, k);
                for c in 0..f.channels {
                    q[(k * f.channels + c) * f.n + i] = quantise(v[c], r[c], max);
                }
            }
        }
        Ok(Quantised {
            n: f.n,
            keys: f.keys,
            channels: f.channels,
            bits,
            predictor,
            ranges: r,
            q,
        })
    }

    /// The decoded features, `(K, C, N)` (the decoder's column layout): `lo + q ((hi - lo) /
    /// (2^b - 1))` in binary32 in this order; a constant channel (`hi <= lo`) gives `lo`.
    pub fn columns(&self) -> Vec<f32> {
        let max = ((1u32 << self.bits) - 1) as f32;
        let steps: Vec<f32> = self
            .ranges
            .iter()
            .map(|&(lo, hi)| (hi - lo) / max)
            .collect();
        let mut out = Vec::with_capacity(self.q.len());
        for (kc, col) in self.q.chunks(self.n.max(1)).enumerate() {
            let c = kc % self.channels.max(1);
            let (lo, hi) = self.ranges[c];
            if hi > lo {
                out.extend(col.iter().map(|&q| lo + f32::from(q) * steps[c]));
            } else {
                out.extend(col.iter().map(|_| lo));
            }
        }
        out.truncate(self.keys * self.channels * self.n);
        out
    }

    /// The decoded features in the model's `(N, K, C)` layout.
    pub fn features(&self) -> TimeFeatures {
        let cols = self.columns();
        let mut f = TimeFeatures::zeros(self.n, self.keys, self.channels);
        for k in 0..self.keys {
            for c in 0..self.channels {
                let col = &cols[(k * self.channels + c) * self.n..][..self.n];
                for (i, &v) in col.iter().enumerate() {
                    f.at_mut(i, k)[c] = v;
                }
            }
        }
        f
    }
}

/// `round((x - lo) / (hi - lo) * max)` clamped to `[0, max]`; a constant channel gives 0.
fn quantise(x: f32, (lo, hi): (f32, f32), max: f32) -> u16 {
    if !(hi > lo) {
        return 0;
    }
    ((x - lo) / (hi - lo) * max).round().clamp(0.0, max) as u16
}

fn zigzag(d: i32, bits: u8) -> u16 {
    // d in (-2^b, 2^b): wrap to [-2^(b-1), 2^(b-1)), then zigzag into [0, 2^b).
    let m = 1i32 << bits;
    let s = (d + m / 2).rem_euclid(m) - m / 2;
    ((s << 1) ^ (s >> 31)) as u16 & (m - 1) as u16
}

fn unzigzag(z: u16) -> i32 {
    let z = i32::from(z);
    (z >> 1) ^ -(z & 1)
}

/// The stored values for `predictor`: key 0 as is, later keys as zigzagged key differences.
fn stored(qz: &Quantised, predictor: u8) -> Vec<u16> {
    if predictor == 0 {
        return qz.q.clone();
    }
    let plane = qz.channels * qz.n;
    let mut z = qz.q.clone();
    for k in 1..qz.keys {
        for j in 0..plane {
            let d = i32::from(qz.q[k * plane + j]) - i32::from(qz.q[(k - 1) * plane + j]);
            z[k * plane + j] = zigzag(d, qz.bits);
        }
    }
    z
}

fn planes(z: &[u16]) -> Vec<u8> {
    let mut b = Vec::with_capacity(z.len() * 2);
    b.extend(z.iter().map(|&v| v as u8));
    b.extend(z.iter().map(|&v| (v >> 8) as u8));
    b
}

/// The body after the 16-byte header, with `qz.predictor`, or else the smaller of both.
pub fn encode_body(qz: &Quantised, zstd_level: i32, out: &mut Vec<u8>) -> Result<()> {
    // What the reader checks, so that a hand-built `Quantised` cannot write a file it refuses.
    let values = qz.n * qz.keys * qz.channels;
    if !BITS.contains(&qz.bits)
        || qz.predictor.is_some_and(|p| p > 1)
        || qz.ranges.len() != qz.channels
        || qz.q.len() != values
        || qz.q.iter().any(|&q| u32::from(q) >= 1 << qz.bits)
    {
        return Err(Error::input(format!(
            "quantised time features: bits {} (6-12), predictor {:?} (0 or 1), {} ranges for {} \
             channels, {} samples for {values}, each below 2^bits",
            qz.bits,
            qz.predictor,
            qz.ranges.len(),
            qz.channels,
            qz.q.len()
        )));
    }
    let mut best: Option<(u8, Vec<u8>)> = None;
    let tried: &[u8] = match qz.predictor {
        Some(0) => &[0],
        Some(_) => &[1],
        None => &[0, 1],
    };
    for &predictor in tried {
        let z = zstd_compress(&planes(&stored(qz, predictor)), zstd_level)?;
        if best.as_ref().is_none_or(|(_, b)| z.len() < b.len()) {
            best = Some((predictor, z));
        }
    }
    let (predictor, z) = best.expect("a predictor tried");
    out.put_u8(predictor);
    for &(lo, hi) in &qz.ranges {
        if !lo.is_finite() || !hi.is_finite() || !(hi - lo).is_finite() {
            return Err(Error::input(
                "time-feature range not finite (or hi - lo overflows binary32)",
            ));
        }
        out.put_f32(lo);
        out.put_f32(hi);
    }
    out.extend_from_slice(&z);
    Ok(())
}

/// Parse the body (the reader is past the 16-byte header, which was checked: shape, codec,
/// `bits` in 6-12). `at`: the payload's first byte.
pub fn decode_body(
    r: &mut ByteReader,
    (n, keys, channels, bits): (usize, usize, usize, u8),
    limits: &Limits,
    at: u64,
) -> Result<Quantised> {
    let values = n as u64 * keys as u64 * channels as u64;
    limits.check_alloc("TFEA features", values * 4, at)?;
    let predictor_at = r.offset();
    let predictor = r.u8("TFEA predictor")?;
    if predictor > 1 {
        return Err(Error::format(
            FormatErrorKind::InvalidField {
                field: "TFEA predictor",
                value: u64::from(predictor),
                reason: "0 (none) or 1 (previous key)",
            },
            predictor_at,
        ));
    }
    let mut ranges = Vec::with_capacity(channels);
    for _ in 0..channels {
        let at_lo = r.offset();
        let lo = r.finite_f32("TFEA range lo")?;
        let hi = r.finite_f32("TFEA range hi")?;
        // hi - lo is the first operation of the dequantisation: it must not overflow.
        if !(hi - lo).is_finite() {
            return Err(Error::format(
                FormatErrorKind::NonFinite {
                    field: "TFEA range hi - lo",
                },
                at_lo,
            ));
        }
        ranges.push((lo, hi));
    }
    let body_at = r.offset();
    let raw = zstd_exact(r.rest(), values * 2, body_at)?;
    let (low, high) = raw.split_at(values as usize);
    let max = (1u16 << bits) - 1;
    let mut q: Vec<u16> = low
        .iter()
        .zip(high)
        .map(|(&l, &h)| u16::from(l) | (u16::from(h) << 8))
        .collect();
    if let Some(j) = q.iter().position(|&z| z > max) {
        return Err(Error::format(
            FormatErrorKind::InvalidField {
                field: "TFEA stored value",
                value: u64::from(q[j]),
                reason: "each stored value is below 2^bits",
            },
            body_at,
        ));
    }
    if predictor == 1 {
        let plane = channels * n;
        for k in 1..keys {
            let (done, rest) = q.split_at_mut(k * plane);
            let prev = &done[(k - 1) * plane..];
            for (z, &p) in rest[..plane].iter_mut().zip(prev) {
                *z = ((i32::from(p) + unzigzag(*z)) & i32::from(max)) as u16;
            }
        }
    }
    Ok(Quantised {
        n,
        keys,
        channels,
        bits,
        predictor: Some(predictor),
        ranges,
        q,
    })
}

#[cfg(test)]
#[allow(clippy::disallowed_methods)] // test data from the platform's sin
mod tests {
    use super::*;

    #[test]
    fn zigzag_round_trips_every_difference_modulo_2_to_the_bits() {
        for bits in BITS {
            let m = 1i32 << bits;
            for a in [0, 1, m / 2, m - 1] {
                for b in 0..m {
                    let z = zigzag(b - a, bits);
                    assert!(i32::from(z) < m);
                    assert_eq!(
                        (a + unzigzag(z)).rem_euclid(m),
                        b,
                        "bits {bits}: {a} -> {b}"
                    );
                }
            }
        }
        assert_eq!(zigzag(0, 12), 0);
        assert_eq!(zigzag(-1, 12), 1);
        assert_eq!(zigzag(1, 12), 2);
    }

    use crate::chunks::tfea::{decode, encode, TfeaBody};
    use crate::container::SceneHeader;
    use crate::error::FormatErrorKind as K;

    /// A 60-frame GOP of `n` dynamic Gaussians, 16 channels, a key every 10 frames.
    fn scene(n: u32) -> SceneHeader {
        let mut s = SceneHeader::still(0, 0);
        s.n_dynamic = n;
        s.time_channels = 16;
        s.gop_length = 60;
        s.key_interval = 10;
        s.frame_count = 60;
        s
    }

    fn feats(n: usize) -> TimeFeatures {
        let mut f = TimeFeatures::zeros(n, 7, 16);
        for (j, v) in f.data.iter_mut().enumerate() {
            // Smooth over keys (channel-dependent drift) with a constant channel 5.
            let (i, k, c) = (j / (7 * 16), (j / 16) % 7, j % 16);
            *v = if c == 5 {
                0.25
            } else {
                (i as f32 * 0.7 + c as f32).sin() + 0.05 * k as f32 * c as f32
            };
        }
        f
    }

    #[test]
    fn round_trip_every_depth_and_predictor_within_half_a_step() {
        let s = scene(37);
        let f = feats(37);
        for bits in BITS {
            for predictor in [Some(0), Some(1), None] {
                let q = Quantised::from_features(&f, bits, predictor).unwrap();
                let p = encode(&TfeaBody::Quantised(q.clone()), 3).unwrap();
                assert_eq!((p[0], p[1], &p[12..16]), (4, bits, &[0u8; 4][..]));
                assert!(predictor.is_none_or(|x| p[16] == x));
                let TfeaBody::Quantised(back) = decode(&p, 0, &s, &Limits::tiny()).unwrap() else {
                    panic!("codec 4 decodes to Quantised");
                };
                assert_eq!(back.q, q.q, "bits {bits} predictor {predictor:?}");
                let g = back.features();
                let max = ((1u32 << bits) - 1) as f32;
                for (j, (a, b)) in f.data.iter().zip(&g.data).enumerate() {
                    let (lo, hi) = q.ranges[j % 16];
                    let step = (hi - lo) / max;
                    assert!(
                        (a - b).abs() <= step * 0.5 + 1e-5,
                        "bits {bits}: {a} vs {b}"
                    );
                }
                // The constant channel decodes to its value exactly.
                assert!((0..37).all(|i| g.at(i, 3)[5] == 0.25));
                // The decoder's column layout is the same values, (K, C, N).
                let cols = back.columns();
                assert_eq!(
                    cols[(3 * 16 + 2) * 37 + 11].to_bits(),
                    g.at(11, 3)[2].to_bits()
                );
            }
        }
    }

    #[test]
    fn twelve_bits_dequantise_as_codec_1() {
        let f = feats(9);
        let q = Quantised::from_features(&f, 12, None).unwrap();
        let r = q.ranges.clone();
        let g = q.features();
        for i in 0..9 {
            for k in 0..7 {
                for c in 0..16 {
                    let want = crate::chunks::tfea::dequantise(
                        crate::chunks::tfea::quantise(f.at(i, k)[c], r[c]),
                        r[c],
                    );
                    assert_eq!(g.at(i, k)[c].to_bits(), want.to_bits());
                }
            }
        }
    }

    #[test]
    fn malformed_payloads_are_typed_errors() {
        let s = scene(5);
        let q = Quantised::from_features(&feats(5), 10, Some(0)).unwrap();
        let p = encode(&TfeaBody::Quantised(q.clone()), 3).unwrap();
        let kind = |bytes: &[u8]| decode(bytes, 1000, &s, &Limits::tiny()).unwrap_err();
        // Bit depth outside 6..=12: Payload at the payload's start.
        for depth in [0u8, 5, 13] {
            let mut b = p.clone();
            b[1] = depth;
            let e = kind(&b);
            assert!(e.to_string().contains("unknown codec 4"), "{e}");
            assert_eq!(e.offset(), Some(1000));
        }
        // Predictor 2: InvalidField at byte 16.
        let mut b = p.clone();
        b[16] = 2;
        let e = kind(&b);
        assert!(
            matches!(
                e.format_kind(),
                Some(K::InvalidField {
                    field: "TFEA predictor",
                    ..
                })
            ),
            "{e}"
        );
        assert_eq!(e.offset(), Some(1016));
        // A non-finite range: NonFinite.
        let mut b = p.clone();
        b[17..21].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(matches!(kind(&b).format_kind(), Some(K::NonFinite { .. })));
        // A range whose width overflows binary32: NonFinite at its lo.
        let mut b = p.clone();
        b[17 + 8 * 3..17 + 8 * 3 + 4].copy_from_slice(&(-3e38f32).to_le_bytes());
        b[17 + 8 * 3 + 4..17 + 8 * 4].copy_from_slice(&3e38f32.to_le_bytes());
        let e = kind(&b);
        assert!(matches!(e.format_kind(), Some(K::NonFinite { .. })), "{e}");
        assert_eq!(e.offset(), Some(1000 + 17 + 8 * 3));
        // Cut inside the ranges: Truncated; a frame of the wrong size: Decompress.
        assert!(matches!(
            kind(&p[..30]).format_kind(),
            Some(K::Truncated { .. })
        ));
        let mut b = p[..17 + 16 * 8].to_vec();
        b.extend(zstd_compress(&[0u8; 10], 3).unwrap());
        assert!(matches!(kind(&b).format_kind(), Some(K::Decompress(_))));
        // A stored value of 2^10 at 10 bits: InvalidField at the frame.
        let mut high = vec![0u8; 2 * 5 * 7 * 16];
        high[5 * 7 * 16 + 3] = 4; // value 1024
        let mut b = p[..17 + 16 * 8].to_vec();
        b.extend(zstd_compress(&high, 3).unwrap());
        let e = kind(&b);
        assert!(
            matches!(
                e.format_kind(),
                Some(K::InvalidField {
                    field: "TFEA stored value",
                    ..
                })
            ),
            "{e}"
        );
        assert_eq!(e.offset(), Some(1000 + 17 + 16 * 8));
        // The writer refuses a hand-built body the reader would refuse.
        let mut hand = q.clone();
        hand.q[0] = 1024;
        assert!(encode(&TfeaBody::Quantised(hand), 3).is_err());
        let mut hand = q.clone();
        hand.predictor = Some(2);
        assert!(encode(&TfeaBody::Quantised(hand), 3).is_err());
        let mut hand = q.clone();
        hand.ranges.pop();
        assert!(encode(&TfeaBody::Quantised(hand), 3).is_err());
        // The writer refuses depths outside 6..=12, a predictor above 1 and non-finite features.
        assert!(Quantised::from_features(&feats(5), 5, None).is_err());
        assert!(Quantised::from_features(&feats(5), 13, None).is_err());
        assert!(Quantised::from_features(&feats(5), 8, Some(2)).is_err());
        let mut nan = feats(5);
        nan.data[7] = f32::INFINITY;
        assert!(Quantised::from_features(&nan, 8, None).is_err());
    }

    #[test]
    fn the_allocation_limit_is_checked_before_decompressing() {
        let s = scene(5);
        let p = encode(
            &TfeaBody::Quantised(Quantised::from_features(&feats(5), 8, None).unwrap()),
            3,
        )
        .unwrap();
        let mut limits = Limits::tiny();
        limits.max_alloc = 5 * 7 * 16 * 4 - 1;
        let e = decode(&p, 0, &s, &limits).unwrap_err();
        assert!(e.name() == "LimitExceeded" && e.offset() == Some(0), "{e}");
    }
}
