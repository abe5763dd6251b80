//! Dynamic Gaussians end to end: time features through 12-bit HEVC (libx265), the decoders,
//! frames at and between frame times.
//!
//! NOTE: no real trained DLGStream model exists in this repository's data. Every dynamic model
//! here is built by `dlgs_testkit::synth` from a REAL canonical scene in ../shared/data (a
//! compact subset made dynamic, smooth synthetic time features, calibrated random decoders).

use std::io::Cursor;

use dlgs::chunks::mlpw::WeightType;
use dlgs::chunks::tfea::{self, Tiling};
use dlgs::container::header::DeformModel;
use dlgs::Limits;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::{EncoderConfig, FeatureCodec, HevcSettings};
use dlgs_render::{metrics, orbit_cameras, render, Camera, OrbitSpec, RenderOptions};
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthModel, SynthSpec};
use dlgs_tests::load;
use dlgs_tests::reference_deform::deform_reference;

const SCENE: &str = "ply/gs3d-fork_lod2_tile_0_6831_sh3.ply";

fn model(language: bool, gops: u32) -> SynthModel {
    let spec = SynthSpec {
        language,
        gops,
        ..Default::default()
    };
    synth_dynamic(&load(SCENE), &spec).unwrap()
}

fn encode(m: &SynthModel, features: FeatureCodec) -> Vec<u8> {
    let cfg = EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features,
            ..Default::default()
        },
        ..Default::default()
    };
    write_model(m, cfg, Vec::new()).unwrap()
}

fn exact(m: &SynthModel) -> Vec<u8> {
    encode(m, FeatureCodec::Exact)
}

fn open(bytes: &[u8]) -> Decoder<Cursor<&[u8]>> {
    Decoder::new(Cursor::new(bytes), Limits::default()).unwrap()
}

fn camera(m: &SynthModel) -> Camera {
    let spec = OrbitSpec {
        width: 320,
        height: 240,
        ..Default::default()
    };
    orbit_cameras(&m.canonical.merged(), &spec).remove(0)
}

fn opts(cam: &Camera, language: bool) -> FrameOptions {
    FrameOptions {
        camera_center: cam.position.to_array(),
        language,
    }
}

fn render_at(dec: &mut Decoder<Cursor<&[u8]>>, t: f64, cam: &Camera) -> Vec<f32> {
    let f = dec.frame_at(t, &opts(cam, false)).unwrap();
    render(&f.merged(), cam, &RenderOptions::default())
        .unwrap()
        .color
}

#[test]
fn decoder_matches_an_independent_f64_implementation() {
    let m = model(true, 2);
    let bytes = exact(&m);
    let mut dec = open(&bytes);
    let cam = camera(&m);
    for (t, gop) in [(0.0, 0usize), (0.123, 0), (1.7, 0), (2.0, 1), (3.95, 1)] {
        let f = dec.frame_at(t, &opts(&cam, true)).unwrap();
        let tp = f.time;
        assert_eq!(tp.gop as usize, gop);
        let want = deform_reference(
            &m.canonical.dynamics,
            &m.gops[gop],
            tp.key,
            tp.delta as f64,
            cam.position.to_array(),
            true,
        );
        let got = &f.dynamics;
        let worst = |a: &[f32], b: &[f32]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0f32, f32::max)
        };
        let flat3 = |v: &[[f32; 3]]| v.concat();
        let flat4 = |v: &[[f32; 4]]| v.concat();
        let e = [
            worst(&flat3(&got.positions), &flat3(&want.positions)),
            worst(&flat4(&got.rotations), &flat4(&want.rotations)),
            worst(&flat3(&got.log_scales), &flat3(&want.log_scales)),
            worst(&got.opacity, &want.opacity),
            worst(&got.lang_opacity, &want.lang_opacity),
            worst(&got.sh, &want.sh),
            worst(&got.lang, &want.lang),
        ];
        println!("t {t}: max abs error pos/rot/scale/opa/langopa/sh/lang {e:?}");
        assert!(e.iter().all(|&x| x < 2e-4), "t {t}: {e:?}");
        // Static Gaussians are untouched.
        assert_eq!(f.statics(), &m.canonical.statics);
    }
}

#[test]
fn exact_features_round_trip_bit_for_bit() {
    let m = model(true, 2);
    let bytes = exact(&m);
    let mut dec = open(&bytes);
    for g in 0..2 {
        let gop = dec.gop(g).unwrap();
        let d = gop.dynamic().unwrap().unwrap();
        assert_eq!(d.features, m.gops[g as usize].features);
        assert_eq!(d.mlps, m.gops[g as usize].mlps);
        assert_eq!(*gop.canonical, m.canonical);
    }
}

fn feature_error_table(m: &SynthModel, bytes: &[u8]) -> (f32, f32) {
    let mut dec = open(bytes);
    let d = dec.gop(0).unwrap();
    let got = d.dynamic().unwrap().unwrap().features;
    let want = &m.gops[0].features;
    let ranges = tfea::ranges(want, false);
    let (mut worst_max, mut worst_mean) = (0f32, 0f32);
    for c in 0..16 {
        let errs: Vec<f32> = (0..want.n)
            .flat_map(|i| (0..want.keys).map(move |k| (i, k)))
            .map(|(i, k)| (got.at(i, k)[c] - want.at(i, k)[c]).abs())
            .collect();
        let max = errs.iter().cloned().fold(0f32, f32::max);
        let mean = errs.iter().sum::<f32>() / errs.len() as f32;
        let span = ranges[c].1 - ranges[c].0;
        println!(
            "channel {c:2}: range {span:.4}  max error {max:.6} ({:.4} % of range)  mean error {mean:.7}",
            100.0 * max / span
        );
        worst_max = worst_max.max(max / span);
        worst_mean = worst_mean.max(mean / span);
    }
    (worst_max, worst_mean)
}

#[test]
fn hevc_lossless_is_exactly_the_12_bit_quantisation() {
    let m = model(false, 1);
    let bytes = encode(
        &m,
        FeatureCodec::Hevc(HevcSettings {
            lossless: true,
            preset: "ultrafast".into(),
            ..Default::default()
        }),
    );
    let mut dec = open(&bytes);
    let gop = dec.gop(0).unwrap();
    let got = gop.dynamic().unwrap().unwrap().features;
    let f = &m.gops[0].features;
    let t = Tiling::for_count(f.n, f.keys, f.channels);
    let r = tfea::ranges(f, false);
    let want = tfea::untile(&tfea::tile(f, &t, &r), &t, &r);
    assert_eq!(
        &got, &want,
        "lossless HEVC must reproduce the 12-bit samples"
    );
    let (max, _) = feature_error_table(&m, &bytes);
    assert!(max <= 0.5 / 4095.0 + 1e-6, "quantisation error {max}");
}

#[test]
fn hevc_crf6_feature_error_per_channel() {
    let m = model(false, 1);
    let bytes = encode(&m, FeatureCodec::Hevc(HevcSettings::default()));
    let (max, mean) = feature_error_table(&m, &bytes);
    println!(
        "crf 6: worst channel max error {:.4} % of range, worst mean {:.5} %",
        100.0 * max,
        100.0 * mean
    );
    // Measured on this scene (Morton-ordered tiles, no PLAS sort): mean ≈ 0.5 % of the range
    // (about 20 12-bit steps), max ≈ 4.6 %. The bounds leave room for x265 versions.
    assert!(mean < 0.01, "mean error {mean}");
    assert!(max < 0.10, "max error {max}");
}

#[test]
fn rendered_psnr_at_and_between_frame_times() {
    let m = model(false, 1);
    let reference = exact(&m);
    let coded = encode(&m, FeatureCodec::Hevc(HevcSettings::default()));
    let (mut a, mut b) = (open(&reference), open(&coded));
    let cam = camera(&m);
    let mut worst = f64::INFINITY;
    for (label, t) in [
        ("frame 0", 0.0),
        ("frame 7", 7.0 / 30.0),
        ("frame 35", 35.0 / 30.0),
        ("frame 59", 59.0 / 30.0),
        ("between 3|4", 3.5 / 30.0),
        ("between 12|13", 12.37 / 30.0),
        ("between 58|59", 58.9 / 30.0),
        ("end", 2.0),
    ] {
        let p = metrics::psnr(&render_at(&mut a, t, &cam), &render_at(&mut b, t, &cam));
        println!("{label:14} t = {t:.4} s: PSNR decoded(crf 6) vs exact {p:.2} dB");
        worst = worst.min(p);
    }
    assert!(worst > 40.0, "worst PSNR {worst}");
}

#[test]
fn motion_is_visible_and_smooth() {
    let m = model(false, 1);
    let bytes = exact(&m);
    let mut dec = open(&bytes);
    let cam = camera(&m);
    let f0 = render_at(&mut dec, 0.0, &cam);
    let f1 = render_at(&mut dec, 1.0, &cam);
    let p01 = metrics::psnr(&f0, &f1);
    // Consecutive display frames at 60 FPS from a 30 FPS stream differ much less.
    let g0 = render_at(&mut dec, 1.0 - 1.0 / 60.0, &cam);
    let p_step = metrics::psnr(&g0, &f1);
    println!("t=0 vs t=1 s: {p01:.2} dB; 1/60 s apart: {p_step:.2} dB");
    assert!(f1.iter().all(|v| v.is_finite()));
    assert!(p01 < 35.0, "motion not visible: {p01} dB");
    assert!(p_step > p01 + 5.0, "motion not smooth: {p_step} vs {p01}");
}

/// The paper's Table 5 setting: keys only every 2nd / 3rd key time (interval 20 / 30 instead
/// of 10), frames between decoded by interpolation, compared with the full model.
#[test]
fn sparser_keys_interpolate() {
    let full = model(false, 1);
    let cam = camera(&full);
    let full_bytes = exact(&full);
    let mut full_dec = open(&full_bytes);
    for (every, keys) in [(2usize, vec![0, 2, 4, 6]), (3, vec![0, 3, 6])] {
        let mut sparse = full.clone();
        sparse.scene.key_interval *= every as u32;
        for g in &mut sparse.gops {
            g.features = g.features.select_keys(&keys);
        }
        let bytes = exact(&sparse);
        let mut dec = open(&bytes);
        let mut sum = 0.0;
        let mut n = 0;
        let mut worst = f64::INFINITY;
        for f in 0..60 {
            let t = f as f64 / 30.0;
            let p = metrics::psnr(
                &render_at(&mut full_dec, t, &cam),
                &render_at(&mut dec, t, &cam),
            );
            if p.is_finite() {
                sum += p;
                n += 1;
            }
            worst = worst.min(p);
        }
        println!(
            "keys every {every} (interval {}): mean PSNR over the {n} non-key frames {:.2} dB, worst {worst:.2} dB",
            10 * every,
            sum / n as f64
        );
        assert!(worst > 20.0);
    }
}

#[test]
fn frames_do_not_depend_on_thread_count() {
    let m = model(true, 1);
    let bytes = exact(&m);
    let cam = camera(&m);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut dec = open(&bytes);
            dec.frame_at(0.77, &opts(&cam, true)).unwrap().dynamics
        })
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(bits(&a), bits(&b));
}

fn bits(g: &dlgs::Gaussians) -> Vec<u32> {
    g.positions
        .concat()
        .iter()
        .chain(&g.log_scales.concat())
        .chain(&g.rotations.concat())
        .chain(&g.sh)
        .chain(&g.opacity)
        .chain(&g.lang)
        .map(|v| v.to_bits())
        .collect()
}

#[test]
fn frames_do_not_depend_on_the_order_keys_were_first_needed() {
    // Key geometry is computed per key on first use: a decoder that seeks to the last key pair
    // first, one that plays from the start, and the stream decoder (all keys up front) agree.
    let m = model(false, 1);
    let bytes = exact(&m);
    let cam = camera(&m);
    let o = opts(&cam, false);
    let times = [1.95, 0.0, 0.95, 1.05, 0.33];
    let mut late_first = open(&bytes);
    let a: Vec<_> = times
        .iter()
        .map(|&t| bits(&late_first.frame_at(t, &o).unwrap().dynamics))
        .collect();
    for (i, &t) in times.iter().enumerate() {
        let mut fresh = open(&bytes);
        assert_eq!(
            bits(&fresh.frame_at(t, &o).unwrap().dynamics),
            a[i],
            "t = {t}"
        );
    }
    let mut stream = dlgs_decoder::stream::StreamDecoder::new(bytes.as_slice()).unwrap();
    let scene = stream.scene().clone();
    let gop = stream.next_gop().unwrap().expect("one GOP");
    for (i, &t) in times.iter().enumerate() {
        let f =
            dlgs_decoder::DecodedGop::frame(&gop, scene.locate(t).unwrap(), &o, Default::default())
                .unwrap();
        assert_eq!(bits(&f.dynamics), a[i], "stream, t = {t}");
    }
}

#[test]
fn language_decoder_runs_only_when_asked() {
    let m = model(true, 1);
    let bytes = exact(&m);
    let cam = camera(&m);
    let mut dec = open(&bytes);
    let without = dec.frame_at(0.5, &opts(&cam, false)).unwrap();
    assert_eq!(without.dynamics.lang, m.canonical.dynamics.lang);
    let with = dec.frame_at(0.5, &opts(&cam, true)).unwrap();
    assert_ne!(with.dynamics.lang, m.canonical.dynamics.lang);
    let img = render(
        &with.merged(),
        &cam,
        &RenderOptions {
            features: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(img.features.unwrap().iter().all(|v| v.is_finite()));
}

#[test]
fn paper_lerp_variant_decodes() {
    let spec = SynthSpec {
        deform_model: DeformModel::PaperLerp,
        ..Default::default()
    };
    let m = synth_dynamic(&load(SCENE), &spec).unwrap();
    let bytes = exact(&m);
    let mut dec = open(&bytes);
    let cam = camera(&m);
    let a = render_at(&mut dec, 0.3, &cam);
    let b = render_at(&mut dec, 0.3 + 1.0 / 120.0, &cam);
    assert!(a.iter().all(|v| v.is_finite()));
    assert!(metrics::psnr(&a, &b) > 30.0);
}

#[test]
fn f16_weights_cost_little() {
    let m = model(false, 1);
    let cam = camera(&m);
    let reference = exact(&m);
    let cfg = EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: FeatureCodec::Exact,
            mlp_weights: WeightType::F16,
            ..Default::default()
        },
        ..Default::default()
    };
    let half = write_model(&m, cfg, Vec::new()).unwrap();
    let (mut a, mut b) = (open(&reference), open(&half));
    let p = metrics::psnr(
        &render_at(&mut a, 0.77, &cam),
        &render_at(&mut b, 0.77, &cam),
    );
    println!(
        "f16 MLP weights: {} bytes smaller, PSNR vs f32 {p:.2} dB",
        reference.len() - half.len()
    );
    assert!(p > 45.0);
}

#[test]
fn encoder_rejects_non_finite_dynamic_input() {
    let mut m = model(false, 1);
    m.gops[0].features.data[17] = f32::NAN;
    let err = write_model(&m, EncoderConfig::default(), Vec::new()).unwrap_err();
    assert!(err.to_string().contains("not finite"), "{err}");
    let mut m = model(false, 1);
    m.gops[0].mlps.color.layers[1].weights[3] = f32::INFINITY;
    let err = write_model(
        &m,
        EncoderConfig {
            dynamic: dlgs_encoder::DynamicSettings {
                features: FeatureCodec::Exact,
                ..Default::default()
            },
            ..Default::default()
        },
        Vec::new(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("not finite"), "{err}");
}

/// A camera exactly at a dynamic Gaussian's canonical position (distance 0: the reference
/// divides by zero there) and a zero canonical quaternion still give finite Gaussians.
#[test]
fn degenerate_view_and_rotation_stay_finite() {
    let mut m = model(true, 1);
    m.canonical.dynamics.rotations[0] = [0.0; 4];
    let bytes = exact(&m);
    let mut dec = open(&bytes);
    let o = FrameOptions {
        camera_center: m.canonical.dynamics.positions[0],
        language: true,
    };
    let f = dec.frame_at(0.4, &o).unwrap();
    let d = &f.dynamics;
    let all = d
        .positions
        .concat()
        .into_iter()
        .chain(d.rotations.concat())
        .chain(d.sh.iter().copied())
        .chain(d.opacity.iter().copied())
        .chain(d.lang_opacity.iter().copied())
        .chain(d.lang.iter().copied());
    assert!(all.into_iter().all(f32::is_finite));
}

#[test]
fn intra_only_features_seek_by_decoding_two_keys_and_give_the_same_frames() {
    // SYNTHETIC dynamic model from the real lod2 tile, 2 GOPs; time features as intra-only
    // HEVC (TFEA codec 3).
    let m = model(false, 2);
    let intra = encode(
        &m,
        FeatureCodec::Hevc(HevcSettings {
            intra_only: true,
            preset: "ultrafast".into(),
            ..Default::default()
        }),
    );
    let inter = encode(
        &m,
        FeatureCodec::Hevc(HevcSettings {
            preset: "ultrafast".into(),
            ..Default::default()
        }),
    );
    let o = opts(&camera(&m), false);
    let duration = m.scene.frame_count as f64 / m.scene.fps();
    let times = [0.0, 0.37 * duration, 0.5 * duration + 0.01, duration];
    // The stream decoder decodes every key of a GOP up front: the reference frames.
    let mut stream = dlgs_decoder::stream::StreamDecoder::new(intra.as_slice()).unwrap();
    let scene = stream.scene().clone();
    let mut gops = Vec::new();
    while let Some(g) = stream.next_gop().unwrap() {
        assert_eq!(g.deformer.as_ref().unwrap().loaded_keys(), 7);
        gops.push(g);
    }
    for &t in &times {
        let time = scene.locate(t).unwrap();
        let want =
            dlgs_decoder::DecodedGop::frame(&gops[time.gop as usize], time, &o, Default::default())
                .unwrap();
        // A fresh random-access decoder: the seek decodes the 2 keys around t, no more.
        let mut dec = open(&intra);
        let got = dec.seek(t, &o).unwrap();
        let loaded = got.gop.deformer.as_ref().unwrap().loaded_keys();
        assert_eq!(loaded, 2, "t = {t}: keys {} and {}", time.key, time.key + 1);
        assert_eq!(bits(&got.dynamics), bits(&want.dynamics), "t = {t}");
        // Moving on within the GOP decodes the next keys on demand, same values.
        let later = (t + 0.6 * scene.gop_length as f64 / scene.fps()).min(duration);
        let lt = scene.locate(later).unwrap();
        if lt.gop == time.gop {
            let a = dec.frame_at(later, &o).unwrap();
            let b =
                dlgs_decoder::DecodedGop::frame(&gops[lt.gop as usize], lt, &o, Default::default())
                    .unwrap();
            assert_eq!(bits(&a.dynamics), bits(&b.dynamics), "t = {later}");
        }
    }
    // Intra-only costs bytes at the same crf and changes the error; both stay close.
    let (intra_max, _) = feature_error_table(&m, &intra);
    let (inter_max, _) = feature_error_table(&m, &inter);
    println!("bytes: intra-only {}, default {}", intra.len(), inter.len());
    println!("worst max error / range: intra-only {intra_max:.5}, default {inter_max:.5}");
    // Measured (ultrafast, crf 6): 3.5 % and 3.7 % of the channel range at worst.
    assert!(intra_max < 0.05 && inter_max < 0.05);
    assert!(
        intra.len() < inter.len() * 11 / 10,
        "intra-only within 10 % of the bytes"
    );
}

#[test]
fn merged_frames_decode_in_place_to_the_merged_frame() {
    // `frame_at_merged` (what the Python bindings hand to numpy) decodes the dynamic set
    // straight into the tail of the merged buffers, `frame_at_merged_into` into memory the
    // caller owns (numpy's, reused): the same floats as `Frame::merged`.
    let m = model(true, 2);
    let bytes = exact(&m);
    let mut dec = open(&bytes);
    let cam = camera(&m);
    let end = dec.scene().duration_seconds();
    for t in [0.0, 0.4321, end / 2.0, end] {
        for language in [false, true] {
            let o = opts(&cam, language);
            let want = dec.frame_at(t, &o).unwrap().merged();
            let got = dec.frame_at_merged(t, &o).unwrap();
            assert_eq!(got, want, "t = {t}, language {language}");
            let s = dec.scene();
            assert_eq!(got.len() as u32, s.n_static + s.n_dynamic);
            assert!(s.n_static > 0 && s.n_dynamic > 0 && got.has_language());
            // Into caller-owned slices holding garbage: the same floats again.
            let mut into = want.clone();
            for v in into.sh.iter_mut().chain(&mut into.opacity) {
                *v = f32::NAN;
            }
            into.positions.iter_mut().for_each(|p| *p = [7.0; 3]);
            let slices = dlgs_decoder::FrameSlices {
                positions: &mut into.positions,
                log_scales: &mut into.log_scales,
                rotations: &mut into.rotations,
                opacity: &mut into.opacity,
                lang_opacity: &mut into.lang_opacity,
                sh: &mut into.sh,
                lang: &mut into.lang,
            };
            dec.frame_at_merged_into(t, &o, slices).unwrap();
            assert_eq!(into, want, "t = {t}, language {language}, into slices");
        }
    }
}
