//! SYNTHETIC language from per-Gaussian semantic labels, to test queries on real scenes with
//! real labels (no CLIP model or trained language field exists here).
//!
//! Every category gets a unit 3-dim code: placed for the scene by
//! [`LabelCodebook::for_scene`] (categories that touch in 3D get near-orthogonal codes, see
//! `code_layout`), or the vertices of an icosahedron (12 codes, 63.4 degrees apart) by
//! [`LabelCodebook::new`]; a constructed 3 -> 16 -> 32 -> 64 -> 128 -> 256 -> 512 ReLU
//! decoder maps each code to its own unit 512-dim vector: the first layer's unit `j` is `ReLU(c_j . x - 0.5)`
//! (zero at every other code), the middle layers pass it on, the last layer sums
//! `h_j v_j + 0.01 v_bg`. The vectors `v_j` and `v_bg` are orthonormal; the four stand-in
//! negatives have cosine ~0.2 with each of them, as generic CLIP phrases resemble everything.
//!
//! Levels: level 1 holds the category code, level 2 a coarse code ("any category"), level 3
//! one code for the whole scene; Gaussians labelled 0 ("not annotated") have zero features at
//! levels 1 and 2, so that a category's query is answered
//! by level 1 and level selection has real choices.

use dlgs::model::lang_decoder::{DenseLayer, LangDecoder, NamedEmbedding, REFERENCE_WIDTHS};
use dlgs::Gaussians;

use crate::code_layout;
use dlgs_query::embeddings::Embeddings;
use dlgs_query::error::{QueryError, Result};

/// Categories a codebook holds (labels 0..=9).
pub const MAX_CATEGORIES: usize = 10;
const CODES: usize = 12;
const CODE_LABELLED_COARSE: usize = 11;
/// First-layer threshold: above every cosine between two codes (at most 0.447 for the
/// icosahedron, `code_layout::MAX_COSINE` for placed codes), so a code activates only its own
/// unit, and a pixel needs more than half its weight from one category to decode to it.
const CAP: f32 = 0.5;
const BACKGROUND_GAIN: f32 = 0.01;
const NEGATIVE_SHARE: f32 = 0.3;
/// Names of the stand-in negatives (the reference's canonical phrases).
pub const NEGATIVE_NAMES: [&str; 4] = ["object", "things", "stuff", "texture"];

/// Codes, decoder and embeddings of the synthetic language.
pub struct LabelCodebook {
    pub codes: Vec<[f32; 3]>,
    pub decoder: LangDecoder,
    /// `v_j` per code.
    pub code_embeddings: Vec<Vec<f32>>,
}

fn icosahedron() -> Vec<[f32; 3]> {
    let p = (1.0 + 5f32.sqrt()) / 2.0;
    let mut v = Vec::new();
    for s1 in [1.0, -1.0] {
        for s2 in [1.0, -1.0] {
            v.push([0.0, s1, s2 * p]);
            v.push([s1, s2 * p, 0.0]);
            v.push([s2 * p, 0.0, s1]);
        }
    }
    let n = (1.0 + p * p).sqrt();
    v.iter().map(|a| a.map(|x| x / n)).collect()
}

/// `count` orthonormal vectors of `dims` values (Gram-Schmidt on seeded random vectors).
fn orthonormal(count: usize, dims: usize, seed: u64) -> Vec<Vec<f32>> {
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut out: Vec<Vec<f64>> = Vec::new();
    while out.len() < count {
        let mut v: Vec<f64> = (0..dims).map(|_| rng.f64() * 2.0 - 1.0).collect();
        for u in &out {
            let d: f64 = v.iter().zip(u).map(|(a, b)| a * b).sum();
            v.iter_mut().zip(u).for_each(|(a, b)| *a -= d * b);
        }
        let n = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        v.iter_mut().for_each(|a| *a /= n);
        out.push(v);
    }
    out.into_iter()
        .map(|v| v.into_iter().map(|a| a as f32).collect())
        .collect()
}

impl LabelCodebook {
    /// Codes at the vertices of an icosahedron (label `l` gets vertex `l`), whatever the scene.
    pub fn new(seed: u64) -> Self {
        Self::with_codes(icosahedron(), seed)
    }

    /// Codes placed for this scene (`code_layout`): categories whose Gaussians touch in 3D get
    /// near-orthogonal codes where 3 dimensions allow, so that a pixel blending them
    /// decodes to a category only where that category holds more than half of it. Labels with
    /// no Gaussian get no code (their unit never switches on). Falls back to [`Self::new`]'s
    /// icosahedron if no placement keeps every pair apart.
    pub fn for_scene(g: &Gaussians, labels: &[u16], seed: u64) -> Result<Self> {
        check_labels(g, labels)?;
        let mut present = [false; MAX_CATEGORIES];
        labels.iter().for_each(|&l| present[l as usize] = true);
        let slots: Vec<usize> = (1..MAX_CATEGORIES)
            .filter(|&l| present[l])
            .chain([CODE_LABELLED_COARSE])
            .collect();
        // One row per code slot: the coarse code's slot touches nothing (no label reaches it).
        let touches = code_layout::touch_weights(g, labels, CODES);
        let weights: Vec<Vec<f64>> = slots
            .iter()
            .map(|&a| slots.iter().map(|&b| touches[a][b]).collect())
            .collect();
        let Some(placed) = code_layout::place_codes(&weights, seed) else {
            return Ok(Self::new(seed));
        };
        let mut codes = vec![[0.0f32; 3]; CODES];
        for (&slot, c) in slots.iter().zip(placed) {
            codes[slot] = c.map(|v| v as f32);
        }
        Ok(Self::with_codes(codes, seed))
    }

    fn with_codes(codes: Vec<[f32; 3]>, seed: u64) -> Self {
        let w = REFERENCE_WIDTHS;
        let embed = w[6];
        let vectors = orthonormal(CODES + 1 + NEGATIVE_NAMES.len(), embed, seed);
        let mut layers = Vec::new();
        // Layer 1: one cap unit per code.
        let mut w1 = vec![0.0f32; w[1] * w[0]];
        let mut b1 = vec![0.0f32; w[1]];
        for (j, c) in codes.iter().enumerate() {
            w1[j * 3..j * 3 + 3].copy_from_slice(c);
            b1[j] = -CAP;
        }
        layers.push(DenseLayer {
            inputs: w[0],
            outputs: w[1],
            weight: w1,
            bias: b1,
        });
        // Middle layers: identity on the first 16 units (ReLU of a non-negative value is itself).
        for l in 1..5 {
            let mut m = vec![0.0f32; w[l + 1] * w[l]];
            for j in 0..w[1] {
                m[j * w[l] + j] = 1.0;
            }
            layers.push(DenseLayer {
                inputs: w[l],
                outputs: w[l + 1],
                weight: m,
                bias: vec![0.0; w[l + 1]],
            });
        }
        // Last layer: unit j writes v_j; the bias points to v_bg so that zero input decodes.
        let mut w6 = vec![0.0f32; embed * w[5]];
        for j in 0..CODES {
            for o in 0..embed {
                w6[o * w[5] + j] = vectors[j][o];
            }
        }
        let bias = vectors[CODES].iter().map(|v| v * BACKGROUND_GAIN).collect();
        layers.push(DenseLayer {
            inputs: w[5],
            outputs: embed,
            weight: w6,
            bias,
        });
        // Like CLIP's generic phrases, the negatives resemble everything a little (cosine
        // ~0.2 with every code's vector), so unrelated features score below one half instead
        // of exactly one half.
        let shared: Vec<f32> = (0..embed)
            .map(|o| vectors[..=CODES].iter().map(|v| v[o]).sum::<f32>())
            .collect();
        let negatives = NEGATIVE_NAMES
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let raw: Vec<f32> = vectors[CODES + 1 + i]
                    .iter()
                    .zip(&shared)
                    .map(|(u, s)| u + NEGATIVE_SHARE * s)
                    .collect();
                let norm = dlgs::model::lang_decoder::l2_norm(&raw);
                NamedEmbedding {
                    name: n.to_string(),
                    values: raw.iter().map(|v| v / norm).collect(),
                }
            })
            .collect();
        LabelCodebook {
            codes,
            decoder: LangDecoder { layers, negatives },
            code_embeddings: vectors[..CODES].to_vec(),
        }
    }

    /// The text embedding that names category `label`.
    pub fn category_embedding(&self, label: u16) -> Embeddings {
        Embeddings::from_rows(
            vec![format!("category {label}")],
            vec![self.code_embeddings[label as usize].clone()],
        )
        .expect("unit vectors")
    }

    /// Embedding of the coarse "any category" code (answered by level 2).
    pub fn labelled_embedding(&self) -> Embeddings {
        Embeddings::from_rows(
            vec!["any category".into()],
            vec![self.code_embeddings[CODE_LABELLED_COARSE].clone()],
        )
        .expect("unit vectors")
    }

    /// The stand-in negatives as embeddings.
    pub fn negatives(&self) -> Embeddings {
        Embeddings::from_named(&self.decoder.negatives).expect("unit vectors")
    }

    /// The 9-dim feature of a Gaussian with `label`.
    /// Label 0 means "not annotated": no semantics, so its fine and coarse features are zero
    /// (blending it into a pixel then shrinks the pixel's feature instead of turning it
    /// towards another category's code).
    pub fn feature(&self, label: u16) -> [f32; 9] {
        let (fine, coarse) = if label == 0 {
            ([0.0; 3], [0.0; 3])
        } else {
            (self.codes[label as usize], self.codes[CODE_LABELLED_COARSE])
        };
        let scene = self.codes[CODE_LABELLED_COARSE];
        let mut f = [0.0; 9];
        f[..3].copy_from_slice(&fine);
        f[3..6].copy_from_slice(&coarse);
        f[6..].copy_from_slice(&scene);
        f
    }

    /// The category whose code is closest to a level-1 feature (for Gaussians whose language
    /// a dynamic decoder has moved a little).
    pub fn label_of(&self, level1: &[f32]) -> u16 {
        let mut best = (0u16, f32::NEG_INFINITY);
        for (l, c) in self.codes[..MAX_CATEGORIES].iter().enumerate() {
            let d = c[0] * level1[0] + c[1] * level1[1] + c[2] * level1[2];
            if d > best.1 {
                best = (l as u16, d);
            }
        }
        best.0
    }

    /// `g` with 3-level language features from `labels` (language opacity = colour opacity).
    pub fn apply(&self, g: &Gaussians, labels: &[u16]) -> Result<Gaussians> {
        check_labels(g, labels)?;
        let mut out = g.without_language();
        out.lang_width = 9;
        out.lang_opacity = g.opacity.clone();
        out.lang = labels.iter().flat_map(|&l| self.feature(l)).collect();
        Ok(out)
    }
}

fn check_labels(g: &Gaussians, labels: &[u16]) -> Result<()> {
    if labels.len() != g.len() {
        return Err(QueryError::Invalid(format!(
            "{} labels for {} Gaussians",
            labels.len(),
            g.len()
        )));
    }
    if let Some(l) = labels.iter().find(|&&l| l as usize >= MAX_CATEGORIES) {
        return Err(QueryError::Invalid(format!(
            "label {l} outside 0..{MAX_CATEGORIES}"
        )));
    }
    Ok(())
}

/// `g` with a one-hot label per Gaussian as its "language" (`classes` channels), for rendering
/// the ground-truth label map with the same dual-opacity compositing.
pub fn one_hot(g: &Gaussians, labels: &[u16], classes: usize) -> Result<Gaussians> {
    check_labels(g, labels)?;
    let mut out = g.without_language();
    out.lang_width = classes;
    out.lang_opacity = if g.has_language() {
        g.lang_opacity.clone()
    } else {
        g.opacity.clone()
    };
    out.lang = labels
        .iter()
        .flat_map(|&l| (0..classes).map(move |c| if c == l as usize { 1.0 } else { 0.0 }))
        .collect();
    Ok(out)
}

/// Per pixel, the label whose accumulated weight is largest and above `min_weight`.
pub fn label_map(one_hot_image: &[f32], classes: usize, min_weight: f32) -> Vec<Option<u16>> {
    one_hot_image
        .chunks_exact(classes)
        .map(|px| {
            let (best, w) = px
                .iter()
                .enumerate()
                .fold(
                    (0, f32::NEG_INFINITY),
                    |a, (i, &v)| if v > a.1 { (i, v) } else { a },
                );
            (w > min_weight).then_some(best as u16)
        })
        .collect()
}

/// Labels from a SuperSplat / PlayCanvas annotation file: the first sample's first label
/// set's `point_annotations` (one number per Gaussian; 0 = unlabelled).
pub fn read_point_annotations(json: &str) -> Result<Vec<u16>> {
    let bad = |m: &str| QueryError::Invalid(format!("annotations: {m}"));
    let v: serde_json::Value = serde_json::from_str(json).map_err(|e| bad(&e.to_string()))?;
    let labels = v["dataset"]["samples"][0]["labels"]
        .as_object()
        .and_then(|m| m.values().next())
        .ok_or_else(|| bad("no dataset.samples[0].labels"))?;
    labels["attributes"]["point_annotations"]
        .as_array()
        .ok_or_else(|| bad("no point_annotations array"))?
        .iter()
        .map(|x| {
            x.as_f64()
                .filter(|f| f.fract() == 0.0 && *f >= 0.0 && *f < MAX_CATEGORIES as f64)
                .map(|f| f as u16)
                .ok_or_else(|| bad("labels must be integers in 0..10"))
        })
        .collect()
}
