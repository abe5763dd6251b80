//! Truncate a real multi-chunk file at every byte and flip bits all over it: every case is a
//! typed error or a read that returns exactly the original data. A capped global allocator
//! turns any allocation beyond 256 MiB into a test failure (abort).

use std::alloc::System;

use cap::Cap;
use dlgs::chunks::craw::RawCodec;
use dlgs::Limits;
use dlgs_tests::{
    decode_all_random, decode_all_stream, load, multi_gop_file, with_synthetic_language,
};

#[global_allocator]
static ALLOC: Cap<System> = Cap::new(System, 256 << 20);

/// Runs both readers; returns whether (random-access, stream) accepted the file. An accepted
/// file must decode to exactly the original GOPs.
fn check_case(bytes: &[u8], want: &[dlgs::Canonical], what: &str) -> (bool, bool) {
    let limits = Limits::tiny();
    let mut accepted = [false; 2];
    for (k, r) in [
        decode_all_random(bytes, limits.clone()),
        decode_all_stream(bytes, limits),
    ]
    .into_iter()
    .enumerate()
    {
        match r {
            Ok(got) => {
                assert!(got == want, "{what}: read succeeded with different data");
                accepted[k] = true;
            }
            Err(e) => assert!(!e.name().is_empty()),
        }
    }
    (accepted[0], accepted[1])
}

#[test]
fn truncation_at_every_byte_of_a_real_file() {
    let g = load("tiny/metalsplatter_3-points-from-train.ply");
    for codec in [RawCodec::None, RawCodec::Zstd] {
        let (bytes, want) = multi_gop_file(&g, 3, codec);
        for cut in 0..bytes.len() {
            let r = check_case(&bytes[..cut], &want, &format!("cut {cut}"));
            assert_eq!(
                r,
                (false, false),
                "a file truncated at {cut} of {} bytes was accepted",
                bytes.len()
            );
        }
        assert_eq!(check_case(&bytes, &want, "whole"), (true, true));
    }
}

#[test]
fn a_bit_flip_at_every_byte_is_detected_or_harmless() {
    let g = with_synthetic_language(&load("tiny/metalsplatter_3-points-from-train.ply"));
    let (bytes, want) = multi_gop_file(&g, 3, RawCodec::Zstd);
    let mut accepted_by_stream = Vec::new();
    for pos in 0..bytes.len() {
        for bit in [0u8, 3, 7] {
            let mut b = bytes.clone();
            b[pos] ^= 1 << bit;
            // The random-access reader is lazy: a flip in a chunk it never reads (META, an
            // unknown ancillary chunk) is not seen, and check_case asserts the data it returns
            // is the original. The stream reader reads and CRC-checks every byte.
            let (_, by_stream) = check_case(&b, &want, &format!("flip byte {pos} bit {bit}"));
            if by_stream {
                accepted_by_stream.push(pos);
            }
        }
    }
    // Only the minor-version bytes (10, 11) are outside every CRC; minor versions are accepted
    // by design.
    accepted_by_stream.dedup();
    assert!(
        accepted_by_stream.iter().all(|p| (10..12).contains(p)),
        "stream reader accepted flips at {accepted_by_stream:?}"
    );
}

#[test]
fn random_damage_to_a_larger_real_file() {
    let g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let (bytes, want) = multi_gop_file(&g, 2, RawCodec::Zstd);
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for _ in 0..400 {
        let mut b = bytes.clone();
        match next() % 3 {
            0 => b.truncate((next() % bytes.len() as u64) as usize),
            1 => {
                for _ in 0..1 + next() % 8 {
                    let p = (next() % b.len() as u64) as usize;
                    b[p] = next() as u8;
                }
            }
            _ => {
                // Overwrite an 8-byte window with 0xFF (huge lengths / counts).
                let p = (next() % (b.len() as u64 - 8)) as usize;
                b[p..p + 8].fill(0xff);
            }
        }
        check_case(&b, &want, "random damage");
    }
}

/// Decode every GOP of a dynamic file (time features through FFmpeg's HEVC decoder, MLPs)
/// and one deformed frame; the frame's dynamic Gaussians when everything is accepted.
fn decode_dynamic(bytes: &[u8]) -> dlgs::Result<dlgs::Gaussians> {
    let mut dec = dlgs_decoder::Decoder::new(std::io::Cursor::new(bytes), Limits::tiny())?;
    for g in 0..dec.scene().gop_count {
        dec.gop(g)?;
    }
    let o = dlgs_decoder::FrameOptions {
        camera_center: [0.0, 0.0, -3.0],
        language: true,
    };
    Ok(dec.frame_at(0.77, &o)?.dynamics)
}

/// The same guarantees for a dynamic file (SYNTHETIC motion on a real 3-Gaussian scene: no
/// trained DLGStream model exists here), exact and HEVC time features.
#[test]
fn damage_to_a_dynamic_file_is_detected_or_harmless() {
    use dlgs_encoder::{EncoderConfig, FeatureCodec, HevcSettings};
    use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};
    let g = load("tiny/metalsplatter_3-points-from-train.ply");
    let spec = SynthSpec {
        dynamic_fraction: 0.5,
        language: true,
        gops: 2,
        ..Default::default()
    };
    let model = synth_dynamic(&g, &spec).unwrap();
    for features in [
        FeatureCodec::Exact,
        FeatureCodec::Hevc(HevcSettings {
            preset: "ultrafast".into(),
            ..Default::default()
        }),
    ] {
        let cfg = EncoderConfig {
            dynamic: dlgs_encoder::DynamicSettings {
                features,
                ..Default::default()
            },
            ..Default::default()
        };
        let bytes = write_model(&model, cfg, Vec::new()).unwrap();
        let want = decode_dynamic(&bytes).unwrap();
        for cut in 0..bytes.len() {
            let e = decode_dynamic(&bytes[..cut]).expect_err("truncated file accepted");
            assert!(!e.name().is_empty());
        }
        for at in (0..bytes.len()).step_by(5) {
            let mut b = bytes.clone();
            b[at] ^= 1 << (at % 8);
            match decode_dynamic(&b) {
                Ok(got) => assert!(got == want, "flip at {at}: accepted with different data"),
                Err(e) => assert!(!e.name().is_empty()),
            }
        }
    }
}
