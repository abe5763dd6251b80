//! Tests of `adaptive_coder.rs` (kept apart so the coder's file stays small).

use super::*;

fn noise(n: usize, seed: u32, bits: u8) -> Vec<u16> {
    let mut s = seed;
    (0..n)
        .map(|i| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            // A smooth ramp plus noise, wrapped to the bits.
            (((i as u32 / 3) + (s % 9)) % (1u32 << bits)) as u16
        })
        .collect()
}

#[test]
fn every_mode_round_trips_partial_grids_and_extremes() {
    for bits in [1u8, 2, 5, 8, 10, 14, 16] {
        for n in [1usize, 2, 7, 50, 401] {
            let width = (n as f64).sqrt().ceil() as usize;
            let mut q = noise(n, 3, bits);
            // Extremes: 0 and 2^bits - 1 next to each other.
            if n > 3 {
                q[1] = 0;
                q[2] = ((1u32 << bits) - 1) as u16;
            }
            for pb in [bits, 3, 12] {
                let prev_q = noise(n, 7, pb);
                let pv = Some((prev_q.as_slice(), pb));
                let prev2_q = noise(n, 9, 16 - pb);
                let pv2 = Some((prev2_q.as_slice(), 16 - pb));
                let modes = candidate_modes(bits, pv, pv2);
                assert_eq!(
                    modes.iter().any(|m| m.needs_two_previous()),
                    bits <= TREE_MAX_BITS
                );
                for mode in modes {
                    let e = encode(&q, pv, pv2, width, bits, mode).unwrap();
                    let d = decode(ByteReader::new(&e, 0), n, width, bits, pv, pv2).unwrap();
                    assert_eq!(d, q, "bits {bits}, n {n}, mode {mode:?}");
                }
            }
        }
    }
}

#[test]
fn a_channel_that_follows_the_previous_one_codes_smaller_with_it() {
    let n = 4096;
    let prev = noise(n, 11, 8);
    // Each value a function of the previous channel's value: the tree learns the map.
    let q: Vec<u16> = prev.iter().map(|&v| (v * 7 + 3) % 256).collect();
    let alone = encode(&q, None, None, 64, 8, Mode::Residual).unwrap().len();
    let tree = encode(
        &q,
        Some((&prev, 8)),
        None,
        64,
        8,
        Mode::TreeGivenPrevious(8),
    )
    .unwrap()
    .len();
    assert!(tree * 2 < alone, "tree {tree} B, alone {alone} B");
}

#[test]
fn the_mixed_mode_learns_from_neighbours_and_the_previous_channel() {
    // Rows of one of four levels (the upper neighbour knows the cell), plus a low part
    // that follows the previous channel: no single context of modes 3-4 sees both.
    let (n, width) = (4096, 64);
    let prev = noise(n, 13, 8);
    let q: Vec<u16> = (0..n)
        .map(|i| ((i / width % 4) as u16 * 64 + prev[i] % 64) & 255)
        .collect();
    let pv = Some((prev.as_slice(), 8));
    let best_tree = [
        Mode::Tree,
        Mode::TreeGivenPrevious(2),
        Mode::TreeGivenPrevious(8),
    ]
    .into_iter()
    .map(|m| encode(&q, pv, None, width, 8, m).unwrap().len())
    .min()
    .unwrap();
    let mixed = encode(&q, pv, None, width, 8, Mode::Mixed(8)).unwrap();
    assert!(
        mixed.len() * 10 < best_tree * 9,
        "mixed {} B, trees {best_tree} B",
        mixed.len()
    );
    // Its decoder needs the same previous channel.
    assert_eq!(
        decode(ByteReader::new(&mixed, 0), n, width, 8, pv, None).unwrap(),
        q
    );
    assert!(decode(ByteReader::new(&mixed, 0), n, width, 8, None, None).is_err());
}

#[test]
fn malformed_headers_and_streams_are_typed_errors() {
    let q = noise(100, 5, 9);
    let e = encode(&q, None, None, 10, 9, Mode::Residual).unwrap();
    // Unknown mode, modes without a previous channel, a tree too wide, too many context
    // bits.
    for (m, k) in [
        (6u8, 0u8),
        (1, 0),
        (2, 0),
        (3, 4),
        (0, 1),
        (4, 1),
        (5, 2),
        (5, 9),
    ] {
        let mut bad_e = e.clone();
        bad_e[0] = m;
        bad_e[1] = k;
        assert!(decode(ByteReader::new(&bad_e, 0), 100, 10, 9, None, None).is_err());
    }
    let prev = noise(100, 1, 12);
    // Too wide for a tree; mode 6 without the channel before, or with 0 or 5 of its bits.
    let pv2 = Some((prev.as_slice(), 12));
    for (m, k, bits, p2) in [
        (3u8, 4u8, 12u8, pv2),
        (5, 0, 12, pv2),
        (5, 4, 12, pv2),
        (6, 0x12, 12, pv2),
        (6, 0x12, 9, None),
        (6, 0x02, 9, pv2),
        (6, 0x52, 9, pv2),
        (6, 0x10, 9, pv2),
    ] {
        let mut tree = e.clone();
        tree[0] = m;
        tree[1] = k;
        let pv = Some((&prev[..], 12));
        let got = decode(ByteReader::new(&tree, 0), 100, 10, bits, pv, p2);
        assert!(got.is_err(), "mode {m} k {k:#x} bits {bits}");
    }
    // Truncated words, trailing bytes.
    assert!(decode(
        ByteReader::new(&e[..e.len() - 1], 0),
        100,
        10,
        9,
        None,
        None
    )
    .is_err());
    let mut long = e.clone();
    long.push(0);
    assert!(decode(ByteReader::new(&long, 0), 100, 10, 9, None, None).is_err());
    // Garbage words decode to some values or a typed error, never a panic, and every value
    // fits the bits.
    let mut junk = e.clone();
    for (i, b) in junk.iter_mut().enumerate().skip(6) {
        *b = (i * 37 % 251) as u8;
    }
    if let Ok(v) = decode(ByteReader::new(&junk, 0), 100, 10, 9, None, None) {
        assert!(v.iter().all(|&x| x < 512));
    }
    // Random streams in every mode and width: values fit or a typed error, never a panic.
    let mut s = 0x9e37_79b9u32;
    let mut rnd = || {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        s
    };
    let prev = noise(300, 2, 8);
    for round in 0..320 {
        let bits = [1u8, 4, 8, 10, 16][round % 5];
        let (m, k) = [(0u8, 0u8), (1, 0), (2, 0), (3, 5), (4, 0), (5, 0), (5, 3)][round / 5 % 7];
        let words = rnd() % 40;
        let mut e = vec![m, k];
        e.put_u32(words);
        for _ in 0..words {
            e.put_u32(rnd());
        }
        let pv = Some((prev.as_slice(), 8));
        if let Ok(v) = decode(ByteReader::new(&e, 0), 300, 18, bits, pv, pv) {
            assert!(v.iter().all(|&x| (x as u32) < 1 << bits));
        }
    }
}
