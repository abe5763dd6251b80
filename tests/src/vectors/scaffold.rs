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
use dlgs_decoder::scaffold::{ScaffoldDecoder, ViewRequest};
use dlgs_encoder::scaffold::{scaffold_scene, ResidualViewMlps, ScaffoldWriter};

use super::Vector;

pub const VALID: &str = "scaffold-tiny";
/// The residual vector (since 1.17).
pub const RESIDUAL: &str = "scaffold-tiny-residual";
/// Times (s) and camera centre of the listed frames.
pub const TIMES: [f64; 3] = [0.0, 0.85, 1.95];
/// Times of the residual vector's listed frames: all in its GOP 1.
pub const RESIDUAL_TIMES: [f64; 3] = [2.0, 2.85, 3.95];
pub const CAMERA: [f32; 3] = [0.4, -0.3, -2.5];

fn model() -> (
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

pub const AHAC_VALID: &str = "scaffold-ahac-tiny";

/// `AHAC` content (§6.13) for the tiny model's 3 anchors: positions quantised from the 3 real
/// points in a box around them, one-level grids (3D: R 5, 2^4 entries; planes: R 6, 2^5; 2
/// features), `mlp_grid` 8 -> 4 -> 175, generated weights and integers, batches of 2.
pub fn hac_anchors() -> dlgs::chunks::ahac::HacAnchors {
    use dlgs::model::hac_context::{GridShape, HacContext, CONTEXT_OUT};
    let (c, _, d, _) = model();
    let mut rng = fastrand::Rng::with_seed(53);
    let shape = |r: u32, log2: u8| GridShape {
        resolutions: vec![r],
        log2_table: log2,
        features: 2,
    };
    let (grid3, grid2) = (shape(5, 4), shape(6, 5));
    let levels = HacContext::level_bits(&grid3, &grid2)
        .into_iter()
        .map(|n| (0..n).map(|_| rng.bool()).collect())
        .collect();
    let (inputs, hidden) = (8, 4);
    let mut w = |n: usize, s: f32, b: f32| (0..n).map(|_| (rng.f32() - 0.5) * s + b).collect();
    let (bmin, bmax) = (d.bound_min, d.bound_max);
    let quantized = c
        .statics
        .positions
        .iter()
        .chain(&c.dynamics.positions)
        .map(|p| std::array::from_fn(|a| ((p[a] - bmin[a]) / (bmax[a] - bmin[a]) * 65535.0) as u16))
        .collect();
    let context = HacContext {
        grid3,
        grid2,
        bound_min: bmin,
        bound_max: bmax,
        q_base: [0.25, 0.001, 0.05],
        levels,
        hidden,
        w1: w(inputs * hidden, 2.0, 0.0),
        b1: w(hidden, 0.5, 0.2),
        w2: w(hidden * CONTEXT_OUT, 0.5, 0.0),
        b2: w(CONTEXT_OUT, 0.5, 0.5),
    };
    let mut s = |n: usize, lo: i32, hi: i32| (0..3 * n).map(|_| rng.i32(lo..=hi)).collect();
    dlgs::chunks::ahac::HacAnchors {
        n_static: 2,
        n_dynamic: 1,
        batch: 2,
        context,
        quantized,
        symbols: [
            s(FEAT_DIM, -4, 4),
            s(SCALING_DIM, -3100, -2900),
            s(3 * N_OFFSETS, -9, 9),
        ],
    }
}

/// The tiny model with its anchors in `AHAC` instead of `ANCR`.
pub fn ahac_bytes() -> Vec<u8> {
    let (_, m, d, f) = model();
    let scene = scaffold_scene(2, 1, true, 30, 60, 10, 60);
    let mut w = ScaffoldWriter::new(Vec::new(), scene, 19).unwrap();
    w.push_gop_hac(&hac_anchors(), &m, Some((&d, &TfeaBody::Exact(f))))
        .unwrap();
    w.finish().unwrap()
}

/// Offset of batch header `k` (batches x attributes) in the `AHAC` payload: the headers end
/// where the streams start, and the streams end the payload.
fn ahac_batch_header(payload_len: usize, k: usize) -> usize {
    let h = hac_anchors();
    let scene = scaffold_scene(2, 1, true, 30, 60, 10, 60);
    let (_, sizes) = dlgs::chunks::ahac::encode(&h, &scene, 19).unwrap();
    let nb = 2; // 3 anchors in batches of 2
    payload_len - sizes.streams.iter().sum::<usize>() - 36 * nb + 12 * k
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

/// The listed frames: per time, every child's position (3), scale (3), rotation (4), colour (3),
/// colour opacity (1), language opacity (1) and language (9), children in anchor then offset
/// order; preceded by the child count (as f32) so that a reader can check it first. `name`
/// picks the times ([`TIMES`], or [`RESIDUAL_TIMES`] for [`RESIDUAL`]).
pub fn frames(name: &str, bytes: &[u8]) -> Vec<f32> {
    let mut dec =
        ScaffoldDecoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap();
    let mut out = Vec::new();
    let times = if name == RESIDUAL {
        RESIDUAL_TIMES
    } else {
        TIMES
    };
    for t in times {
        let f = dec
            .frame_at(
                t,
                &ViewRequest {
                    camera_center: CAMERA,
                    language: true,
                    visible: None,
                },
            )
            .unwrap();
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
    out
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
