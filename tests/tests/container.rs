//! Container round trips over both readers, chunk-skipping rules, and typed errors.

use dlgs::chunks::craw::RawCodec;
use dlgs::container::{
    ChunkType, FileReader, SceneHeader, StreamReader, Writer, FLAG_MUST_UNDERSTAND,
};
use dlgs::{Error, FormatErrorKind, LimitError, Limits};
use dlgs_tests::{
    decode_all_random, decode_all_stream, load, multi_gop_file, with_synthetic_language,
};

#[test]
fn multi_gop_round_trip_on_both_readers_raw_and_zstd() {
    let g = with_synthetic_language(&load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply"));
    for codec in [RawCodec::None, RawCodec::Zstd] {
        let (bytes, want) = multi_gop_file(&g, 3, codec);
        assert!(decode_all_random(&bytes, Limits::default()).unwrap() == want);
        assert!(decode_all_stream(&bytes, Limits::default()).unwrap() == want);
        // One byte at a time through the stream reader gives the same result.
        struct OneByte<'a>(&'a [u8]);
        impl std::io::Read for OneByte<'_> {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                if self.0.is_empty() || buf.is_empty() {
                    return Ok(0);
                }
                buf[0] = self.0[0];
                self.0 = &self.0[1..];
                Ok(1)
            }
        }
        let mut r = StreamReader::new(OneByte(&bytes)).unwrap();
        let mut n = 0;
        while let Some(ev) = r.next_event().unwrap() {
            if let dlgs::container::StreamEvent::GopChunk(c, _) = ev {
                assert_eq!(c.ty, ChunkType::CRAW, "unknown XTRA chunks must be skipped");
                n += 1;
            }
        }
        assert_eq!(n, 3);
    }
}

#[test]
fn index_seeks_and_frame_lookup() {
    let g = load("ply/supersplat_fruit_drops_minimal_4721_sh3.ply");
    let (bytes, want) = multi_gop_file(&g, 4, RawCodec::Zstd);
    let mut dec =
        dlgs_decoder::Decoder::new(std::io::Cursor::new(&bytes), Limits::default()).unwrap();
    // Random access in any order.
    for gop in [3u32, 0, 2, 1, 3] {
        assert!(*dec.gop_canonical(gop).unwrap() == want[gop as usize]);
    }
    // 30 fps, 2 frames per GOP: t = 0.2 s is frame 6, GOP 3.
    let o = dlgs_decoder::FrameOptions {
        camera_center: [0.0; 3],
        language: false,
    };
    assert!(dec.frame_at(0.2, &o).unwrap().merged() == want[3].merged());
    assert!(dec.frame_at(0.0, &o).unwrap().merged() == want[0].merged());
    assert!(matches!(
        dec.frame_at(1.0, &o).err().unwrap(),
        Error::Request(_)
    ));
    assert!(matches!(
        dec.frame_at(f64::NAN, &o).err().unwrap(),
        Error::Request(_)
    ));
    assert!(matches!(
        dec.gop_canonical(4).unwrap_err(),
        Error::Request(_)
    ));
}

#[test]
fn unknown_must_understand_chunks_are_rejected_by_both_readers() {
    let g = load("tiny/metalsplatter_3-points-from-train.ply");
    for scene_level in [true, false] {
        let mut w = Writer::new(Vec::new(), SceneHeader::still(3, 3)).unwrap();
        if scene_level {
            w.scene_chunk(ChunkType(*b"ZZZZ"), FLAG_MUST_UNDERSTAND, b"x")
                .unwrap();
        }
        w.begin_gop().unwrap();
        if !scene_level {
            w.gop_chunk(ChunkType(*b"ZZZZ"), FLAG_MUST_UNDERSTAND, b"x")
                .unwrap();
        }
        let c = dlgs::Canonical::from_static(g.clone());
        w.gop_chunk(
            ChunkType::CRAW,
            FLAG_MUST_UNDERSTAND,
            &dlgs::chunks::craw::encode(&c, RawCodec::None, 0).unwrap(),
        )
        .unwrap();
        let bytes = w.finish().unwrap();
        let e = decode_all_random(&bytes, Limits::default()).unwrap_err();
        assert_eq!(
            e.format_kind(),
            Some(&FormatErrorKind::UnknownCriticalChunk(ChunkType(*b"ZZZZ"))),
            "{e}"
        );
        let e = decode_all_stream(&bytes, Limits::default()).unwrap_err();
        assert_eq!(
            e.format_kind(),
            Some(&FormatErrorKind::UnknownCriticalChunk(ChunkType(*b"ZZZZ"))),
            "{e}"
        );
    }
}

#[test]
fn errors_name_what_and_where() {
    let g = load("tiny/metalsplatter_3-points-from-train.ply");
    let (bytes, _) = multi_gop_file(&g, 2, RawCodec::None);
    // Bad magic at byte 0.
    let mut b = bytes.clone();
    b[1] = b'X';
    let e = FileReader::open(std::io::Cursor::new(&b)).err().unwrap();
    assert_eq!((e.name(), e.offset()), ("BadMagic", Some(0)));
    // Major version 2 at byte 8.
    let mut b = bytes.clone();
    b[8] = 2;
    let e = FileReader::open(std::io::Cursor::new(&b)).err().unwrap();
    assert_eq!((e.name(), e.offset()), ("UnsupportedVersion", Some(8)));
    // A flipped payload byte in HEAD: payload CRC error at the CRC's offset.
    let mut b = bytes.clone();
    b[12 + 24 + 2] ^= 1;
    let e = FileReader::open(std::io::Cursor::new(&b)).err().unwrap();
    assert_eq!(e.name(), "PayloadCrc");
    assert_eq!(e.offset(), Some(12 + 24 + 64));
    // A flipped chunk-length byte: header CRC error.
    let mut b = bytes.clone();
    b[12 + 13] ^= 0x40;
    let e = FileReader::open(std::io::Cursor::new(&b)).err().unwrap();
    assert_eq!((e.name(), e.offset()), ("HeaderCrc", Some(12 + 20)));
    // Display says what and where.
    assert!(e.to_string().contains("at byte 32"), "{e}");
}

#[test]
fn limits_are_enforced_before_allocation() {
    let g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let (bytes, _) = multi_gop_file(&g, 2, RawCodec::None);
    let tight = Limits {
        max_chunk_len: 1000,
        ..Limits::tiny()
    };
    let e = decode_all_random(&bytes, tight.clone()).unwrap_err();
    assert!(
        matches!(
            e,
            Error::Limit(LimitError {
                what: "chunk length",
                ..
            })
        ),
        "{e}"
    );
    let e = decode_all_stream(&bytes, tight).unwrap_err();
    assert!(
        matches!(
            e,
            Error::Limit(LimitError {
                what: "chunk length",
                ..
            })
        ),
        "{e}"
    );
    let few = Limits {
        max_gaussians: 1000,
        ..Limits::default()
    };
    let e = decode_all_random(&bytes, few.clone()).unwrap_err();
    assert!(
        matches!(
            e,
            Error::Limit(LimitError {
                what: "n_static + n_dynamic",
                ..
            })
        ),
        "{e}"
    );
}

#[test]
fn writer_refuses_misuse_and_encoder_refuses_nan() {
    let mut w = Writer::new(Vec::new(), SceneHeader::still(3, 3)).unwrap();
    assert!(w.gop_chunk(ChunkType::CRAW, 0, b"").is_err());
    w.begin_gop().unwrap();
    assert!(w.scene_chunk(ChunkType::META, 0, b"{}").is_err());
    assert!(w.begin_gop().is_err(), "header declares one GOP");
    let w2 = Writer::new(
        Vec::new(),
        SceneHeader {
            gop_count: 2,
            frame_count: 2,
            ..SceneHeader::still(3, 3)
        },
    )
    .unwrap();
    assert!(w2.finish().is_err(), "no GOP written");

    let mut g = load("tiny/metalsplatter_3-points-from-train.ply");
    g.log_scales[1][2] = f32::NAN;
    let e = dlgs_encoder::encode_still(&g, Default::default(), Vec::new()).unwrap_err();
    assert!(e.to_string().contains("log-scale of Gaussian 1"), "{e}");
}

/// Every GOP's chunks draw from one budget: a budget that holds one GOP's buffers decodes a
/// file of many (a fresh budget per GOP), one smaller than a GOP's buffers stops it, and the
/// foreign readers draw the file and its rows from the budget they are given.
#[test]
fn one_budget_per_gop_and_per_foreign_file() {
    let g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let (bytes, want) = multi_gop_file(&g, 3, RawCodec::None);
    // The CRAW body of one GOP (1,971 Gaussians, SH 3, raw f32).
    let body = {
        let mut r = FileReader::open(std::io::Cursor::new(&bytes)).unwrap();
        let c = r.gop_chunks(0).unwrap()[0];
        assert_eq!(c.ty, ChunkType::CRAW);
        let p = r.payload(&c).unwrap();
        let l = Limits::default();
        dlgs::chunks::decode_canonical(c.ty, &p, c.payload_offset(), r.scene(), &l)
            .unwrap()
            .unwrap();
        l.budget.spent()
    };
    assert!(
        body > 0,
        "a chunk decoder draws from the budget it is given"
    );
    let one_gop = Limits {
        max_total_alloc: body + body / 2,
        ..Limits::default()
    };
    assert!(
        decode_all_random(&bytes, one_gop.clone()).unwrap() == want,
        "3 GOPs of {body} bytes each within a {}-byte budget per GOP",
        one_gop.max_total_alloc
    );
    assert!(decode_all_stream(&bytes, one_gop).unwrap() == want);
    let short = Limits {
        max_total_alloc: body / 2,
        ..Limits::default()
    };
    for e in [
        decode_all_random(&bytes, short.clone()).unwrap_err(),
        decode_all_stream(&bytes, short).unwrap_err(),
    ] {
        assert!(
            matches!(e, Error::Limit(LimitError { limit, .. }) if limit == body / 2),
            "{e}"
        );
        assert!(e.to_string().contains("one budget"), "{e}");
    }
    // A PLY: its file size and then its vertex rows are drawn from the same budget.
    let path = dlgs_tests::data("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let size = std::fs::metadata(&path).unwrap().len();
    let l = Limits {
        max_total_alloc: size + size / 2,
        ..Limits::default()
    };
    let e = dlgs::interop::read_splat_file_with_limits(&path, &l).unwrap_err();
    assert_eq!(e.name(), "LimitExceeded", "{e}");
    let roomy = Limits {
        max_total_alloc: 3 * size,
        ..Limits::default()
    };
    dlgs::interop::read_splat_file_with_limits(&path, &roomy).unwrap();
    assert!(roomy.budget.spent() >= 2 * size, "file and rows drawn");
}
