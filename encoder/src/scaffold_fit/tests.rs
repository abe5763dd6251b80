use dlgs::chunks::ahac::encode_payload;
use dlgs::model::scaffold::{Anchors, ScaffoldCanonical, FEAT_DIM, N_OFFSETS, SCALING_DIM};

use super::*;

/// `n` anchors on a curved sheet whose values are smooth functions of position plus a little
/// seeded noise: what a context model can predict and a per-channel prior cannot.
fn smooth_anchors(n: usize, seed: u64) -> ScaffoldCanonical {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut a = Anchors::default();
    for _ in 0..n {
        let (x, y) = (rng.f32(), rng.f32());
        let p = [x, y, 0.3 * (3.0 * x).sin() * y];
        a.positions.push(p);
        let wave = |k: usize| ((k as f32 * 0.7 + 1.0) * x + (k as f32 * 0.3) * y).sin();
        for k in 0..FEAT_DIM {
            a.features.push(2.0 * wave(k) + 0.05 * (rng.f32() - 0.5));
        }
        for k in 0..SCALING_DIM {
            a.log_scalings
                .push(-4.0 + 0.5 * wave(k + 3) + 0.01 * rng.f32());
        }
        for k in 0..3 * N_OFFSETS {
            a.offsets.push(0.8 * wave(k + 7) + 0.02 * (rng.f32() - 0.5));
        }
    }
    ScaffoldCanonical::split_at(a, n * 3 / 4)
}

fn settings() -> ContextFitSettings {
    ContextFitSettings {
        iterations: 80,
        ..ContextFitSettings::new([0.05, 0.01, 0.02])
    }
}

#[test]
fn the_fit_codes_smaller_than_the_prior_and_decodes_to_the_same_values() {
    let c = smooth_anchors(1500, 1);
    let s = settings();
    let (hac, rep) = fit_anchors(&c, &s, |_, _| {}).unwrap();
    let prior = prior_anchors(&c, s.steps).unwrap();
    println!("{rep:?}");
    assert!(rep.kept_fit, "{rep:?}");
    assert!(rep.fitted_bytes * 10 < rep.prior_bytes * 9, "{rep:?}");
    let (bytes, sizes) = encode_payload(&hac, s.zstd_level).unwrap();
    assert_eq!(bytes.len(), rep.fitted_bytes);
    assert_eq!(sizes, rep.sizes);
    // The model changes the bits, not the values.
    assert_eq!(hac.symbols, prior.symbols);
    assert_eq!(hac.canonical(), prior.canonical());
    // The fit lowers the model's bits as it goes.
    let (first, last) = (rep.bits_log[0].1, rep.bits_log.last().unwrap().1);
    assert!(last < 0.8 * first, "{first} -> {last} bits per anchor");
    // The payload reads back to the same anchors.
    let scene = crate::scaffold::scaffold_scene(
        c.statics.len() as u32,
        c.dynamics.len() as u32,
        false,
        30,
        60,
        10,
        60,
    );
    let (back, _) =
        dlgs::chunks::ahac::decode_full(&bytes, 0, &scene, &dlgs::Limits::default()).unwrap();
    assert_eq!(back, hac);
}

#[test]
fn the_fit_is_the_same_on_one_and_two_threads() {
    let c = smooth_anchors(700, 2);
    let s = ContextFitSettings {
        iterations: 30,
        batch: 256,
        ..settings()
    };
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (hac, _) = fit_anchors(&c, &s, |_, _| {}).unwrap();
            encode_payload(&hac, s.zstd_level).unwrap().0
        })
    };
    assert_eq!(run(1), run(2));
}

#[test]
fn degenerate_anchors_fall_back_or_fail_clearly() {
    // Constant channels and one anchor: the prior is kept (nothing to learn), no panic.
    let c = smooth_anchors(1, 3);
    let (hac, rep) = fit_anchors(&c, &settings(), |_, _| {}).unwrap();
    assert!(
        !rep.kept_fit && rep.fitted_bytes >= rep.prior_bytes,
        "{rep:?}"
    );
    assert_eq!(hac, prior_anchors(&c, settings().steps).unwrap());
    let mut flat = smooth_anchors(200, 4);
    flat.statics.features.fill(1.5);
    flat.dynamics.features.fill(1.5);
    assert!(fit_anchors(&flat, &settings(), |_, _| {}).is_ok());
    // No anchors at all.
    let empty = ScaffoldCanonical::default();
    let (hac, rep) = fit_anchors(&empty, &settings(), |_, _| {}).unwrap();
    assert_eq!((hac.quantized.len(), rep.kept_fit), (0, false));
    // NaN is refused before any fitting.
    let mut c = smooth_anchors(10, 3);
    c.statics.features[0] = f32::NAN;
    let err = fit_anchors(&c, &settings(), |_, _| {}).unwrap_err();
    assert!(err.to_string().contains("NaN"), "{err}");
    // Zero iterations: the prior.
    let c = smooth_anchors(50, 5);
    let s = ContextFitSettings {
        iterations: 0,
        ..settings()
    };
    let (hac, rep) = fit_anchors(&c, &s, |_, _| {}).unwrap();
    assert!(!rep.kept_fit);
    assert_eq!(hac, prior_anchors(&c, s.steps).unwrap());
}
