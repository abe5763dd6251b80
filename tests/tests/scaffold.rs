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
