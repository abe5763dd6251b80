//! The context model fitted to raw anchors (issue 68, `dlgs_encoder::scaffold_fit`) on the
//! fitted fixture run's GOP 0: its bytes against the trained HAC model's, the same values as
//! the prior's, the same payload on 1 and 2 threads; and the fuzz seed of a fitted model.

use std::path::{Path, PathBuf};

use dlgs::chunks::ahac::{self, HacAnchors};
use dlgs::model::hac_context::GridShape;
use dlgs::Limits;
use dlgs_encoder::scaffold::scaffold_scene;
use dlgs_encoder::scaffold_fit::{fit_anchors, ContextFitSettings};
use dlgs_encoder::scaffold_prior::prior_anchors;
use dlgs_ingest::hac::{self, HacLimits};

fn gop0_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/scaffold_run/gop0_fixture/compression/best")
}

/// The steps `dlgs encode raw.dlgs` chooses for the fixture within 45 dB (the CLI test
/// `scaffold_fit_cli` checks the search itself).
const STEPS: [f32; 3] = [0.056_568_54, 0.181_019_34, 0.181_019_34];
/// The trained HAC model's bytes for the same anchors' symbols.
const TRAINED_SYMBOL_BYTES: usize = 98_600;

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

#[test]
fn the_fixture_anchors_code_under_the_trained_models_bytes() {
    let g = hac::read_gop(&gop0_dir(), None, HacLimits::default()).unwrap();
    let anchors = g.hac_anchors().unwrap().canonical();
    let s = ContextFitSettings::new(STEPS);
    let run = |threads| {
        in_pool(threads, || {
            let (h, rep) = fit_anchors(&anchors, &s, |_, _| {}).unwrap();
            let (bytes, _) = ahac::encode_payload(&h, s.zstd_level).unwrap();
            (h, rep, bytes)
        })
    };
    let (h, rep, bytes) = run(2);
    println!(
        "fixture GOP 0: {} B fitted (grids {}, mlp_grid {}, symbols {}), {} B with the prior, \
         fit {:.1} s",
        rep.fitted_bytes,
        rep.sizes.grids,
        rep.sizes.mlp,
        rep.sizes.streams.iter().sum::<usize>(),
        rep.prior_bytes,
        rep.fit_seconds
    );
    assert!(rep.kept_fit);
    assert!(bytes.len() <= TRAINED_SYMBOL_BYTES, "{} B", bytes.len());
    assert!(rep.fitted_bytes * 100 <= rep.prior_bytes * 96, "{rep:?}");
    assert_eq!(run(1).2, bytes, "1 and 2 threads differ");
    let prior = prior_anchors(&anchors, STEPS).unwrap();
    assert_eq!(h.canonical(), prior.canonical());
}

/// The fuzz seed of `fuzz_targets/scaffold_payloads.rs` with a fitted model (selector 4: an
/// `AHAC` payload for its scene of 2 static + 1 dynamic anchors): hidden width 16, two 3D
/// levels and a plane level, weights at few mantissa bits. Written with
/// `DLGS_WRITE_FUZZ_SEEDS=1`.
#[test]
fn fitted_ahac_fuzz_seed() {
    let g = hac::read_gop(&gop0_dir(), None, HacLimits::default()).unwrap();
    let anchors = g.hac_anchors().unwrap().canonical();
    let shape = |resolutions: Vec<u32>, log2_table| GridShape {
        resolutions,
        log2_table,
        features: 2,
    };
    let s = ContextFitSettings {
        iterations: 40,
        grids: Some((shape(vec![4, 9], 8), shape(vec![12], 7))),
        ..ContextFitSettings::new(STEPS)
    };
    let (fitted, rep) = fit_anchors(&anchors, &s, |_, _| {}).unwrap();
    assert!(rep.kept_fit && rep.mantissa_bits < 23, "{rep:?}");
    let n = 3;
    let h = HacAnchors {
        n_static: 2,
        n_dynamic: 1,
        quantized: fitted.quantized[..n].to_vec(),
        symbols: std::array::from_fn(|a| {
            let ch = fitted.symbols[a].len() / fitted.quantized.len();
            fitted.symbols[a][..n * ch].to_vec()
        }),
        ..fitted
    };
    let scene = scaffold_scene(2, 1, true, 30, 60, 10, 60);
    let (p, _) = ahac::encode(&h, &scene, 19).unwrap();
    assert_eq!(
        ahac::decode_full(&p, 0, &scene, &Limits::tiny()).unwrap().0,
        h
    );
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/corpus/scaffold_payloads/seed-ahac-fitted");
    let mut seed = vec![4u8];
    seed.extend_from_slice(&p);
    if std::env::var("DLGS_WRITE_FUZZ_SEEDS").is_ok() {
        std::fs::write(&path, &seed).unwrap();
    }
    assert_eq!(
        std::fs::read(&path).unwrap(),
        seed,
        "regenerate with DLGS_WRITE_FUZZ_SEEDS=1"
    );
}
