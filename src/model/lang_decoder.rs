//! The scene's language autoencoder decoder (format-spec §6.8): maps one level of the
//! language feature (DLGStream: 3 dims) to the text-embedding space (CLIP: 512 dims), plus the
//! canonical negative embeddings the relevance score compares against.
//!
//! Only queries use it; decoding a scene never does.

use crate::error::{Error, Result};

/// One dense layer with bias, PyTorch `nn.Linear` layout.
#[derive(Debug, Clone, PartialEq)]
pub struct DenseLayer {
    pub inputs: usize,
    pub outputs: usize,
    /// `[out][in]`, row-major.
    pub weight: Vec<f32>,
    pub bias: Vec<f32>,
}

/// A text embedding with a name (e.g. the canonical negatives "object", "things", ...).
#[derive(Debug, Clone, PartialEq)]
pub struct NamedEmbedding {
    pub name: String,
    pub values: Vec<f32>,
}

/// `x -> L2normalise(L_n(ReLU(... ReLU(L_1(x)))))`.
#[derive(Debug, Clone, PartialEq)]
pub struct LangDecoder {
    pub layers: Vec<DenseLayer>,
    /// Embeddings the relevance score compares against (may be empty; a query then has to
    /// bring its own).
    pub negatives: Vec<NamedEmbedding>,
}

/// The reference decoder's widths (§8 of the reference notes): 3 -> 16 -> ... -> 512.
pub const REFERENCE_WIDTHS: [usize; 7] = [3, 16, 32, 64, 128, 256, 512];

impl LangDecoder {
    /// Input width (dimensions of one language level).
    pub fn input_dims(&self) -> usize {
        self.layers.first().map_or(0, |l| l.inputs)
    }
    /// Output (embedding) width.
    pub fn embed_dims(&self) -> usize {
        self.layers.last().map_or(0, |l| l.outputs)
    }
    /// Layer widths `w_0 .. w_n`.
    pub fn widths(&self) -> Vec<usize> {
        let mut w = vec![self.input_dims()];
        w.extend(self.layers.iter().map(|l| l.outputs));
        w
    }
    /// Multiply-adds per decoded feature.
    pub fn macs(&self) -> usize {
        self.layers.iter().map(|l| l.inputs * l.outputs).sum()
    }

    /// Shapes chain, every value finite, negatives have the output width.
    pub fn validate(&self) -> Result<()> {
        if self.layers.is_empty() {
            return Err(Error::input("language decoder has no layers"));
        }
        for (j, l) in self.layers.iter().enumerate() {
            if l.inputs == 0 || l.outputs == 0 {
                return Err(Error::input(format!(
                    "language decoder layer {j} has width 0"
                )));
            }
            if j > 0 && self.layers[j - 1].outputs != l.inputs {
                return Err(Error::input(format!(
                    "language decoder layer {j} takes {} inputs, layer {} gives {}",
                    l.inputs,
                    j - 1,
                    self.layers[j - 1].outputs
                )));
            }
            if l.weight.len() != l.inputs * l.outputs || l.bias.len() != l.outputs {
                return Err(Error::input(format!(
                    "language decoder layer {j}: weight/bias sizes do not match {}x{}",
                    l.outputs, l.inputs
                )));
            }
            if !l.weight.iter().chain(&l.bias).all(|v| v.is_finite()) {
                return Err(Error::input(format!(
                    "language decoder layer {j} has a NaN or infinite value"
                )));
            }
        }
        for n in &self.negatives {
            if n.values.len() != self.embed_dims() {
                return Err(Error::input(format!(
                    "negative '{}' has {} values, the decoder outputs {}",
                    n.name,
                    n.values.len(),
                    self.embed_dims()
                )));
            }
            if !n.values.iter().all(|v| v.is_finite()) || l2_norm(&n.values) == 0.0 {
                return Err(Error::input(format!(
                    "negative '{}' is zero, NaN or infinite",
                    n.name
                )));
            }
            if n.name.len() > 255 {
                return Err(Error::input(format!(
                    "negative name longer than 255 bytes: {}",
                    n.name
                )));
            }
        }
        Ok(())
    }

    /// Decode one feature the plain way (row by row, bias first, inputs in order). The unit
    /// embedding goes to `out`; a zero pre-normalisation vector gives a zero embedding.
    pub fn decode_one(&self, x: &[f32], out: &mut [f32]) {
        let mut cur = x.to_vec();
        for (j, l) in self.layers.iter().enumerate() {
            let mut next = l.bias.clone();
            for (o, acc) in next.iter_mut().enumerate() {
                let row = &l.weight[o * l.inputs..(o + 1) * l.inputs];
                for (w, v) in row.iter().zip(&cur) {
                    *acc = w.mul_add(*v, *acc);
                }
                if j + 1 < self.layers.len() {
                    *acc = acc.max(0.0);
                }
            }
            cur = next;
        }
        normalise_into(&cur, out);
    }
}

pub fn l2_norm(v: &[f32]) -> f32 {
    v.iter().map(|x| x * x).sum::<f32>().sqrt()
}

/// `out = v / |v|`, or zeros when `|v| = 0` (the reference would produce NaN there).
pub fn normalise_into(v: &[f32], out: &mut [f32]) {
    let n = l2_norm(v);
    let inv = if n > 0.0 { 1.0 / n } else { 0.0 };
    for (o, x) in out.iter_mut().zip(v) {
        *o = x * inv;
    }
}
