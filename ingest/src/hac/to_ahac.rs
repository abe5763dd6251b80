//! A decoded HAC GOP 0 as the content of an `AHAC` chunk (format-spec §6.13): the reference's
//! quantised positions, box, hash-grid bits, `mlp_grid` and coded integers, unchanged.

use bitvec::prelude::*;
use dlgs::chunks::ahac::HacAnchors;
use dlgs::model::hac_context::{GridShape, HacContext, Q_BASE_REFERENCE};

use super::HacGop;

impl HacGop {
    /// The `AHAC` content of a GOP that carries its anchors (GOP 0); `None` for a GOP without
    /// (an NTC GOP) or one whose batch size or `mlp_grid` does not fit.
    pub fn hac_anchors(&self) -> Option<HacAnchors> {
        if self.symbols[0].is_empty() || self.hash_bits.is_empty() {
            return None;
        }
        let grid = self.mlps.grid.as_ref()?;
        let (grid3, grid2) = (GridShape::reference_3d(), GridShape::reference_2d());
        let mut levels = Vec::new();
        let mut at = 0;
        for n in HacContext::level_bits(&grid3, &grid2) {
            let part = self.hash_bits.get(at..at + n)?;
            levels.push(part.iter().copied().collect::<BitVec<u64, Lsb0>>());
            at += n;
        }
        if at != self.hash_bits.len() {
            return None;
        }
        let n = self.quantized.len();
        Some(HacAnchors {
            n_static: self.n_static as u32,
            n_dynamic: (n - self.n_static) as u32,
            batch: u32::try_from(self.batch).ok()?,
            context: HacContext {
                grid3,
                grid2,
                bound_min: self.bound_min,
                bound_max: self.bound_max,
                q_base: Q_BASE_REFERENCE,
                levels,
                hidden: grid.first.outputs,
                w1: grid.first.weights.clone(),
                b1: grid.first.bias.clone()?,
                w2: grid.second.weights.clone(),
                b2: grid.second.bias.clone()?,
            },
            quantized: self.quantized.clone(),
            symbols: self.symbols.clone(),
        })
    }
}
