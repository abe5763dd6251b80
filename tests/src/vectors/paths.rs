//! Valid vectors for decoding paths the encoder's own choices leave out of the other vectors:
//! each `CSOG` grid codec and codec 5's residual modes forced on every channel (§6.5.3),
//! `RDLT` codec 2 (§6.7), `RNTC` scope 1 (§6.6.3) and a dense gate grid (§6.6.4), deform
//! model 1 (§6.4), `TFEA` codecs 1 and 2 (§6.2), `LIFE` (§6.14, since 1.18). [`claims`]
//! checks that each vector still takes its path.

use dlgs::chunks::csog::grid_codecs::{self as grid_coder, GridCodec};
use dlgs::chunks::csog::grid_codecs::{adaptive_encode, AdaptiveMode as Mode, Previous};
use dlgs::chunks::csog::{self, grid_width, quantise_set, QuantBits};
use dlgs::chunks::mlpw::WeightType;
use dlgs::container::header::{DeformModel, ResidualMode};
use dlgs::container::{ChunkType, FileReader, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
use dlgs::Gaussians;

use super::Vector;

/// The first `n` Gaussians of a scene.
fn first(scene: &Gaussians, n: usize) -> Gaussians {
    let mut part = Gaussians::new(scene.sh_degree, scene.lang_width);
    for i in 0..n {
        part.push_from(scene, i);
    }
    part
}

/// How a forced-codec vector codes one channel: (cells, previous channel, the one before it,
/// grid width, bits) -> (codec, data).
type Pick = fn(&[u16], Previous, Previous, usize, u8) -> (GridCodec, Vec<u8>);

/// A still `CSOG` (layout 1: one static part, no dynamic parts) of `g` in grid order at `LOW`
/// bits (every channel at most 12 bits, so codec 3's alphabet always fits), each channel coded
/// as `pick` says rather than by the encoder's smallest-wins choice.
fn csog_forced(g: &Gaussians, pick: Pick) -> Vec<u8> {
    use dlgs_encoder::grid_sort::{grid_order, permute, SortSpec};
    let sorted = permute(g, &grid_order(g, SortSpec::DEFAULT));
    let set = quantise_set(&sorted, &QuantBits::LOW).channels;
    let (n, w) = (sorted.len(), grid_width(sorted.len()));
    let mut p = vec![1u8, 1];
    p.extend((n as u32).to_le_bytes());
    p.extend((w as u32).to_le_bytes());
    p.extend((set.len() as u16).to_le_bytes());
    for (j, (bits, lo, hi, q)) in set.iter().enumerate() {
        let prev = |back: usize| j.checked_sub(back).map(|k| (set[k].3.as_slice(), set[k].0));
        let (codec, data) = pick(q, prev(1), prev(2), w, *bits);
        p.push(*bits);
        p.push(codec as u8);
        p.extend(lo.to_le_bytes());
        p.extend(hi.to_le_bytes());
        p.extend((data.len() as u32).to_le_bytes());
        p.extend(data);
    }
    // The dynamic set: no parts (n_dynamic = 0, since 1.12).
    p.push(0);
    let mut wr = Writer::new(Vec::new(), SceneHeader::still(n as u32, g.sh_degree)).unwrap();
    wr.begin_gop().unwrap();
    wr.gop_chunk(ChunkType::CSOG, FLAG_MUST_UNDERSTAND, &p)
        .unwrap();
    wr.finish().unwrap()
}

fn zstd(q: &[u16], _: Previous, _: Previous, _: usize, bits: u8) -> (GridCodec, Vec<u8>) {
    (GridCodec::Zstd, grid_coder::encode_zstd(q, bits, 19))
}

fn histogram(q: &[u16], _: Previous, _: Previous, _: usize, _: u8) -> (GridCodec, Vec<u8>) {
    let d = grid_coder::encode_histogram(q, 19).expect("at most 4096 symbols");
    (GridCodec::Histogram, d)
}

/// Codec 4 wherever the previous channel has the same bits, else codec 3.
fn histogram_delta(
    q: &[u16],
    prev: Previous,
    p2: Previous,
    w: usize,
    bits: u8,
) -> (GridCodec, Vec<u8>) {
    match prev.filter(|p| p.1 == bits) {
        Some((p, _)) => {
            let d = grid_coder::encode_histogram(&grid_coder::delta(q, p, bits), 19);
            (GridCodec::HistogramDelta, d.expect("at most 4096 symbols"))
        }
        None => histogram(q, prev, p2, w, bits),
    }
}

fn adaptive(
    q: &[u16],
    prev: Previous,
    p2: Previous,
    w: usize,
    bits: u8,
    mode: Mode,
) -> (GridCodec, Vec<u8>) {
    let d = adaptive_encode(q, prev, p2, w, bits, mode).expect("a usable mode");
    (GridCodec::Adaptive, d)
}

/// Codec 5 mode 1 wherever there is a previous channel, else mode 0.
fn mode1(q: &[u16], prev: Previous, p2: Previous, w: usize, bits: u8) -> (GridCodec, Vec<u8>) {
    let mode = match prev {
        Some(_) => Mode::ResidualGivenPrevious,
        None => Mode::Residual,
    };
    adaptive(q, prev, p2, w, bits, mode)
}

/// Codec 5 mode 2 wherever the previous channel has the same bits, else mode 0.
fn mode2(q: &[u16], prev: Previous, p2: Previous, w: usize, bits: u8) -> (GridCodec, Vec<u8>) {
    let mode = match prev {
        Some((_, b)) if b == bits => Mode::ResidualMinusPrevious,
        _ => Mode::Residual,
    };
    adaptive(q, prev, p2, w, bits, mode)
}

/// A small dynamic model (the first 128 lod3 Gaussians, 32 of them moving, 2 GOPs of 60
/// frames, language, f16 MLPW to keep the file small) written with these time features and
/// deform model.
fn small_dynamic(
    scene: &Gaussians,
    features: dlgs_encoder::FeatureCodec,
    deform_model: DeformModel,
    per_gop_range: bool,
) -> (dlgs_testkit::synth::SynthModel, Vec<u8>) {
    use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};
    let spec = SynthSpec {
        dynamic_fraction: 0.25,
        gops: 2,
        language: true,
        deform_model,
        ..Default::default()
    };
    let m = synth_dynamic(&first(scene, 128), &spec).unwrap();
    let cfg = dlgs_encoder::EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features,
            per_gop_range,
            mlp_weights: WeightType::F16,
            ..Default::default()
        },
        ..Default::default()
    };
    let bytes = write_model(&m, cfg, Vec::new()).unwrap();
    (m, bytes)
}

fn quantised(predictor: u8) -> dlgs_encoder::FeatureCodec {
    dlgs_encoder::FeatureCodec::Quantised {
        bits: 10,
        predictor: Some(predictor),
    }
}

fn hevc() -> dlgs_encoder::FeatureCodec {
    dlgs_encoder::FeatureCodec::Hevc(dlgs_encoder::HevcSettings {
        preset: "ultrafast".into(),
        // The vectors' streams predate fast-start GOP 0 streams (x265's own picture types).
        fast_start: dlgs_encoder::FastStart::Off,
        ..Default::default()
    })
}

/// `TFEA` codec 2: libx265's stream of the features tiled with one range for every channel
/// (codec 1 with `per_gop_range`), stored with that range as codec 2's f64 pair. The samples
/// then decode by codec 2's rule (`v16 / 65535`, not codec 1's `q / 4095`): the stored
/// stream is what a reference-implementation model would carry.
fn tfea_reference(scene: &Gaussians) -> Vec<u8> {
    use dlgs::chunks::tfea::{self, TfeaBody};
    let (m, one) = small_dynamic(scene, hevc(), DeformModel::Reference, true);
    let mut r = FileReader::open(std::io::Cursor::new(&one)).unwrap();
    let s = r.scene().clone();
    let cfg = dlgs_encoder::EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: hevc(),
            mlp_weights: WeightType::F16,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut enc = dlgs_encoder::StreamEncoder::new(Vec::new(), s.clone(), cfg).unwrap();
    for (g, d) in m.gops.iter().enumerate() {
        let c = r.gop_chunks(g as u32).unwrap();
        let c = c.iter().find(|c| c.ty == ChunkType::TFEA).unwrap();
        let p = r.payload(c).unwrap();
        let body = tfea::decode(&p, c.payload_offset(), &s, &dlgs::Limits::default()).unwrap();
        let TfeaBody::Hevc {
            tiling,
            ranges,
            packets,
            ..
        } = body
        else {
            panic!("codec 1 expected")
        };
        assert!(ranges.iter().all(|r| *r == ranges[0]), "one range");
        let coded = TfeaBody::Hevc {
            tiling,
            ranges: Vec::new(),
            reference: Some((ranges[0].0 as f64, ranges[0].1 as f64)),
            packets,
            intra: false,
        };
        let canonical = dlgs_encoder::GopCanonical::State(&m.canonical);
        enc.push_coded(canonical, Some(d), Some(&coded)).unwrap();
    }
    enc.finish().unwrap()
}

/// A sequential scene of 2 GOPs (first 128 lod3 Gaussians, 16 moving, exact features, f16
/// MLPW): GOP 0
/// `CRAW`, GOP 1 whatever `second` pushes.
fn residual_scene(
    scene: &Gaussians,
    residual: dlgs_encoder::ResidualConfig,
    second: impl Fn(&mut dlgs_encoder::StreamEncoder<Vec<u8>>, &dlgs_testkit::synth::SynthModel),
) -> Vec<u8> {
    use dlgs_encoder::{GopCanonical, StreamEncoder};
    use dlgs_testkit::synth::{synth_dynamic, SynthSpec};
    let spec = SynthSpec {
        dynamic_fraction: 0.125,
        gops: 2,
        residual_mode: ResidualMode::Sequential,
        ..Default::default()
    };
    let m = synth_dynamic(&first(scene, 128), &spec).unwrap();
    let cfg = dlgs_encoder::EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: dlgs_encoder::FeatureCodec::Exact,
            residual,
            mlp_weights: WeightType::F16,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut enc = StreamEncoder::new(Vec::new(), m.scene.clone(), cfg).unwrap();
    enc.push(GopCanonical::State(&m.canonical), Some(&m.gops[0]))
        .unwrap();
    second(&mut enc, &m);
    enc.finish().unwrap()
}

/// `RDLT` whose position deltas form a smooth ramp over the grid, which codec 2 (predictive)
/// codes smaller than zstd.
fn rdlt_predictive(scene: &Gaussians) -> Vec<u8> {
    use dlgs::model::residual::{AttrGroup, DeltaTarget};
    let residual = dlgs_encoder::ResidualConfig {
        groups: AttrGroup::ALL
            .into_iter()
            .map(|g| match g {
                AttrGroup::Position => (g, DeltaTarget::Bound(1e-4)),
                _ => (g, DeltaTarget::Exact),
            })
            .collect(),
        follow_quantisation: false,
    };
    residual_scene(scene, residual, |enc, m| {
        let mut s1 = m.canonical.clone();
        for set in [&mut s1.statics, &mut s1.dynamics] {
            let w = grid_width(set.len());
            for (i, p) in set.positions.iter_mut().enumerate() {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                p[0] += 0.003 * x + 0.002 * y;
                p[1] -= 0.001 * x * y / w as f32;
                p[2] += 0.004 * y;
            }
        }
        enc.push(dlgs_encoder::GopCanonical::State(&s1), Some(&m.gops[1]))
            .unwrap();
    })
}

/// `RNTC` with small grids whose bits code smaller with one frequency for all plane segments
/// (scope 1) than with each segment's own: the first seed from 0 for which that holds (the
/// encoder codes both ways and keeps the smaller, §6.6.3).
fn rntc_grid_scope(scene: &Gaussians) -> Vec<u8> {
    use dlgs::chunks::rntc::grid_report;
    use dlgs::model::ntc::NtcConfig;
    residual_scene(scene, Default::default(), |enc, m| {
        let small = NtcConfig {
            resolutions: vec![16, 32, 64, 128],
            features: 4,
            log2_table: 10,
            gate_resolution: 18,
            gate_log2_table: 10,
        };
        let field = (0..1000u64)
            .map(|seed| {
                let mut rng = fastrand::Rng::with_seed(seed);
                let mut f =
                    dlgs_testkit::synth::synth_ntc(&m.canonical, &mut rng, 1.0, small.clone());
                // Every plane level as dense as the others (the generator's thin out by level,
                // where each segment's own frequency wins by far): the scopes then differ by
                // the range coder's last words only.
                for p in &mut f.planes {
                    for mut b in p.iter_mut() {
                        *b = rng.bool();
                    }
                }
                f
            })
            .find(|f| {
                let r = grid_report(f);
                let sum = |f: fn(&dlgs::chunks::rntc::SegmentReport) -> usize| {
                    r.iter().map(f).sum::<usize>()
                };
                sum(|s| s.bytes_grid) < sum(|s| s.bytes_segment)
            })
            .expect("a seed where scope 1 wins");
        enc.push(dlgs_encoder::GopCanonical::Ntc(&field), Some(&m.gops[1]))
            .unwrap();
    })
}

/// `RNTC` whose gate grid is dense (`R3^3 <= 2^T3`: R 6 in 2^8 entries, §6.6.4), so the gate
/// is read at `sum k_d R^d` rather than the hash; plane levels dense (16^2 <= 2^10) and hashed
/// (32^2).
fn rntc_dense_gate(scene: &Gaussians) -> Vec<u8> {
    use dlgs::model::ntc::NtcConfig;
    residual_scene(scene, Default::default(), |enc, m| {
        let config = NtcConfig {
            resolutions: vec![16, 32],
            features: 2,
            log2_table: 10,
            gate_resolution: 6,
            gate_log2_table: 8,
        };
        let mut rng = fastrand::Rng::with_seed(79);
        let field = dlgs_testkit::synth::synth_ntc(&m.canonical, &mut rng, 1.0, config);
        enc.push(dlgs_encoder::GopCanonical::Ntc(&field), Some(&m.gops[1]))
            .unwrap();
    })
}

/// The dynamic Gaussians the `LIFE` vector shows for part of a GOP, per GOP: (index, first,
/// last). GOP 0: 3 born at local frame 20, 7 gone after frame 10, 12 never shown; GOP 1: 3 gone
/// after frame 30, 20 born at frame 5.
pub const LIVES: [&[(u32, u16, u16)]; 2] = [
    &[(3, 20, 59), (7, 0, 10), (12, u16::MAX, 0)],
    &[(3, 0, 30), (20, 5, 59)],
];

/// lod3-dynamic-lerp's scene (32 of 128 lod3 Gaussians moving, 2 GOPs of 60 frames, language,
/// exact features, f16 `MLPW`, deform model 1) with a `LIFE` chunk in each GOP ([`LIVES`]).
fn dynamic_life(scene: &Gaussians) -> Vec<u8> {
    use dlgs::model::{Life, Lifetimes};
    use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};
    let spec = SynthSpec {
        dynamic_fraction: 0.25,
        gops: 2,
        language: true,
        deform_model: DeformModel::PaperLerp,
        ..Default::default()
    };
    let mut m = synth_dynamic(&first(scene, 128), &spec).unwrap();
    for (gop, lives) in m.gops.iter_mut().zip(LIVES) {
        let entries = lives
            .iter()
            .map(|&(index, first, last)| Life { index, first, last })
            .collect();
        gop.life = Some(Lifetimes { entries });
    }
    let cfg = dlgs_encoder::EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: dlgs_encoder::FeatureCodec::Exact,
            mlp_weights: WeightType::F16,
            ..Default::default()
        },
        ..Default::default()
    };
    write_model(&m, cfg, Vec::new()).unwrap()
}

/// Names of the vectors that list decoded frames (`valid/<name>.frames.f32`) besides
/// `lod3-dynamic` and `lod3-dynamic-intra`.
pub const LERP_VECTOR: &str = "lod3-dynamic-lerp";
pub const HEVC_VECTOR: &str = "lod3-dynamic-hevc";
pub const HEVC_REFERENCE_VECTOR: &str = "lod3-dynamic-hevc-ref";
/// The `LIFE` vector (since 1.18): its frames show the hidden Gaussians' opacities at `-1e4`.
pub const LIFE_VECTOR: &str = "lod3-dynamic-life";
/// `TFEA` codec 4 (since 1.19): the time features quantised to 10 bits, zstd; stored as they are
/// (predictor 0) and as key differences (predictor 1).
pub const QUANTISED_VECTOR: &str = "lod3-dynamic-quantised";
pub const QUANTISED_KEYS_VECTOR: &str = "lod3-dynamic-quantised-keys";

pub fn all(lod3: &Gaussians) -> Vec<Vector> {
    let part = first(lod3, 256);
    let csog = |name: &'static str, pick: Pick, about: &'static str| Vector {
        name,
        bytes: csog_forced(&part, pick),
        error: None,
        about,
    };
    vec![
        csog("lod3-csog-zstd", zstd, "256 lod3 Gaussians as CSOG layout 1 (grid positions, preset low, no dynamic parts), every channel grid codec 1 (zstd, u8 or u16 LE cells), SH bands 1-3 (all 0) included"),
        csog("lod3-csog-histogram", histogram, "as lod3-csog-zstd, every channel grid codec 3 (histogram: stored order-0 table, range-coded cells)"),
        csog("lod3-csog-histogram-delta", histogram_delta, "as lod3-csog-zstd, every channel whose previous record has the same bits grid codec 4 (histogram of the difference from the previous channel, chains included), the others codec 3"),
        csog("lod3-csog-adaptive-mode1", mode1, "as lod3-csog-zstd, every channel but the first grid codec 5 mode 1 (residual, context from the previous channel's residual class, previous channel of other bits included), the first mode 0"),
        csog("lod3-csog-adaptive-mode2", mode2, "as lod3-csog-zstd, every channel whose previous record has the same bits grid codec 5 mode 2 (residual minus the previous channel's residual), the others mode 0"),
        Vector {
            name: "lod3-rdlt-predictive",
            bytes: rdlt_predictive(lod3),
            error: None,
            about: "2 sequential GOPs of 128 lod3 Gaussians (16 moving, exact TFEA, f16 MLPW): GOP 0 CRAW, GOP 1 an RDLT whose positions (mode 1, bound 1e-4) move by a smooth ramp over the grid, so their delta channels take grid codec 2 (predictive); the other groups exact and unchanged (codec 0)",
        },
        Vector {
            name: "lod3-rntc-grid-scope",
            bytes: rntc_grid_scope(lod3),
            error: None,
            about: "as lod3-rdlt-predictive's scene, GOP 1 a generated RNTC (small grids, every group) whose bits are coded with frequency scope 1 (one 1-bit frequency over all plane segments, §6.6.3)",
        },
        Vector {
            name: "lod3-rntc-dense-gate",
            bytes: rntc_dense_gate(lod3),
            error: None,
            about: "as lod3-rdlt-predictive's scene, GOP 1 a generated RNTC whose gate grid is dense (R 6, 6^3 = 216 <= 2^8 entries: read at sum k_d R^d, not the hash, §6.6.4); plane levels R 16 (dense in 2^10) and R 32 (hashed), 2 features",
        },
        Vector {
            name: LERP_VECTOR,
            bytes: small_dynamic(lod3, dlgs_encoder::FeatureCodec::Exact, DeformModel::PaperLerp, false).1,
            error: None,
            about: "2 GOPs of 60 frames, 32 of 128 lod3 Gaussians animated, language, exact TFEA, f16 MLPW, deform model 1 (the paper's lerp form, §6.4); decoded frames in lod3-dynamic-lerp.frames.f32",
        },
        Vector {
            name: HEVC_VECTOR,
            bytes: small_dynamic(lod3, hevc(), DeformModel::Reference, false).1,
            error: None,
            about: "lod3-dynamic-lerp's scene with deform model 0 and its time features as 12-bit HEVC (TFEA codec 1, one range per channel; libx265 crf 6, preset ultrafast); decoded frames in lod3-dynamic-hevc.frames.f32",
        },
        Vector {
            name: HEVC_REFERENCE_VECTOR,
            bytes: tfea_reference(lod3),
            error: None,
            about: "as lod3-dynamic-hevc with TFEA codec 2 (the reference implementation's dequantisation, one f64 range; the HEVC stream of the features tiled over one range); decoded frames in lod3-dynamic-hevc-ref.frames.f32",
        },
        Vector {
            name: QUANTISED_VECTOR,
            bytes: small_dynamic(lod3, quantised(0), DeformModel::Reference, false).1,
            error: None,
            about: "lod3-dynamic-hevc's scene with its time features quantised per channel to 10 bits and coded with zstd, the samples stored as they are (TFEA codec 4, predictor 0; since 1.19, the web player's codec); decoded frames in lod3-dynamic-quantised.frames.f32",
        },
        Vector {
            name: QUANTISED_KEYS_VECTOR,
            bytes: small_dynamic(lod3, quantised(1), DeformModel::Reference, false).1,
            error: None,
            about: "as lod3-dynamic-quantised, the samples of keys 1.. stored as zigzagged differences from the previous key modulo 2^10 (TFEA codec 4, predictor 1); decoded frames in lod3-dynamic-quantised-keys.frames.f32",
        },
        Vector {
            name: LIFE_VECTOR,
            bytes: dynamic_life(lod3),
            error: None,
            about: "lod3-dynamic-lerp's scene with a LIFE chunk in each GOP (since 1.18, §6.14): GOP 0 dynamic Gaussian 3 born at local frame 20, 7 gone after frame 10, 12 never shown (first 0xFFFF, last 0); GOP 1 3 gone after frame 30, 20 born at frame 5; decoded frames in lod3-dynamic-life.frames.f32, where the hidden Gaussians' colour and language opacities are -1e4",
        },
    ]
}

/// The payloads of every chunk of type `ty` in the GOPs of `bytes`.
fn payloads(bytes: &[u8], ty: ChunkType) -> (SceneHeader, Vec<(u64, Vec<u8>)>) {
    let mut r = FileReader::open(std::io::Cursor::new(bytes)).unwrap();
    let scene = r.scene().clone();
    let mut out = Vec::new();
    for g in 0..scene.gop_count {
        for c in r.gop_chunks(g).unwrap() {
            if c.ty == ty {
                out.push((c.payload_offset(), r.payload(&c).unwrap()));
            }
        }
    }
    (scene, out)
}

/// Every `CSOG` record's coding as `dlgs info --channels` names it.
fn csog_codings(bytes: &[u8]) -> Vec<String> {
    let (scene, ps) = payloads(bytes, ChunkType::CSOG);
    ps.iter()
        .flat_map(|(at, p)| csog::describe(p, *at, &scene).unwrap().records)
        .map(|r| r.coding)
        .collect()
}

/// The `codec` byte of every `RDLT` channel (§6.7.1).
fn rdlt_codecs(bytes: &[u8]) -> Vec<u8> {
    let mut codecs = Vec::new();
    for (_, p) in payloads(bytes, ChunkType::RDLT).1 {
        let mut at = 4 + 12 * p[0] as usize;
        while at + 12 <= p.len() {
            codecs.push(p[at + 4]);
            at += 12 + u32::from_le_bytes(p[at + 8..at + 12].try_into().unwrap()) as usize;
        }
    }
    codecs
}

/// The path each vector of [`all`] exists for, checked on its bytes: `Err` says what changed.
pub fn claims(name: &str, bytes: &[u8]) -> Option<Result<(), String>> {
    let all_of = |want: &[&str], at_least: &str| {
        let c = csog_codings(bytes);
        let ok = c.iter().all(|s| want.iter().any(|w| s.contains(w)))
            && c.iter().any(|s| s.contains(at_least));
        if ok {
            Ok(())
        } else {
            Err(format!("{name}: codings {c:?}"))
        }
    };
    let first_byte = |ty: ChunkType, at: usize, want: u8| {
        let ps = payloads(bytes, ty).1;
        if !ps.is_empty() && ps.iter().all(|(_, p)| p[at] == want) {
            Ok(())
        } else {
            Err(format!(
                "{name}: {ty} byte {at} is not {want} in every chunk"
            ))
        }
    };
    Some(match name {
        "lod3-csog-zstd" => all_of(&["(codec 1)"], "(codec 1)"),
        "lod3-csog-histogram" => all_of(&["(codec 3)"], "(codec 3)"),
        "lod3-csog-histogram-delta" => all_of(&["(codec 3)", "(codec 4)"], "(codec 4)"),
        "lod3-csog-adaptive-mode1" => all_of(&["(mode 0)", "(mode 1)"], "(mode 1)"),
        "lod3-csog-adaptive-mode2" => all_of(&["(mode 0)", "(mode 2)"], "(mode 2)"),
        "lod3-rdlt-predictive" => {
            let c = rdlt_codecs(bytes);
            if c.contains(&2) && c.iter().all(|&c| c <= 3) {
                Ok(())
            } else {
                Err(format!("{name}: RDLT channel codecs {c:?}"))
            }
        }
        "lod3-rntc-grid-scope" => first_byte(ChunkType::RNTC, 6, 1),
        "lod3-rntc-dense-gate" => {
            // §6.6.2: T3 at byte 4, R3 at bytes 32..36; dense when R3^3 <= 2^T3.
            let ps = payloads(bytes, ChunkType::RNTC).1;
            let dense = |p: &Vec<u8>| {
                let r = u32::from_le_bytes(p[32..36].try_into().unwrap()) as u64;
                r.pow(3) <= 1 << p[4]
            };
            if !ps.is_empty() && ps.iter().all(|(_, p)| dense(p)) {
                Ok(())
            } else {
                Err(format!("{name}: an RNTC gate grid is hashed"))
            }
        }
        LIFE_VECTOR => {
            let n = payloads(bytes, ChunkType::LIFE).1.len();
            if n == LIVES.len() {
                Ok(())
            } else {
                Err(format!("{name}: {n} LIFE chunks"))
            }
        }
        LERP_VECTOR => {
            let r = FileReader::open(std::io::Cursor::new(bytes)).unwrap();
            match r.scene().deform_model {
                DeformModel::PaperLerp => first_byte(ChunkType::TFEA, 0, 0),
                m => Err(format!("{name}: deform model {m:?}")),
            }
        }
        HEVC_VECTOR => first_byte(ChunkType::TFEA, 0, 1),
        QUANTISED_VECTOR | QUANTISED_KEYS_VECTOR => {
            // codec 4, 10 bits, the predictor (byte 16) the name says, in every GOP.
            let want = u8::from(name == QUANTISED_KEYS_VECTOR);
            let ps = payloads(bytes, ChunkType::TFEA).1;
            let got: Vec<[u8; 3]> = ps.iter().map(|(_, p)| [p[0], p[1], p[16]]).collect();
            if !got.is_empty() && got.iter().all(|g| *g == [4, 10, want]) {
                Ok(())
            } else {
                Err(format!("{name}: TFEA codec, bits, predictor {got:?}"))
            }
        }
        HEVC_REFERENCE_VECTOR => first_byte(ChunkType::TFEA, 0, 2),
        _ => return None,
    })
}
