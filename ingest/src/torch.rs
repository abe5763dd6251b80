//! PyTorch tensors out of `torch.save` files (zip: `<name>/data.pkl` + `<name>/data/<key>`) and
//! out of plain pickles (a tensor pickled by `pickle.dump` carries its storage as a legacy
//! `torch.save` blob: five pickles, then per storage an i64 element count and the raw bytes).
//! Only little-endian, CPU-layout storages are accepted; nothing is executed.

use std::borrow::Cow;
use std::collections::HashMap;
use std::io::{Read, Seek};

use crate::pickle::{self, Id, Obj, Pickle};
use crate::IngestError;

/// Element types the reference writes (float32 parameters, int64 indices).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DType {
    F32,
    F64,
    F16,
    I64,
    I32,
    I16,
    I8,
    U8,
    Bool,
}

impl DType {
    fn from_storage(name: &str) -> Option<Self> {
        Some(match name {
            "FloatStorage" => DType::F32,
            "DoubleStorage" => DType::F64,
            "HalfStorage" => DType::F16,
            "LongStorage" => DType::I64,
            "IntStorage" => DType::I32,
            "ShortStorage" => DType::I16,
            "CharStorage" => DType::I8,
            "ByteStorage" => DType::U8,
            "BoolStorage" => DType::Bool,
            _ => return None,
        })
    }
    pub fn size(self) -> usize {
        match self {
            DType::F64 | DType::I64 => 8,
            DType::F32 | DType::I32 => 4,
            DType::F16 | DType::I16 => 2,
            DType::I8 | DType::U8 | DType::Bool => 1,
        }
    }
}

/// A dense tensor: shape and values in row-major order.
#[derive(Debug, Clone, PartialEq)]
pub struct Tensor {
    pub dtype: DType,
    pub shape: Vec<usize>,
    /// Raw little-endian bytes of the elements in row-major order.
    pub bytes: Vec<u8>,
}

impl Tensor {
    pub fn numel(&self) -> usize {
        self.shape.iter().product()
    }
    /// The values as f32; only float32 tensors convert (what the reference stores).
    pub fn f32s(&self, what: &str) -> Result<Vec<f32>, IngestError> {
        match self.dtype {
            DType::F32 => Ok(self
                .bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect()),
            d => Err(IngestError::shape(
                what,
                format!("dtype {d:?}, expected float32"),
            )),
        }
    }
    /// Integer values (int64/int32/int16/int8/uint8/bool tensors).
    pub fn i64s(&self, what: &str) -> Result<Vec<i64>, IngestError> {
        let b = &self.bytes;
        Ok(match self.dtype {
            DType::I64 => b
                .chunks_exact(8)
                .map(|c| i64::from_le_bytes(c.try_into().expect("8")))
                .collect(),
            DType::I32 => b
                .chunks_exact(4)
                .map(|c| i32::from_le_bytes(c.try_into().expect("4")) as i64)
                .collect(),
            DType::I16 => b
                .chunks_exact(2)
                .map(|c| i16::from_le_bytes([c[0], c[1]]) as i64)
                .collect(),
            DType::I8 => b.iter().map(|&v| v as i8 as i64).collect(),
            DType::U8 | DType::Bool => b.iter().map(|&v| v as i64).collect(),
            d => {
                return Err(IngestError::shape(
                    what,
                    format!("dtype {d:?}, expected integers"),
                ))
            }
        })
    }
}

/// Largest archive entry read (far above the reference's checkpoints).
const MAX_ENTRY: u64 = 1 << 32;

/// Resolves a tensor's storage argument to its element type and bytes.
type StorageOf<'a, 's> = &'a dyn Fn(Id) -> Result<(DType, Cow<'s, [u8]>), String>;

/// Raw storages by key, as found in the file.
type Storages = HashMap<String, (DType, Vec<u8>)>;

/// Build the tensor a `_rebuild_tensor_v2(storage, offset, size, stride, ...)` call describes.
/// `storage_of` maps the call's storage argument to its dtype and bytes.
/// A pickled tuple of ints (a tensor's size or stride).
fn int_tuple(p: &Pickle, id: Id, what: &str) -> Result<Vec<i64>, String> {
    p.items(id)
        .ok_or(format!("{what} is not a tuple"))?
        .iter()
        .map(|&i| p.int(i).ok_or(format!("{what} entry is not an int")))
        .collect()
}

fn rebuild<'s>(p: &Pickle, call_args: Id, storage_of: StorageOf<'_, 's>) -> Result<Tensor, String> {
    let args = p
        .items(call_args)
        .ok_or("tensor arguments are not a tuple")?;
    if args.len() < 4 {
        return Err("tensor arguments too short".into());
    }
    let (dtype, data) = storage_of(args[0])?;
    let data: &[u8] = &data;
    let offset = p.int(args[1]).ok_or("storage offset is not an int")?;
    let size = int_tuple(p, args[2], "size")?;
    let stride = int_tuple(p, args[3], "stride")?;
    if size.len() != stride.len() || size.iter().chain(&stride).any(|&v| v < 0) || offset < 0 {
        return Err("inconsistent size / stride / offset".into());
    }
    let es = dtype.size();
    let elems = data.len() / es;
    let numel = size
        .iter()
        .try_fold(1usize, |a, &s| a.checked_mul(s as usize))
        .ok_or("tensor size overflows")?;
    // A saved tensor never has more elements than its storage: this bounds the allocation
    // and the copy loop by the bytes present (a stride-0 view could claim any size).
    if numel > elems {
        return Err(format!("{numel} elements in a {elems}-element storage"));
    }
    // Largest element index the view touches must lie inside the storage.
    if numel > 0 {
        let last = size
            .iter()
            .zip(&stride)
            .try_fold(offset as u128, |a, (&s, &st)| {
                Some(a + (s as u128 - 1) * st as u128)
            })
            .ok_or("index overflow")?;
        if last >= elems as u128 {
            return Err(format!(
                "view reaches element {last} of a {elems}-element storage"
            ));
        }
    }
    let mut bytes = Vec::with_capacity(numel * es);
    let mut idx = vec![0usize; size.len()];
    for _ in 0..numel {
        let e = offset as usize
            + idx
                .iter()
                .zip(&stride)
                .map(|(&i, &st)| i * st as usize)
                .sum::<usize>();
        bytes.extend_from_slice(&data[e * es..(e + 1) * es]);
        for d in (0..idx.len()).rev() {
            idx[d] += 1;
            if idx[d] < size[d] as usize {
                break;
            }
            idx[d] = 0;
        }
    }
    Ok(Tensor {
        dtype,
        shape: size.iter().map(|&s| s as usize).collect(),
        bytes,
    })
}

/// `('storage', <Global torch.XStorage>, key, location, numel[, view])` → (dtype, key).
fn storage_key(p: &Pickle, pid: Id) -> Result<(DType, String), String> {
    let items = p.items(pid).ok_or("persistent id is not a tuple")?;
    if items.len() < 5 || p.str(items[0]) != Some("storage") {
        return Err("persistent id is not a storage".into());
    }
    let (module, name) = p
        .global_name(items[1])
        .ok_or("storage type is not a class")?;
    if module != "torch" {
        return Err(format!("storage type {module}.{name}"));
    }
    let dtype = DType::from_storage(name).ok_or_else(|| format!("storage type torch.{name}"))?;
    let key = p
        .str(items[2])
        .ok_or("storage key is not a string")?
        .to_string();
    Ok((dtype, key))
}

/// Is `id` a call of one of the tensor rebuild functions? Returns its argument tuple, and for
/// `_rebuild_parameter` the inner tensor call's.
fn tensor_args(p: &Pickle, id: Id) -> Option<Id> {
    let Obj::Call { callable, args, .. } = p.get(id) else {
        return None;
    };
    match p.global_name(*callable)? {
        ("torch._utils", "_rebuild_tensor_v2") | ("torch._utils", "_rebuild_tensor") => Some(*args),
        ("torch._utils", "_rebuild_parameter")
        | ("torch._utils", "_rebuild_parameter_with_state") => {
            let inner = *p.items(*args)?.first()?;
            tensor_args(p, inner)
        }
        _ => None,
    }
}

/// Turn every tensor reachable from a dict into (name, tensor), resolving storages through
/// `storage_of`. Tensors in nested dicts (e.g. the reference's `mlps.pth`, a dict of
/// state_dicts) are named `outer.inner`, as PyTorch flattens them; nesting deeper than 4 is
/// ignored (a pickle may reference itself).
fn named_tensors<'s>(
    p: &Pickle,
    dict: Id,
    nested: bool,
    storage_of: StorageOf<'_, 's>,
) -> Result<Vec<(String, Tensor)>, String> {
    let mut out = Vec::new();
    let depth = if nested { 0 } else { 4 };
    collect_tensors(p, dict, "", depth, storage_of, &mut out)?;
    Ok(out)
}

fn collect_tensors<'s>(
    p: &Pickle,
    dict: Id,
    prefix: &str,
    depth: usize,
    storage_of: StorageOf<'_, 's>,
    out: &mut Vec<(String, Tensor)>,
) -> Result<(), String> {
    let entries = p
        .dict(dict)
        .ok_or("the pickle is not a dict (a state_dict)")?;
    for &(k, v) in entries {
        let Some(name) = p.str(k) else { continue };
        if let Some(args) = tensor_args(p, v) {
            out.push((format!("{prefix}{name}"), rebuild(p, args, storage_of)?));
        } else if depth < 4 && p.dict(v).is_some() {
            collect_tensors(
                p,
                v,
                &format!("{prefix}{name}."),
                depth + 1,
                storage_of,
                out,
            )?;
        }
    }
    Ok(())
}

/// Read a `torch.save` zip file (any tensors at the top level of its dict) from memory.
pub fn read_zip_state_dict<R: Read + Seek>(
    reader: R,
    what: &str,
) -> Result<Vec<(String, Tensor)>, IngestError> {
    read_zip(reader, what, false)
}

/// As [`read_zip_state_dict`], with the tensors of nested dicts too, named `outer.inner` (the
/// reference's HAC `mlps.pth` is a dict of state_dicts and bounds).
pub fn read_zip_nested<R: Read + Seek>(
    reader: R,
    what: &str,
) -> Result<Vec<(String, Tensor)>, IngestError> {
    read_zip(reader, what, true)
}

fn read_zip<R: Read + Seek>(
    reader: R,
    what: &str,
    nested: bool,
) -> Result<Vec<(String, Tensor)>, IngestError> {
    let err = |r: String| IngestError::format(what, r);
    let mut zip = zip::ZipArchive::new(reader).map_err(|e| err(format!("not a torch zip: {e}")))?;
    let pkl_name = (0..zip.len())
        .filter_map(|i| zip.name_for_index(i).map(str::to_string))
        .find(|n| n.ends_with("/data.pkl"))
        .ok_or_else(|| err("no data.pkl in the archive".into()))?;
    let prefix = pkl_name.trim_end_matches("data.pkl").to_string();
    let mut pkl = Vec::new();
    read_entry(&mut zip, &pkl_name, &mut pkl).map_err(err)?;
    if let Some(order) = read_entry_string(&mut zip, &format!("{prefix}byteorder")) {
        if order.trim() != "little" {
            return Err(err(format!("byte order {order:?}")));
        }
    }
    let p = pickle::parse(&pkl).map_err(|e| err(e.to_string()))?;
    // Load each referenced storage once.
    let mut storages: Storages = HashMap::new();
    for o in &p.objects {
        if let Obj::Persistent(pid) = o {
            let (dtype, key) = storage_key(&p, *pid).map_err(err)?;
            if let std::collections::hash_map::Entry::Vacant(e) = storages.entry(key.clone()) {
                let mut bytes = Vec::new();
                read_entry(&mut zip, &format!("{prefix}data/{key}"), &mut bytes).map_err(err)?;
                e.insert((dtype, bytes));
            }
        }
    }
    let storage_of = |id: Id| -> Result<(DType, Cow<'_, [u8]>), String> {
        let Obj::Persistent(pid) = p.get(id) else {
            return Err("tensor storage is not a persistent id".into());
        };
        let (_, key) = storage_key(&p, *pid)?;
        let (dt, b) = storages.get(&key).ok_or("storage not loaded")?;
        Ok((*dt, Cow::Borrowed(b.as_slice())))
    };
    named_tensors(&p, p.root, nested, &storage_of).map_err(err)
}

fn read_entry<R: Read + Seek>(
    zip: &mut zip::ZipArchive<R>,
    name: &str,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let mut f = zip
        .by_name(name)
        .map_err(|e| format!("archive entry {name}: {e}"))?;
    // Grows with the bytes actually read (a declared size is not trusted), capped.
    (&mut f)
        .take(MAX_ENTRY)
        .read_to_end(out)
        .map_err(|e| format!("archive entry {name}: {e}"))?;
    Ok(())
}

fn read_entry_string<R: Read + Seek>(zip: &mut zip::ZipArchive<R>, name: &str) -> Option<String> {
    let mut v = Vec::new();
    read_entry(zip, name, &mut v).ok()?;
    String::from_utf8(v).ok()
}

/// The storage inside a legacy `torch.save` blob (what `TypedStorage.__reduce__` pickles):
/// returns (dtype, bytes) of its one storage.
pub fn legacy_storage(blob: &[u8]) -> Result<(DType, Vec<u8>), String> {
    let mut at = 0usize;
    // magic number, protocol version, sys_info
    for what in ["magic", "protocol", "sys_info"] {
        let p = pickle::parse(&blob[at..]).map_err(|e| format!("legacy {what}: {e}"))?;
        if what == "sys_info" {
            if let Some(le) = p.dict_get(p.root, "little_endian") {
                if p.int(le) != Some(1) {
                    return Err("big-endian storage".into());
                }
            }
        }
        at += p.consumed;
    }
    let obj = pickle::parse(&blob[at..]).map_err(|e| format!("legacy object: {e}"))?;
    at += obj.consumed;
    let Obj::Persistent(pid) = obj.get(obj.root) else {
        return Err("legacy blob does not hold a storage".into());
    };
    let (dtype, key) = storage_key(&obj, *pid)?;
    let keys = pickle::parse(&blob[at..]).map_err(|e| format!("legacy keys: {e}"))?;
    at += keys.consumed;
    let key_list = keys.items(keys.root).ok_or("legacy keys are not a list")?;
    if key_list.len() != 1 || keys.str(key_list[0]) != Some(key.as_str()) {
        return Err("legacy blob holds other storages".into());
    }
    if blob.len() - at < 8 {
        return Err("legacy storage size missing".into());
    }
    let n = u64::from_le_bytes(blob[at..at + 8].try_into().expect("8"));
    at += 8;
    let len = (n as u128) * dtype.size() as u128;
    if len > (blob.len() - at) as u128 {
        return Err(format!(
            "legacy storage declares {n} elements, {} bytes present",
            blob.len() - at
        ));
    }
    Ok((dtype, blob[at..at + len as usize].to_vec()))
}

/// A tensor pickled by `pickle.dump` (storage through `torch.storage._load_from_bytes`).
pub fn plain_tensor(p: &Pickle, id: Id) -> Result<Tensor, String> {
    let args = tensor_args(p, id).ok_or("not a tensor")?;
    let storage_of = |sid: Id| -> Result<(DType, Cow<'_, [u8]>), String> {
        let blob = match p.get(sid) {
            Obj::Call {
                callable,
                args: blob_args,
                ..
            } if p.is_global(*callable, "torch.storage", "_load_from_bytes") => p
                .items(*blob_args)
                .and_then(|a| a.first().copied())
                .and_then(|b| match p.get(b) {
                    Obj::Bytes(b) => Some(b.as_slice()),
                    _ => None,
                })
                .ok_or("storage bytes missing")?,
            _ => return Err("tensor storage is not rebuilt from bytes".into()),
        };
        let (dt, bytes) = legacy_storage(blob)?;
        Ok((dt, Cow::Owned(bytes)))
    };
    rebuild(p, args, &storage_of)
}
