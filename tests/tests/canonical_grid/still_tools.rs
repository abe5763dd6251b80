//! The still encoder's tools on real scenes: the closest-to-identity orientation, bit reallocation,
//! leaving out never-drawn Gaussians and all-zero SH bands, shaped levels and importance tiers.

use std::io::Cursor;

use dlgs::chunks::csog::{self, quantise_set, QuantBits};
use dlgs::model::{Canonical, Gaussians};
use dlgs::Limits;
use dlgs_decoder::Decoder;
use dlgs_encoder::grid_sort::{permute, SortSpec};
use dlgs_encoder::orientation::closest_to_identity;
use dlgs_encoder::{CanonicalCodec, EncoderConfig};
use dlgs_render::{metrics, orbit_cameras, render, OrbitSpec, RenderOptions};
use dlgs_tests::{load, on_threads};

use crate::{encode_still, every_nth, orbit_psnr};

#[test]
fn closest_to_identity_rotations_render_the_same_and_code_smaller() {
    // Real lod1 tile (14,051 Gaussians): the representatives change, the images do not.
    let g = load("ply/gs3d-fork_lod1_tile_0_0.5x_14051_sh3.ply");
    let spec = OrbitSpec {
        width: 320,
        height: 240,
        count: 4,
        ..Default::default()
    };
    let cams = orbit_cameras(&g, &spec);
    let image = |g: &Gaussians, i: usize| {
        render(g, &cams[i], &RenderOptions::default())
            .unwrap()
            .color
    };
    let c = closest_to_identity(&g);
    for i in 0..cams.len() {
        let p = metrics::psnr(&image(&g, i), &image(&c, i));
        println!("camera {i}: unquantised original vs re-oriented {p:.2} dB");
        assert!(p > 70.0, "camera {i}: {p} dB");
    }
    let (kept_bytes, kept) = encode_still(&g, false);
    let (oriented_bytes, oriented) = encode_still(&g, true);
    let mut worst = f64::INFINITY;
    for i in 0..cams.len() {
        let (pk, po) = (
            metrics::psnr(&image(&g, i), &image(&kept, i)),
            metrics::psnr(&image(&g, i), &image(&oriented, i)),
        );
        println!("camera {i}: medium kept {pk:.2} dB, re-oriented {po:.2} dB");
        worst = worst.min(po - pk);
    }
    println!("bytes: kept {kept_bytes}, re-oriented {oriented_bytes}");
    // Measured: 165,890 -> 156,995 B at `medium` (-5.4 %).
    assert!(
        (oriented_bytes as f64) < kept_bytes as f64 * 0.97,
        "{oriented_bytes} vs {kept_bytes}"
    );
    assert!(worst > -0.5, "re-oriented renders {worst} dB worse");
}

#[test]
fn spheres_take_the_identity_rotation_and_code_smaller() {
    // The real gsplat scene's spheres (three equal log-scales: 20.6 % of its Gaussians; every
    // Gaussian of the wave sequence is one). A sphere renders the same whatever its rotation,
    // so the encoder stores the identity.
    let g = load("ply/gsplat_DATA_new_22589_sh3.ply");
    let spheres: Vec<u32> = (0..g.len() as u32)
        .filter(|&i| {
            let s = g.log_scales[i as usize];
            s[0] == s[1] && s[1] == s[2]
        })
        .collect();
    assert!(spheres.len() > 4000, "{} spheres", spheres.len());
    let g = permute(&g, &spheres);
    assert!(closest_to_identity(&g)
        .rotations
        .iter()
        .all(|q| *q == [1.0, 0.0, 0.0, 0.0]));
    let (kept_bytes, kept) = encode_still(&g, false);
    let (oriented_bytes, oriented) = encode_still(&g, true);
    // Every rotation decodes to the identity's neighbour on the quantiser's levels (the
    // rotation range [-1/sqrt 2, 1/sqrt 2] has no level at 0).
    assert!(
        oriented.rotations.iter().all(|q| q[0] > 0.9999),
        "{:?}",
        &oriented.rotations[..3]
    );
    let (pk, po) = (orbit_psnr(&g, &kept, 4), orbit_psnr(&g, &oriented, 4));
    println!("kept {kept_bytes} B {pk:.2} dB, identity {oriented_bytes} B {po:.2} dB");
    assert!(po > pk - 0.05, "{po:.2} vs {pk:.2} dB");
    assert!(
        (oriented_bytes as f64) < kept_bytes as f64 * 0.9,
        "{oriented_bytes} vs {kept_bytes}"
    );
}

#[test]
fn bit_reallocation_buys_quality_within_the_presets_bytes() {
    // The real plant capture (.splat) stores 8-bit opacities: `medium`'s 7 opacity bits
    // merge them in pairs, so the allocator should move a bit there (measured: from rotation,
    // 1,223,506 -> 1,190,199 bytes, 58.24 -> 59.87 dB on its views). Every fourth Gaussian
    // keeps those opacities and codes and renders 4x faster: there the allocator moves a bit
    // from SH DC to opacity, then one from rotation to SH DC (285,984 -> 283,330 bytes, 56.50
    // -> 57.84 dB on its views; 24 s instead of 67 s for the whole plant).
    let g = every_nth(&load("splat/marcelpadilla_plant.splat"), 4);
    let cfg = EncoderConfig {
        coding: dlgs_encoder::CanonicalSettings {
            codec: CanonicalCodec::Sorted {
                bits: QuantBits::MEDIUM,
                sort: SortSpec::DEFAULT,
            },
            ..Default::default()
        },
        still: dlgs_encoder::StillTools {
            reallocate_bits: 4,
            ..Default::default()
        },
        ..Default::default()
    };
    let (bytes, report) = dlgs_encoder::encode_still_reporting(&g, cfg, Vec::new()).unwrap();
    let a = report
        .allocation
        .expect("a still scene with reallocate_bits runs the allocator");
    println!("{a:?}");
    assert!(
        a.bytes as f64
            <= a.start_bytes as f64 * (1.0 + dlgs_encoder::bit_allocation::BYTES_TOLERANCE),
        "{} > {}",
        a.bytes,
        a.start_bytes
    );
    assert!(
        a.psnr > a.start_psnr + 1.0,
        "{} vs {}",
        a.psnr,
        a.start_psnr
    );
    assert_eq!(a.bits.opacity, QuantBits::MEDIUM.opacity + 1);
    assert!(!a.moves.is_empty() && a.moves.len() <= 4);
    // Every move keeps the total bit count.
    let total = |b: &QuantBits| {
        [
            b.position,
            b.log_scale,
            b.rotation,
            b.opacity,
            b.sh_dc,
            b.sh_rest,
            b.sh_high,
        ]
        .iter()
        .map(|&v| v as i32)
        .sum::<i32>()
    };
    assert_eq!(total(&a.bits), total(&QuantBits::MEDIUM));
    // The file holds what was chosen: its CSOG payload is within a header of the allocator's.
    assert!(bytes.len() >= a.bytes && bytes.len() < a.bytes + 4096);
}

/// Three small orbit views (of `a`'s bounds) render the same pixels from `a` and `b`.
fn assert_same_pixels(a: &Gaussians, b: &Gaussians) {
    let spec = OrbitSpec {
        width: 320,
        height: 240,
        count: 3,
        ..Default::default()
    };
    for cam in orbit_cameras(a, &spec) {
        let ia = render(a, &cam, &RenderOptions::default()).unwrap();
        let ib = render(b, &cam, &RenderOptions::default()).unwrap();
        assert_eq!(ia.color, ib.color, "camera {}", cam.name);
    }
}

/// `g` through [`dlgs_encoder::encode_still_reporting`] at `bits` with the rest of `cfg`:
/// file bytes, report and decoded static set (checked against the header's SH degree).
fn still_file(
    g: &Gaussians,
    bits: QuantBits,
    cfg: EncoderConfig,
) -> (usize, dlgs_encoder::StillReport, Gaussians) {
    let cfg = EncoderConfig {
        coding: dlgs_encoder::CanonicalSettings {
            codec: CanonicalCodec::Sorted {
                bits,
                sort: SortSpec::DEFAULT,
            },
            ..cfg.coding
        },
        ..cfg
    };
    let (bytes, report) = dlgs_encoder::encode_still_reporting(g, cfg, Vec::new()).unwrap();
    let mut dec = Decoder::new(Cursor::new(bytes.as_slice()), Limits::default()).unwrap();
    assert_eq!(dec.scene().sh_degree, report.sh_degree);
    let statics = dec.gop_canonical(0).unwrap().statics.clone();
    (bytes.len(), report, statics)
}

#[test]
fn never_drawn_gaussians_are_left_out_without_changing_a_pixel() {
    // Real Mip-Splatting donut (45,624 Gaussians), 3.3 % of them with opacity below 1/255.
    let g = load("ply/v3dg_donut_mipsplatting_45624_sh0.ply");
    let (kept, dropped) = dlgs_encoder::invisible::drop_never_drawn(&g);
    assert_eq!(dropped, 1518, "measured on the donut");
    assert_same_pixels(&g, &kept);
    let encode = |drop_invisible: bool| {
        let cfg = EncoderConfig {
            still: dlgs_encoder::StillTools {
                drop_invisible,
                ..Default::default()
            },
            ..Default::default()
        };
        let (bytes, report, statics) = still_file(&g, QuantBits::MEDIUM, cfg);
        (bytes, report.dropped_invisible, statics.len())
    };
    let (all_bytes, none_dropped, all_n) = encode(false);
    let (pruned_bytes, pruned, pruned_n) = encode(true);
    println!("all {all_bytes} B, without the never-drawn {pruned_bytes} B");
    assert_eq!((none_dropped, all_n), (0, g.len()));
    assert_eq!((pruned, pruned_n), (dropped, g.len() - dropped));
    assert!(
        (pruned_bytes as f64) < all_bytes as f64 * 0.975,
        "{pruned_bytes} vs {all_bytes}"
    );
}

#[test]
fn sh_bands_that_are_zero_everywhere_are_left_out_without_changing_a_pixel() {
    // Real gs3d lod3 tile: declared SH 3, every band 1-3 coefficient 0.0.
    let g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    assert_eq!(g.sh_degree, 3);
    assert_eq!(dlgs_encoder::zero_bands::degree_in_use(&g), 0);
    let encode = |trim: bool| {
        let cfg = EncoderConfig {
            still: dlgs_encoder::StillTools {
                trim_zero_sh_bands: trim,
                ..Default::default()
            },
            ..Default::default()
        };
        let (bytes, _, statics) = still_file(&g, QuantBits::HIGH, cfg);
        (bytes, statics)
    };
    let (kept_bytes, kept) = encode(false);
    let (trimmed_bytes, trimmed) = encode(true);
    println!("SH 3 kept {kept_bytes} B, trimmed to SH 0 {trimmed_bytes} B");
    assert_eq!((kept.sh_degree, trimmed.sh_degree), (3, 0));
    // 45 band channel records of at least 6 bytes each (layout 4's head, binary16 range and
    // length, §6.5.7) are gone; nothing else changes.
    assert!(
        kept_bytes >= trimmed_bytes + 45 * 6,
        "{kept_bytes} vs {trimmed_bytes}"
    );
    assert_eq!(trimmed.positions, kept.positions);
    assert_eq!(trimmed.log_scales, kept.log_scales);
    assert_eq!(trimmed.rotations, kept.rotations);
    assert_eq!(trimmed.opacity, kept.opacity);
    assert_eq!(trimmed.sh, kept.with_sh_degree(0).sh);
    assert_same_pixels(&kept, &trimmed);
}

#[test]
fn shaped_levels_stay_near_their_values_and_shrink_a_real_sh3_scene() {
    // Real SuperSplat fruit (4,721 Gaussians, SH 3): the importance-weighted shaper may move a
    // level up to MAX_MOVE steps; measured at 1352x1014 it codes a third smaller for 1.4 dB.
    let g = load("ply/supersplat_fruit_drops_minimal_4721_sh3.ply");
    let encode = |tolerance: f64, threads: usize| {
        let cfg = EncoderConfig {
            coding: dlgs_encoder::CanonicalSettings {
                codec: CanonicalCodec::Sorted {
                    bits: QuantBits::HIGH,
                    sort: SortSpec::DEFAULT,
                },
                ..Default::default()
            },
            still: dlgs_encoder::StillTools {
                shape_tolerance: tolerance,
                ..Default::default()
            },
            ..Default::default()
        };
        let bytes = on_threads(threads, || {
            dlgs_encoder::encode_still(&g, cfg, Vec::new()).unwrap()
        });
        let mut dec = Decoder::new(Cursor::new(bytes.as_slice()), Limits::default()).unwrap();
        let statics = dec.gop_canonical(0).unwrap().statics.clone();
        (bytes, statics)
    };
    let (plain_bytes, plain) = encode(0.0, 2);
    let (shaped_bytes, shaped) = encode(0.1, 2);
    assert_eq!(
        shaped_bytes,
        encode(0.1, 1).0,
        "shaping depends on the thread count"
    );
    println!(
        "plain {} B, shaped {} B",
        plain_bytes.len(),
        shaped_bytes.len()
    );
    assert!(
        shaped_bytes.len() * 10 < plain_bytes.len() * 8,
        "{} vs {}",
        shaped_bytes.len(),
        plain_bytes.len()
    );
    // Same Gaussians in the same grid order; positions and SH within MAX_MOVE steps of the
    // nearest levels the plain file holds, and some of them moved.
    let kept = dlgs_encoder::invisible::drop_never_drawn(&g).0;
    let q = quantise_set(&kept, &QuantBits::HIGH);
    let step = |c: usize| {
        let (b, lo, hi, _) = q.channels[c];
        (hi - lo) / ((1u32 << b) - 1) as f32
    };
    let limit = |c: usize| step(c) * (dlgs::chunks::csog::grid_codecs::MAX_MOVE as f32 + 0.01);
    assert_eq!(shaped.len(), plain.len());
    let mut moved = 0;
    for i in 0..plain.len() {
        for a in 0..3 {
            let d = (shaped.positions[i][a] - plain.positions[i][a]).abs();
            assert!(d <= limit(a), "Gaussian {i} axis {a} moved {d}");
        }
        let stride = plain.sh_stride();
        for j in 0..stride {
            let d = (shaped.sh[i * stride + j] - plain.sh[i * stride + j]).abs();
            // SH channels follow position, log-scale, rotation index + 3, opacity.
            assert!(d <= limit(11 + j), "Gaussian {i} SH {j} moved {d}");
            moved += (d > 0.0) as usize;
        }
    }
    assert!(moved > plain.len(), "only {moved} SH values moved");
    // The image cost stays bounded on views other than the importance pass's.
    let spec = OrbitSpec {
        width: 400,
        height: 300,
        count: 4,
        ..Default::default()
    };
    let (mut p_plain, mut p_shaped) = (0.0, 0.0);
    for cam in orbit_cameras(&g, &spec) {
        let img = |s: &Gaussians| render(s, &cam, &RenderOptions::default()).unwrap().color;
        let reference = img(&g);
        p_plain += metrics::psnr(&reference, &img(&plain)) / 4.0;
        p_shaped += metrics::psnr(&reference, &img(&shaped)) / 4.0;
    }
    println!("PSNR plain {p_plain:.2} dB, shaped {p_shaped:.2} dB");
    assert!(p_shaped > p_plain - 3.0, "{p_shaped} vs {p_plain}");
}

#[test]
fn shaping_handles_degenerate_and_tiny_sets() {
    // Degenerate Gaussians and a constant channel on a real tile, then 1 and 0 Gaussians: the
    // shaped file decodes to as many finite Gaussians, the constant channel stays exact.
    let mut g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    for i in 0..50 {
        g.rotations[i] = [0.0; 4];
        g.log_scales[i] = [if i % 2 == 0 { -30.0 } else { 12.0 }; 3];
    }
    for p in &mut g.positions {
        p[0] = 0.25;
    }
    let mut one = Gaussians::new(g.sh_degree, 0);
    one.push_from(&g, 60);
    let empty = Gaussians::new(g.sh_degree, 0);
    for (name, s) in [("tile", &g), ("one", &one), ("empty", &empty)] {
        let cfg = EncoderConfig {
            coding: dlgs_encoder::CanonicalSettings {
                codec: CanonicalCodec::Sorted {
                    bits: QuantBits::MEDIUM,
                    sort: SortSpec::DEFAULT,
                },
                ..Default::default()
            },
            still: dlgs_encoder::StillTools {
                shape_tolerance: 0.1,
                drop_invisible: false,
                ..Default::default()
            },
            ..Default::default()
        };
        let bytes = dlgs_encoder::encode_still(s, cfg, Vec::new()).unwrap();
        let mut dec = Decoder::new(Cursor::new(bytes.as_slice()), Limits::default()).unwrap();
        let d = dec.gop_canonical(0).unwrap().statics.clone();
        assert_eq!(d.len(), s.len(), "{name}");
        assert!(d.positions.iter().all(|p| p[0] == 0.25), "{name}");
        for v in [
            d.log_scales.as_flattened(),
            d.rotations.as_flattened(),
            &d.sh,
        ] {
            assert!(v.iter().all(|x| x.is_finite()), "{name}");
        }
    }
    // Bad weights are an input error, not a panic.
    let c = Canonical::from_static(one.clone());
    for w in [vec![f32::NAN], vec![-1.0], vec![1.0, 1.0]] {
        assert!(csog::encode_shaped(&c, &QuantBits::HIGH, 3, Some(&w)).is_err());
    }
}

#[test]
fn tiers_keep_the_image_and_shrink_a_real_scene() {
    // Real donut (45,624 Gaussians, SH 0): the least important Gaussians holding 4.3 % of
    // the blending weight one bit coarser. Measured on the benchmark's 8 views (`dlgs
    // compare`, format 1.9, `--reallocate-bits 4`): 546,670 B at 58.31 dB -> 526,295 B at
    // 58.38 dB (-3.7 %).
    let g = load("ply/v3dg_donut_mipsplatting_45624_sh0.ply");
    let encode = |tiers: Vec<f64>| {
        let cfg = EncoderConfig {
            coding: dlgs_encoder::CanonicalSettings {
                codec: CanonicalCodec::Sorted {
                    bits: QuantBits::HIGH,
                    sort: SortSpec::DEFAULT,
                },
                ..Default::default()
            },
            still: dlgs_encoder::StillTools {
                tier_weights: tiers,
                ..Default::default()
            },
            ..Default::default()
        };
        let bytes = dlgs_encoder::encode_still(&g, cfg, Vec::new()).unwrap();
        let mut dec = Decoder::new(Cursor::new(bytes.as_slice()), Limits::default()).unwrap();
        let d = dec.gop_canonical(0).unwrap().statics.clone();
        (bytes, d)
    };
    let (one, d1) = encode(Vec::new());
    let (two, d2) = encode(vec![0.043]);
    let (again, _) = encode(vec![0.043]);
    assert_eq!(two, again, "deterministic");
    let (p1, p2) = (orbit_psnr(&g, &d1, 4), orbit_psnr(&g, &d2, 4));
    println!(
        "one part {} B {p1:.2} dB, tiers {} B {p2:.2} dB",
        one.len(),
        two.len()
    );
    assert!(
        (two.len() as f64) < one.len() as f64 * 0.97,
        "{} vs {}",
        two.len(),
        one.len()
    );
    assert!(p2 > p1 - 0.5, "tiers {p2:.2} dB vs {p1:.2} dB");
}
