//! GOP-to-GOP residuals (format-spec §6.6 binary voxel fields, §6.7 explicit deltas), the
//! sequential and parallel residual modes, and seeking.
//!
//! NOTE: no real trained DLGStream model exists in this repository's data. The multi-GOP models
//! here are built by `dlgs_testkit::synth` from a REAL canonical scene in ../shared/data: GOP 0
//! is the real scene with a synthetic dynamic subset, and every later GOP carries a GENERATED
//! binary voxel residual field (reference shapes, random bits with falling +1 frequency per
//! level, a random MLP rescaled to plausible offsets).

use std::io::Cursor;

use bitvec::prelude::*;
use dlgs::chunks::rntc;
use dlgs::container::header::ResidualMode;
use dlgs::entropy::binary_bits;
use dlgs::model::ntc::{NtcConfig, NtcField};
use dlgs::model::residual::{AttrGroup, DeltaResidual, DeltaTarget};
use dlgs::{Canonical, Limits};
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::{EncoderConfig, FeatureCodec, GopCanonical, ResidualConfig, StreamEncoder};
use dlgs_testkit::synth::{synth_dynamic, synth_ntc, write_model, SynthModel, SynthSpec};
use dlgs_tests::{decode_all_stream, load};

const SCENE: &str = "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply";

fn model(mode: ResidualMode, gops: u32) -> SynthModel {
    let spec = SynthSpec {
        gops,
        residual_mode: mode,
        language: true,
        ..Default::default()
    };
    synth_dynamic(&load(SCENE), &spec).unwrap()
}

fn exact_cfg() -> EncoderConfig {
    EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: FeatureCodec::Exact,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn open(bytes: &[u8]) -> Decoder<Cursor<&[u8]>> {
    Decoder::new(Cursor::new(bytes), Limits::default()).unwrap()
}

fn bits_identical(a: &Canonical, b: &Canonical) -> bool {
    let body = dlgs::chunks::craw::canonical_body;
    body(a) == body(b)
}

fn opts() -> FrameOptions {
    FrameOptions {
        camera_center: [0.5, 0.3, 4.0],
        language: true,
    }
}

#[test]
fn binary_grids_code_within_one_percent_of_the_entropy_bound() {
    let mut rng = fastrand::Rng::with_seed(11);
    let n = 1usize << 17;
    let mut rows = Vec::new();
    for p in [0.5, 0.1, 0.01] {
        rows.push((
            format!("iid p={p}"),
            (0..n).map(|_| rng.f64() < p).collect::<BitVec<u64, Lsb0>>(),
        ));
    }
    // Spatial structure: a 512x256 dense grid, +1 inside blobs of a smooth field.
    let blobs: BitVec<u64, Lsb0> = (0..n)
        .map(|i| {
            let (x, y) = ((i % 512) as f64 / 40.0, (i / 512) as f64 / 30.0);
            (x.sin() * y.cos() + 0.3 * (2.1 * x + y).sin()) > 0.9
        })
        .collect();
    rows.push(("smooth blobs".into(), blobs));
    println!(
        "{:<14} {:>8} {:>12} {:>12} {:>8}",
        "grid", "p(+1)", "bound B", "coded B", "ratio"
    );
    for (name, bits) in rows {
        let ones = bits.count_ones() as u64;
        let p1 = binary_bits::probability_of_one(ones, n as u64);
        let words = binary_bits::encode(&bits, p1);
        let coded = words.len() as f64 * 4.0;
        let back = binary_bits::decode(words, n, p1).unwrap();
        assert_eq!(back, bits, "{name}: round trip");
        let bound = binary_bits::entropy_bits(ones, n as u64) / 8.0;
        println!(
            "{name:<14} {:>8.4} {bound:>12.1} {coded:>12.0} {:>8.4}",
            ones as f64 / n as f64,
            coded / bound
        );
        // 1 % of the bound plus the coder's flush (at most two 32-bit words).
        assert!(
            coded <= bound * 1.01 + 8.0,
            "{name}: {coded} B vs bound {bound} B"
        );
    }
}

#[test]
fn ntc_chunk_round_trips_every_bit_and_weight() {
    let m = model(ResidualMode::Sequential, 2);
    let field = m.residuals[1].as_ref().unwrap();
    let p = rntc::encode(field, &m.scene, 9).unwrap();
    let back = rntc::decode(&p, 0, &m.scene, &Limits::default()).unwrap();
    assert_eq!(&back, field);
    let segs = rntc::grid_report(field);
    println!("segment   bits      p(+1)   bound B  own-p B  grid-p B");
    for (i, s) in segs.iter().enumerate() {
        println!(
            "{i:>7} {:>7} {:>9.4} {:>9.0} {:>8} {:>9}",
            s.bits,
            s.ones as f64 / s.bits as f64,
            s.entropy_bits / 8.0,
            s.bytes_segment,
            s.bytes_grid
        );
    }
    let own: usize = segs.iter().map(|s| s.bytes_segment).sum();
    let grid: usize = segs.iter().map(|s| s.bytes_grid).sum();
    let bound: f64 = segs.iter().map(|s| s.entropy_bits).sum::<f64>() / 8.0;
    println!(
        "total: bound {bound:.0} B, per-level p {own} B, per-grid p {grid} B; RNTC payload {} B",
        p.len()
    );
    assert!((own.min(grid) as f64) <= bound * 1.01 + 8.0 * segs.len() as f64);
    // Levels with different +1 frequencies: per-level probabilities must win here.
    assert!(own < grid);
}

#[test]
fn constant_and_degenerate_grids_round_trip() {
    let m = model(ResidualMode::Sequential, 2);
    let mut f = m.residuals[1].clone().unwrap();
    f.planes[0].fill(false);
    f.planes[1].fill(true);
    f.gate.fill(true);
    let p = rntc::encode(&f, &m.scene, 3).unwrap();
    assert_eq!(
        rntc::decode(&p, 0, &m.scene, &Limits::default()).unwrap(),
        f
    );
    // NaN weights are refused by the encoder.
    f.mlp.b2[0] = f32::NAN;
    assert!(rntc::encode(&f, &m.scene, 3).is_err());
}

/// Every row of `rows` (from `residuals_at`) has the bits of the plain one-position evaluation.
fn assert_plain_rows(field: &NtcField, pos: &[[f32; 3]], rows: &[f32], what: &str) {
    let no = field.mlp.outputs;
    for (i, &p) in pos.iter().enumerate() {
        let plain = field.residual_at(p);
        let row = &rows[i * no..(i + 1) * no];
        assert!(
            plain
                .iter()
                .zip(row)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{what}: row {i} at {p:?}"
        );
    }
}

#[test]
fn ntc_residuals_are_the_plain_evaluation_on_any_thread_count() {
    let m = model(ResidualMode::Sequential, 2);
    let field: &NtcField = m.residuals[1].as_ref().unwrap();
    let pos = m.canonical.merged().positions;
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| field.residuals_at(&pos))
    };
    let (one, two) = (run(1), run(2));
    assert!(one
        .iter()
        .zip(&two)
        .all(|(a, b)| a.to_bits() == b.to_bits()));
    assert_plain_rows(field, &pos, &one, "");
    // Outside the normalisation box (and at NaN) there is no residual at all, not even the
    // output bias; on the box's faces there is one.
    let (lo, hi) = (field.bound_min, field.bound_max);
    for p in [
        [hi[0] * 2.0 - lo[0], lo[1], lo[2]],
        [lo[0], lo[1] - 1e-3, lo[2]],
        [f32::NAN, 0.0, 0.0],
    ] {
        assert!(field.residual_at(p).iter().all(|&v| v == 0.0), "{p:?}");
    }
    assert!(field.residual_at(lo).iter().any(|&v| v != 0.0));
    assert!(field.residual_at(hi).iter().any(|&v| v != 0.0));
}

/// The lane evaluation against the plain one on the layouts the reference's shapes do not
/// reach: 6 features per entry (byte tables instead of nibbles), dense levels and a dense gate
/// (small resolutions), positions on the box's faces and corners, and a count that leaves a
/// short last batch.
#[test]
fn ntc_lane_evaluation_matches_the_plain_one_on_every_table_layout() {
    let m = model(ResidualMode::Sequential, 1);
    for (features, gate_resolution) in [(6u8, 9u32), (3, 18), (8, 600)] {
        let config = NtcConfig {
            resolutions: vec![16, 32, 200],
            features,
            log2_table: 10,
            gate_resolution,
            gate_log2_table: 10,
        };
        let field = synth_ntc(&m.canonical, &mut fastrand::Rng::with_seed(5), 1.0, config);
        let (lo, hi) = (field.bound_min, field.bound_max);
        let mut pos: Vec<[f32; 3]> = m.canonical.merged().positions;
        pos.truncate(997);
        for corner in 0..8 {
            let pick = |a: usize| if corner >> a & 1 == 1 { hi[a] } else { lo[a] };
            pos.push([pick(0), pick(1), pick(2)]);
        }
        pos.push([(lo[0] + hi[0]) / 2.0, lo[1], hi[2]]);
        let rows = field.residuals_at(&pos);
        assert_plain_rows(
            &field,
            &pos,
            &rows,
            &format!("{features} features, gate {gate_resolution}"),
        );
        let nonzero = rows
            .chunks_exact(field.mlp.outputs)
            .filter(|row| row.iter().any(|&v| v != 0.0))
            .count();
        assert!(nonzero > pos.len() / 2, "the field must act: {nonzero}");
    }
}

#[test]
fn sequential_and_parallel_streams_decode_to_the_model_states() {
    for mode in [ResidualMode::Sequential, ResidualMode::Parallel] {
        let m = model(mode, 5);
        let want = m.canonical_states().unwrap();
        // The modes must differ: states really chain (or not).
        assert!(!bits_identical(&want[1], &want[2]));
        let bytes = write_model(&m, exact_cfg(), Vec::new()).unwrap();
        for threads in [1, 2] {
            let got = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut d = open(&bytes);
                    (0..5)
                        .map(|g| (*d.gop_canonical(g).unwrap()).clone())
                        .collect::<Vec<_>>()
                });
            for g in 0..5 {
                assert!(
                    bits_identical(&got[g], &want[g]),
                    "{mode:?} GOP {g}, {threads} threads"
                );
            }
        }
        let streamed = decode_all_stream(&bytes, Limits::default()).unwrap();
        assert!(streamed
            .iter()
            .zip(&want)
            .all(|(a, b)| bits_identical(a, b)));
    }
}

#[test]
fn seeking_in_any_order_gives_the_frames_of_playback() {
    for mode in [ResidualMode::Sequential, ResidualMode::Parallel] {
        let m = model(mode, 5);
        let bytes = write_model(&m, exact_cfg(), Vec::new()).unwrap();
        let mut rng = fastrand::Rng::with_seed(5);
        let times: Vec<f64> = (0..12).map(|_| rng.f64() * 9.99).collect();
        let mut play = open(&bytes);
        let mut sorted = times.clone();
        sorted.sort_by(|a, b| a.total_cmp(b));
        let want: Vec<(f64, Vec<f32>)> = sorted
            .iter()
            .map(|&t| {
                let f = play.frame_at(t, &opts()).unwrap();
                (
                    t,
                    dlgs::chunks::craw::canonical_body(&Canonical {
                        statics: f.statics().clone(),
                        dynamics: f.dynamics,
                    })
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                    .collect(),
                )
            })
            .collect();
        for (cache, gop_cache) in [(0, 1), (1, 1), (4, 1), (0, 3), (4, 5)] {
            let mut d = open(&bytes);
            d.set_state_cache(cache);
            d.set_gop_cache(gop_cache);
            for &t in &times {
                let f = d.seek(t, &opts()).unwrap();
                let body = dlgs::chunks::craw::canonical_body(&Canonical {
                    statics: f.statics().clone(),
                    dynamics: f.dynamics,
                });
                let w = &want.iter().find(|w| w.0 == t).unwrap().1;
                let got: Vec<f32> = body
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                    .collect();
                assert!(
                    got.iter().zip(w).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{mode:?} t = {t}, state cache {cache}, GOP cache {gop_cache}"
                );
            }
        }
    }
}

#[test]
fn a_kept_gop_is_reused_and_the_least_recently_used_one_dropped() {
    // 5 GOPs of 2 s; GOP g holds [2g, 2g + 2).
    let m = model(ResidualMode::Parallel, 5);
    let bytes = write_model(&m, exact_cfg(), Vec::new()).unwrap();
    let mut d = open(&bytes);
    d.set_gop_cache(3);
    let first: Vec<_> = [1.0, 3.0, 5.0, 7.0]
        .iter()
        .map(|&t| d.seek(t, &opts()).unwrap().gop)
        .collect();
    assert_eq!(d.cached_gops(), vec![1, 2, 3]);
    // Back into GOP 1: the kept decode, not a new one.
    let again = d.seek(3.5, &opts()).unwrap().gop;
    assert!(std::sync::Arc::ptr_eq(&again, &first[1]));
    // GOP 0 was dropped: decoded anew, and GOP 2 (least recently used) makes room.
    let zero = d.seek(0.5, &opts()).unwrap().gop;
    assert!(!std::sync::Arc::ptr_eq(&zero, &first[0]));
    assert_eq!(d.cached_gops(), vec![0, 1, 3]);
    // The default keeps only the GOP last used.
    let mut d = open(&bytes);
    d.seek(1.0, &opts()).unwrap();
    d.seek(3.0, &opts()).unwrap();
    assert_eq!(d.cached_gops(), vec![1]);
}

#[test]
fn a_five_gop_stream_plays_every_frame_start_to_end() {
    let m = model(ResidualMode::Sequential, 5);
    let bytes = write_model(&m, exact_cfg(), Vec::new()).unwrap();
    let mut d = open(&bytes);
    let mut frame = dlgs::Gaussians::default();
    let mut gops_seen = Vec::new();
    for f in 0..m.scene.frame_count {
        let t = (f as f64 + 0.5) / 30.0;
        let fr = d.frame_at_reusing(t, &opts(), frame).unwrap();
        assert_eq!(fr.time.frame, f);
        assert_eq!(fr.dynamics.len(), m.scene.n_dynamic as usize);
        assert!(fr
            .dynamics
            .positions
            .iter()
            .flatten()
            .all(|v| v.is_finite()));
        if gops_seen.last() != Some(&fr.time.gop) {
            gops_seen.push(fr.time.gop);
        }
        frame = fr.dynamics;
    }
    assert_eq!(gops_seen, vec![0, 1, 2, 3, 4]);
}

#[test]
fn explicit_residuals_are_exact_or_within_their_declared_bounds() {
    // An intra model whose GOPs differ (the residual model's states, stored in full)
    // re-encoded as a sequential stream with explicit residuals.
    let m = model(ResidualMode::Sequential, 3);
    let states = m.canonical_states().unwrap();
    let mut scene = m.scene.clone();
    scene.residual_mode = ResidualMode::Sequential;
    let bounds = [
        (AttrGroup::Position, 1e-4f32),
        (AttrGroup::ShDc, 2e-3),
        (AttrGroup::Lang, 1e-3),
    ];
    for exact in [true, false] {
        let mut cfg = exact_cfg();
        if !exact {
            cfg.dynamic.residual = ResidualConfig {
                groups: AttrGroup::ALL
                    .into_iter()
                    .map(|g| match bounds.iter().find(|b| b.0 == g) {
                        Some(&(_, b)) => (g, DeltaTarget::Bound(b)),
                        None => (g, DeltaTarget::Exact),
                    })
                    .collect(),
                follow_quantisation: false,
            };
        }
        let mut enc = StreamEncoder::new(Vec::new(), scene.clone(), cfg).unwrap();
        for (s, d) in states.iter().zip(&m.gops) {
            enc.push(GopCanonical::State(s), Some(d)).unwrap();
        }
        let bytes = enc.finish().unwrap();
        let mut dec = open(&bytes);
        for (g, want) in states.iter().enumerate() {
            let got = dec.gop_canonical(g as u32).unwrap();
            assert_eq!(
                dec.gop(g as u32).unwrap().source.as_str(),
                if g == 0 { "CRAW" } else { "RDLT" }
            );
            if exact {
                assert!(bits_identical(&got, want), "GOP {g}");
                continue;
            }
            for &(group, bound) in &bounds {
                for (a, b) in [
                    (&got.statics, &want.statics),
                    (&got.dynamics, &want.dynamics),
                ] {
                    for i in 0..a.len() {
                        for (x, y) in group.values(a, i).iter().zip(group.values(b, i)) {
                            assert!(
                                (x - y).abs() <= bound,
                                "GOP {g} {}: {x} vs {y}",
                                group.name()
                            );
                        }
                    }
                }
            }
            // Unbounded groups stay exact even though earlier GOPs were lossy elsewhere.
            for i in 0..got.statics.len() {
                assert_eq!(got.statics.rotations[i], want.statics.rotations[i]);
            }
        }
        println!(
            "explicit residuals, exact = {exact}: {} bytes for 3 GOPs",
            bytes.len()
        );
    }
}

#[test]
fn residual_encoder_refuses_nan_and_impossible_bounds() {
    let m = model(ResidualMode::Sequential, 2);
    let base = m.canonical.clone();
    let mut t = base.clone();
    t.statics.positions[3][1] = f32::NAN;
    let all = ResidualConfig::default().groups;
    let e = DeltaResidual::compute(&t, &base, &all).unwrap_err();
    assert!(e.to_string().contains("position"), "{e}");
    let mut t = base.clone();
    t.statics.positions[0][0] += 1.0;
    let tiny = [(AttrGroup::Position, DeltaTarget::Bound(1e-12))];
    assert!(DeltaResidual::compute(&t, &base, &tiny).is_err());
    assert!(DeltaResidual::compute(
        &t,
        &base,
        &[(AttrGroup::Position, DeltaTarget::Bound(-1.0))]
    )
    .is_err());
}

#[test]
fn damaged_residual_files_fail_cleanly_or_decode_identically() {
    let m = model(ResidualMode::Parallel, 2);
    let bytes = write_model(&m, exact_cfg(), Vec::new()).unwrap();
    let want = m.canonical_states().unwrap();
    let mut errors = 0;
    let step = (bytes.len() / 400).max(1);
    for at in (0..bytes.len()).step_by(step) {
        let mut b = bytes.clone();
        b[at] ^= 0x21;
        match Decoder::new(Cursor::new(&b[..]), Limits::default())
            .and_then(|mut d| d.gop_canonical(1).map(|c| (*c).clone()))
        {
            Ok(c) => assert!(bits_identical(&c, &want[1]), "flip at {at} changed GOP 1"),
            Err(_) => errors += 1,
        }
    }
    assert!(errors > 0);
    // The residual field alone: truncations give typed errors.
    let f = synth_ntc(
        &m.canonical,
        &mut fastrand::Rng::with_seed(3),
        1.0,
        Default::default(),
    );
    let p = rntc::encode(&f, &m.scene, 3).unwrap();
    for cut in (0..p.len()).step_by(997) {
        assert!(rntc::decode(&p[..cut], 0, &m.scene, &Limits::default()).is_err());
    }
}
