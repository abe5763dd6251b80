//! Time features re-laid out key- and channel-major, `(K, C, N)`, for the decoder's panels:
//! the 16 rows of a panel at one key and channel are 16 consecutive floats, so building a
//! panel is a vector load and a frame reads only the channels its decoders use, as sequential
//! streams the hardware prefetcher follows. (The file and the reference keep `(N, K, C)`.)

use std::ops::Range;
use std::sync::{Arc, OnceLock};

use dlgs::model::TimeFeatures;
use dlgs::Result;
use rayon::prelude::*;

use crate::interp::lerp;
use crate::panel::{Lane, PANEL};

/// Decodes one key's features, `(C, N)` column-major, on demand (intra-only HEVC time
/// features: each key is its own picture; one-stream features: a prefix of the stream).
pub trait KeySource: Send + Sync {
    fn key(&self, k: usize) -> Result<Vec<f32>>;

    /// Fill the slots of the keys of `needed` (each key's `(C, N)` block), and any other slot
    /// the same work decoded; a slot already filled keeps its value (the same). Default: each
    /// key of `needed` with [`Self::key`], in parallel.
    fn fill(&self, needed: &[usize], slots: &[OnceLock<Vec<f32>>]) -> Result<()> {
        let decoded: Vec<(usize, Vec<f32>)> = needed
            .par_iter()
            .map(|&k| self.key(k).map(|v| (k, v)))
            .collect::<Result<_>>()?;
        for (k, v) in decoded {
            // Another thread may have filled it first with the same values.
            let _ = slots[k].set(v);
        }
        Ok(())
    }
}

#[derive(Clone)]
enum Store {
    /// `data[(k * channels + c) * n + i]`.
    Whole(Vec<f32>),
    /// Key `k`'s `(C, N)` block in `slots[k]`, decoded from `source` when first needed.
    PerKey {
        slots: Vec<OnceLock<Vec<f32>>>,
        source: Arc<dyn KeySource>,
    },
}

#[derive(Clone)]
pub struct PlanarFeatures {
    pub n: usize,
    pub keys: usize,
    pub channels: usize,
    store: Store,
}

impl std::fmt::Debug for PlanarFeatures {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PlanarFeatures")
            .field("n", &self.n)
            .field("keys", &self.keys)
            .field("channels", &self.channels)
            .field("loaded_keys", &self.loaded_keys())
            .finish()
    }
}

impl PlanarFeatures {
    /// From features already laid out `(K, C, N)` (see `tfea::untile_columns`).
    pub fn from_columns(n: usize, keys: usize, channels: usize, data: Vec<f32>) -> Self {
        assert_eq!(data.len(), n * keys * channels, "(K, C, N) layout");
        PlanarFeatures {
            n,
            keys,
            channels,
            store: Store::Whole(data),
        }
    }

    /// Features whose keys are decoded by `source` when first needed ([`Self::ensure_keys`]):
    /// intra-only and one-stream HEVC features (`prefix_keys.rs`).
    pub fn per_key(n: usize, keys: usize, channels: usize, source: Arc<dyn KeySource>) -> Self {
        PlanarFeatures {
            n,
            keys,
            channels,
            store: Store::PerKey {
                slots: (0..keys).map(|_| OnceLock::new()).collect(),
                source,
            },
        }
    }

    /// Decode the keys of `range` not decoded yet (in parallel). Every reader of a key calls
    /// this first; a key that fails to decode is an error here, never later.
    pub fn ensure_keys(&self, range: Range<usize>) -> Result<()> {
        let Store::PerKey { slots, source } = &self.store else {
            return Ok(());
        };
        let range = range.start.min(self.keys)..range.end.min(self.keys);
        let missing: Vec<usize> = range.filter(|&k| slots[k].get().is_none()).collect();
        if missing.is_empty() {
            return Ok(());
        }
        source.fill(&missing, slots)?;
        for k in missing {
            // The sources are this crate's own untiling, sized by the tiling: not input.
            let v = slots[k].get().expect("the source filled every needed key");
            assert_eq!(v.len(), self.channels * self.n, "key {k}'s (C, N) block");
        }
        Ok(())
    }

    /// Keys decoded so far (all of them for features decoded as a whole).
    pub fn loaded_keys(&self) -> usize {
        match &self.store {
            Store::Whole(_) => self.keys,
            Store::PerKey { slots, .. } => slots.iter().filter(|s| s.get().is_some()).count(),
        }
    }

    pub fn new(f: &TimeFeatures) -> Self {
        let (n, keys, ch) = (f.n, f.keys, f.channels);
        let mut data = vec![0f32; f.data.len()];
        for (i, row) in f.data.chunks_exact(keys * ch).enumerate() {
            for (kc, &v) in row.iter().enumerate() {
                data[kc * n + i] = v;
            }
        }
        PlanarFeatures {
            n,
            keys,
            channels: ch,
            store: Store::Whole(data),
        }
    }

    /// Back to the file's `(N, K, C)` layout (decodes every key).
    pub fn to_time_features(&self) -> Result<TimeFeatures> {
        self.ensure_keys(0..self.keys)?;
        let (n, ch) = (self.n, self.channels);
        let mut f = TimeFeatures::zeros(n, self.keys, ch);
        let kc = self.keys * ch;
        for (i, row) in f.data.chunks_exact_mut(kc).enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = self.column(j / ch, j % ch, i..i + 1)[0];
            }
        }
        Ok(f)
    }

    fn column(&self, k: usize, c: usize, rows: Range<usize>) -> &[f32] {
        let (block, o) = match &self.store {
            Store::Whole(data) => (data.as_slice(), (k * self.channels + c) * self.n),
            Store::PerKey { slots, .. } => (
                slots[k]
                    .get()
                    .expect("ensure_keys runs before a key is read")
                    .as_slice(),
                c * self.n,
            ),
        };
        &block[o + rows.start..o + rows.end]
    }

    /// Panel columns `x[j] = lerp(F_k, F_k+1, δ)[c0 + j]` over `rows` (zero past the end).
    pub fn lerp_panel(&self, rows: Range<usize>, k: usize, d: f32, c0: usize, x: &mut [Lane]) {
        for (j, lane) in x.iter_mut().enumerate() {
            let a = self.column(k, c0 + j, rows.clone());
            let b = self.column(k + 1, c0 + j, rows.clone());
            match (<&Lane>::try_from(a), <&Lane>::try_from(b)) {
                (Ok(a), Ok(b)) => *lane = std::array::from_fn(|l| lerp(a[l], b[l], d)),
                _ => {
                    *lane = [0.0; PANEL];
                    for ((o, &a), &b) in lane.iter_mut().zip(a).zip(b) {
                        *o = lerp(a, b, d);
                    }
                }
            }
        }
    }

    /// Panel columns `x[j] = F_k[c0 + j]` over `rows` (zero past the end).
    pub fn key_panel(&self, rows: Range<usize>, k: usize, c0: usize, x: &mut [Lane]) {
        for (j, lane) in x.iter_mut().enumerate() {
            *lane = [0.0; PANEL];
            let a = self.column(k, c0 + j, rows.clone());
            lane[..a.len()].copy_from_slice(a);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_round_trip_and_panels_read_the_right_values() {
        let mut f = TimeFeatures::zeros(37, 3, 5);
        for (j, v) in f.data.iter_mut().enumerate() {
            *v = j as f32 * 0.25 - 3.0;
        }
        let p = PlanarFeatures::new(&f);
        assert_eq!(p.to_time_features().unwrap(), f);
        let mut x = vec![[0.0; PANEL]; 3];
        for rows in [0..16, 16..32, 32..37] {
            p.lerp_panel(rows.clone(), 1, 0.25, 2, &mut x);
            for (l, i) in rows.clone().enumerate() {
                for j in 0..3 {
                    let want = lerp(f.at(i, 1)[2 + j], f.at(i, 2)[2 + j], 0.25);
                    assert_eq!(x[j][l], want);
                }
            }
            for l in rows.len()..PANEL {
                assert_eq!(x[0][l], 0.0);
            }
            p.key_panel(rows.clone(), 2, 1, &mut x);
            for (l, i) in rows.enumerate() {
                assert_eq!(x[2][l], f.at(i, 2)[3]);
            }
        }
    }
}
