//! The `.b` files of a HAC `bitstreams/` folder. Gaussian-coded streams:
//! `min:f32 | max:f32 | nbytes_cnt:i32 | cnt[nbytes_cnt/4]:i32 | payload`; binary grids:
//! `p:f32 | nbytes_cnt:i32 | cnt[]:i32 | payload`. The payload is one independent torchac
//! stream per [`CHUNK`] symbols, `cnt[k]` bytes each, concatenated.

use std::path::Path;

use crate::latents::{integer_cdf, torchac_decode};
use crate::IngestError;

/// Symbols per independent torchac stream (`chunk_size_cuda`).
pub const CHUNK: usize = 10_000;

/// A parsed `.b` file: its header value(s) and the byte range of each chunk.
#[derive(Debug, Clone, PartialEq)]
pub struct Chunked<'a> {
    /// `(min, max)` of a Gaussian stream, or `(p, p)` of a binary one.
    pub header: (f32, f32),
    pub chunks: Vec<&'a [u8]>,
}

fn le_i32(b: &[u8], at: usize) -> Option<i32> {
    b.get(at..at + 4)
        .map(|s| i32::from_le_bytes([s[0], s[1], s[2], s[3]]))
}

fn le_f32(b: &[u8], at: usize) -> Option<f32> {
    b.get(at..at + 4)
        .map(|s| f32::from_le_bytes([s[0], s[1], s[2], s[3]]))
}

/// Parse a `.b` file holding `n_symbols` symbols (`gaussian`: two header floats, else one).
pub fn parse<'a>(
    bytes: &'a [u8],
    gaussian: bool,
    n_symbols: usize,
    what: &str,
) -> Result<Chunked<'a>, IngestError> {
    let err = |r: String| IngestError::format(what, r);
    let head = if gaussian { 8 } else { 4 };
    let (a, b) = if gaussian {
        (le_f32(bytes, 0), le_f32(bytes, 4))
    } else {
        (le_f32(bytes, 0), le_f32(bytes, 0))
    };
    let (Some(a), Some(b), Some(nb)) = (a, b, le_i32(bytes, head)) else {
        return Err(err(format!("{} bytes: truncated header", bytes.len())));
    };
    if nb < 0 || nb % 4 != 0 {
        return Err(err(format!("chunk table of {nb} bytes")));
    }
    let start = head + 4;
    let table = bytes
        .get(start..start + nb as usize)
        .ok_or_else(|| err(format!("chunk table of {nb} bytes past the end")))?;
    let want = n_symbols.div_ceil(CHUNK);
    if table.len() / 4 != want {
        return Err(err(format!(
            "{} chunks for {n_symbols} symbols (expected {want})",
            table.len() / 4
        )));
    }
    let mut at = start + nb as usize;
    let mut chunks = Vec::with_capacity(want);
    for (k, c) in table.chunks_exact(4).enumerate() {
        let len = i32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        let end = usize::try_from(len)
            .ok()
            .and_then(|l| at.checked_add(l))
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| {
                err(format!(
                    "chunk {k} of {len} bytes overruns the {}-byte payload",
                    bytes.len() - start - nb as usize
                ))
            })?;
        chunks.push(&bytes[at..end]);
        at = end;
    }
    if at != bytes.len() {
        return Err(err(format!(
            "{} bytes after the last chunk",
            bytes.len() - at
        )));
    }
    Ok(Chunked {
        header: (a, b),
        chunks,
    })
}

pub(crate) fn read(path: &Path) -> Result<Vec<u8>, IngestError> {
    std::fs::read(path).map_err(|source| IngestError::Io {
        what: path.display().to_string(),
        source,
    })
}

/// Decode a binary grid file of `n` bits (CDF `[0, 1-p, 1]` for every bit; 1 = +1).
pub fn decode_binary(bytes: &[u8], n: usize, what: &str) -> Result<Vec<bool>, IngestError> {
    let c = parse(bytes, false, n, what)?;
    let p = c.header.0;
    if !(0.0..=1.0).contains(&p) {
        return Err(IngestError::format(what, format!("bit probability {p}")));
    }
    let cdf = integer_cdf(&[0.0, 1.0 - p, 1.0]);
    let mut out = Vec::with_capacity(n);
    for (k, chunk) in c.chunks.iter().enumerate() {
        let m = CHUNK.min(n - k * CHUNK);
        out.extend(torchac_decode(&cdf, chunk, m).into_iter().map(|s| s == 1));
    }
    Ok(out)
}

/// Read and decode a binary grid file.
pub fn read_binary(path: &Path, n: usize) -> Result<Vec<bool>, IngestError> {
    decode_binary(&read(path)?, n, &path.display().to_string())
}
