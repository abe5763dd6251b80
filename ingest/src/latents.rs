//! The reference's GOP residual latents (`offset_compressed.pkl`): a pickle of
//! `{latents: {name: CompressedLatents}, decoder_state_dict: {name: {div, layers.0.scale,
//! layers.0.shift}}, decoder_args: {name: {latent_dim, feature_dim, ldecode_matrix}}}`.
//! A `CompressedLatents` holds integer latents coded with torchac (one float CDF shared by every
//! symbol, 16-bit range coder), a value mapping, and "tail" values stored by position.

use crate::pickle::{self, Id, Obj, Pickle};
use crate::torch::{plain_tensor, DType};
use crate::IngestError;

/// One attribute's residual: `Δ = (round(z) / div) @ scale + shift` per Gaussian.
#[derive(Debug, Clone, PartialEq)]
pub struct LatentResidual {
    /// The pickle key, e.g. `_features_dc_dynamic_offset`.
    pub name: String,
    pub count: usize,
    pub latent_dim: usize,
    pub feature_dim: usize,
    /// `count * latent_dim` integer latents, Gaussian-major.
    pub latents: Vec<i32>,
    pub div: Vec<f32>,
    /// `latent_dim x feature_dim`, row-major (`scale[i][j]`).
    pub scale: Vec<f32>,
    pub shift: Vec<f32>,
}

/// Symbols one file may declare (bounds the decode loop and the output).
const MAX_SYMBOLS: u64 = 1 << 26;

/// torchac's integer CDF from its float CDF: `rint(cdf * (2^16 - (Lp-1))) + s` as u16.
pub fn integer_cdf(cdf: &[f32]) -> Vec<u16> {
    let lp = cdf.len();
    let scale = 65536.0f32 - (lp as f32 - 1.0);
    cdf.iter()
        .enumerate()
        .map(|(s, &c)| {
            let v = (c * scale).round_ties_even();
            // float -> int16 conversion then + s in int16: the wrap only reaches the last entry,
            // which the coder never reads (the top symbol's upper bound is 0x10000).
            ((v as i64 + s as i64) & 0xFFFF) as u16
        })
        .collect()
}

/// Decode `n` symbols of torchac's range coder (precision 16) with one CDF for all.
/// Reads zero bits past the end of `stream`, as torchac does; never panics.
pub fn torchac_decode(cdf: &[u16], stream: &[u8], n: usize) -> Vec<u16> {
    if cdf.is_empty() {
        return vec![0; n];
    }
    torchac_decode_with(stream, n, cdf.len(), |_, s| cdf[s])
}

/// [`torchac_decode`] with a CDF per symbol: `cdf(i, s)` is entry `s < lp` of symbol `i`'s
/// integer CDF (only the entries the decoder reads are asked for). `lp >= 1`.
pub fn torchac_decode_with(
    stream: &[u8],
    n: usize,
    lp: usize,
    mut cdf_at: impl FnMut(usize, usize) -> u16,
) -> Vec<u16> {
    let max_symbol = lp.saturating_sub(2);
    let mut bits = BitReader {
        data: stream,
        pos: 0,
    };
    let mut low: u32 = 0;
    let mut high: u32 = u32::MAX;
    let mut value: u32 = 0;
    for _ in 0..32 {
        value = (value << 1) | bits.next();
    }
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let span = (high as u64).wrapping_sub(low as u64).wrapping_add(1);
        let count = ((value as u64)
            .wrapping_sub(low as u64)
            .wrapping_add(1)
            .wrapping_mul(0x10000)
            .wrapping_sub(1)
            / span.max(1)) as u16;
        // Binary search as torchac: largest s in [0, max_symbol] with cdf[s] <= count.
        let (mut left, mut right) = (0usize, max_symbol + 1);
        let sym = loop {
            if left + 1 >= right {
                break left;
            }
            let m = (left + right) / 2;
            let v = cdf_at(i, m);
            if v < count {
                left = m;
            } else if v > count {
                right = m;
            } else {
                break m;
            }
        };
        out.push(sym as u16);
        if i + 1 == n {
            break;
        }
        let c_low = cdf_at(i, sym) as u64;
        let c_high = if sym == max_symbol {
            0x10000
        } else {
            cdf_at(i, sym + 1) as u64
        };
        high = low
            .wrapping_sub(1)
            .wrapping_add((span.wrapping_mul(c_high) >> 16) as u32);
        low = low.wrapping_add((span.wrapping_mul(c_low) >> 16) as u32);
        loop {
            if low >= 0x8000_0000 || high < 0x8000_0000 {
                low <<= 1;
                high = (high << 1) | 1;
                value = (value << 1) | bits.next();
            } else if low >= 0x4000_0000 && high < 0xC000_0000 {
                low = (low << 1) & 0x7FFF_FFFF;
                high = (high << 1) | 0x8000_0001;
                value = (value.wrapping_sub(0x4000_0000) << 1) | bits.next();
            } else {
                break;
            }
        }
    }
    out
}

struct BitReader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl BitReader<'_> {
    /// Next bit, most significant first; 0 past the end.
    fn next(&mut self) -> u32 {
        let byte = self.pos / 8;
        let bit = if byte < self.data.len() {
            (self.data[byte] >> (7 - self.pos % 8)) as u32 & 1
        } else {
            0
        };
        self.pos = self.pos.saturating_add(1);
        bit
    }
}

/// A NumPy array rebuilt by `numpy.core.multiarray._reconstruct` + `BUILD`: (dtype, shape, bytes).
pub(crate) fn numpy_array(p: &Pickle, id: Id) -> Result<(String, Vec<usize>, Vec<u8>), String> {
    let Obj::Call {
        callable, state, ..
    } = p.get(id)
    else {
        return Err("not a NumPy array".into());
    };
    match p.global_name(*callable) {
        Some((m, "_reconstruct"))
            if m == "numpy.core.multiarray" || m == "numpy._core.multiarray" => {}
        _ => return Err("not a NumPy array".into()),
    }
    let st = p
        .items(state.ok_or("NumPy array without state")?)
        .ok_or("NumPy state is not a tuple")?;
    if st.len() != 5 {
        return Err("NumPy state has another layout".into());
    }
    let shape = p
        .items(st[1])
        .ok_or("NumPy shape")?
        .iter()
        .map(|&i| {
            p.int(i)
                .filter(|&v| v >= 0)
                .map(|v| v as usize)
                .ok_or("NumPy shape entry")
        })
        .collect::<Result<Vec<_>, _>>()?;
    // dtype: numpy.dtype('f4', ...) with state (3, '<', ...)
    let Obj::Call {
        args: dargs,
        state: dstate,
        ..
    } = p.get(st[2])
    else {
        return Err("NumPy dtype".into());
    };
    let code = p
        .items(*dargs)
        .and_then(|a| a.first().copied())
        .and_then(|a| p.str(a))
        .ok_or("NumPy dtype code")?
        .to_string();
    if let Some(ds) = dstate.and_then(|s| p.items(s)) {
        if let Some(order) = ds.get(1).and_then(|&o| p.str(o)) {
            if order == ">" {
                return Err("big-endian NumPy array".into());
            }
        }
    }
    if p.int(st[3]) == Some(1) {
        return Err("Fortran-ordered NumPy array".into());
    }
    let Obj::Bytes(data) = p.get(st[4]) else {
        return Err("NumPy data is not bytes".into());
    };
    Ok((code, shape, data.clone()))
}

fn dict_int(p: &Pickle, d: Id, key: &str, what: &str) -> Result<i64, IngestError> {
    p.dict_get(d, key)
        .and_then(|v| p.int(v))
        .ok_or_else(|| IngestError::format(what, format!("no integer {key}")))
}

/// Decode one `CompressedLatents` object into `count * latent_dim` integers.
fn uncompress(p: &Pickle, obj: Id, what: &str) -> Result<(usize, usize, Vec<i32>), IngestError> {
    let err = |r: String| IngestError::format(what, r);
    let state = match p.get(obj) {
        Obj::Call {
            callable,
            state: Some(s),
            ..
        } if p.global_name(*callable).map(|g| g.1) == Some("CompressedLatents") => *s,
        _ => return Err(err("not a CompressedLatents object".into())),
    };
    let count = dict_int(p, state, "num_latents", what)?;
    let dim = dict_int(p, state, "latent_dim", what)?;
    if count < 0 || !(1..=4096).contains(&dim) {
        return Err(err(format!("{count} latents of dimension {dim}")));
    }
    let n = count as u64 * dim as u64;
    if n > MAX_SYMBOLS {
        return Err(err(format!("{n} latents exceed the limit")));
    }
    let stream = match p.dict_get(state, "byte_stream").map(|b| p.get(b)) {
        Some(Obj::Bytes(b)) => b.as_slice(),
        _ => return Err(err("no byte_stream".into())),
    };
    let (code, shape, cdf_bytes) = numpy_array(
        p,
        p.dict_get(state, "cdf")
            .ok_or_else(|| err("no cdf".into()))?,
    )
    .map_err(|r| err(format!("cdf: {r}")))?;
    if code != "f4"
        || shape.len() != 1
        || shape[0] < 2
        || shape[0] > 65537
        || cdf_bytes.len() != 4 * shape[0]
    {
        return Err(err(format!(
            "cdf is {code} {shape:?}, expected float32 of 2..=65537 entries"
        )));
    }
    let cdf: Vec<f32> = cdf_bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if cdf.iter().any(|c| !c.is_finite()) {
        return Err(err("cdf is not finite".into()));
    }
    // value -> symbol index; inverted for decoding.
    let map = p
        .dict(
            p.dict_get(state, "mapping")
                .ok_or_else(|| err("no mapping".into()))?,
        )
        .ok_or_else(|| err("mapping is not a dict".into()))?;
    let mut inverse = vec![None; cdf.len() - 1];
    for &(k, v) in map {
        let (Some(value), Some(index)) = (p.int(k), p.int(v)) else {
            return Err(err("mapping entries are not integers".into()));
        };
        let slot = usize::try_from(index).ok().and_then(|i| inverse.get_mut(i));
        match (slot, i32::try_from(value)) {
            (Some(s), Ok(v)) => *s = Some(v),
            _ => return Err(err(format!("mapping {value} -> {index} outside the CDF"))),
        }
    }
    let symbols = torchac_decode(&integer_cdf(&cdf), stream, n as usize);
    let mut out = Vec::with_capacity(n as usize);
    for s in symbols {
        match inverse.get(s as usize).copied().flatten() {
            Some(v) => out.push(v),
            None => {
                return Err(err(format!(
                    "decoded symbol {s} has no value in the mapping"
                )))
            }
        }
    }
    let tails = p
        .dict(
            p.dict_get(state, "tail_locs")
                .ok_or_else(|| err("no tail_locs".into()))?,
        )
        .ok_or_else(|| err("tail_locs is not a dict".into()))?;
    for &(k, v) in tails {
        let value = p
            .int(k)
            .and_then(|v| i32::try_from(v).ok())
            .ok_or_else(|| err("tail value".into()))?;
        let t = plain_tensor(p, v).map_err(|r| err(format!("tail positions: {r}")))?;
        if t.dtype != DType::I64 {
            return Err(err("tail positions are not int64".into()));
        }
        for pos in t.i64s(what)? {
            match usize::try_from(pos).ok().filter(|&i| i < out.len()) {
                Some(i) => out[i] = value,
                None => {
                    return Err(err(format!(
                        "tail position {pos} outside {} latents",
                        out.len()
                    )))
                }
            }
        }
    }
    Ok((count as usize, dim as usize, out))
}

/// Read every latent residual of an `offset_compressed.pkl`.
pub fn read(bytes: &[u8], what: &str) -> Result<Vec<LatentResidual>, IngestError> {
    let p = pickle::parse(bytes).map_err(|e| IngestError::format(what, e.to_string()))?;
    let err = |r: String| IngestError::format(what, r);
    let latents = p
        .dict_get(p.root, "latents")
        .ok_or_else(|| err("no latents".into()))?;
    let decoders = p
        .dict_get(p.root, "decoder_state_dict")
        .ok_or_else(|| err("no decoder_state_dict".into()))?;
    let args = p
        .dict_get(p.root, "decoder_args")
        .ok_or_else(|| err("no decoder_args".into()))?;
    let mut out = Vec::new();
    for &(k, v) in p
        .dict(latents)
        .ok_or_else(|| err("latents is not a dict".into()))?
    {
        let name = p
            .str(k)
            .ok_or_else(|| err("latent name is not a string".into()))?
            .to_string();
        let w = format!("{what} {name}");
        let (count, latent_dim, values) = uncompress(&p, v, &w)?;
        let a = p
            .dict_get(args, &name)
            .ok_or_else(|| err(format!("no decoder_args for {name}")))?;
        let feature_dim = dict_int(&p, a, "feature_dim", &w)?;
        if dict_int(&p, a, "latent_dim", &w)? != latent_dim as i64
            || !(1..=4096).contains(&feature_dim)
        {
            return Err(IngestError::shape(
                &w,
                "decoder_args do not match the latents",
            ));
        }
        if let Some(m) = p.dict_get(a, "ldecode_matrix").and_then(|m| p.str(m)) {
            if m.contains("dft") {
                return Err(IngestError::format(
                    &w,
                    format!("ldecode_matrix {m:?} is not supported (only 'learnable')"),
                ));
            }
        }
        let sd = p
            .dict_get(decoders, &name)
            .ok_or_else(|| err(format!("no decoder for {name}")))?;
        let tensor = |key: &str, shape: &[usize]| -> Result<Vec<f32>, IngestError> {
            let id = p
                .dict_get(sd, key)
                .ok_or_else(|| IngestError::format(&w, format!("decoder has no {key}")))?;
            let t =
                plain_tensor(&p, id).map_err(|r| IngestError::format(&w, format!("{key}: {r}")))?;
            if t.shape != shape {
                return Err(IngestError::shape(&w, format!("{key} is {:?}, expected {shape:?} (a decoder with hidden layers is not supported)", t.shape)));
            }
            let v = t.f32s(&w)?;
            crate::check_finite(&format!("{w} {key}"), &v)?;
            Ok(v)
        };
        let feature_dim = feature_dim as usize;
        let div = tensor("div", &[latent_dim])?;
        if div.contains(&0.0) {
            return Err(IngestError::format(&w, "a latent divisor (div) is 0"));
        }
        out.push(LatentResidual {
            div,
            scale: tensor("layers.0.scale", &[latent_dim, feature_dim])?,
            shift: tensor("layers.0.shift", &[1, feature_dim])?,
            name,
            count,
            latent_dim,
            feature_dim,
            latents: values,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_torchac_bytes() {
        // torchac.encode_float_cdf([[0, .3, .9, 1]] * 10, [0,1,2,1,1,0,2,2,1,0]) == 43 37 e0
        let cdf = integer_cdf(&[0.0, 0.3, 0.9, 1.0]);
        assert_eq!(
            torchac_decode(&cdf, &[0x43, 0x37, 0xe0], 10),
            vec![0, 1, 2, 1, 1, 0, 2, 2, 1, 0]
        );
    }

    #[test]
    fn garbage_streams_do_not_panic() {
        let cdf = integer_cdf(&[0.0, 1e-9, 0.5, 0.5, 1.0]);
        let mut rng = fastrand::Rng::with_seed(3);
        for _ in 0..200 {
            let v: Vec<u8> = (0..rng.usize(0..40)).map(|_| rng.u8(..)).collect();
            let s = torchac_decode(&cdf, &v, 100);
            assert!(s.iter().all(|&x| (x as usize) < cdf.len() - 1));
        }
    }
}
