//! From a fit to an `AHAC` context model: grid bits from the latents' signs (entries no anchor
//! reads take the more common bit), weights back to real units, rounded to `mantissa` bits.

use bitvec::prelude::*;

use dlgs::model::hac_context::{HacContext, CONTEXT_OUT};

use super::train::{Problem, Trained, TRAINED_OUT};
use crate::mantissa::round_mantissa;

/// The context model of `t` (box and steps from `prior`), weights at `mantissa` bits. The
/// output biases keep every bit: they carry the channels' means at the steps' precision.
pub(super) fn context(t: &Trained, p: &Problem, prior: &HacContext, mantissa: u32) -> HacContext {
    let used = t.touched.iter().filter(|&&u| u).count();
    let ones = t
        .latent
        .iter()
        .zip(&t.touched)
        .filter(|&(&l, &u)| u && l >= 0.0)
        .count();
    let filler = 2 * ones > used;
    let bits = HacContext::level_bits(p.grid3, p.grid2);
    let levels = t
        .level_at
        .iter()
        .zip(&bits)
        .map(|(&(start, _), &n)| {
            (start..start + n)
                .map(|k| {
                    if t.touched[k] {
                        t.latent[k] >= 0.0
                    } else {
                        filler
                    }
                })
                .collect::<BitVec<u64, Lsb0>>()
        })
        .collect();
    let nh = t.hidden;
    let mut w2 = vec![0f32; CONTEXT_OUT * nh];
    let mut b2 = vec![0f32; CONTEXT_OUT];
    for o in 0..TRAINED_OUT {
        for j in 0..nh {
            w2[o * nh + j] = round_mantissa(t.w2[o * nh + j] * p.unit[o], mantissa);
        }
        b2[o] = (f64::from(p.shift[o]) + f64::from(p.unit[o]) * f64::from(t.b2[o])) as f32;
    }
    HacContext {
        grid3: p.grid3.clone(),
        grid2: p.grid2.clone(),
        bound_min: prior.bound_min,
        bound_max: prior.bound_max,
        q_base: prior.q_base,
        levels,
        hidden: nh,
        w1: t.w1.iter().map(|&w| round_mantissa(w, mantissa)).collect(),
        b1: t.b1.iter().map(|&w| round_mantissa(w, mantissa)).collect(),
        w2,
        b2,
    }
}
