//! Row-at-a-time evaluation of the Scaffold-GS variant's MLPs, with the same arithmetic as the
//! 3DGS variant's decoders: each output starts at its bias (or +0) and adds its inputs in
//! increasing order, one fused multiply-add each; ReLU is `max(v, 0)`; `tanh` is the decoder's
//! own ([`crate::panel::tanh_f32`]) and the logistic function is `dlgs::elementary`'s. So a row
//! gives the same bits on every platform and thread count.

use dlgs::elementary::sigmoid_f32;
use dlgs::model::scaffold::{Activation, Dense, TwoLayer};
use multiversion::multiversion;

use crate::panel::tanh_f32;

/// Every output's own chain of fused multiply-adds in increasing input order, the outputs'
/// chains interleaved (inputs outer, outputs inner) so that they run side by side instead of
/// one after another: the same operations, so the same bits. Compiled for FMA targets too, so
/// that `mul_add` is one instruction there instead of a call into the C library's `fmaf`
/// (the same correctly rounded result either way).
#[multiversion(targets("x86_64+avx512f+avx512vl+avx2+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn dense(d: &Dense, x: &[f32], out: &mut [f32]) {
    let out = &mut out[..d.outputs];
    match &d.bias {
        Some(b) => out.copy_from_slice(&b[..d.outputs]),
        None => out.fill(0.0),
    }
    for (i, &xi) in x.iter().enumerate().take(d.inputs) {
        for (o, acc) in out.iter_mut().enumerate() {
            *acc = d.weights[o * d.inputs + i].mul_add(xi, *acc);
        }
    }
}

#[inline]
pub fn activate(a: Activation, v: f32) -> f32 {
    match a {
        Activation::Identity => v,
        Activation::Relu => v.max(0.0),
        Activation::Tanh => tanh_f32(v),
        Activation::Sigmoid => sigmoid_f32(v),
    }
}

/// `out = act(W2 relu(W1 x + b1) + b2)` for one row; `hidden` is scratch of at least the hidden
/// width, `out` at least the output width.
pub fn eval(m: &TwoLayer, x: &[f32], hidden: &mut [f32], out: &mut [f32]) {
    let h = &mut hidden[..m.first.outputs];
    dense(&m.first, x, h);
    for v in h.iter_mut() {
        *v = v.max(0.0);
    }
    dense(&m.second, h, out);
    for v in out.iter_mut().take(m.second.outputs) {
        *v = activate(m.output, *v);
    }
}
