//! Layouts 2-4 (§6.5.5-6.5.7): octree-ordered static parts, coarse rotations and compact channel
//! records, their thread independence and damaged payloads.

use dlgs::chunks::csog::grid_codecs as grid_coder;
use dlgs::chunks::csog::{self, quantise_set, rotation_shift, QuantBits, RotationCoarsening};
use dlgs::container::SceneHeader;
use dlgs::model::{Canonical, Gaussians};
use dlgs::Limits;
use dlgs_encoder::grid_sort::{grid_order, permute, SortSpec};
use dlgs_tests::{load, on_threads};

use crate::{degenerate_lod3, scene_of};

/// A GOP in layout 2: the source, its static parts, the payload and the stored static order.
type OctreeGop = (Canonical, Vec<(Gaussians, QuantBits)>, Vec<u8>, Vec<u32>);

/// Layout 2 of the real lod3 scene in three parts, with the dynamic set the last 200.
fn octree_lod3() -> OctreeGop {
    octree_lod3_with(None)
}

/// [`octree_lod3`], in layout 3 when `coarsening` is set.
fn octree_lod3_with(coarsening: Option<RotationCoarsening>) -> OctreeGop {
    octree_lod3_framed(coarsening, false)
}

/// [`octree_lod3_with`], in layout 4 (compact records) when `compact`.
fn octree_lod3_framed(coarsening: Option<RotationCoarsening>, compact: bool) -> OctreeGop {
    let g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let cut = |r: std::ops::Range<u32>| permute(&g, &r.collect::<Vec<u32>>());
    let parts = vec![
        (cut(0..1500), QuantBits::MEDIUM),
        (cut(1500..1700), QuantBits::LOW),
        (cut(1700..1771), QuantBits::LOW.coarser(2)),
    ];
    let dynamics = cut(1771..1971);
    let gop = csog::PartedGop {
        static_parts: &parts,
        static_weight: None,
        dynamics: &dynamics,
        dynamic_bits: &QuantBits::HIGH,
        rotation_coarsening: coarsening,
        compact_records: compact,
        mixed_margin: Some(grid_coder::MIXED_MARGIN),
    };
    let (p, order) = csog::encode_octree(&gop, 3).unwrap();
    let c = Canonical {
        statics: cut(0..1771),
        dynamics,
    };
    (c, parts, p, order)
}

#[test]
fn octree_sets_decode_in_the_order_the_encoder_reports() {
    // Layout 2 (format 1.10): each static part's positions are an octree and the part is
    // stored in the k-d order of its decoded positions; the dynamic set keeps its order.
    let (c, parts, p, order) = octree_lod3();
    assert_eq!(p[0], 2, "layout 2");
    let d = csog::decode(&p, 0, &scene_of(&c), &Limits::default()).unwrap();
    assert_eq!(d.statics.len(), c.statics.len());
    let mut seen = order.clone();
    seen.sort_unstable();
    assert_eq!(seen, (0..c.statics.len() as u32).collect::<Vec<_>>());
    assert_ne!(order, seen, "the octree's order is not the given one");
    // Each part's Gaussians stay in that part, each attribute within its part's step.
    let mut start = 0usize;
    for (part, bits) in &parts {
        let q = quantise_set(part, bits);
        let step =
            |j: usize| (q.channels[j].2 - q.channels[j].1) / ((1u32 << q.channels[j].0) - 1) as f32;
        for k in start..start + part.len() {
            let i = order[k] as usize;
            assert!(
                (start..start + part.len()).contains(&i),
                "Gaussian {i} left its part"
            );
            for a in 0..3 {
                let e = (d.statics.positions[k][a] - c.statics.positions[i][a]).abs();
                assert!(e <= 0.5 * step(a) * 1.001 + 1e-6, "position {k}/{a}: {e}");
                let e = (d.statics.sh[k * 48 + a] - c.statics.sh[i * 48 + a]).abs();
                let j = 11 + a; // SH DC channels follow 3 + 3 + 1 + 3 + 1
                assert!(e <= 0.5 * step(j) * 1.001 + 1e-6, "SH DC {k}/{a}: {e}");
            }
        }
        start += part.len();
    }
    for i in 0..c.dynamics.len() {
        for a in 0..3 {
            assert!((d.dynamics.positions[i][a] - c.dynamics.positions[i][a]).abs() < 1e-3);
        }
    }
    // Octree positions code smaller than grid positions in the best grid order.
    let sorted: Vec<(Gaussians, QuantBits)> = parts
        .iter()
        .map(|(g, b)| (permute(g, &grid_order(g, SortSpec::DEFAULT)), *b))
        .collect();
    let grid = csog::encode_parts(&sorted, &c.dynamics, &QuantBits::HIGH, 3).unwrap();
    assert!(
        p.len() < grid.len(),
        "octree {} B, grid {} B",
        p.len(),
        grid.len()
    );
}

#[test]
fn octree_sets_decode_the_same_floats_on_any_thread_count() {
    // Layout 2, and layout 3 whose rotation shifts and regrouping also run in parallel.
    for coarsening in [None, Some(COARSE)] {
        let (c, _, p, _) = octree_lod3_with(coarsening);
        let run = |n: usize| {
            on_threads(n, || {
                let d = csog::decode(&p, 0, &scene_of(&c), &Limits::default()).unwrap();
                dlgs::chunks::craw::canonical_body(&d)
            })
        };
        let one = run(1);
        assert_eq!(one, run(2), "{coarsening:?}");
        assert_eq!(one, run(5), "{coarsening:?}");
    }
}

/// Decode `p` 300 times, each with one bit flipped at a pseudo-random byte (seeded by `seed`) in
/// the 4,000 bytes from `from`: damaged payloads must give an error or some set, never a panic.
fn decode_with_flipped_bits(p: &[u8], scene: &SceneHeader, from: usize, seed: u32) {
    let mut s = seed;
    for _ in 0..300 {
        s = s.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        let mut b = p.to_vec();
        let at = from + (s as usize >> 8) % 4000;
        b[at] ^= 1 << (s % 8);
        let _ = csog::decode(&b, 0, scene, &Limits::default());
    }
}

#[test]
fn damaged_octree_sets_give_typed_errors_not_panics() {
    let (c, _, p, _) = octree_lod3();
    let scene = scene_of(&c);
    // Byte 0 layout, 1 part count, 2..6 the first part's count, 6..10 width, 10..12 channels,
    // 12 position bits, 13..37 ranges, 37..41 octree length.
    // `describe` walks the parts as decoding does and reports the same errors.
    let err = |b: &[u8]| {
        let e = csog::decode(b, 0, &scene, &Limits::default())
            .unwrap_err()
            .to_string();
        let d = csog::describe(b, 0, &scene).unwrap_err().to_string();
        assert_eq!(e, d);
        e
    };
    for bits in [0u8, 17] {
        let mut b = p.clone();
        b[12] = bits;
        assert!(
            err(&b).contains(&format!("octree positions of {bits} bits")),
            "{}",
            err(&b)
        );
    }
    let mut b = p.clone();
    b[13..17].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(err(&b).contains("position min"), "{}", err(&b));
    let mut b = p.clone();
    b[37..41].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(err(&b).contains("octree data"), "{}", err(&b));
    // Flipped bits anywhere in the first part: an error or a different set, never a panic.
    decode_with_flipped_bits(&p, &scene, 41, 5);
}

/// An unsigned LEB128 varint at `p[at..]`: (value, bytes).
fn varint(p: &[u8], at: usize) -> (u32, usize) {
    let mut v = 0u32;
    for i in 0..5 {
        v |= ((p[at + i] & 0x7f) as u32) << (7 * i);
        if p[at + i] & 0x80 == 0 {
            return (v, i + 1);
        }
    }
    panic!("varint longer than 5 bytes at {at}");
}

/// `v` as a varint of exactly `n` bytes (readers accept padded varints).
fn padded_varint(v: u32, n: usize) -> Vec<u8> {
    (0..n)
        .map(|i| (v >> (7 * i)) as u8 & 0x7f | if i + 1 < n { 0x80 } else { 0 })
        .collect()
}

/// Byte offsets of the first static part's channel records in a layout-4 payload (§6.5.7),
/// from log-scale x on: (offset of `head`, offset of `len`).
fn compact_records(p: &[u8], channels: usize) -> Vec<(usize, usize)> {
    let (_, n) = varint(p, 2); // layout, part count, the part's Gaussian count
    let mut at = 2 + n;
    let h = p[at] >> 7;
    at += 1 + if h == 1 { 12 } else { 24 };
    let (len, n) = varint(p, at);
    at += n + len as usize + 5; // the octree, then max shift and threshold
    let mut out = Vec::new();
    for j in 3..channels {
        let head = p[at];
        let range = match (j == 6, head >> 7) {
            (true, _) => 0, // the rotation index has no range
            (false, 1) => 4,
            (false, _) => 8,
        };
        let len_at = at + 1 + range;
        let (len, n) = varint(p, len_at);
        out.push((at, len_at));
        at = len_at + n + len as usize;
    }
    out
}

#[test]
fn compact_records_decode_to_layout_3s_gaussians_in_fewer_bytes() {
    // Layout 4 (format 1.14): layout 3's streams and cells in tighter records.
    let (c, _, p3, order3) = octree_lod3_with(Some(COARSE));
    let (_, _, p4, order4) = octree_lod3_framed(Some(COARSE), true);
    assert_eq!((p3[0], p4[0]), (3, 4), "layouts");
    assert_eq!(order4, order3, "the order follows the positions alone");
    let scene = scene_of(&c);
    let body = |p: &[u8]| {
        let d = csog::decode(p, 0, &scene, &Limits::default()).unwrap();
        dlgs::chunks::craw::canonical_body(&d)
    };
    assert_eq!(body(&p4), body(&p3), "the same Gaussians, bit for bit");
    // Every record saves at least its second head byte and a length byte (all are under 2 MB),
    // every set its width and channel count (6 bytes): 3 static parts of 56 records after the
    // octree, one dynamic part of 59 (SH 3, no language).
    let channels = 59;
    let least = 3 * (6 + 2 * (channels - 3)) + 6 + 2 * channels;
    assert!(
        p3.len() >= p4.len() + least,
        "layout 3 {} B, layout 4 {} B",
        p3.len(),
        p4.len()
    );
    // Deterministic on any thread count.
    let run = |n: usize| on_threads(n, || body(&p4));
    assert_eq!(run(1), run(3));
}

#[test]
fn damaged_compact_records_give_typed_errors_not_panics() {
    let (c, _, p, _) = octree_lod3_framed(Some(COARSE), true);
    let scene = scene_of(&c);
    let err = |b: &[u8]| match csog::decode(b, 0, &scene, &Limits::default()) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("a damaged payload decoded"),
    };
    let records = compact_records(&p, 59);
    // A codec this version does not define (the head's bits 4-6).
    let (head, _) = records[0];
    let mut b = p.clone();
    b[head] = b[head] & 0x8f | 6 << 4;
    assert!(err(&b).contains("unknown grid codec 6"), "{}", err(&b));
    // The rotation index record flagging a range it does not have.
    let (index, _) = records[3];
    let mut b = p.clone();
    b[index] |= 0x80;
    assert!(err(&b).contains("no range to flag"), "{}", err(&b));
    // A codec-5 stream that is not whole words.
    let (_, len_at) = *records
        .iter()
        .find(|&&(h, _)| p[h] >> 4 & 7 == 5)
        .expect("a codec-5 record");
    let (len, n) = varint(&p, len_at);
    let mut b = p.clone();
    b.splice(len_at..len_at + n, padded_varint(len - 1, n));
    assert!(err(&b).contains("whole 32-bit words"), "{}", err(&b));
    // A part count varint of 6 bytes, and the payload cut anywhere.
    let mut b = p.clone();
    b.splice(2..2, [0x80; 5]);
    assert!(err(&b).contains("varint"), "{}", err(&b));
    for cut in (0..p.len()).step_by(97) {
        let _ = err(&p[..cut]);
    }
    // Flipped bits anywhere in the first part: an error or a different set, never a panic.
    decode_with_flipped_bits(&p, &scene, 2, 7);
}

/// Layout 3 of [`octree_lod3`] with a large factor, so every shift class occurs.
const COARSE: RotationCoarsening = RotationCoarsening {
    factor: 16.0,
    max_shift: 4,
};

/// The first part's (max shift, threshold) and the byte offset of the max shift.
fn first_coarsening(p: &[u8]) -> (u8, f32, usize) {
    // Layout, part count, part size, width, channel count, position bits and ranges, then the
    // octree's length and bytes.
    let len = u32::from_le_bytes(p[37..41].try_into().unwrap()) as usize;
    let at = 41 + len;
    let t = f32::from_le_bytes(p[at + 1..at + 5].try_into().unwrap());
    (p[at], t, at)
}

#[test]
fn coarse_rotation_sets_turn_small_gaussians_within_their_shifted_steps() {
    // Layout 3 (format 1.11): a Gaussian with shift k stores its rotation components times
    // 2^-k, so its error may be 2^k times larger; everything else decodes as in layout 2.
    let (c, parts, p2, order2) = octree_lod3();
    let (_, _, p3, order3) = octree_lod3_with(Some(COARSE));
    assert_eq!(p3[0], 3, "layout 3");
    assert_eq!(order3, order2, "the order follows the positions alone");
    assert!(p3.len() < p2.len(), "{} B vs {} B", p3.len(), p2.len());
    let scene = scene_of(&c);
    let d2 = csog::decode(&p2, 0, &scene, &Limits::default()).unwrap();
    let d3 = csog::decode(&p3, 0, &scene, &Limits::default()).unwrap();
    assert_eq!(d3.statics.positions, d2.statics.positions);
    assert_eq!(d3.statics.log_scales, d2.statics.log_scales);
    assert_eq!(d3.statics.sh, d2.statics.sh);
    assert_eq!(d3.statics.opacity, d2.statics.opacity);
    assert_eq!(d3.dynamics.rotations, d2.dynamics.rotations);
    let (max_shift, t, _) = first_coarsening(&p3);
    assert_eq!(max_shift, 4);
    // The first part (medium: 8 rotation bits): each component within half a shifted step of
    // the source's sign-fixed normalised component.
    let n0 = parts[0].0.len();
    let step = std::f32::consts::SQRT_2 / 255.0;
    let mut per_shift = [0usize; 5];
    for k in 0..n0 {
        let shift = rotation_shift(d3.statics.log_scales[k], t, max_shift);
        per_shift[shift as usize] += 1;
        let src = normalised(c.statics.rotations[order3[k] as usize]);
        let got = normalised(d3.statics.rotations[k]);
        let bound = 0.5 * step * (1u32 << shift) as f32 * 1.01 + 1e-5;
        // The stored three are the source's smallest (sign: its largest component positive);
        // the largest follows from them, with up to ~4x their error.
        let m = (0..4)
            .max_by(|&a, &b| src[a].abs().total_cmp(&src[b].abs()).then(b.cmp(&a)))
            .unwrap();
        let (ss, sg) = (src[m].signum(), if got[m] < 0.0 { -1.0 } else { 1.0 });
        for a in 0..4 {
            let e = (src[a] * ss - got[a] * sg).abs();
            let b = if a == m { 5.0 * bound } else { bound };
            assert!(
                e <= b,
                "Gaussian {k}, shift {shift}, component {a}: error {e}"
            );
        }
        if shift == 0 {
            assert_eq!(d3.statics.rotations[k], d2.statics.rotations[k], "{k}");
        }
    }
    assert!(
        per_shift.iter().all(|&m| m > 0),
        "every shift class occurs in lod3 at factor 16: {per_shift:?}"
    );
}

/// Unit quaternion.
fn normalised(q: [f32; 4]) -> [f32; 4] {
    let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
    q.map(|v| v / n)
}

#[test]
fn damaged_coarse_rotation_records_give_typed_errors_not_panics() {
    let (c, _, p, _) = octree_lod3_with(Some(COARSE));
    let scene = scene_of(&c);
    // `describe` walks the parts as decoding does and reports the same errors.
    let err = |b: &[u8]| {
        let e = csog::decode(b, 0, &scene, &Limits::default())
            .unwrap_err()
            .to_string();
        let d = csog::describe(b, 0, &scene).unwrap_err().to_string();
        assert_eq!(e, d);
        e
    };
    let (_, _, at) = first_coarsening(&p);
    let mut b = p.clone();
    b[at] = 9;
    assert!(err(&b).contains("rotation max shift 9"), "{}", err(&b));
    let mut b = p.clone();
    b[at + 1..at + 5].copy_from_slice(&f32::INFINITY.to_le_bytes());
    assert!(err(&b).contains("rotation threshold"), "{}", err(&b));
    // Max shift 0 turns coarsening off: the file still decodes (to other rotations).
    let mut b = p.clone();
    b[at] = 0;
    assert!(csog::decode(&b, 0, &scene, &Limits::default()).is_ok());
    // Flipped bits around the record and in the rotation channels: never a panic.
    let mut s = 11u32;
    for _ in 0..300 {
        s = s.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        let mut b = p.clone();
        let i = at + (s as usize >> 8) % (p.len() - at);
        b[i] ^= 1 << (s % 8);
        let _ = csog::decode(&b, 0, &scene, &Limits::default());
    }
}

#[test]
fn degenerate_gaussians_decode_finite_in_coarse_rotation_sets() {
    // Layout 3: collapsed (e^-30) and huge (e^12) scales give the largest and the smallest
    // shift; a zero quaternion still decodes near the identity, within its coarsened step.
    let g = degenerate_lod3();
    let parts = [(g.clone(), QuantBits::LOW)];
    let empty = Gaussians::new(g.sh_degree, 0);
    let gop = csog::PartedGop {
        static_parts: &parts,
        static_weight: None,
        dynamics: &empty,
        dynamic_bits: &QuantBits::LOW,
        rotation_coarsening: Some(RotationCoarsening::DEFAULT),
        compact_records: true,
        mixed_margin: Some(grid_coder::MIXED_MARGIN),
    };
    let (p, order) = csog::encode_octree(&gop, 3).unwrap();
    assert_eq!(p[0], 4, "layout 4: layout 3 in compact records");
    let c = Canonical::from_static(g);
    let d = csog::decode(&p, 0, &scene_of(&c), &Limits::default())
        .unwrap()
        .statics;
    assert!(d.positions.iter().all(|p| p[0] == 0.25));
    for v in [d.log_scales.as_flattened(), d.rotations.as_flattened()] {
        assert!(v.iter().all(|x| x.is_finite()));
    }
    for (k, &i) in order.iter().enumerate() {
        if i < 50 {
            let q = d.rotations[k];
            let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            assert!(q[0] / n > 0.99, "zero quaternion {i} decoded as {q:?}");
        }
    }
}
