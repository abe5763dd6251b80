//! GOP 1's NTC residual: three binary 2D planes (4 levels 512..4096, 2^15 entries, 4
//! features; `ntc_2D.b` = xy ‖ xz ‖ yz) gated by the sigmoid of a binary 3D grid (514, 2^15,
//! 1 feature; `ntc_3D.b`), through `ntc_mlp` (48 -> 100 -> 80) to `d_feat` (50) and
//! `d_offsets` (30) per anchor. Anchors outside the bounds get zero residuals.

use dlgs::model::scaffold::{TwoLayer, FEAT_DIM, N_OFFSETS};

use super::context::two_layer;
use super::grid::BinaryGrid;

pub const PLANE_RES: [u32; 4] = [512, 1024, 2048, 4096];
pub const PLANE_LOG2: u32 = 15;
pub const PLANE_FEATURES: usize = 4;
pub const GATE_RES: [u32; 1] = [514];
pub const GATE_LOG2: u32 = 15;
/// `ntc_mlp` inputs and outputs.
pub const NTC_IN: usize = 3 * PLANE_RES.len() * PLANE_FEATURES;
pub const NTC_OUT: usize = FEAT_DIM + 3 * N_OFFSETS;

/// Bits of `ntc_2D.b` and `ntc_3D.b`.
pub fn plane_bits() -> usize {
    3 * BinaryGrid::n_bits(&PLANE_RES, 2, PLANE_LOG2, PLANE_FEATURES)
}
pub fn gate_bits() -> usize {
    BinaryGrid::n_bits(&GATE_RES, 3, GATE_LOG2, 1)
}

/// The decoded NTC grids.
#[derive(Debug, Clone, PartialEq)]
pub struct NtcGrids {
    pub planes: [BinaryGrid; 3],
    pub gate: BinaryGrid,
}

impl NtcGrids {
    /// From the decoded bits (`None` if a count is wrong).
    pub fn from_bits(planes: &[bool], gate: &[bool]) -> Option<Self> {
        let n = BinaryGrid::n_bits(&PLANE_RES, 2, PLANE_LOG2, PLANE_FEATURES);
        if planes.len() != 3 * n {
            return None;
        }
        let plane = |k: usize| {
            BinaryGrid::new(
                2,
                &PLANE_RES,
                PLANE_LOG2,
                PLANE_FEATURES,
                planes[k * n..(k + 1) * n].to_vec(),
            )
        };
        Some(NtcGrids {
            planes: [plane(0)?, plane(1)?, plane(2)?],
            gate: BinaryGrid::new(3, &GATE_RES, GATE_LOG2, 1, gate.to_vec())?,
        })
    }
}

/// torch's float32 sigmoid, `1 / (1 + exp(-x))` (exp in f64, rounded).
fn sigmoid_f32(x: f32) -> f32 {
    1.0 / (1.0 + ((-x) as f64).exp() as f32)
}

/// `(d_feat, d_offsets)` of every anchor: `FEAT_DIM` and `3 * N_OFFSETS` values per anchor.
pub fn residuals(
    grids: &NtcGrids,
    mlp: &TwoLayer,
    anchors: &[[f32; 3]],
    bound_min: [f32; 3],
    bound_max: [f32; 3],
) -> (Vec<f32>, Vec<f32>) {
    let mut d_feat = vec![0f32; anchors.len() * FEAT_DIM];
    let mut d_off = vec![0f32; anchors.len() * 3 * N_OFFSETS];
    let mut h = [0f32; NTC_IN];
    let mut gate = [0f32; 1];
    let mut hidden = Vec::new();
    let mut out = [0f32; NTC_OUT];
    for (i, a) in anchors.iter().enumerate() {
        let x: [f32; 3] =
            std::array::from_fn(|d| (a[d] - bound_min[d]) / (bound_max[d] - bound_min[d]));
        if x.iter().any(|v| !(0.0..=1.0).contains(v)) {
            continue;
        }
        let w = grids.planes[0].width();
        for (k, (p, q)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
            grids.planes[k].lookup(&[x[p], x[q]], &mut h[k * w..(k + 1) * w]);
        }
        grids.gate.lookup(&x, &mut gate);
        let g = sigmoid_f32(gate[0]);
        h.iter_mut().for_each(|v| *v *= g);
        two_layer(mlp, &h, &mut hidden, &mut out);
        d_feat[i * FEAT_DIM..(i + 1) * FEAT_DIM].copy_from_slice(&out[..FEAT_DIM]);
        d_off[i * 3 * N_OFFSETS..(i + 1) * 3 * N_OFFSETS].copy_from_slice(&out[FEAT_DIM..]);
    }
    (d_feat, d_off)
}

/// The NTC residual of a GOP as an `RNTC` field over anchor groups (format-spec §6.6, variant 1,
/// since 1.17): the grid bits as the reference stores them (`ntc_2D.b` = xy ‖ xz ‖ yz, each
/// level-major with 2^15 entries of 4 bits, so split by level; `ntc_3D.b` the gate), `ntc_mlp`
/// with outputs `d_feat` ‖ `d_offsets` (groups feature and offsets), every anchor (both
/// sets), and the box the reference normalises by (the anchors' `x_bound_min/max`).
/// `None` if the bit counts or the MLP's shape are not the reference's.
pub fn to_field(
    plane_bits: &[bool],
    gate_bits: &[bool],
    mlp: &TwoLayer,
    bound_min: [f32; 3],
    bound_max: [f32; 3],
) -> Option<dlgs::model::ntc::NtcField> {
    use bitvec::prelude::*;
    use dlgs::model::ntc::{NtcConfig, NtcField, NtcMlp};
    use dlgs::model::residual::{SET_DYNAMIC, SET_STATIC};
    use dlgs::model::scaffold::AnchorGroup;
    let config = NtcConfig {
        resolutions: PLANE_RES.to_vec(),
        features: PLANE_FEATURES as u8,
        log2_table: PLANE_LOG2 as u8,
        gate_resolution: GATE_RES[0],
        gate_log2_table: GATE_LOG2 as u8,
    };
    let level = config.level_bits();
    if plane_bits.len() != 3 * PLANE_RES.len() * level || gate_bits.len() != config.gate_table() {
        return None;
    }
    mlp.check("ntc_mlp", NTC_IN, NTC_OUT, true).ok()?;
    let bits = |b: &[bool]| b.iter().copied().collect::<BitVec<u64, Lsb0>>();
    let field = NtcField {
        planes: plane_bits.chunks_exact(level).map(bits).collect(),
        gate: bits(gate_bits),
        mlp: NtcMlp {
            inputs: NTC_IN,
            hidden: mlp.first.outputs,
            outputs: NTC_OUT,
            w1: mlp.first.weights.clone(),
            b1: mlp.first.bias.clone()?,
            w2: mlp.second.weights.clone(),
            b2: mlp.second.bias.clone()?,
        },
        config,
        bound_min,
        bound_max,
        groups: AnchorGroup::Feature.bit() | AnchorGroup::Offsets.bit(),
        sets: SET_STATIC | SET_DYNAMIC,
    };
    field
        .validate_layout(dlgs::model::ntc::RowLayout::Anchors)
        .ok()?;
    Some(field)
}
