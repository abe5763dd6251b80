//! The dynamic and residual conformance vectors (GOPs of the lod3 scene animated by the
//! synthetic generator, residual and refresh chains) and the frames a reader must give.

use super::*;

/// The first 512 Gaussians of a scene: small dynamic vectors.
pub(super) fn first_512(scene: &dlgs::Gaussians) -> dlgs::Gaussians {
    let mut part = dlgs::Gaussians::new(scene.sh_degree, scene.lang_width);
    for i in 0..512 {
        part.push_from(scene, i);
    }
    part
}

pub(super) fn dynamic_vector(scene: &dlgs::Gaussians) -> Vec<u8> {
    dynamic_model_vector(scene, dlgs_encoder::FeatureCodec::Exact)
}

pub(super) fn dynamic_intra_vector(scene: &dlgs::Gaussians) -> Vec<u8> {
    dynamic_model_vector(
        scene,
        dlgs_encoder::FeatureCodec::Hevc(dlgs_encoder::HevcSettings {
            intra_only: true,
            preset: "ultrafast".into(),
            ..Default::default()
        }),
    )
}

pub(super) fn dynamic_model_vector(
    scene: &dlgs::Gaussians,
    features: dlgs_encoder::FeatureCodec,
) -> Vec<u8> {
    use dlgs_testkit::synth::{synth_dynamic, write_model, SynthSpec};
    // The first 512 Gaussians keep the file small; 128 of them move.
    let part = first_512(scene);
    let spec = SynthSpec {
        dynamic_fraction: 0.25,
        max_dynamic: 128,
        gops: 2,
        language: true,
        ..Default::default()
    };
    let m = synth_dynamic(&part, &spec).unwrap();
    let cfg = dlgs_encoder::EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features,
            ..Default::default()
        },
        ..Default::default()
    };
    write_model(&m, cfg, Vec::new()).unwrap()
}

pub(super) fn residual_vector(scene: &dlgs::Gaussians) -> Vec<u8> {
    use dlgs::container::header::ResidualMode;
    use dlgs::model::ntc::NtcConfig;
    use dlgs::model::residual::{AttrGroup, DeltaTarget};
    use dlgs_encoder::{GopCanonical, ResidualConfig, StreamEncoder};
    use dlgs_testkit::synth::{synth_dynamic, synth_ntc, SynthSpec};
    let part = first_512(scene);
    let spec = SynthSpec {
        dynamic_fraction: 0.25,
        max_dynamic: 64,
        gops: 3,
        residual_mode: ResidualMode::Sequential,
        ..Default::default()
    };
    let m = synth_dynamic(&part, &spec).unwrap();
    // Small grids keep the vector small; every rule of §6.6 still applies (hashed and dense
    // levels: 16^2 <= 2^10 is dense, 64^2 is hashed).
    let small = NtcConfig {
        resolutions: vec![16, 32, 64, 128],
        features: 4,
        log2_table: 10,
        gate_resolution: 18,
        gate_log2_table: 10,
    };
    let field = synth_ntc(&m.canonical, &mut fastrand::Rng::with_seed(77), 1.0, small);
    let s1 = field.apply(&m.canonical).unwrap();
    let mut s2 = s1.clone();
    for (i, p) in s2.statics.positions.iter_mut().enumerate() {
        p[1] += 0.001 * (i % 7) as f32;
    }
    for v in s2.dynamics.sh.iter_mut().step_by(3) {
        *v -= 0.01;
    }
    let cfg = dlgs_encoder::EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: dlgs_encoder::FeatureCodec::Exact,
            residual: ResidualConfig {
                groups: AttrGroup::ALL
                    .into_iter()
                    .map(|g| match g {
                        AttrGroup::Position => (g, DeltaTarget::Bound(1e-4)),
                        AttrGroup::ShDc => (g, DeltaTarget::Bound(2e-3)),
                        _ => (g, DeltaTarget::Exact),
                    })
                    .collect(),
                follow_quantisation: false,
            },
            ..Default::default()
        },
        ..Default::default()
    };
    let mut enc = StreamEncoder::new(Vec::new(), m.scene.clone(), cfg).unwrap();
    enc.push(GopCanonical::State(&m.canonical), Some(&m.gops[0]))
        .unwrap();
    enc.push(GopCanonical::Ntc(&field), Some(&m.gops[1]))
        .unwrap();
    enc.push(GopCanonical::State(&s2), Some(&m.gops[2]))
        .unwrap();
    enc.finish().unwrap()
}

/// 4 sequential GOPs with `refresh_interval` 2: the same generated field in GOPs 1-3, GOP 2
/// written as the full state it gives.
pub(super) fn refresh_vector(scene: &dlgs::Gaussians) -> Vec<u8> {
    use dlgs::container::header::ResidualMode;
    use dlgs::model::ntc::NtcConfig;
    use dlgs_encoder::{GopCanonical, StreamEncoder};
    use dlgs_testkit::synth::{synth_dynamic, synth_ntc, SynthSpec};
    let spec = SynthSpec {
        dynamic_fraction: 0.25,
        max_dynamic: 64,
        gops: 4,
        gop_length: 10,
        key_interval: 5,
        residual_mode: ResidualMode::Sequential,
        refresh_interval: 2,
        ..Default::default()
    };
    let m = synth_dynamic(&first_512(scene).with_sh_degree(0), &spec).unwrap();
    let small = NtcConfig {
        resolutions: vec![16, 32],
        features: 2,
        log2_table: 8,
        gate_resolution: 8,
        gate_log2_table: 8,
    };
    let field = synth_ntc(&m.canonical, &mut fastrand::Rng::with_seed(78), 1.0, small);
    let cfg = dlgs_encoder::EncoderConfig {
        dynamic: dlgs_encoder::DynamicSettings {
            features: dlgs_encoder::FeatureCodec::Exact,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut enc = StreamEncoder::new(Vec::new(), m.scene.clone(), cfg).unwrap();
    enc.push(GopCanonical::State(&m.canonical), Some(&m.gops[0]))
        .unwrap();
    for g in 1..4 {
        enc.push(GopCanonical::Ntc(&field), Some(&m.gops[g]))
            .unwrap();
    }
    enc.finish().unwrap()
}

/// The dynamic Gaussians of `bytes` at [`FRAME_TIMES`], language on, as f32 little-endian:
/// per time, the arrays positions, log-scales, rotations, opacity, language opacity, SH,
/// language, each over all dynamic Gaussians (layout in vectors/README.md).
pub fn dynamic_frames(bytes: &[u8]) -> Vec<f32> {
    let mut dec =
        dlgs_decoder::Decoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap();
    let opts = dlgs_decoder::FrameOptions {
        camera_center: FRAME_CAMERA,
        language: true,
    };
    let mut out = Vec::new();
    for t in FRAME_TIMES {
        let g = dec.frame_at(t, &opts).unwrap().dynamics;
        out.extend(g.positions.iter().flatten());
        out.extend(g.log_scales.iter().flatten());
        out.extend(g.rotations.iter().flatten());
        out.extend(&g.opacity);
        out.extend(&g.lang_opacity);
        out.extend(&g.sh);
        out.extend(&g.lang);
    }
    out
}
