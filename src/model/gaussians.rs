//! In-memory Gaussians, structure-of-arrays, in the reference implementation's units:
//! log-scales, raw (unnormalised) w-first quaternions, pre-sigmoid opacities, SH coefficients
//! coefficient-major per Gaussian (`[coef][rgb]`, coef 0 = DC).

use crate::error::{Error, Result};

/// Number of SH coefficients per colour channel for `degree` (1, 4, 9, 16).
/// A stored (pre-activation) opacity as the opacity compositing uses: `1 / (1 + e^-x)`.
#[inline]
#[allow(clippy::disallowed_methods)] // for renderers and exporters, not decoded data
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

pub fn sh_coeffs(degree: u8) -> usize {
    let d = degree as usize + 1;
    d * d
}

/// A set of Gaussians (static or dynamic) with the same attribute layout.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Gaussians {
    pub sh_degree: u8,
    /// Width of the language feature per Gaussian (0 = no language; DLGStream: 9).
    pub lang_width: usize,
    pub positions: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    /// Raw quaternions (w, x, y, z); normalised only when used.
    pub rotations: Vec<[f32; 4]>,
    /// Colour opacity, pre-sigmoid.
    pub opacity: Vec<f32>,
    /// Language opacity, pre-sigmoid; empty when `lang_width == 0`.
    pub lang_opacity: Vec<f32>,
    /// `len * sh_coeffs * 3` SH coefficients.
    pub sh: Vec<f32>,
    /// `len * lang_width` language features.
    pub lang: Vec<f32>,
}

impl Gaussians {
    pub fn new(sh_degree: u8, lang_width: usize) -> Self {
        Gaussians {
            sh_degree,
            lang_width,
            ..Default::default()
        }
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
    pub fn coeffs(&self) -> usize {
        sh_coeffs(self.sh_degree)
    }
    /// Floats of SH per Gaussian.
    pub fn sh_stride(&self) -> usize {
        self.coeffs() * 3
    }
    pub fn has_language(&self) -> bool {
        self.lang_width > 0
    }

    pub fn sh_of(&self, i: usize) -> &[f32] {
        let s = self.sh_stride();
        &self.sh[i * s..(i + 1) * s]
    }
    pub fn lang_of(&self, i: usize) -> &[f32] {
        let w = self.lang_width;
        &self.lang[i * w..(i + 1) * w]
    }

    /// Every array has the length its layout requires.
    pub fn check_shapes(&self) -> Result<()> {
        let n = self.len();
        let lw = self.lang_width;
        let ok = self.log_scales.len() == n
            && self.rotations.len() == n
            && self.opacity.len() == n
            && self.sh.len() == n * self.sh_stride()
            && self.lang.len() == n * lw
            && self.lang_opacity.len() == if lw > 0 { n } else { 0 }
            && self.sh_degree <= 3;
        if ok {
            Ok(())
        } else {
            Err(Error::input(
                "Gaussian attribute arrays have inconsistent lengths",
            ))
        }
    }

    /// Reject NaN/Inf anywhere (the encoder's gate): names the attribute and the Gaussian.
    pub fn check_finite(&self) -> Result<()> {
        let bad = |what: &str, i: usize| {
            Err(Error::input(format!(
                "{what} of Gaussian {i} is NaN or infinite"
            )))
        };
        for i in 0..self.len() {
            if !self.positions[i].iter().all(|v| v.is_finite()) {
                return bad("position", i);
            }
            if !self.log_scales[i].iter().all(|v| v.is_finite()) {
                return bad("log-scale", i);
            }
            if !self.rotations[i].iter().all(|v| v.is_finite()) {
                return bad("rotation", i);
            }
            if !self.opacity[i].is_finite() {
                return bad("opacity", i);
            }
            if !self.sh_of(i).iter().all(|v| v.is_finite()) {
                return bad("SH colour", i);
            }
            if self.has_language()
                && (!self.lang_opacity[i].is_finite()
                    || !self.lang_of(i).iter().all(|v| v.is_finite()))
            {
                return bad("language feature or opacity", i);
            }
        }
        Ok(())
    }

    /// Append Gaussian `i` of `other` (same layout).
    pub fn push_from(&mut self, other: &Gaussians, i: usize) {
        self.positions.push(other.positions[i]);
        self.log_scales.push(other.log_scales[i]);
        self.rotations.push(other.rotations[i]);
        self.opacity.push(other.opacity[i]);
        self.sh.extend_from_slice(other.sh_of(i));
        if self.has_language() {
            self.lang_opacity.push(other.lang_opacity[i]);
            self.lang.extend_from_slice(other.lang_of(i));
        }
    }

    /// A copy without language channels.
    pub fn without_language(&self) -> Gaussians {
        let mut out = self.clone();
        out.lang_width = 0;
        out.lang.clear();
        out.lang_opacity.clear();
        out
    }

    /// Concatenate `other` (same layout) onto `self`.
    pub fn extend(&mut self, other: &Gaussians) {
        if other.sh_degree == self.sh_degree && other.lang_width == self.lang_width {
            self.positions.extend_from_slice(&other.positions);
            self.log_scales.extend_from_slice(&other.log_scales);
            self.rotations.extend_from_slice(&other.rotations);
            self.opacity.extend_from_slice(&other.opacity);
            self.lang_opacity.extend_from_slice(&other.lang_opacity);
            self.sh.extend_from_slice(&other.sh);
            self.lang.extend_from_slice(&other.lang);
            return;
        }
        for i in 0..other.len() {
            self.push_from(other, i);
        }
    }

    /// A copy with SH truncated or zero-extended to `degree`.
    pub fn with_sh_degree(&self, degree: u8) -> Gaussians {
        let mut out = self.clone();
        out.sh_degree = degree;
        let (from, to) = (self.coeffs(), sh_coeffs(degree));
        out.sh = Vec::with_capacity(self.len() * to * 3);
        for i in 0..self.len() {
            let s = self.sh_of(i);
            for k in 0..to {
                for c in 0..3 {
                    out.sh.push(if k < from { s[k * 3 + c] } else { 0.0 });
                }
            }
        }
        out
    }

    /// Axis-aligned bounds of the positions, ignoring non-finite values.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            if p.iter().all(|v| v.is_finite()) {
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
        }
        (lo[0] <= hi[0]).then_some((lo, hi))
    }
}

/// The canonical state of one GOP: static and dynamic Gaussians.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Canonical {
    pub statics: Gaussians,
    pub dynamics: Gaussians,
}

impl Canonical {
    pub fn from_static(g: Gaussians) -> Self {
        let dynamics = Gaussians::new(g.sh_degree, g.lang_width);
        Canonical {
            statics: g,
            dynamics,
        }
    }
    pub fn len(&self) -> usize {
        self.statics.len() + self.dynamics.len()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Static and dynamic Gaussians in one set (static first).
    pub fn merged(&self) -> Gaussians {
        let mut g = self.statics.clone();
        g.extend(&self.dynamics);
        g
    }
}
