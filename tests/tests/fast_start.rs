//! Fast-start time-feature streams and keys decoded from stream prefixes (issue 55,
//! `decoder/src/prefix_keys.rs`, `hevc_headers.rs`): a GOP decodes only the packets up to the
//! key pictures a frame needs, yet every key is the sample-for-sample value of decoding the
//! whole stream, whichever order frames are asked in, on any thread count, with FFmpeg's
//! packet-at-a-time decoder or a plugged-in whole-stream one.
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
use dlgs_decoder::hevc::{display_order, Ffmpeg, KeyPictureDecoder};
use dlgs_decoder::{DecodedGop, Decoder, FrameOptions};
use dlgs_encoder::{EncoderConfig, FastStart, FeatureCodec, HevcSettings};
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};
use dlgs_tests::{load, on_threads};

const SCENE: &str = "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply";

fn file(fast_start: FastStart) -> Vec<u8> {
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
                fast_start,
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
fn keys_decode_from_prefixes_and_every_key_is_the_whole_streams() {
    let bytes = file(FastStart::FirstGop);
    let (packets0, whole0) = whole_stream(&bytes, 0);
    let (packets1, whole1) = whole_stream(&bytes, 1);
    let order0 = display_order(&packets0).expect("readable headers");
    assert_eq!(
        order0[..2],
        [0, 1],
        "GOP 0 starts with its first key interval"
    );
    let order1 = display_order(&packets1).expect("readable headers");
    assert_ne!(
        order1,
        (0..7).collect::<Vec<_>>(),
        "GOP 1 keeps x265's B-frames"
    );
    let fps = 30.0;
    for plugged in [false, true] {
        for threads in [1, 2] {
            on_threads(threads, || {
                let mut d = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
                if plugged {
                    d.set_key_picture_decoder(Arc::new(WholeOnly));
                }
                // A frame of the first key interval decodes GOP 0's first 2 packets only.
                d.frame_at(3.0 / fps, &OPTS).unwrap();
                let gop = d.gop(0).unwrap();
                let deformer = gop.deformer.as_ref().unwrap();
                assert_eq!(deformer.loaded_keys(), 2, "plugged {plugged}");
                // Then a later interval, then an earlier one: each key is the whole stream's.
                d.frame_at(45.0 / fps, &OPTS).unwrap();
                d.frame_at(15.0 / fps, &OPTS).unwrap();
                assert_eq!(deformer.dynamic_gop().unwrap().features, whole0);
                // GOP 1 at its last interval: the packets up to keys 5 and 6 only.
                d.frame_at(115.0 / fps, &OPTS).unwrap();
                let gop1 = d.gop(1).unwrap();
                let deformer1 = gop1.deformer.as_ref().unwrap();
                let m = 1 + order1.iter().rposition(|&k| k >= 5).unwrap();
                assert_eq!(deformer1.loaded_keys(), m, "{order1:?}");
                d.frame_at(61.0 / fps, &OPTS).unwrap();
                assert_eq!(deformer1.dynamic_gop().unwrap().features, whole1);
            });
        }
    }
}

#[test]
fn fast_start_frames_are_the_frames_of_the_random_access_decoder() {
    // Every GOP fast-start: the streaming pipeline and the random-access decoder agree.
    let bytes = file(FastStart::EveryGop);
    for g in 0..2 {
        assert_eq!(
            display_order(&whole_stream(&bytes, g).0).unwrap()[..2],
            [0, 1]
        );
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
fn a_broken_decoder_on_a_prefix_is_a_payload_error_every_time() {
    struct Short;
    impl KeyPictureDecoder for Short {
        fn decode(&self, p: &[&[u8]], w: u32, h: u32, n: usize) -> Result<Vec<Vec<u16>>, String> {
            let mut v = Ffmpeg.decode(p, w, h, n)?;
            v[0].pop();
            Ok(v)
        }
    }
    let bytes = file(FastStart::FirstGop);
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
