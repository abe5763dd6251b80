//! HAC's context model: the dequantised anchor, normalised by the bounds, looked up in the
//! binary 3D hash grid and three 2D planes (96 features), through `mlp_grid` (96 -> 100 ->
//! 175) to the mean, scale and step size of every coded anchor attribute.

use dlgs::model::scaffold::{Dense, TwoLayer, FEAT_DIM, N_OFFSETS, SCALING_DIM};

use super::grid::BinaryGrid;

/// 3D grid: 12 levels, 2^13 entries; 2D planes: 4 levels, 2^15 entries; 4 features each.
pub const RES_3D: [u32; 12] = [18, 24, 33, 44, 59, 80, 108, 148, 201, 275, 376, 514];
pub const LOG2_3D: u32 = 13;
pub const RES_2D: [u32; 4] = [130, 258, 514, 1026];
pub const LOG2_2D: u32 = 15;
pub const FEATURES: usize = 4;
/// Grid features into `mlp_grid`.
pub const GRID_WIDTH: usize = (RES_3D.len() + 3 * RES_2D.len()) * FEATURES;
/// `mlp_grid` outputs: mean, scale of feat, scaling, offsets, then the three Q adjustments.
pub const CONTEXT_OUT: usize = 2 * (FEAT_DIM + SCALING_DIM + 3 * N_OFFSETS) + 3;
/// Base step sizes of feat, scaling, offsets.
pub const Q_BASE: [f32; 3] = [1.0, 0.001, 0.2];

/// The three coded attributes, in file order of their channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Attr {
    Feat,
    Scaling,
    Offsets,
}

impl Attr {
    pub const ALL: [Attr; 3] = [Attr::Feat, Attr::Scaling, Attr::Offsets];
    pub fn channels(self) -> usize {
        match self {
            Attr::Feat => FEAT_DIM,
            Attr::Scaling => SCALING_DIM,
            Attr::Offsets => 3 * N_OFFSETS,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Attr::Feat => "feat",
            Attr::Scaling => "scaling",
            Attr::Offsets => "offsets",
        }
    }
    fn index(self) -> usize {
        self as usize
    }
}

/// The context grids: `encoding_xyz` (3D), `encoding_xy`, `encoding_xz`, `encoding_yz`.
#[derive(Debug, Clone, PartialEq)]
pub struct ContextGrids {
    pub xyz: BinaryGrid,
    pub planes: [BinaryGrid; 3],
}

/// Bits of `hash.b`: the four grids' parameters concatenated, row-major.
pub fn hash_bits() -> usize {
    BinaryGrid::n_bits(&RES_3D, 3, LOG2_3D, FEATURES)
        + 3 * BinaryGrid::n_bits(&RES_2D, 2, LOG2_2D, FEATURES)
}

impl ContextGrids {
    /// Split the decoded `hash.b` bits into the four grids (`None` if the count is wrong).
    pub fn from_bits(bits: &[bool]) -> Option<Self> {
        if bits.len() != hash_bits() {
            return None;
        }
        let n3 = BinaryGrid::n_bits(&RES_3D, 3, LOG2_3D, FEATURES);
        let n2 = BinaryGrid::n_bits(&RES_2D, 2, LOG2_2D, FEATURES);
        let plane = |k: usize| {
            BinaryGrid::new(
                2,
                &RES_2D,
                LOG2_2D,
                FEATURES,
                bits[n3 + k * n2..n3 + (k + 1) * n2].to_vec(),
            )
        };
        Some(ContextGrids {
            xyz: BinaryGrid::new(3, &RES_3D, LOG2_3D, FEATURES, bits[..n3].to_vec())?,
            planes: [plane(0)?, plane(1)?, plane(2)?],
        })
    }

    /// The 96 features at normalised position `x`: [3D, xy, xz, yz].
    pub fn features(&self, x: [f32; 3], out: &mut [f32; GRID_WIDTH]) {
        let w3 = self.xyz.width();
        self.xyz.lookup(&x, &mut out[..w3]);
        let w2 = self.planes[0].width();
        for (k, (a, b)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
            let at = w3 + k * w2;
            self.planes[k].lookup(&[x[a], x[b]], &mut out[at..at + w2]);
        }
    }
}

/// `Linear` as torch computes it on this CPU: per output, a float32 fused multiply-add over
/// the inputs in order from 0, then `+ bias` (checked bit-exact against torch's MKL result).
pub fn dense(layer: &Dense, x: &[f32], out: &mut [f32]) {
    for (o, v) in out.iter_mut().enumerate().take(layer.outputs) {
        let w = &layer.weights[o * layer.inputs..(o + 1) * layer.inputs];
        let mut acc = 0f32;
        for (a, b) in x.iter().zip(w) {
            acc = a.mul_add(*b, acc);
        }
        *v = match &layer.bias {
            Some(b) => acc + b[o],
            None => acc,
        };
    }
}

/// `Linear -> ReLU -> Linear` (no output activation).
pub fn two_layer(m: &TwoLayer, x: &[f32], hidden: &mut Vec<f32>, out: &mut [f32]) {
    hidden.resize(m.first.outputs, 0.0);
    dense(&m.first, x, hidden);
    hidden.iter_mut().for_each(|v| *v = v.max(0.0));
    dense(&m.second, hidden, out);
}

/// tanh for Q: the correctly rounded float32 value and the other float next to the exact
/// value. torch's CPU float32 tanh is MKL's `vsTanh` (checked: same bits), faithful but not
/// correctly rounded (1.5 % of random arguments), so the encoder used one of the two.
pub fn tanh_f32(x: f32) -> (f32, f32) {
    let t = (x as f64).tanh();
    let r = t as f32;
    // MKL rounds the other way only when the exact value is at least 0.437 ulp from the
    // nearest float (60,000 samples against 80-bit values); 0.42 keeps a margin.
    let ulp = (r.abs().next_up() - r.abs()) as f64;
    let other = if (t - r as f64).abs() < 0.42 * ulp {
        r
    } else if (r as f64) < t {
        r.next_up()
    } else if (r as f64) > t {
        r.next_down()
    } else {
        r
    };
    (r, other)
}

/// Per-anchor entropy parameters of one attribute.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AttrContext {
    /// `channels` per anchor.
    pub mean: Vec<f32>,
    pub scale: Vec<f32>,
    /// One per anchor.
    pub q: Vec<f32>,
    /// Q from the other float next to the exact tanh (equal to `q` where both give one Q).
    pub q_alt: Vec<f32>,
}

/// The context of a set of (dequantised) anchors: per attribute mean, scale (σ before the
/// 1e-9 clamp) and Q.
pub fn context(
    grids: &ContextGrids,
    mlp_grid: &TwoLayer,
    anchors: &[[f32; 3]],
    bound_min: [f32; 3],
    bound_max: [f32; 3],
) -> [AttrContext; 3] {
    let mut out: [AttrContext; 3] = Default::default();
    let mut feats = [0f32; GRID_WIDTH];
    let mut hidden = Vec::new();
    let mut o = vec![0f32; CONTEXT_OUT];
    let ext = [
        bound_max[0] - bound_min[0],
        bound_max[1] - bound_min[1],
        bound_max[2] - bound_min[2],
    ];
    for a in anchors {
        let x = [
            (a[0] - bound_min[0]) / ext[0],
            (a[1] - bound_min[1]) / ext[1],
            (a[2] - bound_min[2]) / ext[2],
        ];
        grids.features(x, &mut feats);
        two_layer(mlp_grid, &feats, &mut hidden, &mut o);
        let mut at = 0;
        for attr in Attr::ALL {
            let c = attr.channels();
            let ac = &mut out[attr.index()];
            ac.mean.extend_from_slice(&o[at..at + c]);
            ac.scale.extend_from_slice(&o[at + c..at + 2 * c]);
            at += 2 * c;
        }
        for attr in Attr::ALL {
            let (t, t_alt) = tanh_f32(o[at + attr.index()]);
            let base = Q_BASE[attr.index()];
            out[attr.index()].q.push(base * (1.0 + t));
            out[attr.index()].q_alt.push(base * (1.0 + t_alt));
        }
    }
    out
}
