//! Real motion: per-frame splat files (the real 200-frame PlayCanvas SOG sequence) matched
//! frame to frame, fitted and written as a dynamic .dlgs.

use dlgs::chunks::craw::RawCodec;
use dlgs::container::header::ResidualMode;
use dlgs::Gaussians;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::sequence::{self, match_joint, SequenceSettings};
use dlgs_encoder::{CanonicalCodec, EncoderConfig, FeatureCodec};
use dlgs_tests::data;

fn wave(frame: usize) -> Gaussians {
    let p = data(&format!(
        "sequence/playcanvas_wave_200f/wave_{frame:04}.sog"
    ));
    dlgs::interop::read_splat_file(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Which Gaussian of `a` each Gaussian of `b` continues (all matched).
fn match_frames(a: &Gaussians, b: &Gaussians) -> (Vec<u32>, usize) {
    let m = match_joint(a, &a.positions, b);
    let prev: Vec<u32> = m
        .prev_of
        .iter()
        .map(|p| p.expect("every Gaussian matched"))
        .collect();
    (prev, m.confident)
}

fn shuffled(g: &Gaussians, seed: u64) -> (Gaussians, Vec<usize>) {
    let mut perm: Vec<usize> = (0..g.len()).collect();
    fastrand::Rng::with_seed(seed).shuffle(&mut perm);
    let mut out = Gaussians::new(g.sh_degree, g.lang_width);
    for &i in &perm {
        out.push_from(g, i);
    }
    (out, perm)
}

/// Matching real consecutive frames is confident everywhere, and a known shuffle of the second
/// frame moves the matches by exactly that shuffle.
#[test]
fn a_known_shuffle_of_real_frames_is_recovered() {
    let (a, b) = (wave(1), wave(2));
    let (plain, confident) = match_frames(&a, &b);
    assert_eq!(confident, a.len(), "every match confident on real frames");
    let (b2, perm) = shuffled(&b, 11);
    let (m, _) = match_frames(&a, &b2);
    for (j, &p) in perm.iter().enumerate() {
        assert_eq!(m[j], plain[p], "shuffled Gaussian {j}");
    }
    // A frame against a shuffle of itself: the shuffle, exactly.
    let (a2, perm) = shuffled(&a, 12);
    let (m, _) = match_frames(&a, &a2);
    let want: Vec<u32> = perm.iter().map(|&i| i as u32).collect();
    assert_eq!(m, want);
}

fn settings() -> SequenceSettings {
    SequenceSettings {
        gop_length: 10,
        key_interval: 5,
        residual_mode: ResidualMode::Intra,
        ..SequenceSettings::default()
    }
}

fn exact_config() -> EncoderConfig {
    let mut cfg = EncoderConfig::default();
    cfg.coding.codec = CanonicalCodec::Raw;
    cfg.coding.raw_codec = RawCodec::Zstd;
    cfg.dynamic.features = FeatureCodec::Exact;
    cfg
}

/// A 21-frame real clip (frames shuffled independently, as SOG files are): fitted, written
/// losslessly, decoded at every frame time within 2e-3 of the source positions (the scene is
/// 6 units wide), the same bytes on 1 and 2 threads; a time between two frames decodes too.
#[test]
fn a_short_real_clip_is_fitted_deterministically() {
    let bytes = fit_and_check_clip(&settings());
    assert_eq!((count(&bytes, b"CRAW"), count(&bytes, b"RNTC")), (3, 0));
}

/// The same with the default residuals: GOPs 1 and 2 carry fitted binary voxel fields
/// (`RNTC`) from the decoder's previous state, and their time features are refitted to what
/// the fields give, so frames are as close as with full canonical states.
#[test]
fn a_short_real_clip_with_residual_fields_is_fitted_deterministically() {
    let mut s = settings();
    s.residual_mode = SequenceSettings::default().residual_mode;
    s.residual_field =
        SequenceSettings::default()
            .residual_field
            .map(|f| sequence::NtcFitSettings {
                iterations: 150,
                ..f
            });
    assert!(s.residual_field.is_some());
    let bytes = fit_and_check_clip(&s);
    // GOP 0 in full, GOPs 1 and 2 as fields.
    assert_eq!((count(&bytes, b"CRAW"), count(&bytes, b"RNTC")), (1, 2));
}

fn count(hay: &[u8], needle: &[u8]) -> usize {
    hay.windows(needle.len()).filter(|w| w == &needle).count()
}

fn fit_and_check_clip(s: &SequenceSettings) -> Vec<u8> {
    let frames: Vec<Gaussians> = (1..=21).map(|f| shuffled(&wave(f), f as u64).0).collect();
    let encode = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (model, report) = sequence::build(frames.clone(), s, &mut |_, _, _| {}).unwrap();
            let bytes = sequence::write(&model, exact_config(), Vec::new()).unwrap();
            (bytes, report)
        })
    };
    let (bytes, report) = encode(2);
    assert_eq!(encode(1).0, bytes, "same file on 1 and 2 threads");
    assert_eq!((report.frames, report.n_dynamic), (21, 4225));
    assert!(report.pairs.iter().all(|p| p.confident_share == 1.0));
    for g in &report.gops {
        assert!(g.position_rms < 1e-4, "{g:?}");
        assert!(g.shared_energy_kept > 0.999, "{g:?}");
    }
    // Decoded frames against the source frames. The file stores the dynamic Gaussians in its
    // own order (a k-d layout on the feature tiles): which source Gaussian each one is comes
    // from frame 0 once, then follows the tracks the test builds frame by frame itself.
    let mut dec =
        Decoder::new(std::io::Cursor::new(bytes.clone()), dlgs::Limits::default()).unwrap();
    let opts = FrameOptions {
        camera_center: [0.0, -5.0, 0.0],
        language: false,
    };
    let got0 = dec.frame_at(0.0, &opts).unwrap();
    let (stored, _) = match_frames(&frames[0], &got0.dynamics);
    let mut track = frames[0].clone();
    let mut worst = 0.0f32;
    for (t, f) in frames.iter().enumerate() {
        if t > 0 {
            let (m, _) = match_frames(&track, f);
            let mut next = track.clone();
            for (j, &p) in m.iter().enumerate() {
                next.positions[p as usize] = f.positions[j];
            }
            track = next;
        }
        let got = dec.frame_at(t as f64 / 30.0, &opts).unwrap();
        for (j, a) in got.dynamics.positions.iter().enumerate() {
            let b = track.positions[stored[j] as usize];
            for k in 0..3 {
                worst = worst.max((a[k] - b[k]).abs());
            }
        }
    }
    assert!(worst < 2e-3, "worst position error {worst}");
    // Between frames 3 and 4.
    let mid = dec.frame_at(3.5 / 30.0, &opts).unwrap();
    assert_eq!(mid.dynamics.len(), 4225);
    bytes
}

/// Bad input is refused with the frame named; frames that cannot be matched go on as the
/// tracks carried by the fitted motion (reported as resampled), or start new tracks (with the
/// cut fallback, reported as a cut), or, with cuts not allowed, are refused.
#[test]
fn bad_sequences_are_refused_naming_the_frame() {
    let s = settings();
    let mut frames: Vec<Gaussians> = (1..=4).map(wave).collect();
    frames[3].positions[17][1] = f32::NAN;
    let e = sequence::build(frames, &s, &mut |_, _, _| {}).unwrap_err();
    assert!(e.to_string().contains("frame 3"), "{e}");
    assert_eq!(e.name(), "InvalidInput");
    // Frames with no consistent correspondence (each Gaussian moved by its own large amount).
    let a = wave(1);
    let mut b = a.clone();
    for i in 0..b.len() {
        b.positions[i][0] += 0.5 * (i % 7) as f32;
    }
    let strict = SequenceSettings {
        allow_cuts: false,
        ..s.clone()
    };
    let e = sequence::build(vec![a.clone(), b.clone()], &strict, &mut |_, _, _| {}).unwrap_err();
    assert!(e.to_string().contains("match confidently"), "{e}");
    let (model, report) =
        sequence::build(vec![a.clone(), b.clone()], &s, &mut |_, _, _| {}).unwrap();
    assert_eq!(report.resampled, vec![1]);
    assert!(report.cuts.is_empty());
    assert_eq!(report.slots, 4225, "the tracks went on");
    assert!(report.pairs[0].resampled && !report.pairs[0].cut);
    assert_eq!(model.scene.residual_mode, s.residual_mode);
    let cut = SequenceSettings {
        fallback: sequence::Fallback::Cut,
        ..s.clone()
    };
    let (model, report) = sequence::build(vec![a, b], &cut, &mut |_, _, _| {}).unwrap();
    assert_eq!(report.cuts, vec![1]);
    assert!(report.resampled.is_empty());
    assert_eq!(report.slots, 2 * 4225, "every track ended at the cut");
    assert_eq!(model.scene.n_dynamic, 2 * 4225);
    assert_eq!(model.scene.residual_mode, ResidualMode::Intra);
    let e = sequence::build(vec![wave(1)], &s, &mut |_, _, _| {}).unwrap_err();
    assert!(e.to_string().contains("at least 2 frames"), "{e}");
}

/// A Gaussian fewer in one frame is a death (and its slot is hidden from then on), not a
/// refusal.
#[test]
fn a_frame_with_a_gaussian_fewer_is_a_death() {
    let mut frames: Vec<Gaussians> = (1..=4).map(wave).collect();
    let mut short = Gaussians::new(0, 0);
    for i in 1..frames[2].len() {
        short.push_from(&frames[2], i);
    }
    frames[2] = short;
    // Frame 3 without the Gaussian that continues the one frame 2 lost (wave 3's first).
    let (m, _) = match_frames(&wave(3), &wave(4));
    let mut g = Gaussians::new(0, 0);
    for (j, &p) in m.iter().enumerate() {
        if p != 0 {
            g.push_from(&wave(4), j);
        }
    }
    frames[3] = g;
    let (_, report) = sequence::build(frames, &settings(), &mut |_, _, _| {}).unwrap();
    assert_eq!((report.min_count, report.max_count), (4224, 4225));
    assert_eq!(report.pairs[1].deaths, 1, "{:?}", report.pairs[1]);
    assert_eq!(report.pairs[1].births, 0);
    assert_eq!(report.slots, 4225);
    assert_eq!(report.partial, 1);
}
