//! Rendering and text queries of a set of Gaussians into arrays (what `dlgs render` and
//! `dlgs query` compute, without the PNGs).

use dlgs::model::lang_decoder::LangDecoder;
use dlgs::Gaussians;
use dlgs_query::{query_levels, Embeddings, ImageQuery, MaskParams, Precision, RelevanceField};
use dlgs_render::{render, Accuracy, Camera, RenderOptions};

use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::arrays::owned_array;
use crate::errors::{other, request, Res};

/// A rendered colour image (HxWx3, linear, not clamped) and, when asked, the language
/// feature image (HxWxlang_width). `fast`: the renderer's `Accuracy::Fast` (`--fast-render`).
pub struct Rendered {
    pub width: usize,
    pub height: usize,
    pub color: Vec<f32>,
    pub features: Option<(Vec<f32>, usize)>,
}

pub fn render_arrays(
    g: &Gaussians,
    cam: &Camera,
    features: bool,
    background: [f32; 3],
    fast: bool,
) -> Res<Rendered> {
    if features && !g.has_language() {
        return Err(request(
            "features=True but the scene has no language features",
        ));
    }
    let img = render(
        g,
        cam,
        &RenderOptions {
            background,
            features,
            accuracy: if fast {
                Accuracy::Fast
            } else {
                Accuracy::Exact
            },
        },
    )
    .map_err(other)?;
    let lw = img.lang_width;
    Ok(Rendered {
        width: img.width as usize,
        height: img.height as usize,
        color: img.color,
        features: img.features.map(|f| (f, lw)),
    })
}

/// The query's parameters (the CLI's defaults are the reference's).
pub struct QueryParams {
    pub threshold: f32,
    pub mean_kernel: usize,
    pub smooth_kernel: usize,
    pub min_score: f32,
    pub level: Option<usize>,
    pub temperature: f32,
    pub exact: bool,
}

/// Render the language image of `g` from `cam` and score it against each positive
/// embedding: one [`ImageQuery`] per positive.
pub fn query_arrays(
    g: &Gaussians,
    cam: &Camera,
    dec: &LangDecoder,
    positives: &Embeddings,
    negatives: &Embeddings,
    shape: (usize, usize),
    p: &QueryParams,
) -> Res<Vec<ImageQuery>> {
    let precision = if p.exact {
        Precision::Exact
    } else {
        Precision::Table(dlgs_query::relevance::DEFAULT_TABLE)
    };
    let mut field = RelevanceField::new(dec, positives, negatives, precision).map_err(other)?;
    field.temperature = p.temperature;
    let img = render_arrays(g, cam, true, [1.0, 1.0, 1.0], false)?;
    let (features, _) = img.features.expect("features were asked for");
    let (levels, dims) = shape;
    if let Some(l) = p.level {
        if l >= levels {
            return Err(request(format!(
                "level {l}: the scene has levels 0..{levels}"
            )));
        }
    }
    let params = MaskParams {
        mean_kernel: p.mean_kernel,
        threshold: p.threshold,
        smooth_kernel: p.smooth_kernel,
        level: p.level,
        min_score: p.min_score,
    };
    Ok(query_levels(
        &features, img.width, img.height, levels, dims, &field, &params,
    ))
}

/// Rows of a `(K, D)` (or `(D,)`) float32 array as embeddings named `0..K`.
pub fn embeddings(values: Vec<f32>, shape: &[usize], what: &str) -> Res<Embeddings> {
    let (k, d) = match shape {
        [d] => (1, *d),
        [k, d] => (*k, *d),
        _ => return Err(request(format!("{what}: expected shape (D,) or (K, D)"))),
    };
    let rows = (0..k)
        .map(|i| values[i * d..(i + 1) * d].to_vec())
        .collect();
    Embeddings::from_rows((0..k).map(|i| i.to_string()).collect(), rows).map_err(request)
}

/// Query answers as the dicts `Reader.query` returns (one per text embedding).
pub fn answers_to_list<'py>(py: Python<'py>, answers: Vec<ImageQuery>) -> Res<Bound<'py, PyList>> {
    let list = PyList::empty(py);
    for a in answers {
        let (h, w) = (a.height, a.width);
        let d = PyDict::new(py);
        let levels = a.levels.len();
        let mut rel = Vec::with_capacity(levels * w * h);
        let mut norm = Vec::with_capacity(levels * w * h);
        let mut scores = Vec::with_capacity(levels);
        for l in &a.levels {
            rel.extend_from_slice(&l.relevance);
            norm.extend_from_slice(&l.normalised);
            scores.push(l.score);
        }
        d.set_item("relevance", owned_array(py, rel, &[levels, h, w])?)?;
        d.set_item("normalised", owned_array(py, norm, &[levels, h, w])?)?;
        d.set_item("scores", scores)?;
        d.set_item("level", a.level)?;
        d.set_item("mask", PyArray1::from_vec(py, a.mask).reshape([h, w])?)?;
        list.append(d)?;
    }
    Ok(list)
}
