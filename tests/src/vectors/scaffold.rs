//! Conformance vectors of the Scaffold-GS variant (format-spec §6.9-§6.12): a tiny model whose
//! anchors sit at the 3 real points of the tiny scene (their features, offsets, scalings, MLP
//! weights and time features are generated from a fixed seed: no trained model exists here),
//! its frames for listed times and a camera, and damaged copies with the error a reader gives.
//! Since 1.17 also a 2-GOP sequential file whose GOP 1 is an `RNTC` over anchor groups with a
//! language-only `AMLP`.

use dlgs::chunks::tfea::TfeaBody;
use dlgs::container::chunk::encode_header;
use dlgs::model::scaffold::{
    Activation, AnchorDeformMlps, AnchorDeformation, Anchors, Dense, ScaffoldCanonical,
    ScaffoldMlps, TwoLayer, FEAT_DIM, N_OFFSETS, SCALING_DIM,
};
use dlgs::model::TimeFeatures;
use dlgs_decoder::scaffold::{ScaffoldDecoder, ScaffoldStreamDecoder, ViewRequest};
use dlgs_encoder::scaffold::{scaffold_scene, ResidualViewMlps, ScaffoldWriter};

use super::scaffold_ahac::{ahac_batch_header, ahac_dense_bytes, ahac_scope_bytes};
pub use super::scaffold_ahac::{ahac_bytes, hac_anchors, AHAC_DENSE, AHAC_SCOPE, AHAC_VALID};
use super::Vector;

pub const VALID: &str = "scaffold-tiny";
/// The residual vector (since 1.17).
pub const RESIDUAL: &str = "scaffold-tiny-residual";
/// Times (s) and camera centre of the listed frames.
pub const TIMES: [f64; 3] = [0.0, 0.85, 1.95];
/// Times of the residual vector's listed frames: all in its GOP 1.
pub const RESIDUAL_TIMES: [f64; 3] = [2.0, 2.85, 3.95];
pub const CAMERA: [f32; 3] = [0.4, -0.3, -2.5];

pub(super) fn model() -> (
    ScaffoldCanonical,
    ScaffoldMlps,
    AnchorDeformation,
    TimeFeatures,
) {
    let pts = crate::load("tiny/metalsplatter_3-points-from-train.ply").positions;
    let mut rng = fastrand::Rng::with_seed(51);
    let mut next = |scale: f32| (rng.f32() - 0.5) * scale;
    let mut layer = |i: usize, h: usize, o: usize, biased: bool, output: Activation| {
        let mut d = |i: usize, o: usize| Dense {
            inputs: i,
            outputs: o,
            weights: (0..i * o).map(|_| next(2.0 / (i as f32).sqrt())).collect(),
            bias: biased.then(|| (0..o).map(|_| next(0.5) + 0.1).collect()),
        };
        TwoLayer {
            first: d(i, h),
            second: d(h, o),
            output,
        }
    };
    let mlps = ScaffoldMlps {
        opacity: layer(54, 8, 20, true, Activation::Tanh),
        color: layer(54, 8, 30, true, Activation::Sigmoid),
        cov: layer(54, 8, 70, true, Activation::Identity),
        language: Some(layer(54, 8, 90, true, Activation::Identity)),
    };
    let deform = AnchorDeformMlps {
        position: layer(19, 8, 3, false, Activation::Identity),
        feature: layer(16, 8, 50, false, Activation::Identity),
        offsets: layer(16, 8, 30, false, Activation::Identity),
        scaling: layer(16, 8, 6, false, Activation::Identity),
    };
    let mut rng = fastrand::Rng::with_seed(52);
    let mut set = |ids: &[usize]| Anchors {
        positions: ids.iter().map(|&i| pts[i]).collect(),
        features: (0..ids.len() * FEAT_DIM).map(|_| rng.f32() - 0.5).collect(),
        offsets: (0..ids.len() * 3 * N_OFFSETS)
            .map(|_| rng.f32() - 0.5)
            .collect(),
        log_scalings: (0..ids.len() * SCALING_DIM)
            .map(|_| rng.f32() - 3.0)
            .collect(),
    };
    let canonical = ScaffoldCanonical {
        statics: set(&[0, 1]),
        dynamics: set(&[2]),
    };
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &pts {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a] - 0.1);
            hi[a] = hi[a].max(p[a] + 0.1);
        }
    }
    let features = TimeFeatures {
        n: 1,
        keys: 7,
        channels: 16,
        data: (0..7 * 16).map(|_| rng.f32() - 0.5).collect(),
    };
    let deformation = AnchorDeformation {
        bound_min: lo,
        bound_max: hi,
        mlps: deform,
    };
    (canonical, mlps, deformation, features)
}

pub fn valid_bytes() -> Vec<u8> {
    let (c, m, d, f) = model();
    let scene = scaffold_scene(2, 1, true, 30, 60, 10, 60);
    let mut w = ScaffoldWriter::new(Vec::new(), scene, 19).unwrap();
    w.push_gop(&c, &m, Some((&d, &TfeaBody::Exact(f)))).unwrap();
    w.finish().unwrap()
}

/// A small generated `RNTC` field over all three anchor groups (feature, offsets, log_scaling),
/// both sets; random grid bits and MLP weights from a fixed seed.
fn residual_field(lo: [f32; 3], hi: [f32; 3]) -> dlgs::model::ntc::NtcField {
    use bitvec::prelude::*;
    use dlgs::model::ntc::{NtcConfig, NtcField, NtcMlp};
    let config = NtcConfig {
        resolutions: vec![6, 12],
        features: 2,
        log2_table: 5,
        gate_resolution: 5,
        gate_log2_table: 6,
    };
    let mut rng = fastrand::Rng::with_seed(53);
    let mut bits = |n: usize| (0..n).map(|_| rng.bool()).collect::<BitVec<u64, Lsb0>>();
    let planes = (0..3 * config.levels())
        .map(|_| bits(config.level_bits()))
        .collect();
    let gate = bits(config.gate_table());
    let (i, h, o) = (
        config.input_width(),
        6,
        FEAT_DIM + 3 * N_OFFSETS + SCALING_DIM,
    );
    let mut rng = fastrand::Rng::with_seed(54);
    let mut w = |n: usize, s: f32| (0..n).map(|_| (rng.f32() - 0.5) * s).collect::<Vec<f32>>();
    let mlp = NtcMlp {
        inputs: i,
        hidden: h,
        outputs: o,
        w1: w(i * h, 0.8),
        b1: w(h, 0.2),
        w2: w(h * o, 0.3),
        b2: w(o, 0.05),
    };
    NtcField {
        config,
        bound_min: lo,
        bound_max: hi,
        planes,
        gate,
        mlp,
        groups: 0b111,
        sets: 3,
    }
}

/// The residual vector: `scaffold-tiny`'s model as GOP 0, GOP 1 its `RNTC` residual with a
/// language-only `AMLP` (the language MLP's output biases shifted) and the same deformation.
pub fn residual_bytes() -> Vec<u8> {
    let (c, m, d, f) = model();
    let mut scene = scaffold_scene(2, 1, true, 30, 60, 10, 120);
    scene.residual_mode = dlgs::container::ResidualMode::Sequential;
    let mut w = ScaffoldWriter::new(Vec::new(), scene, 19).unwrap();
    let f = TfeaBody::Exact(f);
    w.push_gop(&c, &m, Some((&d, &f))).unwrap();
    let mut lang = m.language.clone().unwrap();
    for b in lang.second.bias.as_mut().unwrap() {
        *b += 0.25;
    }
    let field = residual_field(d.bound_min, d.bound_max);
    w.push_residual_gop(
        &field,
        ResidualViewMlps::LanguageOnly(&lang),
        Some((&d, &f)),
    )
    .unwrap();
    w.finish().unwrap()
}

/// The refresh vector (since 1.17's `refresh_interval`, §4.1): 4 sequential GOPs, every second
/// one intra.
pub const REFRESH: &str = "scaffold-tiny-refresh";
/// Times of the refresh vector's listed frames: in its refresh GOP 2 and in GOP 3, whose
/// reference is GOP 2.
pub const REFRESH_TIMES: [f64; 3] = [4.35, 6.0, 7.95];

/// 4 GOPs of 60 frames, sequential with `refresh_interval` 2: GOP 0 `scaffold-tiny`'s model;
/// GOP 1 the residual vector's `RNTC` with the view MLPs inherited; GOP 2 a refresh GOP (no
/// reference): `ANCR` of other anchors (features halved plus 0.1, offsets mirrored) and a full
/// `AMLP` (colour output biases shifted); GOP 3 the same `RNTC` against GOP 2, its view MLPs
/// inherited from GOP 2. A decoder that chained GOP 3 to GOP 1 would show other anchors and
/// colours.
pub fn refresh_bytes() -> Vec<u8> {
    let (c, m, d, f) = model();
    let mut scene = scaffold_scene(2, 1, true, 30, 60, 10, 240);
    scene.residual_mode = dlgs::container::ResidualMode::Sequential;
    scene.refresh_interval = 2;
    let mut w = ScaffoldWriter::new(Vec::new(), scene, 19).unwrap();
    let f = TfeaBody::Exact(f);
    let field = residual_field(d.bound_min, d.bound_max);
    let mut c2 = c.clone();
    for set in [&mut c2.statics, &mut c2.dynamics] {
        for v in &mut set.features {
            *v = *v * 0.5 + 0.1;
        }
        for v in &mut set.offsets {
            *v = -*v;
        }
    }
    let mut m2 = m.clone();
    for b in m2.color.second.bias.as_mut().unwrap() {
        *b -= 0.3;
    }
    w.push_gop(&c, &m, Some((&d, &f))).unwrap();
    w.push_residual_gop(&field, ResidualViewMlps::Inherit, Some((&d, &f)))
        .unwrap();
    w.push_gop(&c2, &m2, Some((&d, &f))).unwrap();
    w.push_residual_gop(&field, ResidualViewMlps::Inherit, Some((&d, &f)))
        .unwrap();
    w.finish().unwrap()
}

/// The times whose frames vector `name` lists.
pub fn times(name: &str) -> &'static [f64] {
    match name {
        RESIDUAL => &RESIDUAL_TIMES,
        REFRESH => &REFRESH_TIMES,
        _ => &TIMES,
    }
}

/// The listed frames: per time, every child's position (3), scale (3), rotation (4), colour (3),
/// colour opacity (1), language opacity (1) and language (9), children in anchor then offset
/// order; preceded by the child count (as f32) so that a reader can check it first. `name`
/// picks the times ([`times`]).
pub fn frames(name: &str, bytes: &[u8]) -> Vec<f32> {
    let mut dec =
        ScaffoldDecoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap();
    let mut out = Vec::new();
    for &t in times(name) {
        push_frame(&mut out, &dec.frame_at(t, &VIEW).unwrap());
    }
    out
}

/// The view of the listed frames.
const VIEW: ViewRequest = ViewRequest {
    camera_center: CAMERA,
    language: true,
    visible: None,
};

/// One listed frame: the child count (as f32), then each child's values.
fn push_frame(out: &mut Vec<f32>, f: &dlgs_decoder::scaffold::NeuralGaussians) {
    out.push(f.len() as f32);
    for i in 0..f.len() {
        out.extend_from_slice(&f.positions[i]);
        out.extend_from_slice(&f.scales[i]);
        out.extend_from_slice(&f.rotations[i]);
        out.extend_from_slice(&f.colors[i]);
        out.push(f.opacity[i]);
        out.push(f.lang_opacity[i]);
        out.extend_from_slice(&f.lang[9 * i..9 * i + 9]);
    }
}

/// As [`frames`] through the in-order [`ScaffoldStreamDecoder`] (every GOP decoded as it
/// arrives, the index and tail checked at the end), or the error it stops with.
pub fn stream_frames(name: &str, bytes: &[u8]) -> dlgs::Result<Vec<f32>> {
    let mut dec = ScaffoldStreamDecoder::new(bytes, dlgs::Limits::default())?;
    let mut gops = Vec::new();
    while let Some(g) = dec.next_gop()? {
        gops.push(g);
    }
    let mut out = Vec::new();
    for &t in times(name) {
        let tp = dec.scene().locate(t)?;
        push_frame(
            &mut out,
            &gops[tp.gop as usize].frame(tp.key, tp.delta, &VIEW),
        );
    }
    Ok(out)
}

/// Replace the payload of the first chunk of type `ty` with `f(payload)`, keeping the CRCs
/// valid, so a reader meets the fault in the payload itself.
fn patch(bytes: &[u8], ty: &[u8; 4], f: impl Fn(&mut Vec<u8>)) -> Vec<u8> {
    let mut r = dlgs::container::FileReader::open(std::io::Cursor::new(bytes.to_vec())).unwrap();
    let c = (0..r.scene().gop_count)
        .flat_map(|g| r.gop_chunks(g).unwrap())
        .find(|c| &c.ty.0 == ty)
        .unwrap();
    let mut payload = r.payload(&c).unwrap();
    let len = payload.len();
    f(&mut payload);
    assert_eq!(
        payload.len(),
        len,
        "a patch keeps the payload's length (the GOP index)"
    );
    let at = c.offset as usize;
    let end = c.payload_offset() as usize + c.len as usize + 4;
    let mut out = bytes[..at].to_vec();
    out.extend_from_slice(&encode_header(c.ty, c.flags, c.gop, payload.len() as u64));
    out.extend_from_slice(&payload);
    out.extend_from_slice(&crc32c::crc32c(&payload).to_le_bytes());
    out.extend_from_slice(&bytes[end..]);
    out
}

/// `bytes` with `HEAD`'s payload edited (same length, CRC made valid again).
fn patch_head(bytes: &[u8], f: impl Fn(&mut [u8])) -> Vec<u8> {
    let mut out = bytes.to_vec();
    let len = u64::from_le_bytes(out[24..32].try_into().unwrap()) as usize;
    let p = 12 + 24;
    f(&mut out[p..p + len]);
    let crc = crc32c::crc32c(&out[p..p + len]);
    out[p + len..p + len + 4].copy_from_slice(&crc.to_le_bytes());
    out
}

/// `scaffold-tiny` with its GOP's chunks in the order `ANCR`, `ADEF`, `TFEA`, `AMLP` (§3.3:
/// `AMLP` comes before `ADEF`; `Order`). Every payload is `scaffold-tiny`'s.
fn chunk_order_bytes() -> Vec<u8> {
    use dlgs::chunks::{adef, amlp, ancr, tfea};
    use dlgs::container::{ChunkType, Writer, FLAG_MUST_UNDERSTAND};
    let (c, m, d, f) = model();
    let scene = scaffold_scene(2, 1, true, 30, 60, 10, 60);
    let mut w = Writer::new(Vec::new(), scene.clone()).unwrap();
    w.begin_gop().unwrap();
    for (ty, p) in [
        (ChunkType::ANCR, ancr::encode(&c, &scene, 19).unwrap()),
        (ChunkType::ADEF, adef::encode(&d, 19).unwrap()),
        (
            ChunkType::TFEA,
            tfea::encode(&TfeaBody::Exact(f), 19).unwrap(),
        ),
        (ChunkType::AMLP, amlp::encode(&m, &scene, 19).unwrap()),
    ] {
        w.gop_chunk(ty, FLAG_MUST_UNDERSTAND, &p).unwrap();
    }
    w.finish().unwrap()
}

/// The path each path vector of [`all`] exists for, checked on its bytes: `Err` says what
/// changed; `None` for the other vectors.
pub fn claims(name: &str, bytes: &[u8]) -> Option<Result<(), String>> {
    use dlgs::container::{ChunkType, FileReader, NO_REFERENCE};
    let mut r = FileReader::open(std::io::Cursor::new(bytes)).unwrap();
    let mut gops = Vec::new();
    for g in 0..r.scene().gop_count {
        let chunks = r.gop_chunks(g).unwrap();
        let payloads: Vec<(ChunkType, Vec<u8>)> = chunks
            .iter()
            .map(|c| (c.ty, r.payload(c).unwrap()))
            .collect();
        gops.push((r.gop_entry(g).unwrap().header.reference_gop, payloads));
    }
    let ahac = || {
        let (_, p) = gops[0]
            .1
            .iter()
            .find(|(t, _)| *t == ChunkType::AHAC)
            .unwrap();
        p.clone()
    };
    let ok = |holds: bool, what: &str| {
        if holds {
            Ok(())
        } else {
            Err(format!("{name}: {what}"))
        }
    };
    Some(match name {
        AHAC_SCOPE => ok(ahac()[54] == 1, "AHAC scope is not 1"),
        AHAC_DENSE => {
            // §6.13.1: L3, T3 at 48, 49; L2, T2 at 51, 52; then L3 + L2 u32 resolutions.
            let p = ahac();
            let res = |k: usize| u32::from_le_bytes(p[56 + 4 * k..60 + 4 * k].try_into().unwrap());
            let (l3, t3, l2, t2) = (p[48] as usize, p[49], p[51] as usize, p[52]);
            let dense3 = (0..l3).all(|k| (res(k) as u64).pow(3) <= 1 << t3);
            let dense2 = (l3..l3 + l2).all(|k| (res(k) as u64).pow(2) <= 1 << t2);
            ok(
                l3 > 0 && l2 > 0 && dense3 && dense2,
                "an AHAC grid level is hashed",
            )
        }
        REFRESH => {
            let types = |g: usize| gops[g].1.iter().map(|(t, _)| *t).collect::<Vec<_>>();
            let refs: Vec<u32> = gops.iter().map(|(r, _)| *r).collect();
            ok(
                refs == [NO_REFERENCE, 0, NO_REFERENCE, 2]
                    && types(2)[..2] == [ChunkType::ANCR, ChunkType::AMLP]
                    && types(3)[0] == ChunkType::RNTC
                    && !types(3).contains(&ChunkType::AMLP),
                "GOP 2 is not a refresh GOP with its own anchors and view MLPs, or GOP 3 not a residual of it",
            )
        }
        _ => return None,
    })
}

pub fn all() -> Vec<Vector> {
    let good = valid_bytes();
    let residual = residual_bytes();
    let ahac = ahac_bytes();
    vec![
        Vector {
            name: AHAC_VALID,
            bytes: ahac.clone(),
            error: None,
            about: "scaffold-tiny with its anchors HAC-coded (AHAC, since 1.17): the 3 real points quantised, one-level binary grids, mlp_grid 8->4->175, generated integers in batches of 2 (one log-scaling alphabet of ~200); its frames in scaffold-ahac-tiny.frames.f32",
        },
        Vector {
            name: AHAC_SCOPE,
            bytes: ahac_scope_bytes(),
            error: None,
            about: "scaffold-ahac-tiny's grid shapes with grid bits, mlp_grid weights and integers from the first seed whose grid bits code smaller with one 1-bit frequency per grid group (scope 1, §6.13.4: the 3D level alone, the xy, xz, yz levels together) than with each level's own; its frames in scaffold-ahac-scope.frames.f32",
        },
        Vector {
            name: AHAC_DENSE,
            bytes: ahac_dense_bytes(),
            error: None,
            about: "scaffold-ahac-tiny with dense context grids (§6.13.5 as §6.6.4: entry sum k_d R^d, not the hash): the 3D level R 4 in 2^6 entries (4^3 = 64), the planes R 5 in 2^5 (25 <= 32); its frames in scaffold-ahac-dense.frames.f32",
        },
        Vector {
            name: "x-ahac-alphabet",
            bytes: patch(&ahac, b"AHAC", |p| {
                let at = ahac_batch_header(p.len(), 0);
                p[at + 4..at + 8].copy_from_slice(&70_000i32.to_le_bytes());
            }),
            error: Some("Payload"),
            about: "scaffold-ahac-tiny with batch 0's feature alphabet over 2^16 (hi = 70000)",
        },
        Vector {
            name: "x-ahac-stream-bytes",
            bytes: patch(&ahac, b"AHAC", |p| {
                let at = ahac_batch_header(p.len(), 1) + 8;
                let b = u32::from_le_bytes(p[at..at + 4].try_into().unwrap());
                p[at..at + 4].copy_from_slice(&(b + 2).to_le_bytes());
            }),
            error: Some("Payload"),
            about: "scaffold-ahac-tiny with batch 0's log-scaling stream length not a multiple of 4",
        },
        Vector {
            name: VALID,
            bytes: good.clone(),
            error: None,
            about: "Scaffold-GS (variant 1, since 1.16): 2 static + 1 dynamic anchors at the tiny scene's 3 real points, generated features, offsets, scalings, view MLPs (hidden 8, language) and deformation MLPs, exact TFEA; its frames in scaffold-tiny.frames.f32",
        },
        Vector {
            name: "x-scaffold-anchor-count",
            bytes: patch(&good, b"ANCR", |p| p[4] = 3),
            error: Some("Payload"),
            about: "scaffold-tiny with ANCR declaring 3 static anchors (HEAD says 2)",
        },
        Vector {
            name: "x-scaffold-language-flag",
            bytes: patch(&good, b"AMLP", |p| p[0] = 0),
            error: Some("Payload"),
            about: "scaffold-tiny with AMLP saying no language MLP in a scene with language",
        },
        Vector {
            name: "x-scaffold-box",
            bytes: patch(&good, b"ADEF", |p| p[12..16].copy_from_slice(&(-1e30f32).to_le_bytes())),
            error: Some("Payload"),
            about: "scaffold-tiny with an ADEF box whose max is below its min on axis 0",
        },
        Vector {
            name: RESIDUAL,
            bytes: residual.clone(),
            error: None,
            about: "Scaffold-GS residual GOPs (since 1.17): scaffold-tiny's model as GOP 0, then a sequential GOP 1 with an RNTC over the anchor groups feature, offsets and log_scaling (2 plane levels R 6, 12 of 2^5 entries x 2 features, gate R 5 of 2^6, MLP 12 -> 6 -> 86, random bits and weights) and a language-only AMLP (flags 3); its GOP-1 frames in scaffold-tiny-residual.frames.f32",
        },
        Vector {
            name: REFRESH,
            bytes: refresh_bytes(),
            error: None,
            about: "Scaffold-GS refresh GOPs (refresh_interval 2, since 1.17): 4 sequential GOPs; GOP 0 scaffold-tiny's model, GOP 1 scaffold-tiny-residual's RNTC with the view MLPs inherited, GOP 2 a refresh GOP (no reference: ANCR of other anchors, features halved plus 0.1 and offsets mirrored, and a full AMLP with the colour biases shifted), GOP 3 the same RNTC against GOP 2 with GOP 2's view MLPs inherited; its frames (in GOPs 2 and 3) in scaffold-tiny-refresh.frames.f32",
        },
        Vector {
            name: "x-scaffold-chunk-order",
            bytes: chunk_order_bytes(),
            error: Some("Order"),
            about: "scaffold-tiny's GOP with its chunks in the order ANCR, ADEF, TFEA, AMLP (AMLP comes before ADEF, §3.3, since 1.18 an error)",
        },
        Vector {
            name: "x-scaffold-residual-group",
            bytes: patch(&residual, b"RNTC", |p| p[0] = 0b1111),
            error: Some("Payload"),
            about: "scaffold-tiny-residual with RNTC groups 0x0f: bit 3 is no anchor group",
        },
        Vector {
            name: "x-scaffold-parallel",
            bytes: patch_head(&residual, |p| p[1] = 2),
            error: Some("Payload"),
            about: "scaffold-tiny-residual with HEAD residual_mode 2 (parallel), not defined for Scaffold-GS (its GOP index is the same as sequential's with 2 GOPs)",
        },
    ]
}
