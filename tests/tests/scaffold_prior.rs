//! `AHAC` for anchors without a trained context model (`encoder/src/scaffold_prior.rs`): the
//! fixture's anchors coded with the per-channel prior decode within half a step of the input,
//! in fewer bytes than raw `ANCR`, the same bits on 1 and 2 threads; degenerate inputs (one
//! anchor, a flat box, constant channels) code and decode; NaN and too fine steps are refused.

use std::path::Path;

use dlgs::chunks::{ahac, ancr};
use dlgs::model::scaffold::{Anchors, ScaffoldCanonical};
use dlgs::Limits;
use dlgs_encoder::scaffold::scaffold_scene;
use dlgs_encoder::scaffold_prior::{prior_anchors, DEFAULT_PRIOR_STEPS};
use dlgs_ingest::hac::{self, HacLimits};

fn fixture_anchors() -> ScaffoldCanonical {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/scaffold_run/gop0_fixture/compression/best");
    let g = hac::read_gop(&dir, None, HacLimits::default()).unwrap();
    let n_static = g.hac_anchors().unwrap().n_static as usize;
    ScaffoldCanonical::split_at(g.anchors.clone(), n_static)
}

fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// Code and decode `c` with `steps` on `threads` threads: the decoded anchors and the bytes.
fn round_trip(
    c: &ScaffoldCanonical,
    steps: [f32; 3],
    threads: usize,
) -> (ScaffoldCanonical, usize) {
    let h = prior_anchors(c, steps).unwrap();
    let scene = scaffold_scene(h.n_static, h.n_dynamic, true, 30, 60, 10, 60);
    let (payload, _) = ahac::encode(&h, &scene, 19).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let d = pool.install(|| ahac::decode(&payload, 0, &scene, &Limits::default()).unwrap());
    (d, payload.len())
}

fn check_within_half_a_step(input: &ScaffoldCanonical, out: &ScaffoldCanonical, steps: [f32; 3]) {
    let (a, b) = (input.joined(), out.joined());
    assert_eq!(b.len(), a.len());
    let slack = |q: f32, v: &[f32]| q * 0.5 + v.iter().fold(0f32, |m, x| m.max(x.abs())) * 1e-6;
    assert!(max_diff(&a.features, &b.features) <= slack(steps[0], &a.features));
    assert!(max_diff(&a.log_scalings, &b.log_scalings) <= slack(steps[1], &a.log_scalings));
    assert!(max_diff(&a.offsets, &b.offsets) <= slack(steps[2], &a.offsets));
    // Positions: half of the 16-bit grid's step over the box, per axis.
    for d in 0..3 {
        let lo = a
            .positions
            .iter()
            .map(|p| p[d])
            .fold(f32::INFINITY, f32::min);
        let hi = a
            .positions
            .iter()
            .map(|p| p[d])
            .fold(f32::NEG_INFINITY, f32::max);
        let step = (hi - lo).max(1e-3) / 65535.0;
        let err = a
            .positions
            .iter()
            .zip(&b.positions)
            .map(|(p, q)| (p[d] - q[d]).abs())
            .fold(0f32, f32::max);
        assert!(err <= step * 0.51 + 1e-6, "axis {d}: {err} vs step {step}");
    }
}

#[test]
fn the_fixtures_anchors_code_with_the_prior_smaller_than_raw() {
    let c = fixture_anchors();
    let scene = scaffold_scene(
        c.statics.len() as u32,
        c.dynamics.len() as u32,
        true,
        30,
        60,
        10,
        60,
    );
    let raw = ancr::encode(&c, &scene, 19).unwrap().len();
    for steps in [DEFAULT_PRIOR_STEPS, [0.1, 0.01, 0.02]] {
        let (d1, bytes) = round_trip(&c, steps, 1);
        let (d2, _) = round_trip(&c, steps, 2);
        println!("steps {steps:?}: AHAC with the prior {bytes} B, raw ANCR {raw} B");
        check_within_half_a_step(&c, &d1, steps);
        let bits = |c: &ScaffoldCanonical| {
            let a = c.joined();
            let v: Vec<u32> = a
                .positions
                .iter()
                .flatten()
                .chain(&a.features)
                .chain(&a.log_scalings)
                .chain(&a.offsets)
                .map(|v| v.to_bits())
                .collect();
            v
        };
        assert_eq!(bits(&d1), bits(&d2), "1 and 2 threads");
        assert!(bytes < raw, "{bytes} vs raw {raw}");
    }
}

#[test]
fn degenerate_anchors_code_and_decode() {
    let one = |p: [f32; 3]| Anchors {
        positions: vec![p],
        features: vec![0.25; 50],
        log_scalings: vec![-3.0; 6],
        offsets: vec![0.0; 30],
    };
    let steps = DEFAULT_PRIOR_STEPS;
    // One static anchor; no dynamic one.
    let c = ScaffoldCanonical {
        statics: one([1.0, -2.0, 3.0]),
        dynamics: Anchors::default(),
    };
    let (d, _) = round_trip(&c, steps, 2);
    check_within_half_a_step(&c, &d, steps);
    // Several anchors at one point (a flat box on every axis), constant channels.
    let mut many = one([0.0, 0.0, 0.0]);
    for _ in 0..2500 {
        let a = one([0.0, 0.0, 0.0]);
        many.positions.extend(a.positions);
        many.features.extend(a.features);
        many.log_scalings.extend(a.log_scalings);
        many.offsets.extend(a.offsets);
    }
    let c = ScaffoldCanonical::split_at(many, 1000);
    let (d, _) = round_trip(&c, steps, 2);
    check_within_half_a_step(&c, &d, steps);
}

#[test]
fn nan_anchors_and_bad_steps_are_refused() {
    let c = fixture_anchors();
    let mut nan = c.clone();
    nan.statics.features[7] = f32::NAN;
    let e = prior_anchors(&nan, DEFAULT_PRIOR_STEPS).unwrap_err();
    assert!(e.to_string().contains("NaN"), "{e}");
    let e = prior_anchors(&c, [0.0, 0.001, 0.002]).unwrap_err();
    assert!(e.to_string().contains("finite and > 0"), "{e}");
    let e = prior_anchors(&c, [1e-7, 0.001, 0.002]).unwrap_err();
    assert!(e.to_string().contains("too fine"), "{e}");
}
