//! A bounded reader for Python pickles (protocols 2-5), enough for what PyTorch and NumPy write:
//! `torch.save` state dicts, and plain `pickle.dump` files holding tensors, NumPy arrays and
//! objects. Nothing is executed: `GLOBAL`, `REDUCE`, `NEWOBJ` and `BUILD` only record what the
//! pickle asks for, and the caller interprets the few callables it knows
//! (`torch._utils._rebuild_tensor_v2`, `numpy.core.multiarray._reconstruct`, ...).
//!
//! Why not a crate: `serde-pickle` drops the arguments of unknown callables (so tensors cannot be
//! rebuilt) and has no persistent IDs; the other readers are either unmaintained or part of an
//! ML framework. This one keeps every object in an arena, so each opcode creates at most one
//! object, memo references share instead of copying, and memory is bounded by the input size.

use std::collections::HashMap;

/// Index of an object in [`Pickle::objects`].
pub type Id = usize;

/// One unpickled object.
#[derive(Debug, Clone, PartialEq)]
pub enum Obj {
    None,
    Bool(bool),
    Int(i64),
    /// An integer too large for i64 (two's complement little-endian bytes, as `LONG1`).
    BigInt(Vec<u8>),
    Float(f64),
    Str(String),
    Bytes(Vec<u8>),
    Tuple(Vec<Id>),
    List(Vec<Id>),
    Dict(Vec<(Id, Id)>),
    /// `module.name`, not resolved.
    Global {
        module: String,
        name: String,
    },
    /// `callable(*args)`, not called; `state` is what a later `BUILD` set.
    Call {
        callable: Id,
        args: Id,
        state: Option<Id>,
    },
    /// A persistent ID (`torch.save` uses them for storages).
    Persistent(Id),
}

/// What went wrong, and at which byte of the pickle.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("pickle: {reason} at byte {offset}")]
pub struct PickleError {
    pub reason: String,
    pub offset: usize,
}

/// A parsed pickle: its objects and the one the pickle returned.
#[derive(Debug, Clone)]
pub struct Pickle {
    pub objects: Vec<Obj>,
    pub root: Id,
    /// Bytes of the input the pickle used (up to and including `STOP`).
    pub consumed: usize,
}

/// Protocol versions accepted (`PROTO` opcode).
const MAX_PROTOCOL: u8 = 5;
/// Nesting/stack bound: far above what state dicts need, far below what exhausts memory.
const MAX_STACK: usize = 1 << 20;

struct Vm<'a> {
    data: &'a [u8],
    pos: usize,
    op_at: usize,
    objects: Vec<Obj>,
    stack: Vec<Id>,
    marks: Vec<usize>,
    memo: HashMap<u32, Id>,
}

impl<'a> Vm<'a> {
    fn err<T>(&self, reason: impl Into<String>) -> Result<T, PickleError> {
        Err(PickleError {
            reason: reason.into(),
            offset: self.op_at,
        })
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], PickleError> {
        if self.data.len() - self.pos < n {
            return self.err(format!(
                "truncated: needs {n} bytes, {} left",
                self.data.len() - self.pos
            ));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u8(&mut self) -> Result<u8, PickleError> {
        Ok(self.take(1)?[0])
    }
    fn u16(&mut self) -> Result<u16, PickleError> {
        let b = self.take(2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }
    fn u32(&mut self) -> Result<u32, PickleError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn u64(&mut self) -> Result<u64, PickleError> {
        let b = self.take(8)?;
        Ok(u64::from_le_bytes(b.try_into().expect("8 bytes")))
    }
    fn line(&mut self) -> Result<&'a str, PickleError> {
        let rest = &self.data[self.pos..];
        let Some(n) = rest.iter().position(|&b| b == b'\n') else {
            return self.err("unterminated text line");
        };
        self.pos += n + 1;
        std::str::from_utf8(&rest[..n]).or_else(|_| self.err("text line is not UTF-8"))
    }
    fn utf8(&mut self, n: usize) -> Result<String, PickleError> {
        let b = self.take(n)?;
        String::from_utf8(b.to_vec()).or_else(|_| self.err("string is not UTF-8"))
    }
    fn push_obj(&mut self, o: Obj) -> Result<(), PickleError> {
        let id = self.objects.len();
        self.objects.push(o);
        self.push(id)
    }
    fn push(&mut self, id: Id) -> Result<(), PickleError> {
        if self.stack.len() >= MAX_STACK {
            return self.err("stack too deep");
        }
        self.stack.push(id);
        Ok(())
    }
    fn pop(&mut self) -> Result<Id, PickleError> {
        let floor = self.marks.last().copied().unwrap_or(0);
        if self.stack.len() <= floor {
            return self.err("stack underflow");
        }
        Ok(self.stack.pop().expect("checked"))
    }
    fn top(&self) -> Result<Id, PickleError> {
        match self.stack.last() {
            Some(&id) if self.stack.len() > self.marks.last().copied().unwrap_or(0) => Ok(id),
            _ => self.err("stack underflow"),
        }
    }
    fn pop_mark(&mut self) -> Result<Vec<Id>, PickleError> {
        let Some(m) = self.marks.pop() else {
            return self.err("no mark");
        };
        Ok(self.stack.split_off(m))
    }
    fn memo_put(&mut self, key: u32) -> Result<(), PickleError> {
        let id = self.top()?;
        self.memo.insert(key, id);
        Ok(())
    }
    fn memo_get(&mut self, key: u32) -> Result<(), PickleError> {
        match self.memo.get(&key) {
            Some(&id) => self.push(id),
            None => self.err(format!("memo key {key} not set")),
        }
    }
    fn int_bytes(&mut self, b: &[u8]) -> Result<(), PickleError> {
        // LONG1/LONG4: little-endian two's complement.
        if b.is_empty() {
            return self.push_obj(Obj::Int(0));
        }
        if b.len() <= 8 {
            let neg = b[b.len() - 1] & 0x80 != 0;
            let mut buf = [if neg { 0xFF } else { 0 }; 8];
            buf[..b.len()].copy_from_slice(b);
            return self.push_obj(Obj::Int(i64::from_le_bytes(buf)));
        }
        self.push_obj(Obj::BigInt(b.to_vec()))
    }
    fn append_to(&mut self, target: Id, items: Vec<Id>) -> Result<(), PickleError> {
        match &mut self.objects[target] {
            Obj::List(v) => {
                v.extend(items);
                Ok(())
            }
            // `set`/`collections.deque` etc. built by a call: keep the items as its state.
            _ => self.err("APPEND(S) to an object that is not a list"),
        }
    }
    fn set_items(&mut self, target: Id, items: Vec<Id>) -> Result<(), PickleError> {
        if !items.len().is_multiple_of(2) {
            return self.err("SETITEMS with an odd number of items");
        }
        let pairs: Vec<(Id, Id)> = items.chunks_exact(2).map(|p| (p[0], p[1])).collect();
        match &mut self.objects[target] {
            Obj::Dict(v) => {
                v.extend(pairs);
                Ok(())
            }
            // `collections.OrderedDict()` (a REDUCE) receives its items through SETITEMS too:
            // turn it into a plain dict, which is what an OrderedDict's content is.
            Obj::Call { .. } => {
                self.objects[target] = Obj::Dict(pairs);
                Ok(())
            }
            _ => self.err("SETITEM(S) on an object that is not a dict"),
        }
    }

    fn run(&mut self) -> Result<Id, PickleError> {
        loop {
            self.op_at = self.pos;
            let op = self.u8()?;
            match op {
                0x80 => {
                    // PROTO
                    let v = self.u8()?;
                    if v > MAX_PROTOCOL {
                        return self.err(format!("unsupported protocol {v}"));
                    }
                }
                0x95 => {
                    // FRAME: a length hint only.
                    self.u64()?;
                }
                b'.' => return self.pop(), // STOP
                b'(' => self.marks.push(self.stack.len()),
                b'0' => {
                    self.pop()?;
                }
                b'1' => {
                    self.pop_mark()?;
                }
                b'2' => {
                    let t = self.top()?;
                    self.push(t)?;
                }
                b'N' => self.push_obj(Obj::None)?,
                0x88 => self.push_obj(Obj::Bool(true))?,
                0x89 => self.push_obj(Obj::Bool(false))?,
                b'J' => {
                    let v = self.u32()? as i32;
                    self.push_obj(Obj::Int(v as i64))?
                }
                b'K' => {
                    let v = self.u8()?;
                    self.push_obj(Obj::Int(v as i64))?
                }
                b'M' => {
                    let v = self.u16()?;
                    self.push_obj(Obj::Int(v as i64))?
                }
                0x8a => {
                    // LONG1
                    let n = self.u8()? as usize;
                    let b = self.take(n)?;
                    self.int_bytes(b)?
                }
                0x8b => {
                    // LONG4
                    let n = self.u32()? as usize;
                    let b = self.take(n)?;
                    self.int_bytes(b)?
                }
                b'I' => {
                    // INT (protocol 0 text), also True/False as "01"/"00".
                    let l = self.line()?.trim().to_string();
                    let o = match l.as_str() {
                        "01" => Obj::Bool(true),
                        "00" => Obj::Bool(false),
                        s => match s.parse::<i64>() {
                            Ok(v) => Obj::Int(v),
                            Err(_) => return self.err(format!("bad INT {s:?}")),
                        },
                    };
                    self.push_obj(o)?
                }
                b'G' => {
                    let b = self.take(8)?;
                    let v = f64::from_be_bytes(b.try_into().expect("8 bytes"));
                    self.push_obj(Obj::Float(v))?
                }
                b'X' => {
                    let n = self.u32()? as usize;
                    let s = self.utf8(n)?;
                    self.push_obj(Obj::Str(s))?
                }
                0x8c => {
                    let n = self.u8()? as usize;
                    let s = self.utf8(n)?;
                    self.push_obj(Obj::Str(s))?
                }
                0x8d => {
                    let n = self.u64()?;
                    let n = usize::try_from(n).or_else(|_| self.err("string too long"))?;
                    let s = self.utf8(n)?;
                    self.push_obj(Obj::Str(s))?
                }
                b'B' => {
                    let n = self.u32()? as usize;
                    let b = self.take(n)?.to_vec();
                    self.push_obj(Obj::Bytes(b))?
                }
                b'C' => {
                    let n = self.u8()? as usize;
                    let b = self.take(n)?.to_vec();
                    self.push_obj(Obj::Bytes(b))?
                }
                0x8e | 0x96 => {
                    // BINBYTES8, BYTEARRAY8
                    let n = self.u64()?;
                    let n = usize::try_from(n).or_else(|_| self.err("bytes too long"))?;
                    let b = self.take(n)?.to_vec();
                    self.push_obj(Obj::Bytes(b))?
                }
                b')' => self.push_obj(Obj::Tuple(vec![]))?,
                b't' => {
                    let items = self.pop_mark()?;
                    self.push_obj(Obj::Tuple(items))?
                }
                0x85..=0x87 => {
                    let n = (op - 0x84) as usize;
                    let mut items = Vec::with_capacity(n);
                    for _ in 0..n {
                        items.push(self.pop()?);
                    }
                    items.reverse();
                    self.push_obj(Obj::Tuple(items))?
                }
                b']' => self.push_obj(Obj::List(vec![]))?,
                b'l' => {
                    let items = self.pop_mark()?;
                    self.push_obj(Obj::List(items))?
                }
                b'}' => self.push_obj(Obj::Dict(vec![]))?,
                b'd' => {
                    let items = self.pop_mark()?;
                    if !items.len().is_multiple_of(2) {
                        return self.err("DICT with an odd number of items");
                    }
                    let pairs = items.chunks_exact(2).map(|p| (p[0], p[1])).collect();
                    self.push_obj(Obj::Dict(pairs))?
                }
                0x8f => self.push_obj(Obj::List(vec![]))?, // EMPTY_SET (items kept as a list)
                0x90 => {
                    // ADDITEMS
                    let items = self.pop_mark()?;
                    let t = self.top()?;
                    self.append_to(t, items)?
                }
                0x91 => {
                    // FROZENSET
                    let items = self.pop_mark()?;
                    self.push_obj(Obj::List(items))?
                }
                b'a' => {
                    let v = self.pop()?;
                    let t = self.top()?;
                    self.append_to(t, vec![v])?
                }
                b'e' => {
                    let items = self.pop_mark()?;
                    let t = self.top()?;
                    self.append_to(t, items)?
                }
                b's' => {
                    let v = self.pop()?;
                    let k = self.pop()?;
                    let t = self.top()?;
                    self.set_items(t, vec![k, v])?
                }
                b'u' => {
                    let items = self.pop_mark()?;
                    let t = self.top()?;
                    self.set_items(t, items)?
                }
                b'c' => {
                    let module = self.line()?.to_string();
                    let name = self.line()?.to_string();
                    self.push_obj(Obj::Global { module, name })?
                }
                0x93 => {
                    // STACK_GLOBAL
                    let name = self.pop()?;
                    let module = self.pop()?;
                    match (&self.objects[module], &self.objects[name]) {
                        (Obj::Str(m), Obj::Str(n)) => {
                            let o = Obj::Global {
                                module: m.clone(),
                                name: n.clone(),
                            };
                            self.push_obj(o)?
                        }
                        _ => return self.err("STACK_GLOBAL needs two strings"),
                    }
                }
                b'R' | 0x81 => {
                    // REDUCE, NEWOBJ
                    let args = self.pop()?;
                    let callable = self.pop()?;
                    self.push_obj(Obj::Call {
                        callable,
                        args,
                        state: None,
                    })?
                }
                0x92 => {
                    // NEWOBJ_EX: cls, args, kwargs (kwargs dropped: nothing we read uses them)
                    let _kwargs = self.pop()?;
                    let args = self.pop()?;
                    let callable = self.pop()?;
                    self.push_obj(Obj::Call {
                        callable,
                        args,
                        state: None,
                    })?
                }
                b'b' => {
                    // BUILD
                    let st = self.pop()?;
                    let t = self.top()?;
                    match &mut self.objects[t] {
                        Obj::Call { state, .. } => *state = Some(st),
                        // BUILD on a dict (OrderedDict with attributes such as `_metadata`):
                        // the attributes are not content, drop them.
                        Obj::Dict(_) => {}
                        _ => return self.err("BUILD on an object that was not constructed"),
                    }
                }
                b'Q' => {
                    // BINPERSID
                    let pid = self.pop()?;
                    self.push_obj(Obj::Persistent(pid))?
                }
                b'q' => {
                    let k = self.u8()? as u32;
                    self.memo_put(k)?
                }
                b'r' => {
                    let k = self.u32()?;
                    self.memo_put(k)?
                }
                0x94 => {
                    // MEMOIZE
                    let k = self.memo.len() as u32;
                    self.memo_put(k)?
                }
                b'h' => {
                    let k = self.u8()? as u32;
                    self.memo_get(k)?
                }
                b'j' => {
                    let k = self.u32()?;
                    self.memo_get(k)?
                }
                0x97 => {
                    // NEXT_BUFFER: out-of-band buffers are never written to files.
                    return self.err("out-of-band buffer (NEXT_BUFFER)");
                }
                0x98 => {} // READONLY_BUFFER: no-op on the value
                other => return self.err(format!("unsupported opcode {other:#04x}")),
            }
        }
    }
}

/// Parse one pickle from the start of `data` (which may continue after `STOP`).
pub fn parse(data: &[u8]) -> Result<Pickle, PickleError> {
    let mut vm = Vm {
        data,
        pos: 0,
        op_at: 0,
        objects: Vec::new(),
        stack: Vec::new(),
        marks: Vec::new(),
        memo: HashMap::new(),
    };
    let root = vm.run()?;
    Ok(Pickle {
        objects: vm.objects,
        root,
        consumed: vm.pos,
    })
}

impl Pickle {
    pub fn get(&self, id: Id) -> &Obj {
        &self.objects[id]
    }
    /// The string of a `Str` object.
    pub fn str(&self, id: Id) -> Option<&str> {
        match self.get(id) {
            Obj::Str(s) => Some(s),
            _ => None,
        }
    }
    pub fn int(&self, id: Id) -> Option<i64> {
        match self.get(id) {
            Obj::Int(v) => Some(*v),
            Obj::Bool(b) => Some(*b as i64),
            _ => None,
        }
    }
    /// Items of a tuple or list.
    pub fn items(&self, id: Id) -> Option<&[Id]> {
        match self.get(id) {
            Obj::Tuple(v) | Obj::List(v) => Some(v),
            _ => None,
        }
    }
    /// Entries of a dict (plain or ordered), in pickle order.
    pub fn dict(&self, id: Id) -> Option<&[(Id, Id)]> {
        match self.get(id) {
            Obj::Dict(v) => Some(v),
            // An OrderedDict that received no items is still a call of `OrderedDict()`.
            Obj::Call { callable, .. }
                if self.is_global(*callable, "collections", "OrderedDict") =>
            {
                Some(&[])
            }
            _ => None,
        }
    }
    /// The value of the dict entry whose key is the string `key`.
    pub fn dict_get(&self, id: Id, key: &str) -> Option<Id> {
        self.dict(id)?
            .iter()
            .find(|(k, _)| self.str(*k) == Some(key))
            .map(|&(_, v)| v)
    }
    pub fn is_global(&self, id: Id, module: &str, name: &str) -> bool {
        matches!(self.get(id), Obj::Global { module: m, name: n } if m == module && n == name)
    }
    /// `module.name` of a global.
    pub fn global_name(&self, id: Id) -> Option<(&str, &str)> {
        match self.get(id) {
            Obj::Global { module, name } => Some((module, name)),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests;
