//! Tests of `grid_coder.rs` (kept apart so the coder's file stays small): round trips and costs
//! of the predictive and histogram codecs, and damaged streams.

use super::*;

fn round_trip(q: &[u16], width: usize, bits: u8) -> usize {
    let e = encode_predictive(q, width, bits);
    let d = decode_predictive(ByteReader::new(&e, 0), q.len(), width, bits).unwrap();
    assert_eq!(d, q);
    let (codec, b) = encode_classic(q, width, bits, 3);
    assert_eq!(
        decode(
            codec,
            ByteReader::new(&b, 0),
            q.len(),
            width,
            bits,
            None,
            None
        )
        .unwrap(),
        q
    );
    e.len()
}

#[test]
fn smooth_noisy_extreme_and_partial_grids_round_trip() {
    let mut s = 1u32;
    let mut rnd = || {
        s = s.wrapping_mul(1664525).wrapping_add(1013904223);
        s >> 8
    };
    for bits in [1u8, 2, 5, 8, 12, 16] {
        let max = (1u32 << bits) - 1;
        for (w, n) in [(1, 7), (7, 1), (13, 160), (64, 64 * 64), (50, 2477)] {
            let smooth: Vec<u16> = (0..n)
                .map(|i| (((i % w) * 3 + (i / w) * 2) as u32 % (max + 1)) as u16)
                .collect();
            round_trip(&smooth, w, bits);
            let noise: Vec<u16> = (0..n).map(|_| (rnd() & max) as u16).collect();
            round_trip(&noise, w, bits);
            let ext: Vec<u16> = (0..n)
                .map(|i| if i % 3 == 0 { max as u16 } else { 0 })
                .collect();
            round_trip(&ext, w, bits);
        }
    }
}

#[test]
fn smooth_grids_cost_little() {
    let w = 128;
    let q: Vec<u16> = (0..w * w)
        .map(|i| (((i % w) as f32 * 0.05).sin() * 2000.0 + 30000.0 + (i / w) as f32 * 3.0) as u16)
        .collect();
    let bytes = round_trip(&q, w, 16);
    // 16 bits raw; a smooth field must cost a small fraction.
    assert!(
        bytes * 8 < q.len() * 4,
        "{} bits per cell",
        bytes as f32 * 8.0 / q.len() as f32
    );
}

#[test]
fn damaged_streams_give_errors_not_panics() {
    let q: Vec<u16> = (0..500).map(|i| ((i * 37) % 4096) as u16).collect();
    let e = encode_predictive(&q, 25, 12);
    for cut in 0..e.len() {
        let _ = decode_predictive(ByteReader::new(&e[..cut], 0), q.len(), 25, 12);
    }
    for i in 0..e.len() {
        let mut b = e.clone();
        b[i] ^= 0x5a;
        let _ = decode_predictive(ByteReader::new(&b, 0), q.len(), 25, 12);
    }
}

#[test]
fn histogram_codecs_round_trip_and_reach_the_order0_entropy() {
    let mut s = 7u32;
    let mut rnd = || {
        s = s.wrapping_mul(1664525).wrapping_add(1013904223);
        s >> 8
    };
    // Peaked 9-bit values (like rotation components) and a channel that follows them.
    let n = 20_000;
    let q: Vec<u16> = (0..n)
        .map(|_| (256 + (rnd() % 64) as i32 - (rnd() % 64) as i32) as u16)
        .collect();
    let follow: Vec<u16> = q.iter().map(|&v| (v + (rnd() % 5) as u16) & 511).collect();
    let e = encode_histogram(&q, 3).expect("alphabet fits");
    assert_eq!(decode_histogram(ByteReader::new(&e, 0), n, 9).unwrap(), q);
    let mut counts = std::collections::HashMap::new();
    for &v in &q {
        *counts.entry(v).or_insert(0u64) += 1;
    }
    let h0: f64 = counts
        .values()
        .map(|&c| -(c as f64) * (c as f64 / n as f64).log2())
        .sum();
    let coded = e.len() as f64 * 8.0;
    assert!(coded < h0 * 1.02 + 8.0 * 400.0, "{coded} bits vs H0 {h0}");
    // Codec 4 through encode_best: the difference is far narrower than the values.
    let (codec, b) = encode_best_tabled(&follow, Some((&q, 9)), 100, 9, 3);
    assert_eq!(codec, GridCodec::HistogramDelta);
    assert!(b.len() * 8 < n * 3, "{} bytes", b.len());
    let mut d = decode(codec, ByteReader::new(&b, 0), n, 100, 9, None, None).unwrap();
    undo_delta(&mut d, &q, 9);
    assert_eq!(d, follow);
    // Wrap-around of the modular difference, and a two-symbol alphabet.
    let hi: Vec<u16> = vec![511; 50];
    let lo: Vec<u16> = vec![1; 50];
    let dd = delta(&lo, &hi, 9);
    let mut back = decode_histogram(
        ByteReader::new(&encode_histogram(&dd, 3).unwrap(), 0),
        50,
        9,
    )
    .unwrap();
    undo_delta(&mut back, &hi, 9);
    assert_eq!(back, lo);
    // Alphabets above 4096 symbols are not offered.
    assert!(encode_histogram(&[5000, 1], 3).is_none());
}

#[test]
fn damaged_histogram_streams_give_errors_not_panics() {
    let q: Vec<u16> = (0..800).map(|i| ((i * 37) % 300) as u16).collect();
    let e = encode_histogram(&q, 3).unwrap();
    for cut in 0..e.len() {
        assert!(decode_histogram(ByteReader::new(&e[..cut], 0), q.len(), 9).is_err());
    }
    for i in 0..e.len() {
        let mut b = e.clone();
        b[i] ^= 0x5a;
        let _ = decode_histogram(ByteReader::new(&b, 0), q.len(), 9);
    }
    // More symbols than the bit depth allows.
    assert!(decode_histogram(ByteReader::new(&e, 0), q.len(), 8).is_err());
    // Bytes after the stream.
    let mut long = e.clone();
    long.push(0);
    let err = decode_histogram(ByteReader::new(&long, 0), q.len(), 9).unwrap_err();
    assert!(
        err.to_string()
            .contains("1 bytes after the histogram stream"),
        "{err}"
    );
}
