//! The language autoencoder decoder as a safetensors file, with the reference's (LangSplat's)
//! parameter names: `decoder.<i>.weight` (`[out, in]`) and `decoder.<i>.bias` for the linear
//! layers in `i` order (any prefix before `decoder.` is accepted, encoder keys are ignored).
//! A trained `best_ckpt.pth` converts with the one-liner in docs/queries.md.

use std::collections::BTreeMap;
use std::path::Path;

use dlgs::model::lang_decoder::{DenseLayer, LangDecoder};
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;

use crate::error::{QueryError, Result};

fn values(t: &TensorView) -> std::result::Result<Vec<f32>, String> {
    let d = t.data();
    match t.dtype() {
        Dtype::F32 => Ok(d
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()),
        Dtype::F64 => Ok(d
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")) as f32)
            .collect()),
        Dtype::F16 => Ok(d
            .chunks_exact(2)
            .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
            .collect()),
        other => Err(format!("dtype {other:?} (expected F32, F64 or F16)")),
    }
}

/// Read a decoder (no negatives: those come from `--negatives`).
pub fn load_lang_decoder(path: &Path) -> Result<LangDecoder> {
    let err = |reason: String| QueryError::Decoder(format!("{}: {reason}", path.display()));
    let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
    let st = SafeTensors::deserialize(&bytes).map_err(|e| err(e.to_string()))?;
    let mut found: BTreeMap<usize, (Option<TensorView>, Option<TensorView>)> = BTreeMap::new();
    for (name, t) in st.tensors() {
        let Some(pos) = name.find("decoder.") else {
            continue;
        };
        let rest = &name[pos + "decoder.".len()..];
        let mut parts = rest.split('.');
        let (Some(idx), Some(kind), None) = (parts.next(), parts.next(), parts.next()) else {
            continue;
        };
        let Ok(idx) = idx.parse::<usize>() else {
            continue;
        };
        let e = found.entry(idx).or_default();
        match kind {
            "weight" => e.0 = Some(t),
            "bias" => e.1 = Some(t),
            _ => {}
        }
    }
    if found.is_empty() {
        return Err(err("no decoder.<i>.weight tensors".into()));
    }
    let mut layers = Vec::new();
    for (idx, (w, b)) in found {
        let w = w.ok_or_else(|| err(format!("decoder.{idx}.bias without a weight")))?;
        let shape = w.shape().to_vec();
        let [outputs, inputs] = shape[..] else {
            return Err(err(format!(
                "decoder.{idx}.weight has shape {shape:?}, expected [out, in]"
            )));
        };
        let weight = values(&w).map_err(|e| err(format!("decoder.{idx}.weight: {e}")))?;
        let bias = match b {
            Some(b) => values(&b).map_err(|e| err(format!("decoder.{idx}.bias: {e}")))?,
            None => vec![0.0; outputs],
        };
        if bias.len() != outputs {
            return Err(err(format!(
                "decoder.{idx}.bias has {} values for {outputs} outputs",
                bias.len()
            )));
        }
        layers.push(DenseLayer {
            inputs,
            outputs,
            weight,
            bias,
        });
    }
    let d = LangDecoder {
        layers,
        negatives: Vec::new(),
    };
    d.validate().map_err(|e| err(e.to_string()))?;
    Ok(d)
}

/// Write a decoder's layers as `decoder.<2j>.weight/bias` (LangSplat's `ModuleList` indices:
/// linear layers at even positions, ReLUs between them).
pub fn save_lang_decoder(path: &Path, d: &LangDecoder) -> Result<()> {
    let err = |reason: String| QueryError::Io {
        path: path.display().to_string(),
        reason,
    };
    let mut data: Vec<(String, Vec<u8>, Vec<usize>)> = Vec::new();
    for (j, l) in d.layers.iter().enumerate() {
        let bytes = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        data.push((
            format!("decoder.{}.weight", 2 * j),
            bytes(&l.weight),
            vec![l.outputs, l.inputs],
        ));
        data.push((
            format!("decoder.{}.bias", 2 * j),
            bytes(&l.bias),
            vec![l.outputs],
        ));
    }
    let views: Vec<(String, TensorView)> = data
        .iter()
        .map(|(n, b, s)| {
            TensorView::new(Dtype::F32, s.clone(), b)
                .map(|v| (n.clone(), v))
                .map_err(|e| err(e.to_string()))
        })
        .collect::<Result<_>>()?;
    let out = safetensors::serialize(views, &None).map_err(|e| err(e.to_string()))?;
    std::fs::write(path, out).map_err(|e| err(e.to_string()))
}
