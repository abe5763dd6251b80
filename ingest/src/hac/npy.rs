//! The two NumPy files of a HAC `bitstreams/` folder: `anchor.npy` (uint16 (N, 3), the
//! quantised anchor positions) and `patched_infos.npy` (a pickled object array
//! `[N_static, N_full, N, batch, x_bound_max (1,3) f32, x_bound_min (1,3) f32]`).

use std::path::Path;

use crate::latents::numpy_array;
use crate::pickle::{self, Id, Obj, Pickle};
use crate::IngestError;

/// A parsed `.npy` header and where its data starts.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyHeader {
    pub descr: String,
    pub fortran_order: bool,
    pub shape: Vec<usize>,
    pub data_offset: usize,
}

/// What `patched_infos.npy` holds.
#[derive(Debug, Clone, PartialEq)]
pub struct PatchedInfos {
    pub n_static: usize,
    pub n_full: usize,
    pub n_anchor: usize,
    /// Anchors per coded batch (`MAX_batch_size`).
    pub batch: usize,
    pub x_bound_max: [f32; 3],
    pub x_bound_min: [f32; 3],
}

fn read_file(path: &Path) -> Result<Vec<u8>, IngestError> {
    std::fs::read(path).map_err(|source| IngestError::Io {
        what: path.display().to_string(),
        source,
    })
}

/// Parse the header of a `.npy` file (versions 1-3).
pub fn parse_header(bytes: &[u8], what: &str) -> Result<NpyHeader, IngestError> {
    let err = |r: &str| IngestError::format(what, format!("npy header: {r}"));
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(err("no NUMPY magic"));
    }
    let (len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10usize),
        2 | 3 => {
            let b = bytes.get(8..12).ok_or_else(|| err("truncated"))?;
            (u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize, 12)
        }
        v => return Err(err(&format!("version {v}"))),
    };
    let end = start.checked_add(len).filter(|&e| e <= bytes.len());
    let text = end
        .and_then(|e| std::str::from_utf8(&bytes[start..e]).ok())
        .ok_or_else(|| err("truncated or not text"))?;
    let field = |key: &str| -> Result<&str, IngestError> {
        let k = format!("'{key}':");
        let at = text.find(&k).ok_or_else(|| err(&format!("no {key}")))?;
        Ok(text[at + k.len()..].trim_start())
    };
    let d = field("descr")?;
    let descr = d
        .strip_prefix('\'')
        .and_then(|r| r.split('\'').next())
        .ok_or_else(|| err("descr"))?
        .to_string();
    let fortran_order = field("fortran_order")?.starts_with("True");
    let s = field("shape")?;
    let inner = s
        .strip_prefix('(')
        .and_then(|r| r.split(')').next())
        .ok_or_else(|| err("shape"))?;
    let shape = inner
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| t.parse::<usize>().map_err(|_| err("shape entry")))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(NpyHeader {
        descr,
        fortran_order,
        shape,
        data_offset: start + len,
    })
}

/// `anchor.npy`: `(N, 3)` uint16, C order.
pub fn parse_anchor_npy(bytes: &[u8], what: &str) -> Result<Vec<[u16; 3]>, IngestError> {
    let h = parse_header(bytes, what)?;
    if h.descr != "<u2" || h.fortran_order {
        return Err(IngestError::format(
            what,
            format!("expected little-endian uint16 in C order, not {}", h.descr),
        ));
    }
    if h.shape.len() != 2 || h.shape[1] != 3 {
        return Err(IngestError::shape(
            what,
            format!("{:?}, not (N, 3)", h.shape),
        ));
    }
    let n = h.shape[0];
    let data = &bytes[h.data_offset..];
    if Some(data.len()) != n.checked_mul(6) {
        return Err(IngestError::shape(
            what,
            format!("{} data bytes for {n} anchors", data.len()),
        ));
    }
    Ok(data
        .chunks_exact(6)
        .map(|c| {
            [
                u16::from_le_bytes([c[0], c[1]]),
                u16::from_le_bytes([c[2], c[3]]),
                u16::from_le_bytes([c[4], c[5]]),
            ]
        })
        .collect())
}

/// Read `anchor.npy`.
pub fn read_anchor_npy(path: &Path) -> Result<Vec<[u16; 3]>, IngestError> {
    parse_anchor_npy(&read_file(path)?, &path.display().to_string())
}

/// A Python int, a NumPy integer scalar (`numpy.core.multiarray.scalar(dtype, bytes)`) or a
/// 0-d/one-element integer array.
fn int_like(p: &Pickle, id: Id) -> Option<i64> {
    if let Some(v) = p.int(id) {
        return Some(v);
    }
    let Obj::Call { callable, args, .. } = p.get(id) else {
        return None;
    };
    match p.global_name(*callable) {
        Some((_, "scalar")) => {
            let a = p.items(*args)?;
            let Obj::Bytes(b) = p.get(*a.get(1)?) else {
                return None;
            };
            match b.len() {
                8 => Some(i64::from_le_bytes(b.as_slice().try_into().ok()?)),
                4 => Some(i32::from_le_bytes(b.as_slice().try_into().ok()?) as i64),
                _ => None,
            }
        }
        _ => {
            let (code, shape, data) = numpy_array(p, id).ok()?;
            if shape.iter().product::<usize>() != 1 {
                return None;
            }
            match (code.as_str(), data.len()) {
                ("i8", 8) => Some(i64::from_le_bytes(data.as_slice().try_into().ok()?)),
                ("i4", 4) => Some(i32::from_le_bytes(data.as_slice().try_into().ok()?) as i64),
                _ => None,
            }
        }
    }
}

/// A float32 array of 3 values (shape (1,3) or (3,)).
fn bound3(p: &Pickle, id: Id) -> Result<[f32; 3], String> {
    let (code, shape, data) = numpy_array(p, id)?;
    if code != "f4" || shape.iter().product::<usize>() != 3 || data.len() != 12 {
        return Err(format!("bound is {code} {shape:?}, not 3 float32"));
    }
    let v: Vec<f32> = data
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if v.iter().any(|x| !x.is_finite()) {
        return Err("bound is not finite".into());
    }
    Ok([v[0], v[1], v[2]])
}

/// Parse `patched_infos.npy`.
pub fn parse_patched_infos(bytes: &[u8], what: &str) -> Result<PatchedInfos, IngestError> {
    let h = parse_header(bytes, what)?;
    if h.descr != "|O" {
        return Err(IngestError::format(
            what,
            format!("expected an object array, not {}", h.descr),
        ));
    }
    if h.shape != [6] {
        return Err(IngestError::shape(what, format!("{:?}, not (6,)", h.shape)));
    }
    let p = pickle::parse(&bytes[h.data_offset..])
        .map_err(|e| IngestError::format(what, e.to_string()))?;
    let err = |r: &str| IngestError::format(what, r.to_string());
    let Obj::Call { state, .. } = p.get(p.root) else {
        return Err(err("the pickle is not a NumPy array"));
    };
    let st = state
        .and_then(|s| p.items(s))
        .filter(|s| s.len() == 5)
        .ok_or_else(|| err("NumPy array state"))?;
    let items = p
        .items(st[4])
        .filter(|i| i.len() == 6)
        .ok_or_else(|| err("not 6 objects"))?;
    let count = |k: usize, name: &str| -> Result<usize, IngestError> {
        int_like(&p, items[k])
            .filter(|&v| (0..=(1 << 31)).contains(&v))
            .map(|v| v as usize)
            .ok_or_else(|| err(&format!("{name} is not a count")))
    };
    let out = PatchedInfos {
        n_static: count(0, "N_static")?,
        n_full: count(1, "N_full")?,
        n_anchor: count(2, "N")?,
        batch: count(3, "batch size")?,
        x_bound_max: bound3(&p, items[4]).map_err(|r| err(&r))?,
        x_bound_min: bound3(&p, items[5]).map_err(|r| err(&r))?,
    };
    if out.batch == 0 || out.n_static > out.n_anchor {
        return Err(err("batch size 0 or more static anchors than anchors"));
    }
    Ok(out)
}

/// Read `patched_infos.npy`.
pub fn read_patched_infos(path: &Path) -> Result<PatchedInfos, IngestError> {
    parse_patched_infos(&read_file(path)?, &path.display().to_string())
}
