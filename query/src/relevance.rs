//! Relevance of language features to text queries (the reference's `get_relevancy`): for a
//! unit embedding `e`, positive `p` and canonical negatives `n_i`,
//! `r = min_i softmax(T [e.p, e.n_i])_0 = min_i 1 / (1 + exp(T (e.n_i - e.p)))`.
//!
//! Decoding every pixel through the 3 -> 512 decoder costs ~176k multiply-adds per pixel and
//! level. Because the decoder's input is only 3-dimensional, the default evaluates the decoder
//! once on a regular grid over the features' bounding box and interpolates the cosines
//! trilinearly ([`Precision::Table`]); [`Precision::Exact`] decodes every distinct feature.
//! docs/benchmarks/queries.md gives both costs and the difference they make.

use dlgs::model::lang_decoder::LangDecoder;
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

use crate::batch_decode;
use crate::embeddings::Embeddings;
use crate::error::{QueryError, Result};

/// How features are decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    /// Every distinct feature through the decoder.
    Exact,
    /// The decoder on an `n x n x n` grid, cosines interpolated trilinearly (3-dim features
    /// only; others fall back to exact).
    Table(usize),
}

impl Default for Precision {
    fn default() -> Self {
        Precision::Table(DEFAULT_TABLE)
    }
}

/// Default grid size per axis (measured in docs/benchmarks/queries.md).
pub const DEFAULT_TABLE: usize = 48;

/// The reference's softmax temperature.
pub const TEMPERATURE: f32 = 10.0;

/// Positives and negatives of one query, and how to evaluate them.
pub struct RelevanceField<'a> {
    dec: &'a LangDecoder,
    positives: usize,
    negatives: usize,
    /// Positives then negatives, `embed` values each.
    targets: Vec<f32>,
    pub temperature: f32,
    pub precision: Precision,
    /// The decoded grid, kept across calls (levels, cameras, frames) while it covers the
    /// features asked for.
    table: Mutex<Option<Arc<CosineTable>>>,
}

impl<'a> RelevanceField<'a> {
    /// Check dimensions and gather the targets. `negatives` empty → error (the score is
    /// undefined without them).
    pub fn new(
        dec: &'a LangDecoder,
        positives: &Embeddings,
        negatives: &Embeddings,
        precision: Precision,
    ) -> Result<Self> {
        let e = dec.embed_dims();
        for (what, s) in [("text embedding", positives), ("negatives", negatives)] {
            if s.dims != e {
                return Err(QueryError::Invalid(format!(
                    "{what} have {} dims, the scene's language decoder outputs {e}",
                    s.dims
                )));
            }
        }
        if negatives.count() == 0 {
            return Err(QueryError::Invalid(
                "relevance needs at least one negative embedding".into(),
            ));
        }
        if let Precision::Table(n) = precision {
            if !(2..=256).contains(&n) {
                return Err(QueryError::Invalid(format!(
                    "table size {n} outside 2..=256"
                )));
            }
        }
        let mut targets = positives.values.clone();
        targets.extend_from_slice(&negatives.values);
        Ok(RelevanceField {
            dec,
            positives: positives.count(),
            negatives: negatives.count(),
            targets,
            temperature: TEMPERATURE,
            precision,
            table: Mutex::new(None),
        })
    }

    /// Build (or extend) the table so that it covers `features` (rows of 3), before several
    /// threads ask for parts of them.
    pub fn prepare(&self, features: &[f32]) {
        if let Precision::Table(n) = self.precision {
            if self.dec.input_dims() == 3 {
                self.table_for(features, n);
            }
        }
    }

    pub fn positives(&self) -> usize {
        self.positives
    }

    /// Relevance of each feature row (`input_dims` values) to each positive: `n x positives`.
    /// Rows that are exactly +0.0 (pixels no Gaussian covers: most of a typical view) are
    /// scored once and copied; the others go through the decoder or table. Same values as
    /// scoring every row (the zero row takes the same path).
    pub fn relevance(&self, features: &[f32]) -> Vec<f32> {
        let d = self.dec.input_dims().max(1);
        let k = self.positives;
        let rows = features.len() / d;
        let live: Vec<usize> = (0..rows)
            .filter(|&i| {
                features[i * d..(i + 1) * d]
                    .iter()
                    .any(|v| v.to_bits() != 0)
            })
            .collect();
        if live.len() == rows {
            return self.scores(features);
        }
        // Row 0 of the compacted input is the zero feature.
        let mut compact = vec![0.0f32; (live.len() + 1) * d];
        for (j, &i) in live.iter().enumerate() {
            compact[(j + 1) * d..(j + 2) * d].copy_from_slice(&features[i * d..(i + 1) * d]);
        }
        let scored = self.scores(&compact);
        let mut out = scored[..k].repeat(rows);
        for (j, &i) in live.iter().enumerate() {
            out[i * k..(i + 1) * k].copy_from_slice(&scored[(j + 1) * k..(j + 2) * k]);
        }
        out
    }

    /// Relevance of every row, no shortcut.
    fn scores(&self, features: &[f32]) -> Vec<f32> {
        let cos = self.cosines(features);
        let t = self.positives + self.negatives;
        let mut out = vec![0.0f32; (cos.len() / t) * self.positives];
        out.par_chunks_mut(self.positives.max(1) * 4096)
            .zip(cos.par_chunks(t * 4096))
            .for_each(|(o, c)| {
                for (orow, crow) in o.chunks_mut(self.positives).zip(c.chunks(t)) {
                    for (k, r) in orow.iter_mut().enumerate() {
                        *r = score(crow[k], &crow[self.positives..], self.temperature);
                    }
                }
            });
        out
    }

    fn cosines(&self, features: &[f32]) -> Vec<f32> {
        let d = self.dec.input_dims();
        match self.precision {
            Precision::Table(n) if d == 3 => self.table_for(features, n).lookup_all(features),
            _ => exact_dedup(self.dec, &self.targets, features),
        }
    }
}

impl RelevanceField<'_> {
    /// The cached table if it covers `features`, else a new one covering both.
    fn table_for(&self, features: &[f32], n: usize) -> Arc<CosineTable> {
        let (lo, hi) = feature_box(features);
        let mut slot = self.table.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(t) = slot.as_ref() {
            if t.covers(lo, hi) {
                return t.clone();
            }
        }
        let (lo, hi) = match slot.as_ref() {
            Some(t) => {
                let (tl, th) = t.bounds();
                (
                    [0, 1, 2].map(|a| lo[a].min(tl[a])),
                    [0, 1, 2].map(|a| hi[a].max(th[a])),
                )
            }
            None => (lo, hi),
        };
        let t = Arc::new(CosineTable::build(self.dec, &self.targets, lo, hi, n));
        *slot = Some(t.clone());
        t
    }
}

/// The features' bounding box, at least [-1, 1]^3 (where unit codes blended with weights up
/// to 1 live), at most [-4, 4]^3 (so that one outlier cannot make the grid coarse: features
/// beyond it are clamped to it).
fn feature_box(features: &[f32]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [-1.0f32; 3];
    let mut hi = [1.0f32; 3];
    for f in features.chunks_exact(3) {
        for a in 0..3 {
            if f[a].is_finite() {
                lo[a] = lo[a].min(f[a]).max(-BOX_LIMIT);
                hi[a] = hi[a].max(f[a]).min(BOX_LIMIT);
            }
        }
    }
    (lo, hi)
}

/// `min_i 1 / (1 + exp(T (n_i - p)))`.
pub fn score(pos: f32, negs: &[f32], temperature: f32) -> f32 {
    negs.iter()
        .map(|&n| 1.0 / (1.0 + (temperature * (n - pos)).exp()))
        .fold(f32::INFINITY, f32::min)
}

/// Exact cosines, decoding each distinct feature (bit pattern) once: background pixels and
/// repeated codes cost nothing extra.
fn exact_dedup(dec: &LangDecoder, targets: &[f32], features: &[f32]) -> Vec<f32> {
    let d = dec.input_dims();
    let t = targets.len() / dec.embed_dims();
    let mut index = std::collections::HashMap::new();
    let mut unique: Vec<f32> = Vec::new();
    let slot: Vec<usize> = features
        .chunks(d)
        .map(|f| {
            let key: Vec<u32> = f.iter().map(|v| v.to_bits()).collect();
            *index.entry(key).or_insert_with(|| {
                unique.extend_from_slice(f);
                unique.len() / d - 1
            })
        })
        .collect();
    let cos = batch_decode::cosines(dec, &unique, targets);
    let mut out = Vec::with_capacity(slot.len() * t);
    for s in slot {
        out.extend_from_slice(&cos[s * t..(s + 1) * t]);
    }
    out
}

/// Largest feature magnitude per axis the table covers.
pub const BOX_LIMIT: f32 = 4.0;

/// Cosines on a regular 3D grid over a box, interpolated trilinearly.
pub struct CosineTable {
    lo: [f32; 3],
    hi: [f32; 3],
    step: [f32; 3],
    n: usize,
    t: usize,
    values: Vec<f32>,
}

impl CosineTable {
    /// The decoder on an `n^3` grid spanning `[lo, hi]`.
    pub fn build(dec: &LangDecoder, targets: &[f32], lo: [f32; 3], hi: [f32; 3], n: usize) -> Self {
        let step = [0, 1, 2].map(|a| (hi[a] - lo[a]) / (n - 1) as f32);
        let mut nodes = Vec::with_capacity(n * n * n * 3);
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    nodes.extend([
                        lo[0] + i as f32 * step[0],
                        lo[1] + j as f32 * step[1],
                        lo[2] + k as f32 * step[2],
                    ]);
                }
            }
        }
        let values = batch_decode::cosines(dec, &nodes, targets);
        CosineTable {
            lo,
            hi,
            step,
            n,
            t: targets.len() / dec.embed_dims(),
            values,
        }
    }

    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        (self.lo, self.hi)
    }

    fn covers(&self, lo: [f32; 3], hi: [f32; 3]) -> bool {
        let (tl, th) = self.bounds();
        (0..3).all(|a| tl[a] <= lo[a] && th[a] >= hi[a])
    }

    /// Interpolated cosines of every feature (`n x t`). Coordinates are clamped to the box;
    /// NaN coordinates read the box's low corner.
    pub fn lookup_all(&self, features: &[f32]) -> Vec<f32> {
        let t = self.t;
        let mut out = vec![0.0f32; features.len() / 3 * t];
        out.par_chunks_mut(4096 * t)
            .zip(features.par_chunks(4096 * 3))
            .for_each(|(o, f)| {
                for (orow, x) in o.chunks_mut(t).zip(f.chunks_exact(3)) {
                    self.lookup(x, orow);
                }
            });
        out
    }

    fn lookup(&self, x: &[f32], out: &mut [f32]) {
        let last = (self.n - 1) as f32;
        let mut base = [0usize; 3];
        let mut frac = [0.0f32; 3];
        for a in 0..3 {
            let u = ((x[a] - self.lo[a]) / self.step[a]).clamp(0.0, last);
            let u = if u.is_nan() { 0.0 } else { u };
            let b = (u.floor() as usize).min(self.n - 2);
            base[a] = b;
            frac[a] = u - b as f32;
        }
        out.fill(0.0);
        for corner in 0..8 {
            let mut w = 1.0f32;
            let mut idx = 0usize;
            for a in 0..3 {
                let bit = (corner >> (2 - a)) & 1;
                w *= if bit == 1 { frac[a] } else { 1.0 - frac[a] };
                idx = idx * self.n + base[a] + bit;
            }
            let row = &self.values[idx * self.t..(idx + 1) * self.t];
            for (o, v) in out.iter_mut().zip(row) {
                *o += w * v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dlgs::model::lang_decoder::{DenseLayer, NamedEmbedding};

    /// A 3 -> 8 -> 16 decoder with random weights, a random unit text embedding and two
    /// random negatives.
    fn small_decoder(rng: &mut fastrand::Rng) -> (LangDecoder, Embeddings) {
        let mut layer = |inputs: usize, outputs: usize| DenseLayer {
            inputs,
            outputs,
            weight: (0..inputs * outputs)
                .map(|_| rng.f32() * 2.0 - 1.0)
                .collect(),
            bias: (0..outputs).map(|_| rng.f32() * 0.2 - 0.1).collect(),
        };
        let layers = vec![layer(3, 8), layer(8, 16)];
        let mut unit = || {
            let v: Vec<f32> = (0..16).map(|_| rng.f32() * 2.0 - 1.0).collect();
            let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            v.into_iter().map(|x| x / n).collect::<Vec<f32>>()
        };
        let negatives = ["object", "things"]
            .map(|name| NamedEmbedding {
                name: name.into(),
                values: unit(),
            })
            .to_vec();
        let positives = Embeddings::from_rows(vec!["query".into()], vec![unit()]).unwrap();
        (LangDecoder { layers, negatives }, positives)
    }

    /// The zero-row shortcut gives exactly what scoring every row gives, with the table and
    /// with exact decoding, for zero rows anywhere (first, last, runs) and -0.0 rows (scored
    /// normally).
    #[test]
    fn zero_rows_shortcut_changes_no_value() {
        let mut rng = fastrand::Rng::with_seed(9);
        let (decoder, positives) = small_decoder(&mut rng);
        let negatives = Embeddings::from_named(&decoder.negatives).unwrap();
        let mut features = Vec::new();
        for i in 0..5000 {
            let zero = i == 0 || i == 4999 || (1000..1400).contains(&i) || rng.f32() < 0.5;
            for _ in 0..3 {
                features.push(if zero { 0.0 } else { rng.f32() * 2.0 - 1.0 });
            }
        }
        features[3 * 2500..3 * 2501].copy_from_slice(&[-0.0, -0.0, -0.0]);
        for precision in [Precision::Table(24), Precision::Exact] {
            let field = RelevanceField::new(&decoder, &positives, &negatives, precision).unwrap();
            field.prepare(&features);
            let shortcut = field.relevance(&features);
            let every_row = field.scores(&features);
            assert_eq!(shortcut.len(), every_row.len());
            for (a, b) in shortcut.iter().zip(&every_row) {
                assert_eq!(a.to_bits(), b.to_bits(), "{precision:?}");
            }
        }
    }
}
