//! The conformance vectors of format-spec/vectors, built from real data. `gen_vectors` writes
//! them; `tests/conformance.rs` checks the committed files equal what this code builds and
//! that readers give the listed checksums or errors.

use dlgs::chunks::craw::{self, RawCodec};
use dlgs::container::chunk::encode_header;
use dlgs::container::{ChunkInfo, ChunkType, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
use dlgs::Canonical;

use crate::{load, multi_gop_file, with_synthetic_language};

mod dynamic;
pub mod errors;
pub mod paths;
pub mod scaffold;
pub mod scaffold_ahac;

pub use dynamic::dynamic_frames;
use dynamic::*;

pub struct Vector {
    pub name: &'static str,
    pub bytes: Vec<u8>,
    /// Valid: None. Invalid: the error name a reader must give.
    pub error: Option<&'static str>,
    pub about: &'static str,
}

fn still(c: &Canonical, scene: SceneHeader, codec: RawCodec) -> Vec<u8> {
    let mut w = Writer::new(Vec::new(), scene).unwrap();
    w.begin_gop().unwrap();
    w.gop_chunk(
        ChunkType::CRAW,
        FLAG_MUST_UNDERSTAND,
        &craw::encode(c, codec, 19).unwrap(),
    )
    .unwrap();
    w.finish().unwrap()
}

/// Re-encode the chunk header at `at` with a new length (keeping its CRC valid).
fn set_len(b: &mut [u8], at: usize, len: u64) {
    let ty = ChunkType(b[at..at + 4].try_into().unwrap());
    let flags = u16::from_le_bytes([b[at + 4], b[at + 5]]);
    let gop = u32::from_le_bytes(b[at + 8..at + 12].try_into().unwrap());
    b[at..at + 24].copy_from_slice(&encode_header(ty, flags, gop, len));
}

pub fn all() -> Vec<Vector> {
    let tiny = load("tiny/metalsplatter_3-points-from-train.ply");
    let tiny_c = Canonical::from_static(tiny.clone());
    let tiny_scene = SceneHeader::still(3, 3);
    let base = still(&tiny_c, tiny_scene.clone(), RawCodec::None);
    let lod3 = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    let lang = with_synthetic_language(&tiny);
    let mut lang_scene = SceneHeader::still(3, 3);
    lang_scene.lang_levels = 3;
    lang_scene.lang_dims = 3;

    let mut v = vec![
        Vector {
            name: "tiny-still",
            bytes: base.clone(),
            error: None,
            about: "3 real Gaussians (SH 3), one GOP, raw CRAW; the annotated example of the spec",
        },
        Vector {
            name: "tiny-3gop-zstd",
            bytes: multi_gop_file(&tiny, 3, RawCodec::Zstd).0,
            error: None,
            about: "3 intra GOPs, zstd CRAW, META and unknown ancillary XTRA chunks to skip",
        },
        Vector {
            name: "tiny-language",
            bytes: still(
                &Canonical::from_static(lang.clone()),
                lang_scene,
                RawCodec::None,
            ),
            error: None,
            about: "language opacity and 3x3 language features",
        },
        Vector {
            name: "lod3-still-zstd",
            bytes: still(
                &Canonical::from_static(lod3.clone()),
                SceneHeader::still(1971, 3),
                RawCodec::Zstd,
            ),
            error: None,
            about: "a real 1971-Gaussian scene (GaussianSplats3D lod3 tile, MIT)",
        },
    ];
    v.push(Vector {
        name: "lod3-csog-medium",
        bytes: csog_layout0(&lod3),
        error: None,
        about: "the lod3 scene as sorted quantised grids (CSOG layout 0, grid positions, preset medium, default sort; written by the library, as `dlgs encode` writes layout 1 since 2026-11-25)",
    });
    v.push(Vector {
        name: "lod3-csog-tiered",
        bytes: csog(&lod3, vec![0.1, 0.02], false, None, false),
        error: None,
        about: "the lod3 scene as CSOG layout 1 (since 1.8, grid positions): preset medium, the least important Gaussians holding 10 % of the blending weight one bit coarser and those holding 2 % two bits coarser, three parts; the empty dynamic set as 0 parts (since 1.12)",
    });
    v.push(Vector {
        name: "lod3-csog-octree",
        bytes: csog(&lod3, vec![0.1], true, None, false),
        error: None,
        about: "the lod3 scene as CSOG layout 2 (since 1.10): octree positions, the order derived from them; preset medium, the least important Gaussians holding 10 % of the blending weight one bit coarser, two parts",
    });
    v.push(Vector {
        name: "lod3-csog-coarse-rot",
        bytes: csog(&lod3, vec![0.1], true, Some(COARSE_ROTATIONS), false),
        error: None,
        about: "the lod3 scene as CSOG layout 3 (since 1.11): lod3-csog-octree with coarse rotations (factor 16, max shift 4): each part's small Gaussians store rotations up to 4 bits coarser, the rotation records' cells grouped by shift",
    });
    v.push(Vector {
        name: "lod3-csog-compact",
        bytes: csog(&lod3, vec![0.1], true, Some(COARSE_ROTATIONS), true),
        error: None,
        about: "the lod3 scene as CSOG layout 4 (since 1.14): lod3-csog-coarse-rot in compact records (varint counts and lengths, binary16 ranges, no word counts); what `dlgs encode --max-compression` writes (the default since 1.18 leaves codec 5's mixed modes out)",
    });
    v.push(Vector {
        name: DYNAMIC_VECTOR,
        bytes: dynamic_vector(&lod3),
        error: None,
        about: "2 GOPs of 60 frames, 128 of 512 lod3 Gaussians animated by the synthetic generator (no trained DLGStream model exists here), language, exact TFEA, f32 MLPW; decoded frames in lod3-dynamic.frames.f32",
    });
    v.push(Vector {
        name: INTRA_VECTOR,
        bytes: dynamic_intra_vector(&lod3),
        error: None,
        about: "lod3-dynamic's model with its time features as intra-only 12-bit HEVC (TFEA codec 3, since 1.7: one IDR picture with its own parameter sets per key; libx265 crf 6, preset ultrafast); decoded frames in lod3-dynamic-intra.frames.f32",
    });
    v.push(Vector {
        name: LAED_VECTOR,
        bytes: laed_vector(&lang),
        error: None,
        about: "tiny-language plus a scene-level LAED chunk: a 3 -> 8 -> 16 ReLU decoder with biases in f16 and two named negatives; decoded embeddings in tiny-laed.embeddings.f32",
    });
    v.push(Vector {
        name: "lod3-residuals",
        bytes: residual_vector(&lod3),
        error: None,
        about: "3 sequential GOPs of 512 lod3 Gaussians: GOP 0 CRAW, GOP 1 a generated binary voxel residual field (RNTC, small grids), GOP 2 explicit residuals (RDLT: positions within 1e-4, SH DC within 2e-3, the rest exact); exact TFEA",
    });
    v.push(Vector {
        name: "lod3-refresh",
        bytes: refresh_vector(&lod3),
        error: None,
        about: "4 sequential GOPs of 10 frames (keys every 5) of 512 lod3 Gaussians at SH degree 0 with refresh_interval 2 (since 1.17): GOP 0 CRAW, GOP 1 a generated RNTC field, GOP 2 a refresh GOP (CRAW of the state GOP 1's field applied twice gives; no reference), GOP 3 an RNTC field against GOP 2; exact TFEA",
    });
    v.extend(paths::all(&lod3));
    let life = &v
        .iter()
        .find(|v| v.name == paths::LIFE_VECTOR)
        .unwrap()
        .bytes;
    let life_index = rewrite(life, |g, c, p| match (g, c.ty) {
        (0, ChunkType::LIFE) => {
            // One entry whose index (gap 32 from 0) is n_dynamic: past the dynamic set.
            let mut raw = 32u32.to_le_bytes().to_vec();
            raw.extend([0, 0, 0, 0]);
            let mut p = 1u32.to_le_bytes().to_vec();
            p.extend(dlgs::bytes::zstd_compress(&raw, 19).unwrap());
            vec![(c.ty, c.flags, p)]
        }
        _ => vec![(c.ty, c.flags, p)],
    });
    let mut bad = |name, error, about, f: &dyn Fn(&mut Vec<u8>)| {
        let mut b = base.clone();
        f(&mut b);
        v.push(Vector {
            name,
            bytes: b,
            error: Some(error),
            about,
        });
    };
    bad("x-bad-magic", "BadMagic", "first byte is not 0x89", &|b| {
        b[0] = b'P'
    });
    bad(
        "x-version-2",
        "UnsupportedVersion",
        "major version 2",
        &|b| b[8] = 2,
    );
    bad(
        "x-head-header-crc",
        "HeaderCrc",
        "HEAD chunk header byte changed without fixing its CRC",
        &|b| b[12 + 8] ^= 1,
    );
    bad(
        "x-head-payload-crc",
        "PayloadCrc",
        "HEAD payload byte changed without fixing the payload CRC",
        &|b| b[12 + 24 + 16] ^= 1,
    );
    bad(
        "x-truncated",
        "MissingChunk",
        "file cut 10 bytes before its end: no valid TAIL",
        &|b| b.truncate(b.len() - 10),
    );
    bad(
        "x-huge-chunk",
        "LimitExceeded",
        "HEAD declares a 2^40-byte payload (header CRC valid)",
        &|b| set_len(b, 12, 1 << 40),
    );
    bad(
        "x-chunk-past-end",
        "Truncated",
        "HEAD declares more payload than the file holds (header CRC valid)",
        &|b| {
            let n = b.len() as u64;
            set_len(b, 12, n)
        },
    );
    let mut sh4 = tiny_scene.clone();
    sh4.sh_degree = 4;
    v.push(Vector {
        name: "x-sh-degree-4",
        bytes: still_unchecked(&tiny_c, sh4),
        error: Some("InvalidField"),
        about: "HEAD sh_degree 4 (v1 allows 0..=3)",
    });
    let mut wrong = tiny_scene.clone();
    wrong.n_static = 4;
    v.push(Vector {
        name: "x-count-mismatch",
        bytes: still_unchecked(&tiny_c, wrong),
        error: Some("Payload"),
        about: "HEAD says 4 static Gaussians, CRAW holds 3",
    });
    let mut w = Writer::new(Vec::new(), tiny_scene.clone()).unwrap();
    w.begin_gop().unwrap();
    w.gop_chunk(ChunkType(*b"Q9ZZ"), FLAG_MUST_UNDERSTAND, b"future")
        .unwrap();
    w.gop_chunk(
        ChunkType::CRAW,
        FLAG_MUST_UNDERSTAND,
        &craw::encode(&tiny_c, RawCodec::None, 0).unwrap(),
    )
    .unwrap();
    v.push(Vector {
        name: "x-unknown-critical",
        bytes: w.finish().unwrap(),
        error: Some("UnknownCriticalChunk"),
        about: "a must-understand chunk type this version does not define",
    });
    v.push(Vector {
        name: "x-life-index",
        bytes: life_index,
        error: Some("Payload"),
        about: "lod3-dynamic-life with GOP 0's LIFE holding one entry for dynamic Gaussian 32 (gap 32) of 32: an index >= n_dynamic (§6.14)",
    });
    v.extend(errors::all(&base, &tiny_c, &tiny_scene));
    v
}

/// `bytes` written again through the library's reader and writer, each known chunk of GOP `g`
/// replaced by what `f(g, chunk, payload)` gives (type, flags, payload), in that order; scene
/// chunks kept. Every CRC and the index are valid: a reader meets only the edit.
pub(crate) fn rewrite(
    bytes: &[u8],
    f: impl Fn(u32, &ChunkInfo, Vec<u8>) -> Vec<(ChunkType, u16, Vec<u8>)>,
) -> Vec<u8> {
    let mut r = dlgs::FileReader::open(std::io::Cursor::new(bytes)).unwrap();
    let mut w = Writer::new(Vec::new(), r.scene().clone()).unwrap();
    for c in r.scene_chunks().to_vec() {
        w.scene_chunk(c.ty, c.flags, &r.payload(&c).unwrap())
            .unwrap();
    }
    for g in 0..r.scene().gop_count {
        w.begin_gop().unwrap();
        for c in r.gop_chunks(g).unwrap() {
            let p = r.payload(&c).unwrap();
            for (ty, flags, p) in f(g, &c, p) {
                w.gop_chunk(ty, flags, &p).unwrap();
            }
        }
    }
    w.finish().unwrap()
}

/// Like `still`, for headers that disagree with the payload (the writer does not check).
fn still_unchecked(c: &Canonical, scene: SceneHeader) -> Vec<u8> {
    let mut w = Writer::new(Vec::new(), scene).unwrap();
    w.begin_gop().unwrap();
    w.gop_chunk(
        ChunkType::CRAW,
        FLAG_MUST_UNDERSTAND,
        &craw::encode(c, RawCodec::None, 0).unwrap(),
    )
    .unwrap();
    w.finish().unwrap()
}

/// The language-decoder vector's name; its decoded embeddings are in
/// `valid/<name>.embeddings.f32`.
pub const LAED_VECTOR: &str = "tiny-laed";

/// A small decoder with every feature of §6.8: two layers, biases, negatives; f16 values.
fn small_lang_decoder() -> dlgs::model::lang_decoder::LangDecoder {
    use dlgs::model::lang_decoder::{DenseLayer, LangDecoder, NamedEmbedding};
    let wave =
        |n: usize, f: f32| -> Vec<f32> { (0..n).map(|i| ((i as f32 + 1.0) * f).sin()).collect() };
    let unit = |v: Vec<f32>| {
        let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        v.into_iter().map(|x| x / n).collect::<Vec<f32>>()
    };
    LangDecoder {
        layers: vec![
            DenseLayer {
                inputs: 3,
                outputs: 8,
                weight: wave(24, 0.7),
                bias: wave(8, 1.3).iter().map(|b| b * 0.1).collect(),
            },
            DenseLayer {
                inputs: 8,
                outputs: 16,
                weight: wave(128, 0.37),
                bias: wave(16, 2.1).iter().map(|b| b * 0.1).collect(),
            },
        ],
        negatives: vec![
            NamedEmbedding {
                name: "object".into(),
                values: unit(wave(16, 0.9)),
            },
            NamedEmbedding {
                name: "things".into(),
                values: unit(wave(16, 1.7)),
            },
        ],
    }
}

fn laed_vector(lang: &dlgs::Gaussians) -> Vec<u8> {
    use dlgs::chunks::mlpw::WeightType;
    use dlgs::model::lang_decoder::LangDecoder;
    let mut scene = SceneHeader::still(lang.len() as u32, lang.sh_degree);
    scene.lang_levels = 3;
    scene.lang_dims = 3;
    let d: LangDecoder = small_lang_decoder();
    let mut w = Writer::new(Vec::new(), scene).unwrap();
    w.scene_chunk(
        ChunkType::LAED,
        0,
        &dlgs::chunks::laed::encode(&d, WeightType::F16, 19).unwrap(),
    )
    .unwrap();
    w.begin_gop().unwrap();
    w.gop_chunk(
        ChunkType::CRAW,
        FLAG_MUST_UNDERSTAND,
        &craw::encode(&Canonical::from_static(lang.clone()), RawCodec::None, 19).unwrap(),
    )
    .unwrap();
    w.finish().unwrap()
}

/// What a decoder must produce from the LAED vector, f32: for every Gaussian of GOP 0 in file
/// order and every language level, the decoded (L2-normalised) embedding; then every
/// negative's values.
pub fn laed_embeddings(bytes: &[u8]) -> Vec<f32> {
    let mut dec =
        dlgs_decoder::Decoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap();
    let ld = dec.lang_decoder().unwrap().expect("an LAED chunk");
    let g = dec.gop_canonical(0).unwrap();
    let dims = ld.input_dims();
    let mut out = Vec::new();
    let mut e = vec![0.0; ld.embed_dims()];
    for i in 0..g.statics.len() {
        for level in g.statics.lang_of(i).chunks_exact(dims) {
            ld.decode_one(level, &mut e);
            out.extend(&e);
        }
    }
    for n in &ld.negatives {
        out.extend(&n.values);
    }
    out
}

/// Lines of `expected.txt` for a valid vector: `name gop sha256`.
pub fn expected_lines(v: &Vector) -> Vec<String> {
    let gops = crate::decode_all_random(&v.bytes, dlgs::Limits::default()).unwrap();
    gops.iter()
        .enumerate()
        .map(|(g, c)| format!("{} {g} {}", v.name, craw::canonical_digest(c)))
        .collect()
}

/// The dynamic vector's name; its decoded frames are in `valid/<name>.frames.f32`.
pub const DYNAMIC_VECTOR: &str = "lod3-dynamic";
/// The same model with intra-only HEVC time features (`TFEA` codec 3); frames listed likewise.
pub const INTRA_VECTOR: &str = "lod3-dynamic-intra";
/// Vectors whose decoded frames at [`FRAME_TIMES`] are listed.
pub const FRAME_VECTORS: [&str; 8] = [
    DYNAMIC_VECTOR,
    INTRA_VECTOR,
    paths::LERP_VECTOR,
    paths::HEVC_VECTOR,
    paths::HEVC_REFERENCE_VECTOR,
    paths::LIFE_VECTOR,
    paths::QUANTISED_VECTOR,
    paths::QUANTISED_KEYS_VECTOR,
];
/// Vectors holding libx265 output, which may differ between x265 builds: the conformance test
/// checks their frames against the listed ones instead of their bytes against the generator's.
pub const X265_VECTORS: [&str; 3] = [
    INTRA_VECTOR,
    paths::HEVC_VECTOR,
    paths::HEVC_REFERENCE_VECTOR,
];
/// Times (seconds) whose frames the vector lists: a key, between keys, between frames, the
/// first frame of GOP 1, near the end.
pub const FRAME_TIMES: [f64; 5] = [0.0, 0.5, 1.2345, 2.0, 3.95];
/// Camera centre for the view-dependent decoders.
pub const FRAME_CAMERA: [f32; 3] = [0.3, -0.2, -2.5];
/// Largest absolute difference a conforming decoder may show (format-spec §6.4).
pub const FRAME_TOLERANCE: f32 = 2e-4;

/// The lod3 scene as a still `CSOG` at preset medium with these importance tiers, with octree
/// positions (layouts 2-4) or grid positions (layouts 0 and 1).
/// The coarse-rotation vector's setting: a large factor, so every shift class occurs in lod3.
pub const COARSE_ROTATIONS: dlgs::chunks::csog::RotationCoarsening =
    dlgs::chunks::csog::RotationCoarsening {
        factor: 16.0,
        max_shift: 4,
    };

/// Layout 0 (§6.5.2): `dlgs encode` no longer writes it (layout 1 stores an empty dynamic set
/// in one byte), readers must still decode it. The sorted set at `medium`, in a still file.
fn csog_layout0(g: &dlgs::Gaussians) -> Vec<u8> {
    use dlgs::chunks::csog::{self, QuantBits};
    use dlgs_encoder::grid_sort::{grid_order, permute, SortSpec};
    let sorted = permute(g, &grid_order(g, SortSpec::DEFAULT));
    let c = Canonical::from_static(sorted);
    let payload = csog::encode(&c, &QuantBits::MEDIUM, 9).unwrap();
    let mut w = Writer::new(Vec::new(), SceneHeader::still(g.len() as u32, g.sh_degree)).unwrap();
    w.begin_gop().unwrap();
    w.gop_chunk(ChunkType::CSOG, FLAG_MUST_UNDERSTAND, &payload)
        .unwrap();
    w.finish().unwrap()
}

fn csog(
    g: &dlgs::Gaussians,
    tier_weights: Vec<f64>,
    octree_positions: bool,
    rotation_coarsening: Option<dlgs::chunks::csog::RotationCoarsening>,
    compact_records: bool,
) -> Vec<u8> {
    use dlgs_encoder::{CanonicalCodec, EncoderConfig, SortSpec};
    let cfg = EncoderConfig {
        coding: dlgs_encoder::CanonicalSettings {
            codec: CanonicalCodec::Sorted {
                bits: dlgs::chunks::csog::QuantBits::MEDIUM,
                sort: SortSpec::DEFAULT,
            },
            octree_positions,
            rotation_coarsening,
            compact_records,
            // Codec 5's mixed modes where they code smaller (the encoder's default until
            // 2026-12-02): pinned, so the vectors keep exercising them whatever the default.
            mixed_margin: Some(dlgs::chunks::csog::grid_codecs::MIXED_MARGIN),
            ..Default::default()
        },
        still: dlgs_encoder::StillTools {
            tier_weights,
            // lod3's bands 1-3 are zero everywhere; the vectors keep their channel records.
            trim_zero_sh_bands: false,
            ..Default::default()
        },
        ..Default::default()
    };
    dlgs_encoder::encode_still(g, cfg, Vec::new()).unwrap()
}
