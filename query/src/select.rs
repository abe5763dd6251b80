//! 3D selection: the relevance of every Gaussian's own language feature (no rendering), per
//! level, thresholded. For highlighting, deleting or exporting what a text query names.

use dlgs::Gaussians;

use crate::error::{QueryError, Result};
use crate::relevance::RelevanceField;

/// Default threshold on the raw relevance: the positive must beat every negative with
/// probability above one half.
pub const DEFAULT_THRESHOLD: f32 = 0.5;

/// Which Gaussians a query selects.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Relevance per level: `[level][gaussian]`.
    pub relevance: Vec<Vec<f32>>,
    /// Chosen level (0-based).
    pub level: usize,
    pub selected: Vec<bool>,
}

impl Selection {
    pub fn count(&self) -> usize {
        self.selected.iter().filter(|&&s| s).count()
    }
}

/// Select the Gaussians of `g` relevant to positive `positive` of `field`. Without a forced
/// `level`, the level whose selected Gaussians have the largest mean relevance is used (the
/// reference's "mean" strategy applied to Gaussians instead of pixels).
pub fn select_gaussians(
    g: &Gaussians,
    levels: usize,
    dims: usize,
    field: &RelevanceField,
    positive: usize,
    threshold: f32,
    level: Option<usize>,
) -> Result<Selection> {
    if levels * dims != g.lang_width || levels == 0 {
        return Err(QueryError::Invalid(format!(
            "the Gaussians carry {} language values, expected {levels} levels x {dims} dims",
            g.lang_width
        )));
    }
    if level.is_some_and(|l| l >= levels) || positive >= field.positives() {
        return Err(QueryError::Invalid("level or positive out of range".into()));
    }
    let k = field.positives();
    let relevance: Vec<Vec<f32>> = (0..levels)
        .map(|l| {
            let mut f = Vec::with_capacity(g.len() * dims);
            for i in 0..g.len() {
                f.extend_from_slice(&g.lang_of(i)[l * dims..(l + 1) * dims]);
            }
            field
                .relevance(&f)
                .chunks_exact(k)
                .map(|c| c[positive])
                .collect()
        })
        .collect();
    let level = level.unwrap_or_else(|| {
        let score = |r: &Vec<f32>| {
            let (s, n) = r
                .iter()
                .filter(|&&v| v > threshold)
                .fold((0.0f64, 0usize), |(s, n), &v| (s + v as f64, n + 1));
            if n > 0 {
                s / n as f64
            } else {
                0.0
            }
        };
        let mut best = 0;
        for l in 1..levels {
            if score(&relevance[l]) > score(&relevance[best]) {
                best = l;
            }
        }
        best
    });
    let selected = relevance[level].iter().map(|&r| r > threshold).collect();
    Ok(Selection {
        relevance,
        level,
        selected,
    })
}
