//! Gaussian-coded anchor attributes (`feat_{s}_0.b`, `scaling_{s}_0.b`, `offsets_{s}_0.b`):
//! symbols `round(x/Q) - min` with a per-symbol CDF from the context model's mean and scale
//! (the CUDA `calculate_cdf_kernel` rule, in float32), decoded with torchac's range coder.

use crate::latents::torchac_decode_with;
use crate::IngestError;

use super::bitstream::{parse, CHUNK};
use super::repair::Chunk;

/// Largest symbol alphabet accepted (the symbols are int16).
const MAX_LP: usize = 1 << 16;

/// The complementary error function as torch's CPU float32 `erfc` computes it, as closely as
/// we can without its library: torch calls MKL's `vsErfc` (checked: same bits on 600,000
/// samples), which is faithful (always one of the two floats around the exact value) and for
/// z < 0 returns `f32(2 - erfc(|z|))` (checked: all samples). Here `erfc(|z|)` is fdlibm's
/// f64 `erfc` (the `libm` crate) rounded to f32, the correctly rounded value; MKL's differs
/// from it by one ulp for 1-7 % of arguments (more for larger |z|), where a CDF entry can
/// then round to another integer (measured in `tests/tests/hac_ingest.rs`).
pub fn erfc_f32(z: f32) -> f32 {
    let e = libm::erfc(z.abs() as f64) as f32;
    if z < 0.0 {
        2.0 - e
    } else {
        e
    }
}

/// Integer CDF entry `j` of a symbol with step `q`, mean `mu`, scale `sigma`, for a file with
/// minimum `mn` and `lp` entries: `rint(float32(cdf * (65536 - (lp-1)))) + j` (mod 2^16).
pub fn cdf_entry(mn: i32, j: usize, q: f32, mu: f32, sigma: f32, lp: usize) -> u16 {
    cdf_entries(mn, j, q, mu, sigma, lp).0
}

/// [`cdf_entry`] with `erfc(|z|)` rounded to the nearest float, and with it rounded to the
/// other float next to the exact value (what MKL returns for some arguments).
pub fn cdf_entries(mn: i32, j: usize, q: f32, mu: f32, sigma: f32, lp: usize) -> (u16, u16) {
    let x = (((mn as f64 + j as f64) - 0.5) * q as f64) as f32;
    let s = sigma.max(1e-9f32);
    let z = -(x - mu) / (s * std::f32::consts::SQRT_2);
    let exact = libm::erfc(z.abs() as f64);
    let e = exact as f32;
    // MKL's vsErfc returns the other float only when the exact value is at least 0.400 ulp
    // from the nearest one (60,000 samples against 80-bit values); 0.38 keeps a margin.
    let ulp = (e.next_up() - e) as f64;
    let other = if (exact - e as f64).abs() < 0.38 * ulp {
        e
    } else if (e as f64) < exact {
        e.next_up()
    } else if (e as f64) > exact {
        e.next_down()
    } else {
        e
    };
    let scale = 65536.0f32 - (lp as f32 - 1.0);
    let int = |e: f32| {
        let v = if z < 0.0 { 2.0 - e } else { e };
        let v = (0.5 * v * scale).round_ties_even();
        ((v as i64 + j as i64) & 0xFFFF) as u16
    };
    (int(e), int(other))
}

/// torchac's encoder (precision 16, E1/E2/E3 with pending bits, termination `pending + 1`
/// bits, zero padding) run over `syms`; true iff it writes exactly `stream`. A decode with
/// another CDF than the encoder's still re-encodes to the stream's prefix, but (nearly
/// always) not to its exact end and length: this is the check of a decode.
pub fn reencodes_to(
    stream: &[u8],
    syms: &[u16],
    lp: usize,
    mut cdf_at: impl FnMut(usize, usize) -> u16,
) -> bool {
    struct W<'a> {
        stream: &'a [u8],
        bits: usize,
        ok: bool,
    }
    impl W<'_> {
        fn put(&mut self, bit: bool) {
            let byte = self.bits / 8;
            let want = self
                .stream
                .get(byte)
                .map(|b| b >> (7 - self.bits % 8) & 1 == 1);
            self.ok &= want == Some(bit);
            self.bits += 1;
        }
        fn put_pending(&mut self, bit: bool, pending: &mut u64) {
            self.put(bit);
            while *pending > 0 && self.ok {
                self.put(!bit);
                *pending -= 1;
            }
            *pending = 0;
        }
    }
    let max_symbol = lp.saturating_sub(2);
    let mut w = W {
        stream,
        bits: 0,
        ok: true,
    };
    let (mut low, mut high, mut pending) = (0u32, u32::MAX, 0u64);
    for (i, &s) in syms.iter().enumerate() {
        let s = s as usize;
        if s > max_symbol {
            return false;
        }
        let span = high as u64 - low as u64 + 1;
        let c_low = cdf_at(i, s) as u64;
        let c_high = if s == max_symbol {
            0x10000
        } else {
            cdf_at(i, s + 1) as u64
        };
        high = low
            .wrapping_sub(1)
            .wrapping_add((span.wrapping_mul(c_high) >> 16) as u32);
        low = low.wrapping_add((span.wrapping_mul(c_low) >> 16) as u32);
        loop {
            if high < 0x8000_0000 {
                w.put_pending(false, &mut pending);
            } else if low >= 0x8000_0000 {
                w.put_pending(true, &mut pending);
            } else if low >= 0x4000_0000 && high < 0xC000_0000 {
                pending += 1;
                low = (low << 1) & 0x7FFF_FFFF;
                high = (high << 1) | 0x8000_0001;
                continue;
            } else {
                break;
            }
            low <<= 1;
            high = (high << 1) | 1;
        }
        if !w.ok {
            return false;
        }
    }
    pending += 1;
    w.put_pending(low >= 0x4000_0000, &mut pending);
    while !w.bits.is_multiple_of(8) && w.ok {
        w.put(false);
    }
    w.ok && w.bits == stream.len() * 8
}

/// What decoding one Gaussian `.b` file gave.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GaussianDecode {
    /// `(sym + min) * Q`, anchor-major.
    pub values: Vec<f32>,
    /// The integers `sym + min` (`round(x / Q)` of the reference's encoder), anchor-major.
    pub symbols: Vec<i32>,
    /// Chunks whose decode re-encodes to their bytes exactly, of all chunks.
    pub verified_chunks: usize,
    pub chunks: usize,
    /// Indices of the chunks that did not verify.
    pub unverified: Vec<usize>,
    /// Indices of the chunks that verified only after switches (not proven: see
    /// `repair.rs`).
    pub repaired: Vec<usize>,
    /// Anchors whose Q was switched to the other tanh rounding to make a chunk verify.
    pub q_switched: usize,
    /// CDF entries switched to the other erfc rounding to make a chunk verify.
    pub entries_switched: usize,
}

/// Decode one Gaussian `.b` file of `anchors` anchors × `channels` symbols, anchor-major,
/// with per-anchor `q` (and `q_alt`, the other tanh rounding) and per-symbol `mean`,
/// `scale`. Each chunk's decode is checked by re-encoding it; a chunk that does not
/// re-encode to its bytes is searched for the other roundings of Q and of CDF entries
/// (`repair.rs`, at most `repair_trials` extra decodes per chunk, so corrupt input cannot
/// make it unbounded); if none is found, the first decode is kept and the chunk reported
/// unverified.
pub fn decode_gaussian(
    bytes: &[u8],
    channels: usize,
    mean: &[f32],
    scale: &[f32],
    q: &[f32],
    q_alt: &[f32],
    repair_trials: usize,
    what: &str,
) -> Result<GaussianDecode, IngestError> {
    let n = mean.len();
    if scale.len() != n || q.len().checked_mul(channels) != Some(n) || q_alt.len() != q.len() {
        return Err(IngestError::shape(
            what,
            "context does not match the symbols",
        ));
    }
    let c = parse(bytes, true, n, what)?;
    let (mn, mx) = c.header;
    let ok = |v: f32| v.is_finite() && v.fract() == 0.0 && v.abs() <= 1e9;
    if !ok(mn) || !ok(mx) || mx < mn || (mx - mn) as usize + 2 > MAX_LP {
        return Err(IngestError::format(
            what,
            format!("symbol range [{mn}, {mx}] is not a valid int16 alphabet"),
        ));
    }
    if let Some(i) = (0..n).find(|&i| !(mean[i].is_finite() && scale[i].is_finite())) {
        return Err(IngestError::NonFinite {
            what: format!("{what}: context mean/scale"),
            index: i,
            value: if mean[i].is_finite() {
                scale[i]
            } else {
                mean[i]
            },
        });
    }
    if let Some(i) = (0..q.len()).find(|&i| !(q[i].is_finite() && q_alt[i].is_finite())) {
        return Err(IngestError::NonFinite {
            what: format!("{what}: context Q"),
            index: i,
            value: q[i],
        });
    }
    let (mni, lp) = (mn as i32, (mx - mn) as usize + 2);
    let mut out = GaussianDecode {
        values: Vec::with_capacity(n),
        chunks: c.chunks.len(),
        ..Default::default()
    };
    for (k, chunk) in c.chunks.iter().enumerate() {
        let base = k * CHUNK;
        let m = CHUNK.min(n - base);
        let (a_first, a_end) = (base / channels, (base + m).div_ceil(channels));
        let q0 = q[a_first..a_end].to_vec();
        let first = torchac_decode_with(chunk, m, lp, |i, j| {
            let g = base + i;
            cdf_entry(mni, j, q0[g / channels - a_first], mean[g], scale[g], lp)
        });
        let ok = reencodes_to(chunk, &first, lp, |i, j| {
            let g = base + i;
            cdf_entry(mni, j, q0[g / channels - a_first], mean[g], scale[g], lp)
        });
        let found = if ok || repair_trials == 0 {
            ok.then(|| (q0.clone(), first.clone()))
        } else {
            let problem = Chunk {
                stream: chunk,
                m,
                base,
                lp,
                mn: mni,
                channels,
                mean,
                scale,
                q,
                q_alt,
                table: None,
            }
            .tabulate();
            problem.search(repair_trials).map(|f| {
                out.repaired.push(k);
                out.q_switched += f.q_switched;
                out.entries_switched += f.entries_switched;
                (f.q, f.syms)
            })
        };
        let verified = found.is_some();
        let (qs, syms) = found.unwrap_or((q0, first));
        out.verified_chunks += verified as usize;
        if !verified {
            out.unverified.push(k);
        }
        for (i, s) in syms.into_iter().enumerate() {
            let g = base + i;
            out.values
                .push((s as f32 + mn) * qs[g / channels - a_first]);
            out.symbols.push(s as i32 + mni);
        }
    }
    Ok(out)
}
