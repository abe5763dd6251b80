//! Text embeddings from the user: `.npy` (shape `(D,)` or `(K, D)`, float32 or float64) or
//! JSON (`[..]`, `[[..], ..]` or `{"name": [..], ..}`). Rows are L2-normalised on load, as
//! the reference normalises its CLIP text embeddings.

use std::path::Path;

use dlgs::model::lang_decoder::NamedEmbedding;

use crate::error::{QueryError, Result};

/// `count` embeddings of `dims` values each, unit length, with names.
#[derive(Debug, Clone, PartialEq)]
pub struct Embeddings {
    pub names: Vec<String>,
    pub dims: usize,
    /// Row-major `count x dims`.
    pub values: Vec<f32>,
}

impl Embeddings {
    pub fn count(&self) -> usize {
        self.names.len()
    }
    pub fn row(&self, i: usize) -> &[f32] {
        &self.values[i * self.dims..(i + 1) * self.dims]
    }
    /// From named embeddings (e.g. the negatives stored with a language decoder).
    pub fn from_named(named: &[NamedEmbedding]) -> std::result::Result<Self, String> {
        Self::from_rows(
            named.iter().map(|n| n.name.clone()).collect(),
            named.iter().map(|n| n.values.clone()).collect(),
        )
    }

    /// As named embeddings, to store with a language decoder.
    pub fn to_named(&self) -> Vec<NamedEmbedding> {
        (0..self.count())
            .map(|i| NamedEmbedding {
                name: self.names[i].clone(),
                values: self.row(i).to_vec(),
            })
            .collect()
    }

    /// Build from rows, normalising each; rejects empty, ragged, zero, NaN or infinite rows.
    pub fn from_rows(names: Vec<String>, rows: Vec<Vec<f32>>) -> std::result::Result<Self, String> {
        let dims = rows.first().map_or(0, |r| r.len());
        if rows.is_empty() || dims == 0 {
            return Err("no embedding values".into());
        }
        let mut values = Vec::with_capacity(rows.len() * dims);
        for (name, r) in names.iter().zip(&rows) {
            if r.len() != dims {
                return Err(format!(
                    "embedding '{name}' has {} values, the first has {dims}",
                    r.len()
                ));
            }
            if !r.iter().all(|v| v.is_finite()) {
                return Err(format!("embedding '{name}' has a NaN or infinite value"));
            }
            let n = dlgs::model::lang_decoder::l2_norm(r);
            if n == 0.0 {
                return Err(format!("embedding '{name}' is the zero vector"));
            }
            values.extend(r.iter().map(|v| v / n));
        }
        Ok(Embeddings {
            names,
            dims,
            values,
        })
    }
}

fn npy_rows(bytes: &[u8]) -> std::result::Result<(Vec<String>, Vec<Vec<f32>>), String> {
    let npy = npyz::NpyFile::new(bytes).map_err(|e| format!("not a .npy file: {e}"))?;
    let shape: Vec<usize> = npy.shape().iter().map(|&s| s as usize).collect();
    let (rows, dims) = match shape.as_slice() {
        [d] => (1, *d),
        [k, d] => (*k, *d),
        _ => return Err(format!("shape {shape:?}: expected (D,) or (K, D)")),
    };
    if npy.order() == npyz::Order::Fortran && rows > 1 {
        return Err(
            "Fortran-order arrays are not supported; save with np.ascontiguousarray".into(),
        );
    }
    let flat: Vec<f32> = match npy.dtype() {
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Float && t.size_field() == 4 => {
            npy.into_vec::<f32>().map_err(|e| e.to_string())?
        }
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Float && t.size_field() == 8 => {
            npy.into_vec::<f64>()
                .map_err(|e| e.to_string())?
                .into_iter()
                .map(|v| v as f32)
                .collect()
        }
        d => return Err(format!("dtype {d:?}: expected float32 or float64")),
    };
    if flat.len() != rows * dims {
        return Err(format!("{} values for shape {shape:?}", flat.len()));
    }
    let names = (0..rows).map(|i| i.to_string()).collect();
    Ok((
        names,
        flat.chunks(dims.max(1)).map(|c| c.to_vec()).collect(),
    ))
}

fn json_row(v: &serde_json::Value) -> std::result::Result<Vec<f32>, String> {
    v.as_array()
        .ok_or("expected an array of numbers")?
        .iter()
        .map(|x| {
            x.as_f64()
                .map(|f| f as f32)
                .ok_or("expected numbers".to_string())
        })
        .collect()
}

fn json_rows(text: &str) -> std::result::Result<(Vec<String>, Vec<Vec<f32>>), String> {
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| e.to_string())?;
    match &v {
        serde_json::Value::Object(m) => {
            let mut names = Vec::new();
            let mut rows = Vec::new();
            for (k, x) in m {
                names.push(k.clone());
                rows.push(json_row(x).map_err(|e| format!("'{k}': {e}"))?);
            }
            Ok((names, rows))
        }
        serde_json::Value::Array(a) if a.first().is_some_and(|x| x.is_array()) => {
            let rows: Vec<Vec<f32>> = a
                .iter()
                .map(json_row)
                .collect::<std::result::Result<_, _>>()?;
            Ok(((0..rows.len()).map(|i| i.to_string()).collect(), rows))
        }
        serde_json::Value::Array(_) => Ok((vec!["0".into()], vec![json_row(&v)?])),
        _ => Err("expected an array or an object of arrays".into()),
    }
}

/// Read embeddings from `.npy` or `.json` (by extension; other files are tried as JSON).
pub fn read_embeddings(path: &Path) -> Result<Embeddings> {
    let err = |reason: String| QueryError::Embeddings {
        path: path.display().to_string(),
        reason,
    };
    let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
    let is_npy = bytes.starts_with(b"\x93NUMPY");
    let (mut names, rows) = if is_npy {
        npy_rows(&bytes).map_err(err)?
    } else {
        let text =
            std::str::from_utf8(&bytes).map_err(|_| err("neither .npy nor UTF-8 JSON".into()))?;
        json_rows(text).map_err(err)?
    };
    // Single unnamed embeddings take the file's stem as their name.
    if names.len() == 1 && names[0] == "0" {
        if let Some(stem) = path.file_stem().and_then(|s| s.to_str()) {
            names[0] = stem.to_string();
        }
    }
    Embeddings::from_rows(names, rows).map_err(err)
}

/// Write embeddings as a float32 `.npy` of shape `(K, D)`.
pub fn write_npy(path: &Path, e: &Embeddings) -> Result<()> {
    let io = |reason: String| QueryError::Io {
        path: path.display().to_string(),
        reason,
    };
    let mut out = Vec::new();
    {
        use npyz::WriterBuilder;
        let mut w = npyz::WriteOptions::<f32>::new()
            .default_dtype()
            .shape(&[e.count() as u64, e.dims as u64])
            .writer(&mut out)
            .begin_nd()
            .map_err(|x| io(x.to_string()))?;
        w.extend(e.values.iter().copied())
            .map_err(|x| io(x.to_string()))?;
        w.finish().map_err(|x| io(x.to_string()))?;
    }
    std::fs::write(path, out).map_err(|x| io(x.to_string()))
}
