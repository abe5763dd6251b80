//! Periodic refresh of sequential streams (format-spec §4.1 `refresh_interval`, since 1.17):
//! every K-th GOP carries its full canonical state, so a GOP needs at most K-1 residuals.
//!
//! NOTE: no real trained DLGStream model exists in this repository's data. The models here are
//! built by `dlgs_testkit::synth` from a REAL canonical scene in ../shared/data with a synthetic
//! dynamic subset and GENERATED binary voxel residual fields (see tests/tests/residual.rs).

use std::io::Cursor;

use dlgs::container::gop::NO_REFERENCE;
use dlgs::container::header::{ResidualMode, SceneHeader};
use dlgs::container::reader::FileReader;
use dlgs::container::ChunkType;
use dlgs::error::FormatErrorKind;
use dlgs::{Canonical, Limits};
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::{EncoderConfig, FeatureCodec};
use dlgs_testkit::synth::{synth_dynamic, write_model, SynthModel, SynthSpec};
use dlgs_tests::{decode_all_stream, load, on_threads};

const SCENE: &str = "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply";
const GOPS: u32 = 7;

fn model(refresh: u32) -> SynthModel {
    let spec = SynthSpec {
        gops: GOPS,
        residual_mode: ResidualMode::Sequential,
        refresh_interval: refresh,
        ..Default::default()
    };
    synth_dynamic(&load(SCENE), &spec).unwrap()
}

/// Lossless canonical coding and exact time features: states compare bit for bit.
fn exact_cfg() -> EncoderConfig {
    EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: FeatureCodec::Exact,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn body(c: &Canonical) -> Vec<u8> {
    dlgs::chunks::craw::canonical_body(c)
}

fn opts() -> FrameOptions {
    FrameOptions {
        camera_center: [0.5, 0.3, 4.0],
        language: false,
    }
}

/// The chunk type holding each GOP's canonical state or residual, and its reference GOP.
fn layout(bytes: &[u8]) -> Vec<(ChunkType, u32)> {
    let mut r = FileReader::open(Cursor::new(bytes)).unwrap();
    (0..GOPS)
        .map(|g| {
            let reference = r.gop_entry(g).unwrap().header.reference_gop;
            let chunks = r.gop_chunks(g).unwrap();
            let ty = chunks
                .iter()
                .map(|c| c.ty)
                .find(|t| [ChunkType::CRAW, ChunkType::CSOG, ChunkType::RNTC].contains(t))
                .unwrap();
            (ty, reference)
        })
        .collect()
}

#[test]
fn refresh_gops_carry_the_chain_state_and_cut_the_chain() {
    let plain = write_model(&model(0), exact_cfg(), Vec::new()).unwrap();
    let m = model(3);
    let want = m.canonical_states().unwrap();
    let bytes = write_model(&m, exact_cfg(), Vec::new()).unwrap();
    // GOPs 0, 3 and 6 are full states without a reference; the others chain.
    let got = layout(&bytes);
    for (g, &(ty, reference)) in got.iter().enumerate() {
        if g % 3 == 0 {
            assert_eq!((ty, reference), (ChunkType::CRAW, NO_REFERENCE), "GOP {g}");
        } else {
            assert_eq!((ty, reference), (ChunkType::RNTC, g as u32 - 1), "GOP {g}");
        }
    }
    assert!(layout(&plain)[1..]
        .iter()
        .enumerate()
        .all(|(g, &(ty, r))| ty == ChunkType::RNTC && r == g as u32));
    // Each refresh costs the canonical state's bytes over the residual's.
    assert!(
        bytes.len() > plain.len(),
        "{} vs {}",
        bytes.len(),
        plain.len()
    );
    // The same states as the chain gives, bit for bit, on 1 and 2 threads and streamed.
    for threads in [1, 2] {
        let states = on_threads(threads, || {
            let mut d = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
            (0..GOPS)
                .map(|g| (*d.gop_canonical(g).unwrap()).clone())
                .collect::<Vec<_>>()
        });
        for g in 0..GOPS as usize {
            assert!(
                body(&states[g]) == body(&want[g]),
                "GOP {g}, {threads} threads"
            );
        }
    }
    let streamed = decode_all_stream(&bytes, Limits::default()).unwrap();
    assert!(streamed.iter().zip(&want).all(|(a, b)| body(a) == body(b)));
    // And the same frames as the stream without refresh.
    let mut a = Decoder::new(Cursor::new(&plain[..]), Limits::default()).unwrap();
    let mut b = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
    for t in [0.5, 4.2, 7.9, 13.1] {
        let fa = a.seek(t, &opts()).unwrap();
        let fb = b.seek(t, &opts()).unwrap();
        let (ca, cb) = (
            Canonical {
                statics: fa.statics().clone(),
                dynamics: fa.dynamics,
            },
            Canonical {
                statics: fb.statics().clone(),
                dynamics: fb.dynamics,
            },
        );
        assert!(body(&ca) == body(&cb), "t = {t}");
    }
}

/// A cold seek reads only the GOPs since the last refresh: with GOP 1's residual damaged, a
/// seek into GOP 4 still decodes in the refreshed stream and fails in the plain one.
#[test]
fn a_cold_seek_reads_nothing_before_the_last_refresh() {
    let damage = |bytes: &[u8]| {
        let mut r = FileReader::open(Cursor::new(bytes)).unwrap();
        let c = r.gop_chunks(1).unwrap();
        let rntc = c.iter().find(|c| c.ty == ChunkType::RNTC).unwrap();
        let mut out = bytes.to_vec();
        let at = (rntc.offset + 16 + rntc.len / 2) as usize;
        out[at] ^= 0x40;
        out
    };
    let t_gop4 = 4.0 * 2.0 + 0.7;
    for refresh in [0, 3] {
        let bytes = damage(&write_model(&model(refresh), exact_cfg(), Vec::new()).unwrap());
        let mut d = Decoder::new(Cursor::new(&bytes[..]), Limits::default()).unwrap();
        let r = d.seek(t_gop4, &opts());
        if refresh == 0 {
            let e = r.err().expect("the chain passes the damaged GOP 1");
            assert!(e.to_string().contains("CRC mismatch"), "{e}");
        } else {
            r.unwrap();
            // GOP 1 itself still reports the damage.
            assert!(d.seek(2.5, &opts()).is_err());
        }
    }
}

#[test]
fn refresh_needs_a_sequential_scene_and_an_interval_of_two_or_more() {
    let base = model(3).scene.clone();
    let write = |s: SceneHeader| dlgs::container::writer::Writer::new(Vec::new(), s).err();
    for (mode, k) in [
        (ResidualMode::Sequential, 1),
        (ResidualMode::Parallel, 3),
        (ResidualMode::Intra, 2),
    ] {
        let s = SceneHeader {
            residual_mode: mode,
            refresh_interval: k,
            ..base.clone()
        };
        assert!(write(s.clone()).is_some(), "writer took {mode:?}, K = {k}");
        // A reader refuses the same header, naming the field and its offset.
        let mut p = s.encode();
        let e = SceneHeader::decode(&p, 100, &Limits::default()).unwrap_err();
        match e.format_kind() {
            Some(FormatErrorKind::InvalidField { field, .. }) => {
                assert_eq!(*field, "refresh_interval")
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(e.offset(), Some(140), "{e}");
        p[40..44].copy_from_slice(&0u32.to_le_bytes());
        assert!(SceneHeader::decode(&p, 100, &Limits::default()).is_ok());
    }
    assert!(write(base).is_none());
}
