//! Low-delay time-feature streams (issue 55, `decoder/src/low_delay.rs`): a GOP whose HEVC
//! stream has no B-frames decodes only the key pictures a frame needs, yet every key is the
//! sample-for-sample value of decoding the whole stream, whichever order frames are asked in,
//! on any thread count, with FFmpeg's packet-at-a-time decoder or a plugged-in whole-stream one.
//!
//! NOTE: no real trained DLGStream model exists in this repository's data. The models here are
//! built by `dlgs_testkit::synth` from a REAL canonical scene in ../shared/data with a synthetic
//! dynamic subset (see tests/tests/read_ahead.rs).

use std::io::Cursor;
use std::sync::Arc;

use dlgs::chunks::tfea::{self, TfeaBody};
use dlgs::container::{ChunkType, FileReader};
use dlgs::model::TimeFeatures;
use dlgs::{FormatErrorKind, Limits};
use dlgs_decoder::hevc::{pictures_in_decode_order, Ffmpeg, KeyPictureDecoder};
use dlgs_decoder::{DecodedGop, Decoder, FrameOptions};
use dlgs_encoder::{EncoderConfig, FeatureCodec, HevcSettings, LowDelay};
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};
use dlgs_tests::{load, on_threads};

const SCENE: &str = "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply";

fn file(low_delay: LowDelay) -> Vec<u8> {
    let spec = SynthSpec {
        gops: 2,
        language: true,
        ..Default::default()
    };
    let m = synth_dynamic(&load(SCENE), &spec).unwrap();
    let cfg = EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: FeatureCodec::Hevc(HevcSettings {
                preset: "ultrafast".into(),
                low_delay,
                ..Default::default()
            }),
            ..Default::default()
        },
        ..Default::default()
    };
    write_model(&m, cfg, Vec::new()).unwrap()
}

/// GOP `g`'s HEVC packets, and its features decoded the plain way: the whole stream at once.
fn whole_stream(bytes: &[u8], g: u32) -> (Vec<Vec<u8>>, TimeFeatures) {
    let mut r = FileReader::open(Cursor::new(bytes)).unwrap();
    let scene = r.scene().clone();
    let c = r
        .gop_chunks(g)
        .unwrap()
        .into_iter()
        .find(|c| c.ty == ChunkType::TFEA)
        .unwrap();
    let p = r.payload(&c).unwrap();
    let TfeaBody::Hevc {
        tiling,
        ranges,
        packets,
        ..
    } = tfea::decode(&p, 0, &scene, &Limits::default()).unwrap()
    else {
        panic!("HEVC features")
    };
    let refs: Vec<&[u8]> = packets.iter().map(|p| p.as_slice()).collect();
    let (w, h) = (tiling.width() as u32, tiling.height() as u32);
    let video = dlgs_video::decode_gray12(&refs, w, h, tiling.keys).unwrap();
    (packets, tfea::untile(&video.frames, &tiling, &ranges))
}

const OPTS: FrameOptions = FrameOptions {
    camera_center: [0.5, 0.3, 4.0],
    language: true,
};

/// FFmpeg through `decode` only (no packet-at-a-time stream): the prefix path.
struct WholeOnly;
impl KeyPictureDecoder for WholeOnly {
    fn decode(&self, p: &[&[u8]], w: u32, h: u32, n: usize) -> Result<Vec<Vec<u16>>, String> {
        Ffmpeg.decode(p, w, h, n)
    }
}

#[test]
fn low_delay_gops_decode_only_the_keys_asked_for_and_every_key_is_the_whole_streams() {
    let bytes = file(LowDelay::FirstGop);
    let (packets0, whole0) = whole_stream(&bytes, 0);
    let (packets1, whole1) = whole_stream(&bytes, 1);
    assert!(pictures_in_decode_order(&packets0), "GOP 0 has no B-frames");
    assert!(!pictures_in_decode_order(&packets1), "GOP 1 keeps them");
    let fps = 30.0;
    for plugged in [false, true] {
        for threads in [1, 2] {
            on_threads(threads, || {
                let mut d = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
                if plugged {
                    d.set_key_picture_decoder(Arc::new(WholeOnly));
                }
                // A frame of the first key interval decodes keys 0 and 1 of GOP 0's 7.
                d.frame_at(3.0 / fps, &OPTS).unwrap();
                let gop = d.gop(0).unwrap();
                let deformer = gop.deformer.as_ref().unwrap();
                assert_eq!(deformer.loaded_keys(), 2, "plugged {plugged}");
                // Then a later interval, then an earlier one: each key is the whole stream's.
                d.frame_at(45.0 / fps, &OPTS).unwrap();
                d.frame_at(15.0 / fps, &OPTS).unwrap();
                assert_eq!(deformer.dynamic_gop().unwrap().features, whole0);
                // GOP 1 (B-frames) decodes whole, as before.
                d.frame_at(70.0 / fps, &OPTS).unwrap();
                let gop1 = d.gop(1).unwrap();
                let deformer1 = gop1.deformer.as_ref().unwrap();
                assert_eq!(deformer1.loaded_keys(), 7);
                assert_eq!(deformer1.dynamic_gop().unwrap().features, whole1);
            });
        }
    }
}

#[test]
fn low_delay_frames_are_the_frames_of_the_same_stream_with_b_frames_decoded_whole() {
    // Every GOP low-delay: the streaming pipeline and the random-access decoder agree.
    let bytes = file(LowDelay::EveryGop);
    for g in 0..2 {
        assert!(pictures_in_decode_order(&whole_stream(&bytes, g).0));
    }
    let mut d = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
    let scene = d.scene().clone();
    let mut stream = dlgs_decoder::pipeline::PlaybackStream::open(
        Cursor::new(bytes.clone()),
        Default::default(),
    )
    .unwrap();
    let mut f = 0u32;
    while let Some(ready) = stream.next_gop().unwrap() {
        for _ in 0..scene.gop_length {
            let t = f as f64 / scene.fps();
            let time = scene.locate(t).unwrap();
            let a = DecodedGop::frame(&ready.gop, time, &OPTS, Default::default()).unwrap();
            let b = d.frame_at(t, &OPTS).unwrap();
            assert_eq!(a.dynamics, b.dynamics, "frame {f}");
            f += 1;
        }
    }
    assert_eq!(f, scene.frame_count);
}

/// A plugged-in decoder whose pictures are wrong fails the frame with a typed error of the
/// `TFEA` payload, again on the next request, never a panic.
#[test]
fn a_broken_decoder_on_a_low_delay_stream_is_a_payload_error_every_time() {
    struct Short;
    impl KeyPictureDecoder for Short {
        fn decode(&self, p: &[&[u8]], w: u32, h: u32, n: usize) -> Result<Vec<Vec<u16>>, String> {
            let mut v = Ffmpeg.decode(p, w, h, n)?;
            v[0].pop();
            Ok(v)
        }
    }
    let bytes = file(LowDelay::FirstGop);
    let mut d = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
    d.set_key_picture_decoder(Arc::new(Short));
    for t in [0.1, 1.5] {
        let e = d.frame_at(t, &OPTS).err().expect("refused");
        assert!(
            matches!(e.format_kind(), Some(FormatErrorKind::Payload { .. })),
            "{e}"
        );
    }
}
