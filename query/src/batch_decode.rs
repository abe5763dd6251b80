//! The language decoder on many features at once: each layer is one matrix product
//! (`ndarray` / `matrixmultiply`) over a fixed-size batch, batches in parallel.
//!
//! Deterministic on any thread count: batch boundaries do not depend on the thread count, and
//! a batch's products are computed by one thread.

use dlgs::model::lang_decoder::LangDecoder;
use ndarray::{linalg::general_mat_mul, Array2, ArrayView2};
use rayon::prelude::*;

/// Rows per batch (fixed: results must not depend on how work is split).
pub const BATCH: usize = 256;

/// Unit embeddings of `x` (rows of `dec.input_dims()` values) dotted with every row of
/// `targets` (`t x embed`): `n x t` cosines, row-major. A feature whose decoded vector is zero
/// has cosine 0 with everything.
pub fn cosines(dec: &LangDecoder, x: &[f32], targets: &[f32]) -> Vec<f32> {
    let d = dec.input_dims();
    let e = dec.embed_dims();
    let t = targets.len() / e;
    let n = x.len() / d;
    let targets_t = ArrayView2::from_shape((t, e), targets)
        .expect("targets are t x embed")
        .reversed_axes();
    let mut out = vec![0.0f32; n * t];
    out.par_chunks_mut(BATCH * t)
        .zip(x.par_chunks(BATCH * d))
        .for_each(|(o, xb)| {
            let rows = xb.len() / d;
            let emb = forward(dec, xb, rows);
            let mut c = Array2::<f32>::zeros((rows, t));
            general_mat_mul(1.0, &emb, &targets_t, 0.0, &mut c);
            o.copy_from_slice(c.as_slice().expect("standard layout"));
        });
    out
}

/// The decoder on `rows` features: unit embeddings `rows x embed`.
pub fn forward(dec: &LangDecoder, x: &[f32], rows: usize) -> Array2<f32> {
    let mut cur = ArrayView2::from_shape((rows, dec.input_dims()), x)
        .expect("rows x input")
        .to_owned();
    let last = dec.layers.len() - 1;
    for (j, l) in dec.layers.iter().enumerate() {
        let w = ArrayView2::from_shape((l.outputs, l.inputs), &l.weight).expect("out x in");
        let bias = ArrayView2::from_shape((1, l.outputs), &l.bias).expect("bias");
        let mut next = bias
            .broadcast((rows, l.outputs))
            .expect("broadcast bias")
            .to_owned();
        general_mat_mul(1.0, &cur, &w.t(), 1.0, &mut next);
        if j < last {
            next.mapv_inplace(|v| v.max(0.0));
        }
        cur = next;
    }
    for mut r in cur.rows_mut() {
        let n = r.iter().map(|v| v * v).sum::<f32>().sqrt();
        let inv = if n > 0.0 { 1.0 / n } else { 0.0 };
        r.mapv_inplace(|v| v * inv);
    }
    cur
}
