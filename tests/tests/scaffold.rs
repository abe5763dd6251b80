//! The Scaffold-GS variant's decoding (issue 51) against the fixture in
//! `fixtures/scaffold_run` (a fitted 2-GOP model in the reference's HAC layout, made by
//! `scripts/scaffold_fixture.py`): deformed anchors and neural Gaussians from our decoder
//! against the fixture's independent float64 evaluation of the reference's formulas
//! (`reference_decode/neural_f64.safetensors`), at 3 times and 3 cameras per GOP; the same
//! frames on 1 and 2 threads.

use std::path::{Path, PathBuf};

use dlgs::model::scaffold::{Anchors, ScaffoldMlps, FEAT_DIM, N_OFFSETS, SCALING_DIM};
use dlgs::model::TimeFeatures;
use dlgs_decoder::scaffold::{deform_anchors, neural_gaussians, NeuralGaussians, ViewRequest};
use dlgs_ingest::hac_mlps::{read_hac_mlps, HacMlps};
use safetensors::{Dtype, SafeTensors};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scaffold_run")
}

struct St(Vec<u8>);

impl St {
    fn load(name: &str) -> Self {
        St(std::fs::read(fixture().join("reference_decode").join(name)).unwrap())
    }
    fn f64s(&self, name: &str) -> Vec<f64> {
        let st = SafeTensors::deserialize(&self.0).unwrap();
        let t = st
            .tensor(name)
            .unwrap_or_else(|_| panic!("no tensor {name}"));
        match t.dtype() {
            Dtype::F64 => t
                .data()
                .chunks_exact(8)
                .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
                .collect(),
            Dtype::F32 => t
                .data()
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap()) as f64)
                .collect(),
            Dtype::I64 => t
                .data()
                .chunks_exact(8)
                .map(|b| i64::from_le_bytes(b.try_into().unwrap()) as f64)
                .collect(),
            Dtype::U8 => t.data().iter().map(|&b| b as f64).collect(),
            d => panic!("{name}: dtype {d:?}"),
        }
    }
    fn f32s(&self, name: &str) -> Vec<f32> {
        self.f64s(name).into_iter().map(|v| v as f32).collect()
    }
    fn meta(&self, key: &str) -> String {
        let (_, m) = SafeTensors::read_metadata(&self.0).unwrap();
        m.metadata().as_ref().unwrap()[key].clone()
    }
}

fn mlps(g: usize) -> HacMlps {
    read_hac_mlps(&fixture().join(format!(
        "gop{g}_fixture/compression/best/png_quant/mlps.pth"
    )))
    .unwrap()
}

/// GOP g's canonical anchors (GOP 1: GOP 0's plus the NTC residual, as the reference decodes).
fn anchors(g: usize) -> (Anchors, usize, TimeFeatures) {
    let g0 = St::load("gop0.safetensors");
    let gg = St::load(&format!("gop{g}.safetensors"));
    let pos = g0.f32s("anchor");
    let n_static: usize = g0.meta("n_static").parse().unwrap();
    let a = Anchors {
        positions: pos.chunks(3).map(|p| [p[0], p[1], p[2]]).collect(),
        features: gg.f32s("feat"),
        offsets: gg.f32s("offsets"),
        log_scalings: g0.f32s("scaling"),
    };
    a.check_shapes().unwrap();
    let tf = gg.f32s("temporal_feat");
    let nd = a.len() - n_static;
    let features = TimeFeatures {
        n: nd,
        keys: 7,
        channels: 16,
        data: tf,
    };
    (a, n_static, features)
}

fn view_mlps(g: usize) -> ScaffoldMlps {
    let m0 = mlps(0);
    let mg = mlps(g);
    m0.view_mlps(Some(&mg)).expect("GOP 0 holds the view MLPs")
}

fn cameras() -> Vec<[f32; 3]> {
    let text = std::fs::read_to_string(fixture().join("reference_decode/cameras.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v.as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let p = c["position"].as_array().unwrap();
            [0, 1, 2].map(|i| p[i].as_f64().unwrap() as f32)
        })
        .collect()
}

/// The whole state at (key, δ): static anchors as they are, dynamic ones deformed.
fn state_at(g: usize, key: usize, delta: f32) -> (Anchors, Anchors) {
    let (canon, ns, feats) = anchors(g);
    let m = mlps(g);
    let mut dynamic = Anchors::default();
    for a in ns..canon.len() {
        dynamic.positions.push(canon.positions[a]);
        dynamic.features.extend_from_slice(canon.feature(a));
        dynamic.offsets.extend_from_slice(canon.offset(a));
        dynamic.log_scalings.extend_from_slice(canon.log_scaling(a));
    }
    let moved = deform_anchors(&dynamic, &feats, key, delta, &m.deform, m.bounds);
    let mut state = canon.clone();
    for (j, a) in (ns..canon.len()).enumerate() {
        state.positions[a] = moved.positions[j];
        state.features[a * FEAT_DIM..(a + 1) * FEAT_DIM].copy_from_slice(moved.feature(j));
        state.offsets[a * 3 * N_OFFSETS..(a + 1) * 3 * N_OFFSETS].copy_from_slice(moved.offset(j));
        state.log_scalings[a * SCALING_DIM..(a + 1) * SCALING_DIM]
            .copy_from_slice(moved.log_scaling(j));
    }
    (canon, state)
}

fn max_err(ours: &[f32], theirs: &[f64]) -> f64 {
    assert_eq!(ours.len(), theirs.len());
    ours.iter()
        .zip(theirs)
        .map(|(&a, &b)| (a as f64 - b).abs())
        .fold(0.0, f64::max)
}

fn time_points(f: &St, g: usize) -> Vec<(usize, usize, f32)> {
    (0..3)
        .map(|i| {
            let m: serde_json::Value =
                serde_json::from_str(&f.meta(&format!("g{g}_t{i}"))).unwrap();
            (
                i,
                m["t_idx"].as_u64().unwrap() as usize,
                m["delta"].as_f64().unwrap() as f32,
            )
        })
        .collect()
}

/// Per attribute, the largest absolute difference from the float64 evaluation over both GOPs,
/// 3 times and 3 cameras; the kept-children masks are identical.
#[test]
fn neural_gaussians_match_an_independent_f64_evaluation() {
    let f = St::load("neural_f64.safetensors");
    let subset: Vec<usize> = f
        .f64s("subset_anchor_index")
        .iter()
        .map(|&v| v as usize)
        .collect();
    let cams = cameras();
    let mut worst = std::collections::BTreeMap::<&str, f64>::new();
    let mut note = |k: &'static str, e: f64| {
        let w = worst.entry(k).or_insert(0.0);
        *w = w.max(e);
    };
    for g in 0..2 {
        let vm = view_mlps(g);
        for (i, key, delta) in time_points(&f, g) {
            let (canon, state) = state_at(g, key, delta);
            let ns = anchors(g).1;
            let p = format!("g{g}_t{i}");
            let dyn_pos: Vec<f32> = state.positions[ns..].iter().flatten().copied().collect();
            note(
                "anchor position",
                max_err(&dyn_pos, &f.f64s(&format!("{p}_anchor_deformed_dynamic"))),
            );
            let pick = |v: &[f32], w: usize| -> Vec<f32> {
                subset
                    .iter()
                    .flat_map(|&a| v[a * w..(a + 1) * w].to_vec())
                    .collect()
            };
            note(
                "anchor feature",
                max_err(
                    &pick(&state.features, FEAT_DIM),
                    &f.f64s(&format!("{p}_feat_deformed")),
                ),
            );
            note(
                "anchor offsets",
                max_err(
                    &pick(&state.offsets, 3 * N_OFFSETS),
                    &f.f64s(&format!("{p}_offsets_deformed")),
                ),
            );
            note(
                "anchor scaling",
                max_err(
                    &pick(&state.log_scalings, SCALING_DIM),
                    &f.f64s(&format!("{p}_scaling_deformed")),
                ),
            );
            for (j, cam) in cams.iter().enumerate() {
                let req = ViewRequest {
                    camera_center: *cam,
                    language: true,
                    visible: None,
                };
                let ng = neural_gaussians(&canon.positions, &state, &vm, &req);
                // Kept children of every anchor.
                let mask = f.f64s(&format!("{p}_c{j}_mask"));
                let mut ours = vec![0f64; mask.len()];
                for &(a, k) in &ng.source {
                    ours[a as usize * N_OFFSETS + k as usize] = 1.0;
                }
                let flips = ours.iter().zip(&mask).filter(|(a, b)| a != b).count();
                assert_eq!(flips, 0, "{p} camera {j}: kept-children masks differ");
                // Values of the subset's kept children.
                let rows: Vec<usize> = (0..ng.len())
                    .filter(|&r| subset.binary_search(&(ng.source[r].0 as usize)).is_ok())
                    .collect();
                let col = |get: &dyn Fn(usize) -> Vec<f32>| -> Vec<f32> {
                    rows.iter().flat_map(|&r| get(r)).collect()
                };
                let c = format!("{p}_c{j}");
                note(
                    "xyz",
                    max_err(
                        &col(&|r| ng.positions[r].to_vec()),
                        &f.f64s(&format!("{c}_xyz")),
                    ),
                );
                note(
                    "color",
                    max_err(
                        &col(&|r| ng.colors[r].to_vec()),
                        &f.f64s(&format!("{c}_color")),
                    ),
                );
                note(
                    "opacity",
                    max_err(
                        &col(&|r| vec![ng.opacity[r], ng.lang_opacity[r]]),
                        &f.f64s(&format!("{c}_opacity")),
                    ),
                );
                note(
                    "scaling",
                    max_err(
                        &col(&|r| ng.scales[r].to_vec()),
                        &f.f64s(&format!("{c}_scaling")),
                    ),
                );
                note(
                    "rotation",
                    max_err(
                        &col(&|r| ng.rotations[r].to_vec()),
                        &f.f64s(&format!("{c}_rot")),
                    ),
                );
                note(
                    "language",
                    max_err(
                        &col(&|r| ng.lang[r * 9..r * 9 + 9].to_vec()),
                        &f.f64s(&format!("{c}_language")),
                    ),
                );
            }
        }
    }
    println!("max abs error against the f64 evaluation, per attribute: {worst:#?}");
    for (k, e) in &worst {
        // Measured: at most 4.1e-7 (rotation); f32 rounding of 50-wide sums.
        assert!(*e < 2e-6, "{k}: {e}");
    }
}

/// The same frame on 1 and 2 threads, bit for bit.
#[test]
fn frames_are_the_same_on_one_and_two_threads() {
    let run = |threads: usize| -> NeuralGaussians {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (canon, state) = state_at(1, 2, 0.5);
            let req = ViewRequest {
                camera_center: cameras()[1],
                language: true,
                visible: None,
            };
            neural_gaussians(&canon.positions, &state, &view_mlps(1), &req)
        })
    };
    let a = run(1);
    assert!(a.len() > 1000, "{} children", a.len());
    assert_eq!(a, run(2));
}

/// GOP g of the fixture as the writer takes it.
fn fixture_gop(
    g: usize,
) -> (
    dlgs::model::scaffold::ScaffoldCanonical,
    ScaffoldMlps,
    dlgs::model::scaffold::AnchorDeformation,
    TimeFeatures,
) {
    let (all, ns, features) = anchors(g);
    let split = |range: std::ops::Range<usize>| Anchors {
        positions: all.positions[range.clone()].to_vec(),
        features: all.features[range.start * FEAT_DIM..range.end * FEAT_DIM].to_vec(),
        offsets: all.offsets[range.start * 3 * N_OFFSETS..range.end * 3 * N_OFFSETS].to_vec(),
        log_scalings: all.log_scalings[range.start * SCALING_DIM..range.end * SCALING_DIM].to_vec(),
    };
    let canonical = dlgs::model::scaffold::ScaffoldCanonical {
        statics: split(0..ns),
        dynamics: split(ns..all.len()),
    };
    let m = mlps(g);
    let deformation = dlgs::model::scaffold::AnchorDeformation {
        bound_min: m.bounds.0,
        bound_max: m.bounds.1,
        mlps: m.deform.clone(),
    };
    (canonical, view_mlps(g), deformation, features)
}

/// The fixture's 2 GOPs written as a Scaffold-GS `.dlgs` (exact time features).
fn fixture_file() -> Vec<u8> {
    use dlgs::chunks::tfea::TfeaBody;
    use dlgs_encoder::scaffold::{scaffold_scene, ScaffoldWriter};
    let (c0, ..) = fixture_gop(0);
    let scene = scaffold_scene(
        c0.statics.len() as u32,
        c0.dynamics.len() as u32,
        true,
        30,
        60,
        10,
        120,
    );
    let mut w = ScaffoldWriter::new(Vec::new(), scene, 3).unwrap();
    for g in 0..2 {
        let (c, m, d, f) = fixture_gop(g);
        w.push_gop(&c, &m, Some((&d, &TfeaBody::Exact(f)))).unwrap();
    }
    w.finish().unwrap()
}

/// Written and read back: the same anchors, MLPs and time features, and frames identical to
/// evaluating the model directly, at the fixture's times and cameras (GOP 1 at 60 + local).
#[test]
fn a_scaffold_file_round_trips_exactly() {
    use dlgs_decoder::scaffold::ScaffoldDecoder;
    let bytes = fixture_file();
    let mut dec =
        ScaffoldDecoder::new(std::io::Cursor::new(bytes.clone()), dlgs::Limits::default()).unwrap();
    let f = St::load("neural_f64.safetensors");
    for g in 0..2 {
        let (c, m, d, tf) = fixture_gop(g);
        let gop = dec.gop(g as u32).unwrap();
        assert_eq!(gop.canonical, c);
        assert_eq!(gop.mlps, m);
        let (dd, ff) = gop.dynamic.as_ref().unwrap();
        assert_eq!(dd, &d);
        assert_eq!(ff, &tf);
        for (_, key, delta) in time_points(&f, g) {
            let t = (60 * g) as f64 / 30.0 + (key as f64 + delta as f64) * 10.0 / 30.0;
            for cam in cameras() {
                let req = ViewRequest {
                    camera_center: cam,
                    language: true,
                    visible: None,
                };
                let ours = dec.frame_at(t, &req).unwrap();
                let (canon, state) = state_at(g, key, delta);
                let direct = neural_gaussians(&canon.positions, &state, &view_mlps(g), &req);
                assert_eq!(ours, direct, "GOP {g} t {t}");
            }
        }
    }
    // The 3DGS decoder refuses it with a clear error.
    let e = dlgs_decoder::Decoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default())
        .err()
        .unwrap();
    assert!(e.to_string().contains("Scaffold-GS"), "{e}");
}

/// Damaged files give typed errors, never a panic: every prefix of the file at 97 cut points,
/// and a byte flipped in each Scaffold chunk (caught by its CRC).
#[test]
fn damaged_scaffold_files_give_typed_errors() {
    use dlgs_decoder::scaffold::ScaffoldDecoder;
    let bytes = fixture_file();
    let decode_all = |b: Vec<u8>| -> dlgs::Result<()> {
        let mut dec = ScaffoldDecoder::new(std::io::Cursor::new(b), dlgs::Limits::default())?;
        for g in 0..2 {
            dec.gop(g)?;
        }
        Ok(())
    };
    decode_all(bytes.clone()).unwrap();
    for i in 1..=97 {
        let cut = bytes.len() * i / 98;
        assert!(
            decode_all(bytes[..cut].to_vec()).is_err(),
            "prefix of {cut} bytes"
        );
    }
    for code in [b"ANCR", b"AMLP", b"ADEF"] {
        let at = bytes.windows(4).position(|w| w == code).unwrap();
        let mut b = bytes.clone();
        b[at + 40] ^= 0x55;
        let e = decode_all(b).unwrap_err();
        assert!(
            matches!(e.name(), "PayloadCrc" | "Payload" | "Decompress"),
            "{}: {e} ({})",
            String::from_utf8_lossy(code),
            e.name()
        );
    }
}

/// Frustum culling of anchors (by the reach of their children) decodes fewer anchors from a
/// camera close to the scene and renders the same image, bit for bit.
#[test]
fn culled_anchors_render_the_same_image() {
    use dlgs_decoder::scaffold::ScaffoldDecoder;
    use dlgs_render::{render, Camera, RenderOptions};
    let mut dec = ScaffoldDecoder::new(
        std::io::Cursor::new(fixture_file()),
        dlgs::Limits::default(),
    )
    .unwrap();
    let t = 0.5;
    let (canon, _) = state_at(0, 1, 0.5);
    let n = canon.positions.len() as f32;
    let centre = canon.positions.iter().fold([0f32; 3], |a, p| {
        [a[0] + p[0] / n, a[1] + p[1] / n, a[2] + p[2] / n]
    });
    let mut checked = 0;
    // From each fixture camera at 3 distances towards the scene centre, looking past it:
    // parts of the scene fall outside the view, some of it close to the camera.
    let views: Vec<(glam::Vec3, glam::Vec3)> = cameras()
        .into_iter()
        .flat_map(|cam| {
            [0.3f32, 0.6, 0.8].map(|k| {
                let c = glam::Vec3::from_array(centre);
                let eye = glam::Vec3::from_array(cam).lerp(c, k);
                (eye, c + (c - eye).cross(glam::Vec3::Y).normalize() * 0.3)
            })
        })
        .collect();
    for (i, (eye, target)) in views.into_iter().enumerate() {
        let camera = Camera::look_at(eye, target, glam::Vec3::new(0.0, -1.0, 0.0), 320, 240, 60.0);
        let in_view = |p: &[[f32; 3]], r: &[f32]| dlgs_render::cull::spheres_in_view(&camera, p, r);
        let (culled, kept) = dec
            .frame_in_view(t, eye.to_array(), false, &in_view)
            .unwrap();
        let all = dec
            .frame_at(
                t,
                &ViewRequest {
                    camera_center: eye.to_array(),
                    language: false,
                    visible: None,
                },
            )
            .unwrap();
        assert!(culled.len() <= all.len());
        let opts = RenderOptions::default();
        let a = render(&culled.to_gaussians(), &camera, &opts).unwrap();
        let b = render(&all.to_gaussians(), &camera, &opts).unwrap();
        let differ: Vec<usize> = (0..a.color.len())
            .filter(|&k| a.color[k] != b.color[k])
            .collect();
        assert!(
            differ.is_empty(),
            "camera {i}: {} values differ, first at pixel ({}, {})",
            differ.len(),
            differ[0] / 3 % 320,
            differ[0] / 3 / 320
        );
        if kept < canon.positions.len() {
            checked += 1;
        }
    }
    assert!(checked > 0, "no camera culled anything");
}

/// A tiny Scaffold-GS model (2 static + 1 dynamic anchors, hidden widths 2): seeds for the
/// fuzzer and a round trip that needs no fixture.
fn tiny_file() -> Vec<u8> {
    use dlgs::chunks::tfea::TfeaBody;
    use dlgs::model::scaffold::{Activation, AnchorDeformMlps, AnchorDeformation, Dense, TwoLayer};
    use dlgs_encoder::scaffold::{scaffold_scene, ScaffoldWriter};
    let mut rng = fastrand::Rng::with_seed(7);
    let mut layer = |i: usize, h: usize, o: usize, biased: bool, output: Activation| {
        let mut d = |i: usize, o: usize| Dense {
            inputs: i,
            outputs: o,
            weights: (0..i * o).map(|_| rng.f32() - 0.5).collect(),
            bias: biased.then(|| (0..o).map(|_| rng.f32() - 0.3).collect()),
        };
        TwoLayer {
            first: d(i, h),
            second: d(h, o),
            output,
        }
    };
    let mlps = ScaffoldMlps {
        opacity: layer(54, 2, 20, true, Activation::Tanh),
        color: layer(54, 2, 30, true, Activation::Sigmoid),
        cov: layer(54, 2, 70, true, Activation::Identity),
        language: Some(layer(54, 2, 90, true, Activation::Identity)),
    };
    let deformation = AnchorDeformation {
        bound_min: [-1.0; 3],
        bound_max: [1.0; 3],
        mlps: AnchorDeformMlps {
            position: layer(19, 2, 3, false, Activation::Identity),
            feature: layer(16, 2, 50, false, Activation::Identity),
            offsets: layer(16, 2, 30, false, Activation::Identity),
            scaling: layer(16, 2, 6, false, Activation::Identity),
        },
    };
    let set = |n: usize| Anchors {
        positions: (0..n).map(|i| [0.1 * i as f32, 0.2, 0.3]).collect(),
        features: vec![0.4; n * FEAT_DIM],
        offsets: vec![0.1; n * 3 * N_OFFSETS],
        log_scalings: vec![-2.0; n * SCALING_DIM],
    };
    let canonical = dlgs::model::scaffold::ScaffoldCanonical {
        statics: set(2),
        dynamics: set(1),
    };
    let features = TimeFeatures {
        n: 1,
        keys: 7,
        channels: 16,
        data: (0..7 * 16).map(|i| i as f32 * 0.01).collect(),
    };
    let scene = scaffold_scene(2, 1, true, 30, 60, 10, 60);
    let mut w = ScaffoldWriter::new(Vec::new(), scene, 19).unwrap();
    w.push_gop(
        &canonical,
        &mlps,
        Some((&deformation, &TfeaBody::Exact(features))),
    )
    .unwrap();
    w.finish().unwrap()
}

#[test]
fn a_tiny_scaffold_file_decodes() {
    use dlgs_decoder::scaffold::ScaffoldDecoder;
    let bytes = tiny_file();
    assert!(bytes.len() < 65536, "{} bytes: a fuzzer seed", bytes.len());
    let mut dec = ScaffoldDecoder::new(std::io::Cursor::new(bytes), dlgs::Limits::tiny()).unwrap();
    let f = dec
        .frame_at(
            1.0,
            &ViewRequest {
                camera_center: [0.0, 0.0, -3.0],
                language: true,
                visible: None,
            },
        )
        .unwrap();
    assert_eq!(f.lang.len(), 9 * f.len());
    assert!(f.opacity.iter().all(|&o| o > 0.0 && o < 1.0));
    if std::env::var("DLGS_WRITE_FUZZ_SEEDS").is_ok() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus/scaffold_payloads");
        std::fs::create_dir_all(&dir).unwrap();
        let bytes = tiny_file();
        let mut file = vec![3u8];
        file.extend_from_slice(&bytes);
        std::fs::write(dir.join("seed-tiny_file"), file).unwrap();
        // Each chunk's payload behind its selector.
        let r = dlgs::container::FileReader::open(std::io::Cursor::new(bytes.clone())).unwrap();
        let mut r = r;
        for c in r.gop_chunks(0).unwrap() {
            let sel = match c.ty.as_str() {
                "ANCR" => 0u8,
                "AMLP" => 1,
                "ADEF" => 2,
                _ => continue,
            };
            let mut seed = vec![sel];
            seed.extend_from_slice(&r.payload(&c).unwrap());
            std::fs::write(dir.join(format!("seed-{}", c.ty.as_str())), seed).unwrap();
        }
    }
}
