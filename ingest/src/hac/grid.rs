//! The binary hash-grid lookup of the fixture (a float32 forward pass of HAC++'s
//! `gridencoder.cu`, `tests/fixtures/scaffold_run/README.md`), shared by the context model
//! and the NTC. Every operation is the float32 operation of the fixture's torch code, in its
//! order, so the features are the same bits.

/// One multi-level binary grid of `D` dimensions: per level a resolution and a table of
/// `rows` entries of `features` ±1 values (`true` = +1), entry-major.
#[derive(Debug, Clone, PartialEq)]
pub struct BinaryGrid {
    pub dims: usize,
    pub resolutions: Vec<u32>,
    pub features: usize,
    /// Row offset of each level (running sum of the level sizes) and the total at the end.
    pub offsets: Vec<usize>,
    pub bits: Vec<bool>,
}

const PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];

/// Entries per level: `ceil(min(2^log2, R^D) / 8) * 8`.
pub fn level_offsets(resolutions: &[u32], dims: usize, log2: u32) -> Vec<usize> {
    let mut offs = vec![0usize];
    for &r in resolutions {
        let full = (r as u128).pow(dims as u32);
        let size = full.min(1u128 << log2) as usize;
        let last = *offs.last().unwrap_or(&0);
        offs.push(last + size.div_ceil(8) * 8);
    }
    offs
}

impl BinaryGrid {
    /// Bits needed for this layout.
    pub fn n_bits(resolutions: &[u32], dims: usize, log2: u32, features: usize) -> usize {
        level_offsets(resolutions, dims, log2)
            .last()
            .copied()
            .unwrap_or(0)
            * features
    }

    /// A grid over `bits` (exactly [`Self::n_bits`] of them; the caller slices).
    pub fn new(
        dims: usize,
        resolutions: &[u32],
        log2: u32,
        features: usize,
        bits: Vec<bool>,
    ) -> Option<Self> {
        let offsets = level_offsets(resolutions, dims, log2);
        if !(1..=3).contains(&dims)
            || resolutions.iter().any(|&r| r < 3)
            || bits.len() != offsets.last().copied()? * features
        {
            return None;
        }
        Some(BinaryGrid {
            dims,
            resolutions: resolutions.to_vec(),
            features,
            offsets,
            bits,
        })
    }

    /// Output width: levels × features.
    pub fn width(&self) -> usize {
        self.resolutions.len() * self.features
    }

    /// The interpolated features at `x` (`dims` coordinates), level-major, into `out`
    /// (`width()` values). Any coordinate outside [0, 1] gives zeros.
    pub fn lookup(&self, x: &[f32], out: &mut [f32]) {
        let d_n = self.dims;
        let f_n = self.features;
        out.iter_mut().for_each(|v| *v = 0.0);
        if x.iter().any(|&v| !(0.0..=1.0).contains(&v)) {
            return;
        }
        for (lvl, &r) in self.resolutions.iter().enumerate() {
            let size = self.offsets[lvl + 1] - self.offsets[lvl];
            // `% size` with the level's rounded size, as `grid_lookup`.
            let mut g = [0u32; 3];
            let mut f = [0f32; 3];
            for d in 0..d_n {
                let pos = x[d] * (r - 2) as f32 + 0.5;
                let fl = pos.floor();
                g[d] = fl as u32;
                f[d] = pos - fl;
            }
            let hashed = (r as u128).pow(d_n as u32) > size as u128;
            let mut ws = [0f32; 8];
            let mut rows = [0usize; 8];
            let mut wn = 0f32;
            for c in 0..(1usize << d_n) {
                let mut w = 1f32;
                let mut keep = true;
                let mut dense: u64 = 0;
                let mut stride: u64 = 1;
                let mut h: u32 = 0;
                for d in 0..d_n {
                    let loc = if c >> d & 1 == 0 {
                        w *= 1.0 - f[d];
                        g[d]
                    } else {
                        w *= f[d];
                        (g[d] + 1).min(r - 1)
                    };
                    keep &= loc != 0 && loc != r - 1;
                    dense += loc as u64 * stride;
                    stride *= r as u64;
                    h ^= loc.wrapping_mul(PRIMES[d]);
                }
                let index = if hashed { h as u64 } else { dense } % size as u64;
                ws[c] = if keep { w } else { 0.0 };
                rows[c] = self.offsets[lvl] + index as usize;
                wn += ws[c];
            }
            if wn == 0.0 {
                wn = 1e-9;
            }
            let wn_re = (1.0 / wn as f64) as f32;
            let o = &mut out[lvl * f_n..(lvl + 1) * f_n];
            for c in 0..(1usize << d_n) {
                let w = ws[c] * wn_re;
                let row = rows[c] * f_n;
                for (k, v) in o.iter_mut().enumerate() {
                    *v += w * if self.bits[row + k] { 1.0 } else { -1.0 };
                }
            }
        }
    }
}
