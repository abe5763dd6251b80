//! The page's sparse copy of the file: the byte ranges fetched so far, a `Read + Seek` over
//! them for the decoder (a read of a byte not fetched records the missing range), and the
//! player's methods that feed, trim and query it.

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::io::{self, Read, Seek, SeekFrom};
use std::rc::Rc;

use wasm_bindgen::prelude::*;

use crate::Player;

pub(crate) struct Store {
    pub(crate) len: u64,
    pub(crate) segs: BTreeMap<u64, Vec<u8>>,
    pub(crate) missing: Option<(u64, u64)>,
}

#[derive(Clone)]
pub(crate) struct Sparse {
    pub(crate) store: Rc<RefCell<Store>>,
    pub(crate) pos: u64,
}

impl Read for Sparse {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let mut s = self.store.borrow_mut();
        if buf.is_empty() || self.pos >= s.len {
            return Ok(0);
        }
        let pos = self.pos;
        let hit = s
            .segs
            .range(..=pos)
            .rev()
            .find(|(&start, seg)| start + seg.len() as u64 > pos)
            .map(|(&start, seg)| {
                let from = (pos - start) as usize;
                let n = buf.len().min(seg.len() - from);
                buf[..n].copy_from_slice(&seg[from..from + n]);
                n
            });
        if let Some(n) = hit {
            self.pos += n as u64;
            return Ok(n);
        }
        let end = (pos + buf.len() as u64).min(s.len);
        s.missing = Some((pos, end - pos));
        Err(io::Error::other("dlgs-web: bytes not fetched yet"))
    }
}

impl Seek for Sparse {
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        let len = self.store.borrow().len as i128;
        let p = match to {
            SeekFrom::Start(o) => o as i128,
            SeekFrom::End(o) => len + o as i128,
            SeekFrom::Current(o) => self.pos as i128 + o as i128,
        };
        if p < 0 {
            return Err(io::Error::other("seek before start"));
        }
        self.pos = p as u64;
        Ok(self.pos)
    }
}

#[wasm_bindgen]
impl Player {
    /// Bytes of the file at `offset` (a fetched range).
    pub fn add_bytes(&mut self, offset: f64, bytes: &[u8]) {
        self.store
            .borrow_mut()
            .segs
            .insert(offset as u64, bytes.to_vec());
    }

    /// Forget fetched ranges that lie inside `[offset, offset + len)` (a GOP played and
    /// decoded), to bound memory on long files.
    pub fn drop_bytes(&mut self, offset: f64, len: f64) {
        let (a, b) = (offset as u64, (offset + len) as u64);
        let mut s = self.store.borrow_mut();
        let gone: Vec<u64> = s
            .segs
            .range(a..b)
            .filter(|(&k, v)| k + v.len() as u64 <= b)
            .map(|(&k, _)| k)
            .collect();
        for k in gone {
            s.segs.remove(&k);
        }
    }

    pub fn need_offset(&self) -> f64 {
        self.store.borrow().missing.map_or(0.0, |m| m.0 as f64)
    }
    pub fn need_len(&self) -> f64 {
        self.store.borrow().missing.map_or(0.0, |m| m.1 as f64)
    }
    pub fn fetched_bytes(&self) -> f64 {
        self.store
            .borrow()
            .segs
            .values()
            .map(|v| v.len() as f64)
            .sum()
    }
}
