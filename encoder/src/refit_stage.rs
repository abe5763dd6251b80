//! The refit stage of the still pipeline ([`RefitSettings`]): after a lossy still scene is
//! coded, fit its stored colours (and opacities) to what the rest decodes to, code it again,
//! and keep the refit only if the encoder's held-out views render closer to the source.

use dlgs::chunks::csog::{self, QuantBits};
use dlgs::container::SceneHeader;
use dlgs::Result;

use crate::colour_refit;
use crate::config::RefitSettings;

/// Codes a canonical GOP's static parts: the `CSOG` payload and, per decoded static Gaussian,
/// its index in the parts' concatenation.
pub(crate) type CodeParts<'a> =
    dyn Fn(&[(dlgs::Gaussians, QuantBits)]) -> Result<(Vec<u8>, Vec<u32>)> + 'a;

/// A coded canonical GOP: the `CSOG` payload and the stored order of its static Gaussians.
type Coded = (Vec<u8>, Vec<u32>);

/// The colour refit's judgement ([`RefitSettings::colours`]): mean PSNR against the
/// source over [`colour_refit::holdout_views`], without and with the best refit (colours alone or,
/// with [`RefitSettings::opacities`], opacities and colours; each as offsets or on levels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefitReport {
    pub before_db: f64,
    pub after_db: f64,
    /// Whether the refit coding was stored (it rendered closer).
    pub kept: bool,
    /// Whether the better refit (`after_db`) was the one on the quantiser's levels, not the
    /// continuous offsets rounded by the coder.
    pub on_levels: bool,
    /// Whether the better refit moved opacities too ([`RefitSettings::opacities`]),
    /// not the colours alone.
    pub opacities_moved: bool,
}

/// One refit candidate: a fit's colours as continuous offsets or on the quantiser's levels,
/// with its opacity moves when the fit made them.
struct RefitChoice<'a> {
    fit: &'a colour_refit::Refits,
    opacity: Option<&'a colour_refit::OpacityLevels>,
    on_levels: bool,
}

impl RefitChoice<'_> {
    /// `parts` with this candidate's colours (and opacities) on the Gaussians `decoded` holds
    /// (`stored[k]`: Gaussian `k`'s index in the parts' concatenation, `place`: its part and
    /// index there).
    fn apply(
        &self,
        parts: &[(dlgs::Gaussians, QuantBits)],
        decoded: &dlgs::Gaussians,
        stored: &[u32],
        place: &[(usize, usize)],
        lattice: &colour_refit::DcLattice,
    ) -> Vec<(dlgs::Gaussians, QuantBits)> {
        let mut refit = parts.to_vec();
        for (k, &j) in stored.iter().enumerate() {
            let (p, i) = place[j as usize];
            if self.on_levels {
                lattice.set_dc(&mut refit[p].0, i, p, decoded, k, self.fit.on_levels[k]);
            } else {
                colour_refit::set_refit_dc(&mut refit[p].0, i, decoded, k, self.fit.offsets[k]);
            }
            if let Some(levels) = self.opacity {
                levels.set(&mut refit[p].0, i, k, self.fit.opacity_moves[k]);
            }
        }
        refit
    }
}

/// [`colour_refit`]: decode `payload` (the coding of `parts`), fit colour offsets to what
/// it stores, code the parts again with the refit colours; `Some` (the new payload and
/// stored order) only if the held-out views render closer to `source`; and the held-out
/// PSNRs.
pub(crate) fn refit_colours(
    scene: &SceneHeader,
    settings: &RefitSettings,
    source: &dlgs::Gaussians,
    parts: &[(dlgs::Gaussians, QuantBits)],
    payload: &[u8],
    stored: &[u32],
    code: &CodeParts<'_>,
) -> Result<(Option<Coded>, RefitReport)> {
    let limits = dlgs::limits::Limits::default();
    let decoded = csog::decode(payload, 0, scene, &limits)?.statics;
    // Part, and index within it, of each Gaussian of the parts' concatenation.
    let mut place = Vec::with_capacity(stored.len());
    for (p, (g, _)) in parts.iter().enumerate() {
        place.extend((0..g.len()).map(|i| (p, i)));
    }
    let lattice = colour_refit::DcLattice::of_parts(parts);
    let (steps, moves) = lattice.steps_and_moves(&decoded, stored, &place);
    let opacity = settings
        .opacities
        .then(|| colour_refit::OpacityLevels::of(parts, &decoded, stored, &place));
    // The colours alone, then (when asked) the opacities and colours: the opacity search
    // can render worse on unseen views than the colours alone (gsplat's goal row), so the
    // judge sees both.
    let views = colour_refit::FitTargets::of(source, settings.full_size);
    let mut fits = vec![(
        colour_refit::fit(&views, &decoded, &steps, &moves, None),
        None,
    )];
    if let Some(levels) = &opacity {
        let with_opacity = colour_refit::fit(&views, &decoded, &steps, &moves, Some(levels));
        fits.push((with_opacity, Some(levels)));
    }
    // Each fit as continuous offsets rounded by the coder, then on the quantiser's levels.
    let mut codings = Vec::with_capacity(2 * fits.len());
    let mut redecoded = Vec::with_capacity(2 * fits.len());
    // Per coding: (on the quantiser's levels, opacities moved), for the report.
    let mut kinds = Vec::with_capacity(2 * fits.len());
    for (fit, levels) in &fits {
        for on_levels in [false, true] {
            let refit = RefitChoice {
                fit,
                opacity: *levels,
                on_levels,
            };
            let coding = code(&refit.apply(parts, &decoded, stored, &place, &lattice))?;
            redecoded.push(csog::decode(&coding.0, 0, scene, &limits)?.statics);
            codings.push(coding);
            kinds.push((on_levels, levels.is_some()));
        }
    }
    let mut candidates = vec![&decoded];
    candidates.extend(redecoded.iter());
    let scores = colour_refit::holdout_psnr(source, &candidates);
    // The best refit, the later one on a tie (levels before offsets, opacities and colours
    // before colours alone); stored only if it beats the first coding.
    let best = (2..scores.len()).fold(1, |b, c| if scores[c] >= scores[b] { c } else { b });
    let kept = scores[best] > scores[0];
    let report = RefitReport {
        before_db: scores[0],
        after_db: scores[best],
        kept,
        on_levels: kinds[best - 1].0,
        opacities_moved: kinds[best - 1].1,
    };
    Ok((kept.then(|| codings.swap_remove(best - 1)), report))
}
