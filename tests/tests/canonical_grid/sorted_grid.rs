//! The grid codec itself on real scenes: exact restoration of the quantised values, error bounds,
//! ordering rules, degenerate Gaussians, determinism, damaged payloads and the choice of grid codec
//! per channel (codecs 0-5).

use std::io::Cursor;

use dlgs::bytes::ByteReader;
use dlgs::chunks::csog::grid_codecs::{self as grid_coder, GridCodec};
use dlgs::chunks::csog::{
    self, dequantise, quantise_set, robust_radius, QuantBits, LOG_SCALE_BELOW_RADIUS,
    LOG_SCALE_SPAN,
};
use dlgs::container::SceneHeader;
use dlgs::model::{Canonical, Gaussians};
use dlgs::Limits;
use dlgs_decoder::Decoder;
use dlgs_encoder::grid_sort::{grid_order, permute, SortSpec};
use dlgs_encoder::{CanonicalCodec, EncoderConfig, StreamEncoder};
use dlgs_tests::{load, on_threads, with_synthetic_language};

use crate::{degenerate_lod3, round_trip, scene_of};

#[test]
fn eight_bit_colours_decode_to_their_own_values() {
    // The plant is a `.splat` capture: its SH DC values are 8-bit colours, and the encoder
    // puts the DC levels on them (`colour_lattice`), so at 8 bits every colour comes back
    // (to f32 rounding), where the data's min/max range moved them by up to half a step.
    let g = load("splat/marcelpadilla_plant.splat");
    let colour = |dc: f32| (dc * dlgs::interop::splat::SH_C0 + 0.5) * 255.0;
    let d = round_trip(&Canonical::from_static(g.clone()), &QuantBits::HIGH);
    assert_eq!(d.statics.len(), g.len());
    let worst =
        g.sh.iter()
            .zip(&d.statics.sh)
            .map(|(&a, &b)| (colour(a) - colour(b)).abs())
            .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "a colour moved by {worst} steps");
    // A float-valued scene takes the min/max range as before: the donut's DC is not on colours.
    let donut = load("ply/v3dg_donut_mipsplatting_45624_sh0.ply");
    let dc: Vec<f32> = donut.sh.iter().step_by(3).copied().collect();
    assert_eq!(
        dlgs::chunks::csog::grid_codecs::colour_lattice_range(&dc, 8),
        None
    );
}

#[test]
fn decoding_restores_the_quantised_values_exactly() {
    for (path, lang) in [
        ("ply/supersplat_fruit_drops_minimal_4721_sh3.ply", true),
        ("ply/v3dg_donut_mipsplatting_45624_sh0.ply", false),
    ] {
        let mut g = load(path);
        if lang {
            g = with_synthetic_language(&g);
        }
        let c = Canonical::from_static(g.clone());
        for bits in [QuantBits::HIGH, QuantBits::LOW] {
            let d = round_trip(&c, &bits);
            let q = quantise_set(&g, &bits);
            // Positions and SH: exactly `dequantise(q)` (§6.5.2).
            for a in 0..3 {
                let (b, lo, hi, cells) = &q.channels[a];
                for i in 0..g.len() {
                    assert_eq!(
                        d.statics.positions[i][a],
                        dequantise(cells[i], *lo, *hi, *b)
                    );
                }
            }
            let first_sh = 3 + 3 + 1 + 3 + 1;
            for j in 0..g.sh_stride() {
                let (b, lo, hi, cells) = &q.channels[first_sh + j];
                for i in 0..g.len() {
                    assert_eq!(
                        d.statics.sh[i * g.sh_stride() + j],
                        dequantise(cells[i], *lo, *hi, *b)
                    );
                }
            }
            // Re-quantising the decoded set gives the same integers for position, log-scale,
            // SH and language channels (rotations and opacities are re-derived through
            // normalisation and logit/sigmoid, so near-ties may move).
            let q2 = quantise_set(&d.statics, &bits);
            let rotation_and_opacity = 6..11;
            for (k, (a, b)) in q.channels.iter().zip(&q2.channels).enumerate() {
                let lang_opacity = lang && k == first_sh + g.sh_stride();
                if !(rotation_and_opacity.contains(&k) || lang_opacity) {
                    let differing = a.3.iter().zip(&b.3).filter(|(x, y)| x != y).count();
                    assert_eq!(differing, 0, "{path}: channel {k}");
                }
            }
        }
    }
}

#[test]
fn errors_stay_within_half_a_step() {
    let g = load("ply/gs3d-fork_lod2_tile_0_6831_sh3.ply");
    let bits = QuantBits::MEDIUM;
    let d = round_trip(&Canonical::from_static(g.clone()), &bits).statics;
    let q = quantise_set(&g, &bits);
    for a in 0..3 {
        let (b, lo, hi, _) = q.channels[a];
        let step = (hi - lo) / ((1u32 << b) - 1) as f32;
        let worst = (0..g.len())
            .map(|i| (d.positions[i][a] - g.positions[i][a]).abs())
            .fold(0f32, f32::max);
        assert!(
            worst <= step * 0.5001 + 1e-6,
            "axis {a}: {worst} vs step {step}"
        );
    }
    // Log-scales: within half a step above the floor (at most LOG_SCALE_SPAN below the max and
    // LOG_SCALE_BELOW_RADIUS below ln(radius); this tile has collapsed axes near -23), raised
    // to it below.
    let floor = robust_radius(&g.positions).unwrap().ln() - LOG_SCALE_BELOW_RADIUS;
    for a in 0..3 {
        let (b, lo, hi, _) = q.channels[3 + a];
        // The binary16 ends (§6.5.7) may lower the minimum by under half a step.
        let step = (hi - lo) / ((1u32 << b) - 1) as f32;
        assert!(
            lo >= hi - LOG_SCALE_SPAN - step / 2.0 && lo >= floor - step / 2.0,
            "axis {a}: range {lo}..{hi}"
        );
        assert!(
            lo < floor + 1e-4,
            "axis {a}: the radius floor sets the minimum here"
        );
        let mut raised = 0;
        for i in 0..g.len() {
            let (v, dv) = (g.log_scales[i][a], d.log_scales[i][a]);
            if v < lo {
                raised += 1;
                assert!(
                    (dv - lo).abs() <= step * 0.5001 + 1e-5,
                    "Gaussian {i}: {dv}"
                );
            } else {
                assert!(
                    (dv - v).abs() <= step * 0.5001 + 1e-5,
                    "Gaussian {i}: {dv} vs {v}"
                );
            }
        }
        assert!(
            raised > 0,
            "axis {a}: the tile's collapsed axes should be raised"
        );
    }
    // Rotations: same rotation up to the component step.
    for i in 0..g.len() {
        let n = g.rotations[i].iter().map(|v| v * v).sum::<f32>().sqrt();
        let dot: f32 = (0..4)
            .map(|k| g.rotations[i][k] / n * d.rotations[i][k])
            .sum();
        assert!(dot.abs() > 0.99, "Gaussian {i}: |dot| {dot}");
    }
    // Opacity: alpha within half a step (or the clamp).
    let sig = |x: f32| 1.0 / (1.0 + (-x).exp());
    for i in 0..g.len() {
        let e = (sig(d.opacity[i]) - sig(g.opacity[i])).abs();
        assert!(e <= 0.5 / 127.0 + 1e-4, "Gaussian {i}: alpha error {e}");
    }
}

#[test]
fn statics_are_sorted_dynamics_keep_their_order() {
    let g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let mut statics = Gaussians::new(g.sh_degree, 0);
    let mut dynamics = Gaussians::new(g.sh_degree, 0);
    for i in 0..g.len() {
        if i % 4 == 0 {
            dynamics.push_from(&g, i)
        } else {
            statics.push_from(&g, i)
        }
    }
    // Grid positions: the static set is stored in the grid sort's order (layout 0).
    let cfg = EncoderConfig {
        coding: dlgs_encoder::CanonicalSettings {
            codec: CanonicalCodec::Sorted {
                bits: QuantBits::HIGH,
                sort: SortSpec::DEFAULT,
            },
            octree_positions: false,
            ..Default::default()
        },
        ..Default::default()
    };
    // A dynamic scene needs a deformation field; check the payload directly instead.
    let order = grid_order(&statics, SortSpec::DEFAULT);
    assert_ne!(order, (0..statics.len() as u32).collect::<Vec<_>>());
    let sorted = Canonical {
        statics: permute(&statics, &order),
        dynamics: dynamics.clone(),
    };
    let d = round_trip(&sorted, &QuantBits::HIGH);
    for i in 0..dynamics.len() {
        for a in 0..3 {
            assert!((d.dynamics.positions[i][a] - dynamics.positions[i][a]).abs() < 1e-3);
        }
    }
    // Through the encoder (still scene): the static set comes back as a permutation.
    let c0 = Canonical::from_static(statics.clone());
    let mut enc = StreamEncoder::new(
        Vec::new(),
        SceneHeader::still(statics.len() as u32, g.sh_degree),
        cfg,
    )
    .unwrap();
    enc.push_intra_gop(&c0).unwrap();
    let bytes = enc.finish().unwrap();
    let mut dec = Decoder::new(Cursor::new(bytes.as_slice()), Limits::default()).unwrap();
    let back = dec.gop_canonical(0).unwrap();
    for (k, &i) in order.iter().enumerate() {
        for a in 0..3 {
            assert!((back.statics.positions[k][a] - statics.positions[i as usize][a]).abs() < 1e-3);
        }
    }
}

#[test]
fn degenerate_gaussians_decode_finite_and_nan_is_rejected() {
    let g = degenerate_lod3();
    let d = round_trip(&Canonical::from_static(g.clone()), &QuantBits::LOW).statics;
    assert!(d.positions.iter().all(|p| p[0] == 0.25));
    for v in [
        d.log_scales.as_flattened(),
        d.rotations.as_flattened(),
        &d.opacity,
        &d.sh,
    ] {
        assert!(v.iter().all(|x| x.is_finite()));
    }
    // A zero quaternion codes as the identity (up to the component step: 0 is not a level).
    assert!(d.rotations[0][0] > 0.999, "{:?}", d.rotations[0]);
    let mut bad = g.clone();
    bad.sh[7] = f32::NAN;
    let e = csog::encode(&Canonical::from_static(bad), &QuantBits::HIGH, 3).unwrap_err();
    assert!(
        e.to_string().contains("not finite") || e.to_string().contains("NaN"),
        "{e}"
    );
}

#[test]
fn payload_does_not_depend_on_thread_count() {
    let g = load("ply/supersplat_fruit_drops_minimal_4721_sh3.ply");
    let run = |t| {
        on_threads(t, || {
            let order = grid_order(&g, SortSpec::REFINED);
            let c = Canonical::from_static(permute(&g, &order));
            csog::encode(&c, &QuantBits::HIGH, 3).unwrap()
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn damaged_payloads_give_typed_errors() {
    let g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let c = Canonical::from_static(g);
    let scene = scene_of(&c);
    let p = csog::encode(&c, &QuantBits::MEDIUM, 3).unwrap();
    let limits = Limits::tiny();
    let mut errors = 0;
    for cut in (0..p.len()).step_by(97) {
        if csog::decode(&p[..cut], 0, &scene, &limits).is_err() {
            errors += 1;
        }
    }
    assert_eq!(errors, p.len().div_ceil(97), "every truncation is an error");
    // `describe` (`dlgs info --channels`) reads the same records: the intact payload's
    // records hold all but its heads, every truncation is an error there too.
    let summary = csog::describe(&p, 0, &scene).unwrap();
    let coded: usize = summary.records.iter().map(|r| r.bytes).sum();
    // Two sets (layout 0), each position, log-scale, rotation, opacity and SH channel.
    let per_set = 11 + c.statics.sh_stride();
    assert_eq!(summary.records.len(), 2 * per_set);
    assert!(
        coded < p.len() && p.len() - coded < 16 * 2 * per_set,
        "{coded} of {}",
        p.len()
    );
    for cut in (0..p.len()).step_by(97) {
        assert!(
            csog::describe(&p[..cut], 0, &scene).is_err(),
            "cut at {cut}"
        );
    }
    for i in (0..p.len()).step_by(31) {
        let mut b = p.clone();
        b[i] ^= 0xa5;
        // Errors or finite Gaussians, never a panic; what decodes is also described.
        if let Ok(d) = csog::decode(&b, 0, &scene, &limits) {
            assert_eq!(d.statics.len(), c.statics.len());
            assert!(csog::describe(&b, 0, &scene).is_ok(), "flip at {i}");
        }
    }
}

#[test]
fn delta_codec_needs_a_previous_channel_of_the_same_bits() {
    let g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let c = Canonical::from_static(g);
    let scene = scene_of(&c);
    let mut p = csog::encode(&c, &QuantBits::HIGH, 3).unwrap();
    // Byte 0 layout version, 1..5 grid width, 5..7 channel count, 7 bits, 8 codec of the
    // first channel (position x).
    p[8] = 4;
    let e = csog::decode(&p, 0, &scene, &Limits::default()).unwrap_err();
    assert!(
        e.to_string().contains("codec 4 needs a previous channel"),
        "{e}"
    );
}

#[test]
fn real_scenes_pick_the_smallest_codec_per_channel() {
    // The plant at `high`: codec 5 (adaptive, since 1.9) is the smallest coding of most
    // channels, and the round trip stays exact.
    let g = load("splat/marcelpadilla_plant.splat");
    let c = Canonical::from_static(g.clone());
    let p = csog::encode(&c, &QuantBits::HIGH, 3).unwrap();
    let mut r = 7;
    let mut codecs = Vec::new();
    for _ in 0..14 {
        codecs.push(p[r + 1]);
        let len = u32::from_le_bytes(p[r + 10..r + 14].try_into().unwrap()) as usize;
        r += 14 + len;
    }
    assert!(
        codecs.iter().filter(|&&c| c == 5).count() >= 10,
        "{codecs:?}"
    );
    let d = csog::decode(&p, 0, &scene_of(&c), &Limits::default()).unwrap();
    let q = quantise_set(&g, &QuantBits::HIGH);
    for k in 11..14 {
        let (b, lo, hi, cells) = &q.channels[k];
        for i in 0..g.len() {
            assert_eq!(
                d.statics.sh[i * 3 + k - 11],
                dequantise(cells[i], *lo, *hi, *b)
            );
        }
    }
}

#[test]
fn the_adaptive_codec_shrinks_real_scenes_and_decodes_exactly() {
    // Every channel of two real scenes at `high` in the k-d layout, coded with the best of all
    // codecs and with the best of codecs 0-4 (format 1.8). Measured with
    // `bash experiments/canonical/grid_candidates.sh` (docs/benchmarks/canonical-levers.md
    // "Grid coder candidates"): gsplat 12.4 %
    // smaller, donut 3.2 % (its colour channels by 15 %).
    for (scene, at_most) in [
        ("ply/gsplat_DATA_new_22589_sh3.ply", 0.90),
        ("ply/v3dg_donut_mipsplatting_45624_sh0.ply", 0.985),
    ] {
        let g = load(scene);
        let g = permute(&g, &grid_order(&g, SortSpec::NONE));
        let q = quantise_set(&g, &QuantBits::HIGH);
        let w = csog::grid_width(g.len());
        let (mut best, mut tabled, mut adaptive) = (0, 0, 0);
        for j in 0..q.channels.len() {
            let (b, _, _, cells) = &q.channels[j];
            let prev = j
                .checked_sub(1)
                .map(|p| (q.channels[p].3.as_slice(), q.channels[p].0));
            let prev2 = j
                .checked_sub(2)
                .map(|p| (q.channels[p].3.as_slice(), q.channels[p].0));
            let (codec, data) = grid_coder::encode_best(
                cells,
                prev,
                prev2,
                w,
                *b,
                3,
                Some(grid_coder::MIXED_MARGIN),
            );
            tabled += grid_coder::encode_best_tabled(cells, prev, w, *b, 3)
                .1
                .len();
            best += data.len();
            adaptive += (codec == GridCodec::Adaptive) as usize;
            let mut d = grid_coder::decode(
                codec,
                ByteReader::new(&data, 0),
                cells.len(),
                w,
                *b,
                prev,
                prev2,
            )
            .unwrap();
            if codec == GridCodec::HistogramDelta {
                grid_coder::undo_delta(&mut d, prev.unwrap().0, *b);
            }
            assert_eq!(&d, cells, "{scene} channel {j} ({codec:?})");
        }
        println!("{scene}: {best} B with codec 5 ({adaptive} channels), {tabled} B without");
        assert!(adaptive > 0);
        assert!(
            (best as f64) < tabled as f64 * at_most,
            "{scene}: {best} vs {tabled}"
        );
    }
}

#[test]
fn without_mixing_no_channel_takes_modes_5_or_6_and_every_cell_decodes_the_same() {
    // `dlgs encode --fast-decode`: codec 5's mixed modes (first data byte 5 or 6) are left out
    // of the choice. On the real donut at `high` some channels take them by default, so the
    // channels without them cost more bytes in all, and still decode to the same cells. A
    // larger margin (`--mixed-margin 5`) lets fewer channels take them, for bytes in between.
    let g = load("ply/v3dg_donut_mipsplatting_45624_sh0.ply");
    let g = permute(&g, &grid_order(&g, SortSpec::NONE));
    let q = quantise_set(&g, &QuantBits::HIGH);
    let w = csog::grid_width(g.len());
    let mixed = |codec: GridCodec, data: &[u8]| {
        codec == GridCodec::Adaptive && matches!(data.first(), Some(5 | 6))
    };
    let margins = [Some(grid_coder::MIXED_MARGIN), Some(0.05), None];
    let (mut bytes, mut mixed_channels) = ([0usize; 3], [0usize; 3]);
    for j in 0..q.channels.len() {
        let (b, _, _, cells) = &q.channels[j];
        let earlier = |back: usize| {
            j.checked_sub(back)
                .map(|p| (q.channels[p].3.as_slice(), q.channels[p].0))
        };
        for (k, margin) in margins.into_iter().enumerate() {
            let (codec, data) =
                grid_coder::encode_best(cells, earlier(1), earlier(2), w, *b, 3, margin);
            bytes[k] += data.len();
            mixed_channels[k] += mixed(codec, &data) as usize;
            let mut d = grid_coder::decode(
                codec,
                ByteReader::new(&data, 0),
                cells.len(),
                w,
                *b,
                earlier(1),
                earlier(2),
            )
            .unwrap();
            if codec == GridCodec::HistogramDelta {
                grid_coder::undo_delta(&mut d, earlier(1).unwrap().0, *b);
            }
            assert_eq!(&d, cells, "channel {j}, margin {margin:?}");
        }
    }
    println!("donut high: {bytes:?} B, {mixed_channels:?} mixed channels (margin 1 %, 5 %, none)");
    assert!(mixed_channels[0] > mixed_channels[1] && mixed_channels[2] == 0);
    assert!(bytes[0] < bytes[1] && bytes[1] < bytes[2], "{bytes:?}");
}
