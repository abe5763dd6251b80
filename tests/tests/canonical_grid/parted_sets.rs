//! Layout 1 (§6.5.2): a static set coded in parts at different bits.

use dlgs::chunks::csog::{self, QuantBits};
use dlgs::model::{Canonical, Gaussians};
use dlgs::{Error, LimitError, Limits};
use dlgs_encoder::grid_sort::permute;
use dlgs_tests::{load, on_threads};

use crate::{round_trip, scene_of};

/// Layout 1 (§6.5.2): lod3's static set in three parts at different bits.
fn parted_lod3() -> (Vec<(Gaussians, QuantBits)>, Canonical, Vec<u8>) {
    let g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let cut = |r: std::ops::Range<u32>| permute(&g, &r.collect::<Vec<u32>>());
    let parts = vec![
        (cut(0..1200), QuantBits::HIGH),
        (cut(1200..1900), QuantBits::MEDIUM),
        (cut(1900..1971), QuantBits::LOW),
    ];
    let empty = Gaussians::new(g.sh_degree, 0);
    let p = csog::encode_parts(&parts, &empty, &QuantBits::HIGH, 3).unwrap();
    (parts, Canonical::from_static(g), p)
}

#[test]
fn parted_sets_decode_to_their_parts_quantised_and_concatenated() {
    let (parts, c, p) = parted_lod3();
    assert_eq!(p[0], 1, "layout 1");
    let d = csog::decode(&p, 0, &scene_of(&c), &Limits::default()).unwrap();
    assert_eq!(d.statics.len(), c.statics.len());
    let mut at = 0;
    for (g, bits) in &parts {
        // Each part alone in layout 0 decodes to exactly the same floats.
        let alone = round_trip(&Canonical::from_static(g.clone()), bits);
        let whole = permute(&d.statics, &(at..at + g.len() as u32).collect::<Vec<u32>>());
        assert_eq!(
            dlgs::chunks::craw::canonical_body(&Canonical::from_static(whole)),
            dlgs::chunks::craw::canonical_body(&alone),
            "part at {at}"
        );
        at += g.len() as u32;
    }
}

#[test]
fn parted_sets_decode_the_same_floats_on_any_thread_count() {
    // Every part's octree and channel chains share one pool of tasks: the joined set must not
    // depend on the pool size.
    let (_, c, p) = parted_lod3();
    let scene = scene_of(&c);
    let run = |t| {
        on_threads(t, || {
            let d = csog::decode(&p, 0, &scene, &Limits::default()).unwrap();
            dlgs::chunks::craw::canonical_body(&d)
        })
    };
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(5));
}

#[test]
fn parted_sets_keep_all_their_cells_within_the_allocation_limit() {
    // A reader holds every part's cells at once before dequantising them, so the limit applies
    // to the whole set, not to the largest part.
    let (_, c, p) = parted_lod3();
    let scene = scene_of(&c);
    // lod3 (SH 3, no language): 3 + 3 + 1 + 3 + 1 + 48 channels of 2-byte cells.
    let cells = c.statics.len() as u64 * 2 * 59;
    let limits = |max_alloc| Limits {
        max_alloc,
        ..Limits::default()
    };
    assert!(csog::decode(&p, 0, &scene, &limits(cells)).is_ok());
    // Under the whole set's cells but above its largest part's (1,200 of 1,971 Gaussians).
    let e = csog::decode(&p, 0, &scene, &limits(cells - 1)).unwrap_err();
    assert!(
        matches!(e, Error::Limit(LimitError { .. }))
            && e.to_string().contains("CSOG channel cells"),
        "{e}"
    );
}

#[test]
fn parted_sets_with_wrong_counts_give_typed_errors() {
    let (_, c, p) = parted_lod3();
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
    // Byte 0 layout, 1 part count, 2..6 the first part's Gaussian count.
    for parts in [0u8, 17] {
        let mut b = p.clone();
        b[1] = parts;
        assert!(err(&b).contains(&format!("{parts} parts")), "{}", err(&b));
    }
    let mut b = p.clone();
    b[2..6].copy_from_slice(&5000u32.to_le_bytes());
    assert!(
        err(&b).contains("only 1971 of the set's 1971 are left"),
        "{}",
        err(&b)
    );
    // Two parts declared where three are stored: the counts fall short of the set.
    let mut b = p.clone();
    b[1] = 2;
    assert!(
        err(&b).contains("the parts hold 1900 of the set's 1971"),
        "{}",
        err(&b)
    );
    let mut b = p.clone();
    b[0] = 5;
    assert!(err(&b).contains("layout version 5"), "{}", err(&b));
    // Since 1.12 the empty dynamic set is its part count alone, 0; a scene that declares
    // dynamic Gaussians cannot have none.
    assert_eq!(p.last(), Some(&0));
    let mut dynamic = scene.clone();
    dynamic.n_dynamic = 1;
    let e = csog::decode(&p, 0, &dynamic, &Limits::default()).unwrap_err();
    assert!(e.to_string().contains("0 parts for 1 Gaussians"), "{e}");
    // The 1.11 form of the same set (one part of 0 Gaussians, every channel record) still
    // decodes.
    let mut old = p[..p.len() - 1].to_vec();
    old.push(1);
    old.extend_from_slice(&0u32.to_le_bytes());
    let empty = Gaussians::new(c.statics.sh_degree, 0);
    let with_part = csog::encode(&Canonical::from_static(empty), &QuantBits::HIGH, 3).unwrap();
    // Layout 0's payload is the layout byte, the (empty) static set, the (empty) dynamic set.
    old.extend_from_slice(&with_part[1..1 + (with_part.len() - 1) / 2]);
    let back = csog::decode(&old, 0, &scene, &Limits::default()).unwrap();
    assert_eq!((back.statics.len(), back.dynamics.len()), (1971, 0));
}
