//! Decoding ahead of playback (issue 55): the random-access decoder's read-ahead
//! (`decoder/src/read_ahead.rs`) and the streaming pipeline (`decoder/src/pipeline.rs`) give
//! the same frames, bit for bit, as decoding each GOP in turn, and they do decode ahead.
//!
//! NOTE: no real trained DLGStream model exists in this repository's data. The models here are
//! built by `dlgs_testkit::synth` from a REAL canonical scene in ../shared/data with a synthetic
//! dynamic subset and GENERATED binary voxel residual fields (see tests/tests/residual.rs).

use std::io::Cursor;

use dlgs::container::header::ResidualMode;
use dlgs::{Canonical, Limits};
use dlgs_decoder::pipeline::{PipelineOptions, PlaybackStream};
use dlgs_decoder::{DecodedGop, Decoder, Frame, FrameOptions};
use dlgs_encoder::{EncoderConfig, FeatureCodec};
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};
use dlgs_tests::{decode_all_stream, load, on_threads};

const SCENE: &str = "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply";
const GOPS: u32 = 4;

fn file(mode: ResidualMode, features: FeatureCodec) -> Vec<u8> {
    let spec = SynthSpec {
        gops: GOPS,
        residual_mode: mode,
        language: true,
        ..Default::default()
    };
    let m = synth_dynamic(&load(SCENE), &spec).unwrap();
    let cfg = EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features,
            ..Default::default()
        },
        ..Default::default()
    };
    write_model(&m, cfg, Vec::new()).unwrap()
}

/// 12-bit HEVC time features, as `dlgs encode` writes by default.
fn hevc() -> FeatureCodec {
    dlgs_encoder::DynamicSettings::default().features
}

fn opts() -> FrameOptions {
    FrameOptions {
        camera_center: [0.5, 0.3, 4.0],
        language: true,
    }
}

/// A frame's Gaussians as bytes (static then dynamic set).
fn frame_bytes(f: &Frame) -> Vec<u8> {
    dlgs::chunks::craw::canonical_body(&Canonical {
        statics: f.statics().clone(),
        dynamics: f.dynamics.clone(),
    })
}

/// Every frame in time order, and how many GOPs came from the read-ahead thread.
fn play(bytes: &[u8], read_ahead: bool) -> (Vec<Vec<u8>>, u64) {
    let mut d = Decoder::new(Cursor::new(bytes), Limits::default()).unwrap();
    d.set_read_ahead(read_ahead);
    let scene = d.scene().clone();
    let frames = (0..scene.frame_count)
        .map(|f| {
            let fr = d.frame_at(f as f64 / scene.fps(), &opts()).unwrap();
            frame_bytes(&fr)
        })
        .collect();
    (frames, d.read_ahead_hits())
}

#[test]
fn playing_in_time_order_decodes_the_next_gop_ahead_and_changes_no_bit() {
    for (mode, features) in [
        (ResidualMode::Sequential, FeatureCodec::Exact),
        (ResidualMode::Parallel, hevc()),
    ] {
        let bytes = file(mode, features);
        let (want, none) = play(&bytes, false);
        assert_eq!(none, 0);
        for threads in [1, 2] {
            let (got, hits) = on_threads(threads, || play(&bytes, true));
            // Every GOP after the first was ready from the read-ahead thread.
            assert_eq!(hits, u64::from(GOPS - 1), "{mode:?}, {threads} threads");
            assert_eq!(got.len(), want.len());
            for (f, (a, b)) in got.iter().zip(&want).enumerate() {
                assert!(a == b, "frame {f}, {mode:?}, {threads} threads");
            }
        }
    }
}

/// A single request (a seek, a render) starts nothing; jumping away from a GOP decoded
/// ahead and back gives the same frames.
#[test]
fn seeks_start_no_read_ahead_and_jumps_change_no_bit() {
    let bytes = file(ResidualMode::Sequential, FeatureCodec::Exact);
    let mut plain = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
    plain.set_read_ahead(false);
    let mut d = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
    let gop_s = f64::from(d.scene().gop_length) / d.scene().fps();
    // One request per GOP, backwards: never in time order within a GOP.
    for g in (0..GOPS).rev() {
        d.frame_at(f64::from(g) * gop_s + 0.1, &opts()).unwrap();
    }
    assert_eq!(d.read_ahead_hits(), 0);
    // Two requests in GOP 0 in time order schedule GOP 1; jump to GOP 3, then back to 1.
    for t in [
        0.1,
        0.2,
        3.0 * gop_s + 0.5,
        gop_s + 0.25,
        gop_s + 0.3,
        2.0 * gop_s + 0.1,
    ] {
        let a = d.frame_at(t, &opts()).unwrap();
        let b = plain.frame_at(t, &opts()).unwrap();
        assert!(frame_bytes(&a) == frame_bytes(&b), "t = {t}");
    }
    // GOP 1 was taken from the read-ahead thread, and GOP 2 after playing on in GOP 1.
    assert_eq!(d.read_ahead_hits(), 2);
}

/// The streaming pipeline yields every GOP in order with the stream decoder's states, and
/// GOP 0 (returned after its first key interval) gives the same frames as a decoder that
/// prepared every key first.
#[test]
fn the_playback_pipeline_gives_the_stream_decoders_gops() {
    let bytes = file(ResidualMode::Sequential, hevc());
    let want = decode_all_stream(&bytes, Limits::default()).unwrap();
    let mut plain = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
    plain.set_read_ahead(false);
    let mut stream =
        PlaybackStream::open(Cursor::new(bytes.clone()), PipelineOptions::default()).unwrap();
    let scene = stream.scene().clone();
    let mut g = 0;
    while let Some(ready) = stream.next_gop().unwrap() {
        assert_eq!(ready.gop.index, g);
        assert!(ready.times.total > std::time::Duration::ZERO);
        let body = |c: &Canonical| dlgs::chunks::craw::canonical_body(c);
        assert!(
            body(&ready.gop.canonical) == body(&want[g as usize]),
            "GOP {g}"
        );
        for f in (g * scene.gop_length..(g + 1) * scene.gop_length).step_by(7) {
            let t = f as f64 / scene.fps();
            let time = scene.locate(t).unwrap();
            let a = DecodedGop::frame(&ready.gop, time, &opts(), Default::default()).unwrap();
            let b = plain.frame_at(t, &opts()).unwrap();
            assert!(frame_bytes(&a) == frame_bytes(&b), "frame {f}");
        }
        g += 1;
    }
    assert_eq!(g, GOPS);
    assert!(stream.next_gop().unwrap().is_none());
}

/// A damaged GOP reaches the player as the stream decoder's typed error, after the GOPs
/// before it; the stream then ends.
#[test]
fn a_damaged_gop_reaches_the_player_as_an_error() {
    let mut bytes = file(ResidualMode::Sequential, FeatureCodec::Exact);
    let at = {
        let mut r = dlgs::container::FileReader::open(Cursor::new(&bytes[..])).unwrap();
        let c = r.gop_chunks(2).unwrap()[0];
        c.payload_offset() as usize + 4
    };
    bytes[at] ^= 0x5a;
    let mut stream = PlaybackStream::open(Cursor::new(bytes), PipelineOptions::default()).unwrap();
    assert_eq!(stream.next_gop().unwrap().unwrap().gop.index, 0);
    assert_eq!(stream.next_gop().unwrap().unwrap().gop.index, 1);
    let err = stream.next_gop().err().expect("GOP 2 is damaged");
    assert!(matches!(err, dlgs::Error::Format(_)), "{err}");
    assert!(stream.next_gop().unwrap().is_none());
}

/// Scaffold-GS streams go through the same pipeline (`ScaffoldStreamDecoder` as its
/// `GopSource`), with the stream decoder's GOPs; the 3DGS stream decoder refuses them.
#[test]
fn the_pipeline_plays_scaffold_streams_and_the_3dgs_decoder_refuses_them() {
    use dlgs_decoder::scaffold::{ScaffoldStreamDecoder, ViewRequest};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../format-spec/vectors/valid/scaffold-tiny-residual.dlgs");
    let bytes = std::fs::read(path).unwrap();
    let err = dlgs_decoder::stream::StreamDecoder::new(&bytes[..])
        .err()
        .expect("a Scaffold-GS stream");
    assert!(matches!(err, dlgs::Error::Request(_)), "{err}");
    let view = ViewRequest {
        camera_center: [0.0, 0.0, 4.0],
        language: true,
        visible: None,
    };
    let mut plain = ScaffoldStreamDecoder::new(&bytes[..], Limits::default()).unwrap();
    let dec = ScaffoldStreamDecoder::new(Cursor::new(bytes.clone()), Limits::default()).unwrap();
    let mut stream = PlaybackStream::spawn(dec, PipelineOptions::default()).unwrap();
    let mut n = 0;
    while let Some(ready) = stream.next_gop().unwrap() {
        let want = plain.next_gop().unwrap().expect("as many GOPs");
        assert_eq!(ready.gop.index, want.index);
        let (a, b) = (ready.gop.frame(1, 0.25, &view), want.frame(1, 0.25, &view));
        assert_eq!(format!("{a:?}"), format!("{b:?}"), "GOP {n}");
        n += 1;
    }
    assert!(n >= 2 && plain.next_gop().unwrap().is_none());
}
