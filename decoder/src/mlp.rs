//! Bias-free MLPs evaluated as GEMMs on row blocks (ndarray -> matrixmultiply).

use dlgs::model::Mlp;
use ndarray::{Array2, ArrayView2};

/// An MLP with its weights transposed to `(inputs, outputs)` so a row block `X` maps to
/// `X · W`.
#[derive(Debug, Clone)]
pub struct PreparedMlp {
    layers: Vec<Array2<f32>>,
    tanh: bool,
}

impl PreparedMlp {
    pub fn new(m: &Mlp) -> Self {
        let layers = m
            .layers
            .iter()
            .map(|l| {
                // Shapes were validated when the chunk was parsed.
                let w = ArrayView2::from_shape((l.outputs, l.inputs), &l.weights)
                    .expect("validated MLP shape");
                w.t().as_standard_layout().into_owned()
            })
            .collect();
        PreparedMlp {
            layers,
            tanh: m.role.output_tanh(),
        }
    }

    pub fn outputs(&self) -> usize {
        self.layers.last().map_or(0, |l| l.ncols())
    }

    /// Rows of `x` through the network: ReLU between layers, tanh at the end if the role has it.
    pub fn run(&self, x: ArrayView2<f32>) -> Array2<f32> {
        let mut h = x.dot(&self.layers[0]);
        for w in &self.layers[1..] {
            h.mapv_inplace(|v| v.max(0.0));
            h = h.dot(w);
        }
        if self.tanh {
            h.mapv_inplace(f32::tanh);
        }
        h
    }
}
