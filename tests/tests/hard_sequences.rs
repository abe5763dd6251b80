//! Hard per-frame sequences (issue 65): REAL Gaussians (the supersplat fruit scene) moved by
//! SYNTHETIC motion of up to 10 neighbour spacings per frame, each frame shuffled on its own,
//! some with Gaussians that come and go. Matches are checked against the known identities:
//! none may be wrong.

use dlgs::chunks::craw::RawCodec;
use dlgs::container::header::ResidualMode;
use dlgs::model::lifetimes::HIDDEN_OPACITY;
use dlgs::Gaussians;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::sequence::{self, match_joint, SequenceSettings};
use dlgs_encoder::{CanonicalCodec, EncoderConfig, FeatureCodec};
use dlgs_testkit::motion::{hard_sequence, peak_speed, HardSequence, Motion, MotionSpec};
use dlgs_tests::data;

fn fruit() -> Gaussians {
    let p = data("ply/supersplat_fruit_drops_minimal_4721_sh3.ply");
    dlgs::interop::read_splat_file(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn sequence_of(motion: Motion, frames: usize, births: f32) -> HardSequence {
    noisy_sequence_of(motion, frames, births, 0.0)
}

fn noisy_sequence_of(motion: Motion, frames: usize, births: f32, independent: f32) -> HardSequence {
    hard_sequence(
        &fruit(),
        &MotionSpec {
            motion,
            frames,
            speed: 10.0,
            period: 30.0,
            births,
            independent,
            seed: 5,
        },
    )
}

/// Two source Gaussians no file could tell apart (the fruit scene holds exact duplicates).
fn same_source(scene: &Gaussians, i: u32, j: u32) -> bool {
    let (i, j) = (i as usize, j as usize);
    scene.positions[i] == scene.positions[j]
        && scene.log_scales[i] == scene.log_scales[j]
        && scene.opacity[i] == scene.opacity[j]
        && scene.sh_of(i)[..3] == scene.sh_of(j)[..3]
}

/// Every pair of consecutive frames matched from scratch (no velocity known): no match is
/// wrong (a swap of exact duplicates is not), nearly all Gaussians are matched, and the motion
/// really is several spacings.
fn check_pairs(seq: &HardSequence) {
    let scene = fruit();
    assert!(peak_speed(seq) > 5.0, "peak speed {}", peak_speed(seq));
    for t in 1..seq.frames.len() {
        let (a, b) = (&seq.frames[t - 1], &seq.frames[t]);
        let m = match_joint(a, &a.positions, b);
        let mut wrong = 0;
        for (j, p) in m.prev_of.iter().enumerate() {
            if let Some(i) = p {
                let (x, y) = (seq.ids[t - 1][*i as usize], seq.ids[t][j]);
                if x != y && !same_source(&scene, x, y) {
                    eprintln!(
                        "frames {} -> {t}: source {x} matched to {y}: {:?} {:?}",
                        t - 1,
                        scene.positions[x as usize],
                        scene.positions[y as usize]
                    );
                    wrong += 1;
                }
            }
        }
        assert_eq!(wrong, 0, "frames {} -> {t}: {wrong} wrong matches", t - 1);
        let common = seq.ids[t]
            .iter()
            .filter(|i| seq.ids[t - 1].contains(i))
            .count();
        assert!(
            m.matched as f64 >= 0.99 * common as f64,
            "frames {} -> {t}: {} of {common} matched",
            t - 1,
            m.matched
        );
    }
}

#[test]
fn articulated_motion_of_ten_spacings_is_matched_without_a_wrong_match() {
    check_pairs(&sequence_of(Motion::Articulated, 8, 0.0));
}

#[test]
fn rigid_motion_with_births_and_deaths_is_matched_without_a_wrong_match() {
    let seq = sequence_of(Motion::Rigid, 8, 0.2);
    let counts: Vec<usize> = seq.frames.iter().map(Gaussians::len).collect();
    assert!(counts.iter().min() != counts.iter().max(), "{counts:?}");
    check_pairs(&seq);
}

/// A sequence with changing counts encodes, decodes, and every frame shows exactly as many
/// Gaussians as its source (the others hidden by `LIFE`), near the source positions.
#[test]
fn a_sequence_with_changing_counts_round_trips_frame_by_frame() {
    let seq = sequence_of(Motion::Rigid, 12, 0.2);
    let s = SequenceSettings {
        gop_length: 6,
        key_interval: 2,
        residual_mode: ResidualMode::Intra,
        ..SequenceSettings::default()
    };
    let (model, report) = sequence::build(seq.frames.clone(), &s, &mut |_, _, _| {}).unwrap();
    assert!(report.cuts.is_empty());
    assert!(report.partial > 0);
    let mut cfg = EncoderConfig::default();
    cfg.coding.codec = CanonicalCodec::Raw;
    cfg.coding.raw_codec = RawCodec::Zstd;
    cfg.dynamic.features = FeatureCodec::Exact;
    let bytes = sequence::write(&model, cfg, Vec::new()).unwrap();
    assert!(bytes.windows(4).any(|w| w == b"LIFE"));
    let mut dec = Decoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap();
    let opts = FrameOptions {
        camera_center: [0.0, -5.0, 0.0],
        language: false,
    };
    for (t, src) in seq.frames.iter().enumerate() {
        let got = dec.frame_at_merged(t as f64 / 30.0, &opts).unwrap();
        let shown: Vec<usize> = (0..got.len())
            .filter(|&i| got.opacity[i] > HIDDEN_OPACITY)
            .collect();
        assert_eq!(shown.len(), src.len(), "frame {t}");
        // Every shown Gaussian lies near a source Gaussian (within two spacings).
        let tree_pts = &src.positions;
        let mut far = 0;
        for &i in &shown {
            let p = got.positions[i];
            let near = tree_pts.iter().any(|q| {
                (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f32>() <= (2.0 * seq.spacing).powi(2)
            });
            if !near {
                far += 1;
            }
        }
        assert!(
            far * 100 <= shown.len(),
            "frame {t}: {far} of {} far",
            shown.len()
        );
    }
}

/// Frames with no correspondence at all (each an independent reconstruction: every Gaussian
/// perturbed anew, some left out) are not matched wrongly: the pairs are reported without a
/// consistent match, and the fallback carries one set of Gaussians per GOP by the fitted motion
/// (cuts only at a GOP's first frame), which decodes near the true (noise-free) surface.
#[test]
fn frames_without_correspondence_fall_back_to_a_set_carried_by_fitted_motion() {
    let frames = 12;
    let noisy = noisy_sequence_of(Motion::Articulated, frames, 0.0, 0.5);
    let clean = sequence_of(Motion::Articulated, frames, 0.0);
    let s = SequenceSettings {
        gop_length: 6,
        key_interval: 2,
        ..SequenceSettings::default()
    };
    let (model, report) = sequence::build(noisy.frames.clone(), &s, &mut |_, _, _| {}).unwrap();
    assert!(
        report.resampled.len() >= 6,
        "resampled {:?}, cuts {:?}",
        report.resampled,
        report.cuts
    );
    assert!(report.resampled.iter().all(|t| t % 6 != 0));
    assert!(report.cuts.iter().all(|t| t % 6 == 0), "{:?}", report.cuts);
    for p in &report.pairs {
        assert!(p.confident_share < 0.9 || !(p.resampled || p.cut));
    }
    if !report.cuts.is_empty() {
        assert_eq!(model.scene.residual_mode, ResidualMode::Intra);
    }
    // One set per GOP at most: never a slot per Gaussian of every frame.
    assert!(
        report.slots <= 2 * report.max_count,
        "{} slots",
        report.slots
    );
    let mut cfg = EncoderConfig::default();
    cfg.coding.codec = CanonicalCodec::Raw;
    cfg.coding.raw_codec = RawCodec::Zstd;
    cfg.dynamic.features = FeatureCodec::Exact;
    let bytes = sequence::write(&model, cfg, Vec::new()).unwrap();
    let mut dec = Decoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap();
    let opts = FrameOptions {
        camera_center: [0.0, -5.0, 0.0],
        language: false,
    };
    for (t, truth) in clean.frames.iter().enumerate() {
        let got = dec.frame_at_merged(t as f64 / 30.0, &opts).unwrap();
        let shown: Vec<usize> = (0..got.len())
            .filter(|&i| got.opacity[i] > HIDDEN_OPACITY)
            .collect();
        // About as many Gaussians as a frame has (not every frame's set at once).
        assert!(
            shown.len() <= report.max_count && shown.len() >= report.min_count / 2,
            "frame {t}: {} shown",
            shown.len()
        );
        // Nearly every shown Gaussian (99 %) lies near the true surface: within three spacings of a
        // noise-free Gaussian (the frames' own noise is half a spacing per axis).
        let reach = (3.0 * noisy.spacing).powi(2);
        let far = shown
            .iter()
            .filter(|&&i| {
                let p = got.positions[i];
                !truth
                    .positions
                    .iter()
                    .any(|q| (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f32>() <= reach)
            })
            .count();
        assert!(
            far * 100 <= shown.len(),
            "frame {t}: {far} of {} far from the surface",
            shown.len()
        );
    }
}
