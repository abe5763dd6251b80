//! Tests of [`smallest_at_view_size`]: the kept candidate, the searched groups, unreachable
//! targets, the refit and the options it names.

use super::*;
use std::sync::OnceLock;

/// The tests judge candidates on small views: the search's logic is the same at any size,
/// and at `dlgs compare`'s size each search of the scene below took 45-90 s (two tests at a time).
const VIEW_SIZE: (u32, u32) = (320, 240);

fn search(g: &Gaussians, target_db: f64, base: &EncoderConfig) -> Found {
    smallest_at_view_size(g, target_db, base, VIEW_SIZE, |_| {}).unwrap()
}

/// The search of [`scene`] at 40 dB with the default configuration, run once for the tests
/// that look at it.
fn plain_search() -> &'static Found {
    static FOUND: OnceLock<Found> = OnceLock::new();
    FOUND.get_or_init(|| search(&scene(), 40.0, &EncoderConfig::default()))
}

/// A small generated scene (the CLI test runs the search on a real one): a grid of
/// coloured, anisotropic Gaussians.
fn scene() -> Gaussians {
    let mut g = Gaussians::new(0, 0);
    for i in 0..400 {
        let (x, y) = ((i % 20) as f32 / 20.0, (i / 20) as f32 / 20.0);
        g.positions
            .push([x - 0.5, y - 0.5, ((i * 7) % 13) as f32 / 40.0]);
        g.log_scales.push([-3.2, -3.6, -4.0]);
        g.rotations.push([1.0, 0.1 * x, 0.0, 0.2 * y]);
        g.opacity.push(2.0 - 3.0 * x);
        g.sh.extend_from_slice(&[x, y, 1.0 - x]);
    }
    g
}

#[test]
fn the_smallest_candidate_at_the_target_is_kept_and_decodes_to_its_psnr() {
    let g = scene();
    let found = plain_search();
    let (i, file) = found.best.clone().expect("a preset reaches 40 dB");
    let best = &found.trials[i];
    assert!(best.psnr >= 40.0);
    assert_eq!(best.bytes, file.len());
    for t in &found.trials {
        assert!(t.psnr < 40.0 || t.bytes >= best.bytes, "{t:?} vs {best:?}");
    }
    // The kept file is the candidate measured: decoding it again gives the same PSNR.
    let cams = search_views_sized(&g, VIEW_SIZE);
    let again = mean_psnr(
        &bit_allocation::render_views(&g, &cams).unwrap(),
        &bit_allocation::render_views(&decode_still(&file).unwrap(), &cams).unwrap(),
        PSNR_CAP,
    );
    assert_eq!(again, best.psnr);
    // Every tier set was tried, each from the coarsest preset.
    for tiers in TIER_SETS {
        let first = found.trials.iter().find(|t| t.tiers == tiers).unwrap();
        assert_eq!(first.label, "low");
    }
}

#[test]
fn shaping_is_searched_where_sh_bands_are_stored() {
    // The generated scene at SH 0 never shapes; with view-dependent colour (SH 1) the
    // shaped candidates are coded, and whichever is kept reaches the target.
    let flat = plain_search();
    assert!(flat.trials.iter().all(|t| t.shape == 0.0));
    let mut g = scene();
    g.sh_degree = 1;
    g.sh = (0..g.len())
        .flat_map(|i| {
            let (x, y) = ((i % 20) as f32 / 20.0, (i / 20) as f32 / 20.0);
            // DC, then band 1 (three coefficients per colour channel).
            [
                x,
                y,
                1.0 - x,
                0.3 * x,
                -0.2 * y,
                0.0,
                0.1,
                0.0,
                -0.1 * x,
                0.0,
                0.05,
                0.2 * y,
            ]
        })
        .collect();
    let found = search(&g, 40.0, &EncoderConfig::default());
    let shaped: Vec<&Trial> = found.trials.iter().filter(|t| t.shape > 0.0).collect();
    assert!(!shaped.is_empty());
    assert!(shaped.iter().all(|t| SHAPE_LEVELS.contains(&t.shape)));
    for t in &shaped {
        assert_eq!(t.label.matches("shape=").count(), 1, "{}", t.label);
    }
    let (i, file) = found.best.expect("a candidate reaches 40 dB");
    assert!(found.trials[i].psnr >= 40.0);
    assert_eq!(found.trials[i].bytes, file.len());
}

#[test]
fn an_unreachable_target_keeps_nothing() {
    let found = search(&scene(), PSNR_CAP + 1.0, &EncoderConfig::default());
    assert!(found.best.is_none());
    // With nothing to beat, every preset of every tier set is coded (near-lossless is above
    // the cap on no view, so refinement adds bits to it).
    assert!(found.trials.len() >= PRESETS.len() * TIER_SETS.len());
    assert!(found
        .trials
        .iter()
        .any(|t| t.label.starts_with("near-lossless +")));
}

#[test]
fn with_the_refit_the_closest_candidates_below_are_coded_again_at_the_end() {
    let plain = plain_search();
    let cfg = EncoderConfig {
        refit: crate::config::RefitSettings {
            colours: true,
            ..Default::default()
        },
        ..Default::default()
    };
    let found = search(&scene(), 40.0, &cfg);
    // The search runs as without the refit; the refit trials come after it.
    let n = plain.trials.len();
    let key = |t: &Trial| (t.label.clone(), t.bytes, t.psnr.to_bits(), t.refit);
    assert_eq!(
        found.trials[..n].iter().map(key).collect::<Vec<_>>(),
        plain.trials.iter().map(key).collect::<Vec<_>>()
    );
    let refit = &found.trials[n..];
    assert!(!refit.is_empty());
    assert!(refit.iter().all(|t| t.refit && t.label.contains("+refit")));
    let tries = refit.iter().filter(|t| t.label.ends_with("+refit")).count();
    assert!((1..=REFIT_TRIES).contains(&tries), "{tries}");
    // Each try starts from a candidate below the target and smaller than the best.
    let (pb, _) = plain.best.clone().expect("a preset reaches 40 dB");
    for t in refit.iter().filter(|t| t.label.ends_with("+refit")) {
        let from = plain
            .trials
            .iter()
            .find(|p| format!("{} +refit", p.label) == t.label)
            .expect("the trial it refits");
        assert!(from.psnr < 40.0 && from.bytes < plain.trials[pb].bytes);
    }
    let (b, file) = found.best.expect("still a best");
    assert!(found.trials[b].bytes <= plain.trials[pb].bytes);
    assert_eq!(found.trials[b].bytes, file.len());
}

#[test]
fn options_name_every_group_and_the_tiers() {
    let t = Trial {
        label: "high".into(),
        bits: QuantBits::HIGH,
        tiers: vec![0.3, 0.05],
        shape: 0.0,
        rotations: 1.0,
        refit: false,
        bytes: 0,
        psnr: 0.0,
    };
    assert_eq!(
        t.options(&["position", "log_scale", "sh_dc"]),
        "--bits position=14,log_scale=8,sh_dc=8 --tiers 0.3,0.05"
    );
    let plain = Trial {
        tiers: vec![],
        shape: 0.03,
        ..t
    };
    assert_eq!(plain.options(&["opacity"]), "--bits opacity=8 --shape 0.03");
    let coarse = Trial {
        rotations: 1.5,
        ..plain.clone()
    };
    assert_eq!(
        coarse.options(&["opacity"]),
        "--bits opacity=8 --shape 0.03 --coarse-rotations 1.5"
    );
    let off = Trial {
        rotations: 0.0,
        ..plain.clone()
    };
    assert!(off.options(&[]).ends_with("--coarse-rotations 0"));
    let refit = Trial {
        refit: true,
        ..plain
    };
    assert_eq!(
        refit.options(&["opacity"]),
        "--bits opacity=8 --shape 0.03 --refit-colours"
    );
}

#[test]
fn the_coarse_rotation_factor_is_searched_with_octree_positions_only() {
    let found = plain_search();
    let mut factors: Vec<f32> = found.trials.iter().map(|t| t.rotations).collect();
    factors.sort_by(f32::total_cmp);
    factors.dedup();
    assert_eq!(factors, ROTATION_FACTORS, "every factor is coded (seeds)");
    for t in &found.trials {
        assert!(t.label.matches("rotations=").count() <= 1, "{}", t.label);
    }
    // The presets start from the given factor.
    assert!(found.trials[..PRESETS.len()]
        .iter()
        .all(|t| t.rotations == RotationCoarsening::DEFAULT.factor));
    let (i, file) = found.best.as_ref().expect("a candidate reaches 40 dB");
    assert!(found.trials[*i].psnr >= 40.0);
    assert_eq!(found.trials[*i].bytes, file.len());
    // Grid positions have no coarse rotations to move.
    let grid = EncoderConfig {
        coding: crate::config::CanonicalSettings {
            octree_positions: false,
            rotation_coarsening: None,
            ..Default::default()
        },
        ..EncoderConfig::default()
    };
    let found = search(&scene(), 40.0, &grid);
    assert!(found.trials.iter().all(|t| t.rotations == 0.0));
}
