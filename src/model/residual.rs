//! Residuals between GOPs (format-spec §6.6–§6.7): the attribute groups a residual can change,
//! and the explicit (quantised per-attribute delta) residual.
//!
//! A residual turns the decoded canonical state of a reference GOP into the canonical state of
//! the next one. The Gaussians keep their order and count; only attribute values change.

use crate::error::{Error, Result};
use crate::model::{sh_coeffs, Canonical, Gaussians};

/// One attribute group of a Gaussian, in the fixed order residual rows use (§6.6.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum AttrGroup {
    Position = 0,
    LogScale = 1,
    /// Raw quaternion (w, x, y, z); residuals add to it, it is normalised only when used.
    Rotation = 2,
    /// SH coefficient 0 of R, G, B.
    ShDc = 3,
    /// SH coefficients 1.. (coefficient-major, as stored).
    ShRest = 4,
    /// Colour opacity, pre-sigmoid.
    Opacity = 5,
    /// Language opacity, pre-sigmoid.
    LangOpacity = 6,
    /// Language feature.
    Lang = 7,
}

impl AttrGroup {
    pub const ALL: [AttrGroup; 8] = [
        AttrGroup::Position,
        AttrGroup::LogScale,
        AttrGroup::Rotation,
        AttrGroup::ShDc,
        AttrGroup::ShRest,
        AttrGroup::Opacity,
        AttrGroup::LangOpacity,
        AttrGroup::Lang,
    ];

    pub fn from_u8(v: u8) -> Option<Self> {
        Self::ALL.get(v as usize).copied()
    }
    pub fn bit(self) -> u8 {
        1 << self as u8
    }
    pub fn name(self) -> &'static str {
        match self {
            AttrGroup::Position => "position",
            AttrGroup::LogScale => "log_scale",
            AttrGroup::Rotation => "rotation",
            AttrGroup::ShDc => "sh_dc",
            AttrGroup::ShRest => "sh_rest",
            AttrGroup::Opacity => "opacity",
            AttrGroup::LangOpacity => "lang_opacity",
            AttrGroup::Lang => "lang",
        }
    }
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|g| g.name() == s)
    }

    /// Values per Gaussian for a scene with this SH degree and language width (0 = the group
    /// does not exist in such a scene).
    pub fn width(self, sh_degree: u8, lang_width: usize) -> usize {
        let lang = |w| if lang_width > 0 { w } else { 0 };
        match self {
            AttrGroup::Position | AttrGroup::LogScale | AttrGroup::ShDc => 3,
            AttrGroup::Rotation => 4,
            AttrGroup::ShRest => 3 * (sh_coeffs(sh_degree) - 1),
            AttrGroup::Opacity => 1,
            AttrGroup::LangOpacity => lang(1),
            AttrGroup::Lang => lang(lang_width),
        }
    }

    /// The group's values of Gaussian `i`.
    pub fn values(self, g: &Gaussians, i: usize) -> &[f32] {
        let s = g.sh_stride();
        let l = g.lang_width;
        match self {
            AttrGroup::Position => &g.positions[i],
            AttrGroup::LogScale => &g.log_scales[i],
            AttrGroup::Rotation => &g.rotations[i],
            AttrGroup::ShDc => &g.sh[i * s..i * s + 3],
            AttrGroup::ShRest => &g.sh[i * s + 3..(i + 1) * s],
            AttrGroup::Opacity => std::slice::from_ref(&g.opacity[i]),
            AttrGroup::LangOpacity => std::slice::from_ref(&g.lang_opacity[i]),
            AttrGroup::Lang => &g.lang[i * l..(i + 1) * l],
        }
    }

    /// Mutable access to the group's values of Gaussian `i`.
    pub fn values_mut(self, g: &mut Gaussians, i: usize) -> &mut [f32] {
        let s = g.sh_stride();
        let l = g.lang_width;
        match self {
            AttrGroup::Position => &mut g.positions[i],
            AttrGroup::LogScale => &mut g.log_scales[i],
            AttrGroup::Rotation => &mut g.rotations[i],
            AttrGroup::ShDc => &mut g.sh[i * s..i * s + 3],
            AttrGroup::ShRest => &mut g.sh[i * s + 3..(i + 1) * s],
            AttrGroup::Opacity => std::slice::from_mut(&mut g.opacity[i]),
            AttrGroup::LangOpacity => std::slice::from_mut(&mut g.lang_opacity[i]),
            AttrGroup::Lang => &mut g.lang[i * l..(i + 1) * l],
        }
    }
}

/// The groups present in a scene with this layout, in row order.
pub fn groups_of(sh_degree: u8, lang_width: usize) -> Vec<AttrGroup> {
    AttrGroup::ALL
        .into_iter()
        .filter(|g| g.width(sh_degree, lang_width) > 0)
        .collect()
}

/// Which sets a residual applies to (bit 0 static, bit 1 dynamic).
pub const SET_STATIC: u8 = 1;
pub const SET_DYNAMIC: u8 = 2;

/// How one group's deltas are stored in an explicit residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DeltaMode {
    /// `value = f32::from_bits(ref.to_bits() + k)` (wrapping): bit-exact.
    Exact,
    /// `value = ref + k * step`; every decoded value lies within `bound` of the target.
    Quantised { step: f32, bound: f32 },
}

/// One group of an explicit residual: integer deltas for every Gaussian of both sets,
/// `k[i * width + c]`.
#[derive(Debug, Clone, PartialEq)]
pub struct DeltaGroup {
    pub group: AttrGroup,
    pub mode: DeltaMode,
    pub statics: Vec<i32>,
    pub dynamics: Vec<i32>,
}

/// Explicit residual (`RDLT`, §6.7): quantised per-attribute deltas against the reference GOP.
/// Groups not listed are unchanged.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DeltaResidual {
    pub groups: Vec<DeltaGroup>,
}

/// Apply one delta to one value (§6.7.3); the decoder's only arithmetic.
#[inline]
pub fn apply_delta(reference: f32, k: i32, mode: DeltaMode) -> f32 {
    match mode {
        DeltaMode::Exact => f32::from_bits(reference.to_bits().wrapping_add(k as u32)),
        DeltaMode::Quantised { step, .. } => reference + k as f32 * step,
    }
}

/// What the encoder asks of one group.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DeltaTarget {
    Exact,
    /// Largest absolute error allowed on any value of the group.
    Bound(f32),
}

fn group_deltas(
    group: AttrGroup,
    mode: DeltaMode,
    target: &Gaussians,
    reference: &Gaussians,
) -> Result<Vec<i32>> {
    let w = group.width(reference.sh_degree, reference.lang_width);
    let mut k = Vec::with_capacity(reference.len() * w);
    for i in 0..reference.len() {
        let (t, r) = (group.values(target, i), group.values(reference, i));
        for c in 0..w {
            if !t[c].is_finite() {
                return Err(Error::input(format!(
                    "{} of Gaussian {i} is {} (residual targets must be finite)",
                    group.name(),
                    t[c]
                )));
            }
            k.push(match mode {
                DeltaMode::Exact => t[c].to_bits().wrapping_sub(r[c].to_bits()) as i32,
                DeltaMode::Quantised { step, bound } => {
                    let q = ((t[c] - r[c]) / step).round();
                    if q.abs() > 1.0e9 {
                        return Err(Error::input(format!(
                            "{} of Gaussian {i} changes by {} = {q} steps of {step}; \
                             raise the error bound",
                            group.name(),
                            t[c] - r[c]
                        )));
                    }
                    // Rounding of `ref + k*step` can land just outside the bound: try the
                    // neighbours, and refuse a bound finer than the values' float spacing.
                    let q = q as i32;
                    let best = [q, q - 1, q + 1]
                        .into_iter()
                        .min_by(|&a, &b| {
                            let ea = (apply_delta(r[c], a, mode) - t[c]).abs();
                            let eb = (apply_delta(r[c], b, mode) - t[c]).abs();
                            ea.total_cmp(&eb)
                        })
                        .expect("three candidates");
                    let err = (apply_delta(r[c], best, mode) - t[c]).abs();
                    if err > bound {
                        return Err(Error::input(format!(
                            "{} of Gaussian {i}: error {err} exceeds the bound {bound} \
                             (bound below the float spacing of {})",
                            group.name(),
                            t[c]
                        )));
                    }
                    best
                }
            });
        }
    }
    Ok(k)
}

impl DeltaResidual {
    /// Deltas that take `reference` to `target` (same counts and layout), one entry per group
    /// asked for. Every decoded value is verified against its bound.
    pub fn compute(
        target: &Canonical,
        reference: &Canonical,
        asked: &[(AttrGroup, DeltaTarget)],
    ) -> Result<DeltaResidual> {
        for (t, r, set) in [
            (&target.statics, &reference.statics, "static"),
            (&target.dynamics, &reference.dynamics, "dynamic"),
        ] {
            if t.len() != r.len() || t.sh_degree != r.sh_degree || t.lang_width != r.lang_width {
                return Err(Error::input(format!(
                    "residual target's {set} set ({} Gaussians, SH {}, language {}) differs \
                     from the reference's ({}, SH {}, language {})",
                    t.len(),
                    t.sh_degree,
                    t.lang_width,
                    r.len(),
                    r.sh_degree,
                    r.lang_width
                )));
            }
        }
        let mut groups = Vec::new();
        for &(group, want) in asked {
            if group.width(reference.statics.sh_degree, reference.statics.lang_width) == 0 {
                continue;
            }
            let mode = match want {
                DeltaTarget::Exact => DeltaMode::Exact,
                DeltaTarget::Bound(b) if b.is_finite() && b > 0.0 => DeltaMode::Quantised {
                    // A hair under 2*bound so that round-to-nearest stays inside the bound.
                    step: 2.0 * b * (1.0 - 1.0 / 1024.0),
                    bound: b,
                },
                DeltaTarget::Bound(b) => {
                    return Err(Error::input(format!(
                        "error bound {b} for {} must be positive and finite",
                        group.name()
                    )))
                }
            };
            groups.push(DeltaGroup {
                group,
                mode,
                statics: group_deltas(group, mode, &target.statics, &reference.statics)?,
                dynamics: group_deltas(group, mode, &target.dynamics, &reference.dynamics)?,
            });
        }
        Ok(DeltaResidual { groups })
    }

    /// The canonical state this residual produces from `reference`.
    pub fn apply(&self, reference: &Canonical) -> Canonical {
        let mut out = reference.clone();
        for g in &self.groups {
            for (set, k) in [
                (&mut out.statics, &g.statics),
                (&mut out.dynamics, &g.dynamics),
            ] {
                let w = g.group.width(set.sh_degree, set.lang_width);
                for i in 0..set.len() {
                    let v = g.group.values_mut(set, i);
                    for c in 0..w {
                        v[c] = apply_delta(v[c], k[i * w + c], g.mode);
                    }
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_deltas_restore_every_bit_pattern() {
        for (r, t) in [
            (1.0f32, -3.5f32),
            (0.0, -0.0),
            (f32::MIN_POSITIVE, f32::MAX),
            (-1e-30, 7.0),
        ] {
            let k = t.to_bits().wrapping_sub(r.to_bits()) as i32;
            assert_eq!(apply_delta(r, k, DeltaMode::Exact).to_bits(), t.to_bits());
        }
    }
}
