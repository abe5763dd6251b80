//! Invalid vectors for the index, the tail, a zstd `CRAW` body and a GOP's chunk rules
//! (format-spec §3.3, §5.2, §5.3, §6.1): each is the valid `tiny-still` with exactly one
//! fault, every other CRC kept valid.

use dlgs::chunks::craw::{self, RawCodec};
use dlgs::container::chunk::encode_header;
use dlgs::container::{ChunkType, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
use dlgs::Canonical;

use super::Vector;

/// CRC-32C (Castagnoli, reflected, as §3.1), written out here so the vectors do not lean on the
/// library's own checksum.
fn crc32c(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0x82F6_3B78
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A whole chunk: header (with its CRC), payload and a valid payload CRC.
fn chunk(ty: ChunkType, flags: u16, gop: u32, payload: &[u8]) -> Vec<u8> {
    let mut c = encode_header(ty, flags, gop, payload.len() as u64).to_vec();
    c.extend_from_slice(payload);
    c.extend_from_slice(&crc32c(payload).to_le_bytes());
    c
}

const SCENE: u32 = u32::MAX;
const TAIL_LEN: usize = 36;

/// `b` with its `GIDX` payload replaced by `f(payload)`; the new `GIDX` starts where the old
/// one did, so the rebuilt `TAIL` holds the same offset. Every CRC is valid.
fn with_gidx(b: &[u8], f: impl Fn(&mut Vec<u8>)) -> Vec<u8> {
    let tail_at = b.len() - TAIL_LEN;
    let gidx_at = u64::from_le_bytes(b[tail_at + 24..tail_at + 32].try_into().unwrap()) as usize;
    let mut idx = b[gidx_at + 24..tail_at - 4].to_vec();
    f(&mut idx);
    let mut out = b[..gidx_at].to_vec();
    out.extend(chunk(ChunkType::GIDX, FLAG_MUST_UNDERSTAND, SCENE, &idx));
    out.extend(chunk(
        ChunkType::TAIL,
        0,
        SCENE,
        &(gidx_at as u64).to_le_bytes(),
    ));
    out
}

/// The invalid vectors of this module, made from `base` (`tiny-still`, one GOP) and its
/// Gaussians.
pub fn all(base: &[u8], tiny: &Canonical, tiny_scene: &SceneHeader) -> Vec<Vector> {
    assert_eq!(crc32c(b"123456789"), 0xE306_9283);
    // The rebuild of an unchanged index is the file itself: the helpers add no other change.
    assert_eq!(with_gidx(base, |_| {}), base);
    let mut craw = craw::encode(tiny, RawCodec::Zstd, 19).unwrap();
    craw.extend_from_slice(&[1, 2, 3, 4]);
    let mut w = Writer::new(Vec::new(), tiny_scene.clone()).unwrap();
    w.begin_gop().unwrap();
    w.gop_chunk(ChunkType::CRAW, FLAG_MUST_UNDERSTAND, &craw)
        .unwrap();
    let trailing = w.finish().unwrap();
    let mut bad_crc = base.to_vec();
    let n = bad_crc.len();
    bad_crc[n - 1] ^= 1;
    // HEAD's payload starts after the signature (12) and its chunk header (24).
    let mut head = base[36..36 + 64].to_vec();
    head[40..44].copy_from_slice(&3u32.to_le_bytes());
    let mut refresh = base[..12].to_vec();
    refresh.extend(chunk(ChunkType::HEAD, FLAG_MUST_UNDERSTAND, SCENE, &head));
    refresh.extend_from_slice(&base[12 + 24 + 64 + 4..]);
    // tiny-still's GOP with more chunks after its CRAW (§3.3): each may appear once, and
    // LIFE only with dynamic Gaussians.
    let craw0 = craw::encode(tiny, RawCodec::None, 19).unwrap();
    let gop_with = |extra: (ChunkType, &[u8])| {
        let mut w = Writer::new(Vec::new(), tiny_scene.clone()).unwrap();
        w.begin_gop().unwrap();
        w.gop_chunk(ChunkType::CRAW, FLAG_MUST_UNDERSTAND, &craw0)
            .unwrap();
        w.gop_chunk(extra.0, FLAG_MUST_UNDERSTAND, extra.1).unwrap();
        w.finish().unwrap()
    };
    let mut no_entries = 0u32.to_le_bytes().to_vec();
    no_entries.extend(dlgs::bytes::zstd_compress(&[], 19).unwrap());
    let mut bad_gop = base.to_vec();
    bad_gop[n - TAIL_LEN..n - TAIL_LEN + 24].copy_from_slice(&encode_header(
        ChunkType::TAIL,
        0,
        0,
        8,
    ));
    vec![
        Vector {
            name: "x-gidx-short",
            bytes: with_gidx(base, |idx| idx.truncate(idx.len() - 8)),
            error: Some("Truncated"),
            about: "GIDX payload of 28 bytes for its 1 entry (4 + 32 x 1 = 36: the last entry's `length` cut off), chunk length and both CRCs valid, TAIL still pointing at it",
        },
        Vector {
            name: "x-gidx-entry",
            bytes: with_gidx(base, |idx| idx[12..16].copy_from_slice(&2u32.to_le_bytes())),
            error: Some("InvalidField"),
            about: "GIDX entry 0 says frame_count 2 where HEAD's one-frame scene gives 1 (payload CRC valid)",
        },
        Vector {
            name: "x-craw-zstd-trailing",
            bytes: trailing,
            error: Some("Decompress"),
            about: "tiny-still's CRAW as codec 1 (zstd) with 4 bytes (01 02 03 04, not a zstd frame) after its one frame; every CRC valid",
        },
        Vector {
            name: "x-refresh-intra",
            bytes: refresh,
            error: Some("InvalidField"),
            about: "tiny-still's HEAD with refresh_interval 3 (offset 40, since 1.17) in an intra scene (only sequential scenes refresh); payload CRC valid",
        },
        Vector {
            name: "x-craw-twice",
            bytes: gop_with((ChunkType::CRAW, &craw0)),
            error: Some("Order"),
            about: "tiny-still's GOP with its CRAW written twice (since 1.18 a chunk type a GOP holds once, given twice, is Order at the second, §3.3)",
        },
        Vector {
            name: "x-life-no-dynamic",
            bytes: gop_with((ChunkType::LIFE, &no_entries)),
            error: Some("Order"),
            about: "tiny-still's GOP with a LIFE chunk (0 entries, a valid payload) after its CRAW in a scene without dynamic Gaussians (n_dynamic 0: Order, §3.3, §6.14)",
        },
        Vector {
            name: "x-tail-payload-crc",
            bytes: bad_crc,
            error: Some("MissingChunk"),
            about: "TAIL's header valid, its payload CRC wrong (the last byte changed); a streaming reader reports PayloadCrc (§5.3)",
        },
        Vector {
            name: "x-tail-gop",
            bytes: bad_gop,
            error: Some("MissingChunk"),
            about: "TAIL's gop field 0 instead of 0xFFFFFFFF (header and payload CRCs valid); a streaming reader reports Order (§5.3)",
        },
    ]
}

/// The error the streaming reader gives where it differs from the random-access reader's
/// (format-spec §5.3: it meets the tail as the next chunk, not as the last 36 bytes).
pub fn stream_error(name: &str) -> Option<&'static str> {
    match name {
        "x-tail-payload-crc" => Some("PayloadCrc"),
        "x-tail-gop" => Some("Order"),
        _ => None,
    }
}
