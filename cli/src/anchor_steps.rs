//! The steps raw Scaffold-GS anchors are quantised with when `dlgs encode raw.dlgs` codes them
//! (issue 68): the coarsest per attribute (feature, log-scaling, offsets) whose renders stay
//! within a quality budget of the uncoded anchors, on judge views (orbit cameras at a few
//! times, colour PSNR and, with a language MLP, language PSNR).
//!
//! Each attribute is searched on its own (the others at the prior's fine default steps) on a
//! ladder of half-octaves, needing the budget plus 4.8 dB (three error sources of equal power
//! add up to the budget); then the three together are checked, all steps shrinking by a
//! half-octave until they pass, and the slack left is spent a quarter-octave at a time. Quality depends only on the steps (a fitted context model
//! changes the bits, not the values), so the search codes with the fast prior.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use dlgs_encoder::scaffold_prior::DEFAULT_PRIOR_STEPS;
use dlgs_encoder::scaffold_recode::{recode_anchors, RawAnchorCoding, RecodeOptions};
use dlgs_render::{metrics, Camera, Image};

use crate::cameras_arg::CameraArgs;
use crate::rd_cmd::{renders, sample_times};
use crate::rd_scaffold::{feature_peak, feature_psnr};
use crate::scene_io::Source;

/// Half-octaves above the default step an attribute may go (2^10 = 1024 times).
const LADDER: u32 = 20;
/// 10 log10(3): the margin of each attribute's own search.
const SHARE_DB: f64 = 4.771;

/// Of the budget's error power, what the residual MLPs' rounding may take: 1 % (20 dB).
const RNTC_MARGIN_DB: f64 = 20.0;
/// Mantissa bits tried for the residual MLPs, fewest first.
const RNTC_MANTISSAS: [u32; 8] = [0, 1, 2, 3, 4, 6, 8, 10];

/// One judged set of steps (0: raw anchors kept) and residual MLP precision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Judged {
    pub steps: [f32; 3],
    pub rntc_mantissa: u32,
    /// Mean PSNR over the judge renders (as `dlgs rd`).
    pub colour_db: f64,
    pub language_db: Option<f64>,
    /// The lowest of the renders' PSNRs (colour and language together).
    pub worst_db: f64,
}

impl Judged {
    fn passes(&self, budget: f64) -> bool {
        self.colour_db >= budget && self.language_db.is_none_or(|l| l >= budget)
    }
}

/// Renders of the uncoded file and a scratch file for the candidates.
pub struct Judge {
    input: PathBuf,
    scratch: PathBuf,
    cams: Vec<Camera>,
    times: Vec<f64>,
    language: bool,
    reference: Vec<Image>,
    peak: f64,
    pub judged: Vec<Judged>,
}

impl Judge {
    /// Judge views of `input`: 4 orbit cameras at 480x360, 3 times over the file.
    pub fn new(input: &Path, scratch: &Path) -> Result<Judge> {
        let mut src = Source::open(input)?;
        let cam_args = CameraArgs {
            cameras: None,
            view: None,
            orbit: 4,
            width: Some(480),
            height: Some(360),
            up: "-y".into(),
            distance: 1.6,
        };
        let cams = cam_args.resolve(&src.canonical(0.0)?)?;
        let times = sample_times(&src, 3);
        let language = src.language_shape().is_some();
        let reference = renders(&mut src, &times, &cams, language, false)?;
        let peak = feature_peak(&reference);
        Ok(Judge {
            input: input.to_path_buf(),
            scratch: scratch.to_path_buf(),
            cams,
            times,
            language,
            reference,
            peak,
            judged: Vec::new(),
        })
    }

    /// Renders of the file re-coded as `o` says, against the uncoded one.
    pub fn judge(&mut self, o: &RecodeOptions) -> Result<Judged> {
        let f =
            File::open(&self.input).with_context(|| format!("opening {}", self.input.display()))?;
        let (bytes, _) = recode_anchors(
            BufReader::new(f),
            o,
            crate::hac_ingest_cmd::ZSTD_LEVEL,
            dlgs::Limits::default(),
            &mut |_, _| {},
        )?;
        self.judge_bytes(&bytes, o.raw.steps(), o.rntc_mantissa)
    }

    /// [`Self::judge`] of an already coded file.
    fn judge_bytes(&mut self, bytes: &[u8], steps: [f32; 3], rntc_mantissa: u32) -> Result<Judged> {
        std::fs::write(&self.scratch, bytes)
            .with_context(|| format!("writing {}", self.scratch.display()))?;
        let mut test = Source::open(&self.scratch)?;
        let images = renders(&mut test, &self.times, &self.cams, self.language, false)?;
        let _ = std::fs::remove_file(&self.scratch);
        let (mut colour, mut lang, mut worst) = (0.0, 0.0, f64::INFINITY);
        for (r, t) in self.reference.iter().zip(&images) {
            let c = metrics::psnr(&r.color, &t.color);
            colour += c;
            worst = worst.min(c);
            if let (Some(x), Some(y)) = (&r.features, &t.features) {
                let l = feature_psnr(x, y, self.peak);
                lang += l;
                worst = worst.min(l);
            }
        }
        let n = images.len().max(1) as f64;
        let j = Judged {
            steps,
            rntc_mantissa,
            colour_db: colour / n,
            language_db: self.language.then_some(lang / n),
            worst_db: worst,
        };
        self.judged.push(j);
        Ok(j)
    }
}

/// Step of attribute `a` at rung `j` of the ladder (quarter-octaves above the default).
fn ladder(a: usize, j: u32) -> f32 {
    DEFAULT_PRIOR_STEPS[a] * 2f32.powf(j as f32 / 4.0)
}

/// The coarsest steps within `budget_db`; `progress(judged)` after each candidate.
///
/// With anchor residuals (`rntc`), first the fewest mantissa bits of their MLPs' weights whose
/// rounding alone keeps every judge render [`RNTC_MARGIN_DB`] above the budget (raw anchors
/// kept); every later
/// candidate has them. Then each attribute on its own (half-octave rungs, the budget plus [`SHARE_DB`]), then the
/// three together (all a half-octave finer until they pass), then the slack is spent: each
/// attribute in turn a quarter-octave coarser while the three still pass.
pub fn choose(
    judge: &mut Judge,
    budget_db: f64,
    rntc: bool,
    progress: &mut dyn FnMut(usize),
) -> Result<Judged> {
    let mut rntc_mantissa = 23;
    if rntc {
        for m in RNTC_MANTISSAS {
            let o = RecodeOptions {
                k: 1.0,
                raw: RawAnchorCoding::Keep,
                rntc_mantissa: m,
            };
            let j = judge.judge(&o)?;
            progress(judge.judged.len());
            // Renders of GOPs without residuals are identical (inf): the worst render counts.
            if j.worst_db >= budget_db + RNTC_MARGIN_DB {
                rntc_mantissa = m;
                break;
            }
        }
    }
    let mut chosen = [0u32; 3];
    let mut try_steps = |judge: &mut Judge, c: [u32; 3]| -> Result<Judged> {
        let steps = std::array::from_fn(|a| ladder(a, c[a]));
        let o = RecodeOptions {
            k: 1.0,
            raw: RawAnchorCoding::Prior(steps),
            rntc_mantissa,
        };
        let j = judge.judge(&o)?;
        progress(judge.judged.len());
        Ok(j)
    };
    for a in [0, 2, 1] {
        // The largest rung that passes, assuming quality falls with the step.
        let (mut ok, mut bad) = (0u32, LADDER + 1);
        while bad - ok > 1 {
            let mid = (ok + bad) / 2;
            let mut c = [0; 3];
            c[a] = 2 * mid;
            if try_steps(judge, c)?.passes(budget_db + SHARE_DB) {
                ok = mid;
            } else {
                bad = mid;
            }
        }
        chosen[a] = 2 * ok;
    }
    let mut best = loop {
        let j = try_steps(judge, chosen)?;
        if j.passes(budget_db) || chosen == [0; 3] {
            break j;
        }
        chosen = chosen.map(|c| c.saturating_sub(2));
    };
    let mut open = [true; 3];
    while open.iter().any(|&o| o) {
        for a in [0, 2, 1] {
            if !open[a] || chosen[a] >= LADDER * 2 {
                open[a] = false;
                continue;
            }
            let mut c = chosen;
            c[a] += 1;
            let j = try_steps(judge, c)?;
            if j.passes(budget_db) {
                (chosen, best) = (c, j);
            } else {
                open[a] = false;
            }
        }
    }
    Ok(best)
}
