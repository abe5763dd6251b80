//! Language relevance: the scene's language decoder (`LAED`), the query embedding, and the
//! relevance of each row of the current frame to it.

use dlgs::model::lang_decoder::LangDecoder;
use wasm_bindgen::prelude::*;

use crate::errors::js_err;
use crate::Player;

pub(crate) struct Query {
    /// Positive embedding (unit) then negatives (unit), `dims` each.
    targets: Vec<f32>,
    dims: usize,
    level: usize,
    /// Cosine table over the level's 3-dim codes when the embedding lives in the LAED
    /// decoder's output space: n^3 grid points x targets.
    table: Option<(usize, [f32; 3], [f32; 3], Vec<f32>)>,
}

#[wasm_bindgen]
impl Player {
    /// Does the file carry a language decoder (`LAED`)? Its output width, or 0.
    pub fn laed_dims(&mut self) -> Result<u32, JsError> {
        Ok(self.laed()?.map_or(0, |l| l.embed_dims() as u32))
    }
}

impl Player {
    fn laed(&mut self) -> Result<Option<&LangDecoder>, JsError> {
        if self.lang_dec.is_none() {
            // Scene-level chunks come before GOP 0, which the page fetches first.
            let l = dlgs_decoder::read_lang_decoder(self.reader()?).map_err(js_err)?;
            self.lang_dec = Some(l);
        }
        Ok(self.lang_dec.as_ref().and_then(|l| l.as_ref()))
    }
}

#[wasm_bindgen]
impl Player {
    /// Set the language query: a text embedding of the scene's language decoder's output width
    /// (with LAED: decoded codes, the reference's relevance score against its negatives), or of
    /// a level's code width / the whole feature width (plain cosine). `level` picks the level.
    pub fn set_query(&mut self, embedding: Vec<f32>, level: u32) -> Result<(), JsError> {
        let lw = self.buf.lang_width;
        if lw == 0 {
            return Err(JsError::new("Request: this scene has no language features"));
        }
        let levels = (self.reader()?.scene().lang_levels as usize).max(1);
        let code = lw / levels;
        let level = (level as usize).min(levels - 1);
        let unit = |v: &[f32]| {
            let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            v.iter()
                .map(|x| if n > 0.0 { x / n } else { 0.0 })
                .collect::<Vec<f32>>()
        };
        let laed_dims = self.laed()?.map_or(0, |l| l.embed_dims());
        if embedding.len() == lw || embedding.len() == code {
            self.query = Some(Query {
                targets: unit(&embedding),
                dims: embedding.len(),
                level,
                table: None,
            });
            return Ok(());
        }
        if laed_dims == 0 || embedding.len() != laed_dims || code != 3 {
            return Err(JsError::new(&format!(
                "Request: the embedding has {} values; this scene takes {lw} (whole feature), \
                 {code} (one level){}",
                embedding.len(),
                if laed_dims > 0 {
                    format!(" or {laed_dims} (its language decoder's output)")
                } else {
                    String::new()
                }
            )));
        }
        // Cosine table over the level's codes in this frame (the query crate's method).
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for f in self.buf.lang.chunks_exact(lw) {
            for a in 0..3 {
                let v = f[level * 3 + a];
                if v.is_finite() {
                    lo[a] = lo[a].min(v);
                    hi[a] = hi[a].max(v);
                }
            }
        }
        for a in 0..3 {
            if !(lo[a] < hi[a]) {
                lo[a] = -1.0;
                hi[a] = 1.0;
            }
            let m = 0.1 * (hi[a] - lo[a]);
            lo[a] -= m;
            hi[a] += m;
        }
        let dec = self.laed()?.expect("checked").clone();
        let mut targets = unit(&embedding);
        for n in &dec.negatives {
            targets.extend(unit(&n.values));
        }
        let nt = targets.len() / laed_dims;
        let n = 24;
        let mut table = Vec::with_capacity(n * n * n * nt);
        let mut e = vec![0.0f32; laed_dims];
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    let x = [i, j, k].map(|v| v as f32 / (n - 1) as f32);
                    let p = [0, 1, 2].map(|a| lo[a] + x[a] * (hi[a] - lo[a]));
                    dec.decode_one(&p, &mut e);
                    for t in targets.chunks_exact(laed_dims) {
                        table.push(e.iter().zip(t).map(|(a, b)| a * b).sum());
                    }
                }
            }
        }
        self.query = Some(Query {
            targets,
            dims: laed_dims,
            level,
            table: Some((n, lo, hi, table)),
        });
        Ok(())
    }

    pub fn clear_query(&mut self) {
        self.query = None;
    }
}

impl Player {
    /// Relevance of each row of the current frame to the query (empty without one).
    pub(crate) fn compute_relevance(&mut self) {
        let Some(q) = &self.query else {
            self.relevance.clear();
            return;
        };
        let lw = self.buf.lang_width;
        self.relevance.clear();
        for f in self.buf.lang.chunks_exact(lw) {
            let r = match &q.table {
                None => {
                    let x = if q.dims == lw {
                        f
                    } else {
                        &f[q.level * q.dims..(q.level + 1) * q.dims]
                    };
                    let n = x.iter().map(|v| v * v).sum::<f32>().sqrt();
                    let dot: f32 = x.iter().zip(&q.targets).map(|(a, b)| a * b).sum();
                    if n > 0.0 {
                        dot / n
                    } else {
                        0.0
                    }
                }
                Some((n, lo, hi, table)) => {
                    let nt = q.targets.len() / q.dims;
                    let x = &f[q.level * 3..q.level * 3 + 3];
                    let mut cos = vec![0.0f32; nt];
                    let mut base = [0usize; 3];
                    let mut fr = [0.0f32; 3];
                    for a in 0..3 {
                        let u =
                            ((x[a] - lo[a]) / (hi[a] - lo[a])).clamp(0.0, 1.0) * (*n - 1) as f32;
                        let u = if u.is_finite() { u } else { 0.0 };
                        base[a] = (u.floor() as usize).min(n - 2);
                        fr[a] = u - base[a] as f32;
                    }
                    for c in 0..8 {
                        let (di, dj, dk) = (c >> 2 & 1, c >> 1 & 1, c & 1);
                        let w = [di, dj, dk]
                            .iter()
                            .enumerate()
                            .map(|(a, &d)| if d == 1 { fr[a] } else { 1.0 - fr[a] })
                            .product::<f32>();
                        let cell = ((base[0] + di) * n + base[1] + dj) * n + base[2] + dk;
                        for (t, c) in cos.iter_mut().enumerate() {
                            *c += w * table[cell * nt + t];
                        }
                    }
                    if nt == 1 {
                        cos[0]
                    } else {
                        // The reference's score: min over negatives of softmax(10 [p, n_i])_0.
                        cos[1..]
                            .iter()
                            .map(|&ng| 1.0 / (1.0 + (10.0 * (ng - cos[0])).exp()))
                            .fold(f32::INFINITY, f32::min)
                    }
                }
            };
            self.relevance.push(r);
        }
    }
}
