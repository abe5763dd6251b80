//! The smallest still-scene file at a target PSNR (`dlgs encode --target-psnr`).
//!
//! The presets and importance tiers trade bytes for quality differently on every scene: the
//! smallest file at SOG's PSNR was `high` with two tiers on lod3, `medium` with two finer ones on
//! lod2 (docs/benchmarks/canonical.md "Where we are"), found by hand. This codes the scene with
//! each preset
//! under each of a fixed list of tier fractions, decodes every candidate for real and renders
//! it, and keeps the smallest whose PSNR reaches the target.
//!
//! Quality is measured from cameras of the search's own ([`search_views`]: 12 views at 5 and 35
//! degrees elevation), not the 8 views of `dlgs compare` (20 degrees; same image size), so
//! benchmark numbers are not fitted to their cameras; the two disagree by a fraction of a dB
//! either way (docs/benchmarks/canonical-levers.md "Target PSNR").

use std::io::Cursor;
use std::sync::Arc;

use dlgs::chunks::csog::{self, QuantBits, RotationCoarsening};
use dlgs::container::{ChunkType, FileReader};
use dlgs::{Gaussians, Limits, Result};
use dlgs_render::{metrics, orbit_cameras, Camera, OrbitSpec};

pub use crate::judge_views::search_views;
use crate::judge_views::search_views_sized;
use crate::{
    bit_allocation, importance, orientation, prepare_still, CanonicalCodec, EncoderConfig,
};

/// The presets tried, coarsest first.
pub const PRESETS: [(&str, QuantBits); 4] = [
    ("low", QuantBits::LOW),
    ("medium", QuantBits::MEDIUM),
    ("high", QuantBits::HIGH),
    ("near-lossless", QuantBits::NEAR_LOSSLESS),
];

/// The tier fractions tried with each preset (`--tiers`): none, then the settings that made the
/// smallest files at SOG's PSNR on the real scenes, from the mildest.
pub const TIER_SETS: [&[f64]; 6] = [
    &[],
    &[0.04],
    &[0.06, 0.006],
    &[0.15, 0.02],
    &[0.3, 0.05],
    &[0.5, 0.2],
];

/// A per-view PSNR above this counts as this (identical views would make the mean infinite),
/// so no candidate reaches a target above it.
pub const PSNR_CAP: f64 = 100.0;

/// One coded candidate.
#[derive(Debug, Clone)]
pub struct Trial {
    /// The preset it started from, and the groups moved from it (`high +sh_dc -rotation`).
    pub label: String,
    pub bits: QuantBits,
    pub tiers: Vec<f64>,
    /// The level-shaping tolerance (`--shape`; 0 = nearest levels).
    pub shape: f64,
    /// The coarse-rotation factor (`--coarse-rotations`; 0 = off).
    pub rotations: f32,
    /// Coded with the colour refit (`--refit-colours`, [`crate::colour_refit`]).
    pub refit: bool,
    pub bytes: usize,
    /// Mean over [`search_views`] of each view's PSNR against the uncompressed scene.
    pub psnr: f64,
}

impl Trial {
    /// The `dlgs encode` options that code this candidate (`--bits` for each of `groups`,
    /// `--tiers`, `--shape`, `--coarse-rotations` unless it is the default).
    pub fn options(&self, groups: &[&str]) -> String {
        let bits: Vec<String> = groups
            .iter()
            .map(|&g| format!("{g}={}", bit_allocation::get(&self.bits, g)))
            .collect();
        let mut o = format!("--bits {}", bits.join(","));
        if !self.tiers.is_empty() {
            let f: Vec<String> = self.tiers.iter().map(|f| f.to_string()).collect();
            o += &format!(" --tiers {}", f.join(","));
        }
        if self.shape > 0.0 {
            o += &format!(" --shape {}", self.shape);
        }
        if self.rotations != RotationCoarsening::DEFAULT.factor {
            o += &format!(" --coarse-rotations {}", self.rotations);
        }
        if self.refit {
            o += " --refit-colours";
        }
        o
    }
}

/// What the search found.
#[derive(Debug, Clone)]
pub struct Found {
    /// Every candidate coded, in the order tried.
    pub trials: Vec<Trial>,
    /// The smallest trial reaching the target, and its file; `None` when none does.
    pub best: Option<(usize, Vec<u8>)>,
    /// The attribute groups the coded scene has (for [`Trial::options`]).
    pub groups: Vec<&'static str>,
}

/// The name of the shaping move among the groups' ([`SHAPE_LEVELS`]).
const SHAPE: &str = "shape";
/// The name of the coarse-rotation move ([`ROTATION_FACTORS`]).
const ROTATIONS: &str = "rotations";

/// The coarse-rotation factors tried (`--coarse-rotations`, format-spec §6.5.6), on sets with
/// octree positions: a larger factor stores more small Gaussians' rotations coarser. Real lod1
/// at its `--target-psnr 48.63` bits and tiers: 0 124,405 B at 48.83 dB, 1 (the default)
/// 120,143 B at 48.63, 1.5 117,542 B at 48.25, 2 115,658 B at 47.80, 3 112,714 B at 46.62
/// (docs/benchmarks/canonical-levers.md "Target PSNR"): a cheaper trade per byte than a bit of
/// most groups.
pub const ROTATION_FACTORS: [f32; 5] = [0.0, 1.0, 1.5, 2.0, 3.0];

/// The level-shaping tolerances tried (`--shape`), on scenes that store SH bands above the DC
/// only: there shaping moves band coefficients onto the levels the coder pays least for (real
/// fruit at its `--target-psnr 52.66` bits and tiers: 58,807 B at 52.86 dB, with shaping 0.01
/// 54,241 B at 52.72 dB); on the SH 0 scenes measured it changed a few bytes.
pub const SHAPE_LEVELS: [f64; 5] = [0.0, 0.01, 0.03, 0.1, 0.3];

/// With `--refit-colours`: at the end, this many of the candidates below the target that are
/// smaller than the best (the highest PSNR first) are coded again with the colour refit, which
/// lifts some over the target (real lod2 at its goal-row options: 48.41 -> 48.69 dB on the
/// benchmark's views for 29 bytes more; docs/benchmarks/canonical-levers.md "Colour refit");
/// each costs two codings and
/// the fit.
pub const REFIT_TRIES: usize = 4;

/// Refinement: from this many of the closest candidates below the target, ...
pub const REFINE_STARTS: usize = 2;
/// ... add a bit to the group that buys the most PSNR per byte, at most this many times.
pub const REFINE_STEPS: usize = 3;

/// Mean PSNR of `file` (a still scene the search wrote) against `g` from `dlgs compare`'s
/// default cameras (8 orbit views at 20 degrees, [`OrbitSpec::default`]), uncapped as there:
/// views the search never measures, so the user sees how its choice holds elsewhere. The
/// smallest file that clears a target on some views is, by selection, lucky on them: on the
/// real scenes these views land 0.01-0.14 dB under the target in four of nine cases
/// (docs/benchmarks/canonical-levers.md "Target PSNR").
pub fn compare_views_psnr(g: &Gaussians, file: &[u8]) -> Result<f64> {
    let cams = orbit_cameras(g, &OrbitSpec::default());
    let reference = bit_allocation::render_views(g, &cams)?;
    let decoded = bit_allocation::render_views(&decode_still(file)?, &cams)?;
    Ok(mean_psnr(&reference, &decoded, f64::INFINITY))
}

/// Mean of each view's PSNR, each at most `cap` ([`PSNR_CAP`] in the search).
fn mean_psnr(reference: &[Vec<f32>], decoded: &[Vec<f32>], cap: f64) -> f64 {
    let sum: f64 = reference
        .iter()
        .zip(decoded)
        .map(|(a, b)| metrics::psnr(a, b).min(cap))
        .sum();
    sum / reference.len().max(1) as f64
}

/// Code the still scene `g` with every preset under every tier set of [`TIER_SETS`] (the rest
/// of `base` as given: its `canonical` sort, orientation, octree and coarse rotations) and
/// keep the smallest file whose PSNR on [`search_views`] is at least `target_db`. Within a
/// tier set the presets go from coarse to fine and stop at the first that reaches the target
/// or once a candidate is no smaller than the best so far.
///
/// The presets are one bit apart in every group, a wide step (real donut at `high`: 55.9 dB,
/// `near-lossless` 70.1 dB on these views). So the [`REFINE_STARTS`] candidates below the target
/// with the highest PSNR, among those smaller than the best, then take one bit more in the group
/// that buys the most PSNR per byte, up to [`REFINE_STEPS`] times, while they stay smaller than
/// the best; one that reaches the target, and at the end the best, then give back a bit in
/// each group that can spare one, as long as one can.
///
/// On scenes with SH bands above the DC, shaping is a move too (one step along
/// [`SHAPE_LEVELS`], like a bit, in refinement and sparing); so is the coarse-rotation factor
/// (one step along [`ROTATION_FACTORS`], which also holds `base`'s own factor) when `base`
/// stores octree positions. The presets and tier sets are coded unshaped at `base`'s factor,
/// so after the first refinement and sparing the best file and the [`REFINE_STARTS`] closest
/// below the target are also coded at every shaping level and every factor, and refinement
/// and sparing run again from there.
/// `progress` sees each trial.
pub fn smallest_at(
    g: &Gaussians,
    target_db: f64,
    base: &EncoderConfig,
    progress: impl FnMut(&Trial),
) -> Result<Found> {
    let size = OrbitSpec::default();
    smallest_at_view_size(g, target_db, base, (size.width, size.height), progress)
}

/// [`smallest_at`] judging candidates on [`search_views`] rendered at `view_size` (width,
/// height) instead of `dlgs compare`'s size: smaller views make the search faster (the unit
/// tests use them) but judge position errors more leniently.
pub fn smallest_at_view_size(
    g: &Gaussians,
    target_db: f64,
    base: &EncoderConfig,
    view_size: (u32, u32),
    progress: impl FnMut(&Trial),
) -> Result<Found> {
    let sort = match base.coding.codec {
        CanonicalCodec::Sorted { sort, .. } => sort,
        CanonicalCodec::Raw => crate::SortSpec::DEFAULT,
    };
    let refit = base.refit.colours;
    // Every candidate is `base` with its own bits and tiers, without the other searches.
    let base = EncoderConfig {
        coding: crate::config::CanonicalSettings {
            codec: CanonicalCodec::Sorted {
                bits: QuantBits::HIGH,
                sort,
            },
            ..base.clone().coding
        },
        still: crate::config::StillTools {
            shape_tolerance: 0.0,
            reallocate_bits: 0,
            ..base.clone().still
        },
        refit: crate::config::RefitSettings {
            colours: false,
            ..base.clone().refit
        },
        ..base.clone()
    };
    // The tiers' blending weights, measured once on the set the encoder codes.
    let (prepared, _) = prepare_still(g, &base);
    let coded = prepared.as_ref().unwrap_or(g);
    let oriented = base
        .still
        .canonical_orientation
        .then(|| orientation::closest_to_identity(coded));
    let blend: Arc<[f64]> = importance::blend_weights(oriented.as_ref().unwrap_or(coded)).into();
    let cams = search_views_sized(g, view_size);
    let start_factor = base.coding.rotation_coarsening.map_or(0.0, |c| c.factor);
    // The factors moved through: none but `base`'s without octree positions.
    let mut factors = vec![start_factor];
    if base.coding.octree_positions {
        factors.extend(ROTATION_FACTORS);
        factors.sort_by(f32::total_cmp);
        factors.dedup();
    }
    let mut s = Search {
        g,
        // The groups the coded set has (bands that are zero everywhere are not stored).
        groups: bit_allocation::groups_of(coded),
        target_db,
        base,
        sort,
        blend,
        factors,
        reference: bit_allocation::render_views(g, &cams)?,
        cams,
        trials: Vec::new(),
        best: None,
        refit_now: false,
        progress,
    };
    for tiers in TIER_SETS {
        for (preset, bits) in PRESETS {
            let t = s.code(preset.to_string(), bits, tiers, 0.0, start_factor)?;
            // Finer presets only cost more.
            if s.trials[t].psnr >= target_db || !s.beats_best(t) {
                break;
            }
        }
    }
    s.refine()?;
    if let Some(b) = s.best.as_ref().map(|b| b.0) {
        s.spare_bits(b)?;
    }
    let seeded = s.shaped() || s.factors.len() > 1;
    if seeded {
        let mut seeds: Vec<usize> = s.best.iter().map(|b| b.0).collect();
        seeds.extend(s.closest_below());
        for seed in seeds {
            let t = s.trials[seed].clone();
            if s.shaped() {
                for &level in &SHAPE_LEVELS[1..] {
                    let label = with_token(&t.label, SHAPE, level);
                    s.code(label, t.bits, &t.tiers, level, t.rotations)?;
                }
            }
            for f in s.factors.clone() {
                let label = with_token(&t.label, ROTATIONS, f);
                s.code(label, t.bits, &t.tiers, t.shape, f)?;
            }
        }
        s.refine()?;
        if let Some(b) = s.best.as_ref().map(|b| b.0) {
            s.spare_bits(b)?;
        }
    }
    if refit {
        s.refit_below()?;
    }
    Ok(Found {
        trials: s.trials,
        best: s.best,
        groups: s.groups,
    })
}

struct Search<'a, P: FnMut(&Trial)> {
    g: &'a Gaussians,
    groups: Vec<&'static str>,
    target_db: f64,
    base: EncoderConfig,
    sort: crate::SortSpec,
    blend: Arc<[f64]>,
    /// The coarse-rotation factors moved through, ascending.
    factors: Vec<f32>,
    cams: Vec<Camera>,
    reference: Vec<Vec<f32>>,
    trials: Vec<Trial>,
    best: Option<(usize, Vec<u8>)>,
    /// Code candidates with the colour refit ([`Self::refit_below`]).
    refit_now: bool,
    progress: P,
}

impl<P: FnMut(&Trial)> Search<'_, P> {
    /// Code, decode and render one candidate; keep its file when it is the new best.
    fn code(
        &mut self,
        label: String,
        bits: QuantBits,
        tiers: &[f64],
        shape: f64,
        rotations: f32,
    ) -> Result<usize> {
        let refit = self.refit_now;
        if let Some(i) = self.trials.iter().position(|t| {
            t.bits == bits
                && t.tiers == tiers
                && t.shape == shape
                && t.rotations == rotations
                && t.refit == refit
        }) {
            return Ok(i);
        }
        let cfg = EncoderConfig {
            coding: crate::config::CanonicalSettings {
                codec: CanonicalCodec::Sorted {
                    bits,
                    sort: self.sort,
                },
                rotation_coarsening: (rotations > 0.0).then_some(RotationCoarsening {
                    factor: rotations,
                    ..RotationCoarsening::DEFAULT
                }),
                ..self.base.clone().coding
            },
            still: crate::config::StillTools {
                tier_weights: tiers.to_vec(),
                shape_tolerance: shape,
                importance: Some(self.blend.clone()),
                ..self.base.clone().still
            },
            refit: crate::config::RefitSettings {
                colours: refit,
                ..self.base.clone().refit
            },
            ..self.base.clone()
        };
        let file = crate::encode_still(self.g, cfg, Vec::new())?;
        let decoded = decode_still(&file)?;
        let trial = Trial {
            label,
            bits,
            tiers: tiers.to_vec(),
            shape,
            rotations,
            refit,
            bytes: file.len(),
            psnr: mean_psnr(
                &self.reference,
                &bit_allocation::render_views(&decoded, &self.cams)?,
                PSNR_CAP,
            ),
        };
        (self.progress)(&trial);
        self.trials.push(trial);
        let i = self.trials.len() - 1;
        if self.trials[i].psnr >= self.target_db && self.beats_best(i) {
            self.best = Some((i, file));
        }
        Ok(i)
    }

    /// Whether trial `i` is smaller than the best so far (true when there is none).
    fn beats_best(&self, i: usize) -> bool {
        self.best
            .as_ref()
            .is_none_or(|(b, _)| self.trials[i].bytes < self.trials[*b].bytes)
    }

    /// [`REFIT_TRIES`] of the candidates below the target that are smaller than the best, the
    /// highest PSNR first, coded again with the colour refit; one that reaches the target
    /// then gives back what bits it can spare (each try a refit coding too).
    fn refit_below(&mut self) -> Result<()> {
        let mut below: Vec<usize> = (0..self.trials.len())
            .filter(|&i| self.trials[i].psnr < self.target_db && self.beats_best(i))
            .collect();
        below.sort_by(|&a, &b| self.trials[b].psnr.total_cmp(&self.trials[a].psnr));
        self.refit_now = true;
        for at in below.into_iter().take(REFIT_TRIES) {
            if !self.beats_best(at) {
                continue;
            }
            let t = self.trials[at].clone();
            let label = format!("{} +refit", t.label);
            let c = self.code(label, t.bits, &t.tiers, t.shape, t.rotations)?;
            if self.trials[c].psnr >= self.target_db && self.best.as_ref().is_some_and(|b| b.0 == c)
            {
                self.spare_bits(c)?;
            }
        }
        self.refit_now = false;
        Ok(())
    }

    /// Whether shaping is searched: the coded scene stores SH bands above the DC.
    fn shaped(&self) -> bool {
        self.groups.contains(&"sh_rest")
    }

    /// The [`REFINE_STARTS`] trials below the target with the highest PSNR, among those
    /// smaller than the best.
    fn closest_below(&self) -> Vec<usize> {
        let mut below: Vec<usize> = (0..self.trials.len())
            .filter(|&i| self.trials[i].psnr < self.target_db && self.beats_best(i))
            .collect();
        below.sort_by(|&a, &b| self.trials[b].psnr.total_cmp(&self.trials[a].psnr));
        below.truncate(REFINE_STARTS);
        below
    }

    /// The moves from a trial: a bit in each group, on [`Self::shaped`] scenes one step of
    /// shaping ([`SHAPE`]), and with octree positions one step of the coarse-rotation factor
    /// ([`ROTATIONS`]).
    fn moves(&self) -> Vec<&'static str> {
        let mut m = self.groups.clone();
        if self.shaped() {
            m.push(SHAPE);
        }
        if self.factors.len() > 1 {
            m.push(ROTATIONS);
        }
        m
    }

    fn refine(&mut self) -> Result<()> {
        for start in self.closest_below() {
            let mut at = start;
            for _ in 0..REFINE_STEPS {
                if self.trials[at].psnr >= self.target_db || !self.beats_best(at) {
                    break;
                }
                let mut up = None;
                for grp in self.moves() {
                    let Some(c) = self.nudge(at, grp, 1)? else {
                        continue;
                    };
                    let (t, ct) = (&self.trials[at], &self.trials[c]);
                    let gain = (ct.psnr - t.psnr) / (ct.bytes as f64 - t.bytes as f64).max(1.0);
                    if up.is_none_or(|(_, best_gain)| gain > best_gain) {
                        up = Some((c, gain));
                    }
                }
                match up {
                    Some((c, _)) => at = c,
                    None => break,
                }
            }
            if self.trials[at].psnr >= self.target_db {
                self.spare_bits(at)?;
            }
        }
        Ok(())
    }

    /// Trial `at` with group `grp` one bit finer (`delta` 1) or coarser (-1), or with `grp`
    /// = [`SHAPE`] ([`ROTATIONS`]) one shaping level (factor) lower or higher; coded if new.
    /// `None` outside 1..=16 bits, [`SHAPE_LEVELS`] or the factors searched.
    fn nudge(&mut self, at: usize, grp: &'static str, delta: i8) -> Result<Option<usize>> {
        let t = &self.trials[at];
        let (mut bits, mut shape, mut rotations) = (t.bits, t.shape, t.rotations);
        // One step down a list of levels, finest first (finer = `delta` 1).
        let step = |levels: &[f64], at: f64| {
            let i = levels.iter().position(|&l| l == at).unwrap_or(0) as i8 - delta;
            usize::try_from(i).ok().and_then(|i| levels.get(i)).copied()
        };
        let label = if grp == SHAPE {
            let Some(l) = step(&SHAPE_LEVELS, t.shape) else {
                return Ok(None);
            };
            shape = l;
            with_token(&t.label, SHAPE, l)
        } else if grp == ROTATIONS {
            let factors: Vec<f64> = self.factors.iter().map(|&f| f as f64).collect();
            let Some(f) = step(&factors, t.rotations as f64) else {
                return Ok(None);
            };
            rotations = f as f32;
            with_token(&t.label, ROTATIONS, rotations)
        } else {
            let v = bit_allocation::get(&t.bits, grp) as i8 + delta;
            if !(1..=16).contains(&v) {
                return Ok(None);
            }
            bits = bit_allocation::with(&t.bits, grp, v as u8);
            let sign = if delta > 0 { '+' } else { '-' };
            format!("{} {sign}{grp}", t.label)
        };
        let tiers = t.tiers.clone();
        self.code(label, bits, &tiers, shape, rotations).map(Some)
    }

    /// From trial `at` (at the target), take a bit from each group in turn where the file
    /// stays at the target, and again until no group can spare one.
    fn spare_bits(&mut self, mut at: usize) -> Result<()> {
        let start = at;
        for grp in self.moves() {
            let Some(c) = self.nudge(at, grp, -1)? else {
                continue;
            };
            if self.trials[c].psnr >= self.target_db && self.trials[c].bytes < self.trials[at].bytes
            {
                at = c;
            }
        }
        if at != start {
            self.spare_bits(at)?;
        }
        Ok(())
    }
}

/// `label` with its `key=` token (if any) replaced by `key=value`, last.
fn with_token(label: &str, key: &str, value: impl std::fmt::Display) -> String {
    let prefix = format!("{key}=");
    let moves: Vec<&str> = label
        .split(' ')
        .filter(|w| !w.starts_with(&prefix))
        .collect();
    format!("{} {prefix}{value}", moves.join(" "))
}

/// The static Gaussians of a still file's `CSOG`, decoded as every reader does.
fn decode_still(file: &[u8]) -> Result<Gaussians> {
    let mut r = FileReader::open(Cursor::new(file))?;
    let scene = r.scene().clone();
    let chunks = r.gop_chunks(0)?;
    let Some(info) = chunks.iter().find(|c| c.ty == ChunkType::CSOG) else {
        return Err(dlgs::Error::input(
            "quality search: the candidate holds no CSOG",
        ));
    };
    let payload = r.payload(info)?;
    Ok(csog::decode(&payload, info.payload_offset(), &scene, &Limits::default())?.statics)
}

#[cfg(test)]
#[path = "quality_search_tests.rs"]
mod tests;
