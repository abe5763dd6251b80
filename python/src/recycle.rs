//! The arrays of earlier merged frames, decoded into again once Python has let go of them:
//! `frame(t)` then writes the next frame into warm memory numpy already owns (the static rows
//! copied, the dynamic rows decoded in place) instead of new buffers, the merged layout's
//! only cost over the decoder's own `frame_at`.
//!
//! A set is reused only when nothing but this cache can reach its memory: every array (the
//! `(N, ...)` view handed out), the 1-D array it views and the buffer owner below that have
//! no other reference (numpy collapses views of views onto the 1-D array, so a view a user
//! kept shows up there). The last [`KEEP`] sets are kept (a loop `f = r.frame(t)` still holds
//! the previous frame while the next is decoded).

use std::collections::VecDeque;
use std::sync::Mutex;

use numpy::{PyArrayDyn, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use dlgs_decoder::{FrameOptions, FrameSlices};

use crate::errors::{IntoPy, Res};
use crate::reader::Reader;

/// Sets of arrays kept for reuse.
const KEEP: usize = 2;

/// The keys of a merged frame dict, in the order of `dlgs_decoder::FrameSlices`.
pub const KEYS: [&str; 7] = [
    "positions",
    "log_scales",
    "rotations",
    "opacities",
    "lang_opacities",
    "sh",
    "lang_features",
];

#[derive(Default)]
pub struct Recycler {
    sets: Mutex<VecDeque<Vec<Option<Py<PyAny>>>>>,
}

/// Whether only this cache (one reference to `a`) reaches `a`'s memory.
fn only_ours(py: Python<'_>, a: &Py<PyAny>) -> bool {
    if a.get_refcnt(py) != 1 {
        return false;
    }
    // Down the `base` chain to the buffer's owner: each base is held once by the array above
    // it and once by our `Bound`.
    let mut obj = a.bind(py).clone();
    while obj.downcast::<numpy::PyUntypedArray>().is_ok() {
        match obj.getattr("base") {
            Ok(b) if b.is_none() => return true,
            Ok(b) if b.get_refcnt() == 2 => obj = b,
            _ => return false,
        }
    }
    true
}

impl Recycler {
    /// Keep the arrays of `d` (a merged frame just handed out).
    pub fn remember(&self, d: &Bound<'_, PyDict>) -> Res<()> {
        let mut set = Vec::with_capacity(KEYS.len());
        for k in KEYS {
            set.push(d.get_item(k)?.map(|a| a.unbind()));
        }
        let mut sets = self.sets.lock().unwrap_or_else(|e| e.into_inner());
        sets.push_back(set);
        while sets.len() > KEEP {
            sets.pop_front();
        }
        Ok(())
    }

    /// A kept set Python no longer reaches, taken out of the cache.
    pub fn take_free(&self, py: Python<'_>) -> Option<Vec<Option<Py<PyAny>>>> {
        let mut sets = self.sets.lock().unwrap_or_else(|e| e.into_inner());
        let i = sets
            .iter()
            .position(|s| s.iter().flatten().all(|a| only_ours(py, a)))?;
        sets.remove(i)
    }
}

/// `a` as a writable float32 array (`None` if the user made it read-only, or changed it so).
pub fn writable<'py>(
    py: Python<'py>,
    a: &Option<Py<PyAny>>,
) -> Option<Option<numpy::PyReadwriteArrayDyn<'py, f32>>> {
    match a {
        None => Some(None),
        Some(a) => {
            let arr = a.bind(py).downcast::<PyArrayDyn<f32>>().ok()?.clone();
            arr.try_readwrite().ok().map(Some)
        }
    }
}

/// The order `gaussians_to_dict` inserts the keys in.
const DICT_ORDER: [usize; 7] = [0, 1, 2, 3, 5, 6, 4];

impl Reader {
    /// The merged frame at `t` decoded into a kept set of arrays Python has released, as a new
    /// dict of those arrays; `None` when there is no such set.
    pub(crate) fn decode_into_free<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        opts: &FrameOptions,
    ) -> Res<Option<Bound<'py, PyDict>>> {
        let Some(set) = self.recycler.take_free(py) else {
            return Ok(None);
        };
        let mut rw = Vec::with_capacity(set.len());
        for a in &set {
            match writable(py, a) {
                Some(x) => rw.push(x),
                None => return Ok(None),
            }
        }
        let mut flat: Vec<&mut [f32]> = Vec::with_capacity(rw.len());
        for r in rw.iter_mut() {
            match r {
                None => flat.push(&mut []),
                Some(r) => match r.as_slice_mut() {
                    Ok(s) => flat.push(s),
                    Err(_) => return Ok(None),
                },
            }
        }
        let mut it = flat.into_iter();
        let mut next = || it.next().expect("one slice per key");
        let (pos, scales, rot) = (next(), next(), next());
        let (Ok(positions), Ok(log_scales), Ok(rotations)) = (
            bytemuck::try_cast_slice_mut::<f32, [f32; 3]>(pos),
            bytemuck::try_cast_slice_mut::<f32, [f32; 3]>(scales),
            bytemuck::try_cast_slice_mut::<f32, [f32; 4]>(rot),
        ) else {
            return Ok(None);
        };
        let slices = FrameSlices {
            positions,
            log_scales,
            rotations,
            opacity: next(),
            lang_opacity: next(),
            sh: next(),
            lang: next(),
        };
        self.detach(py, || self.dec()?.frame_at_merged_into(t, opts, slices))
            .py_err()?;
        drop(rw);
        let d = PyDict::new(py);
        for i in DICT_ORDER {
            if let Some(a) = &set[i] {
                d.set_item(KEYS[i], a.bind(py))?;
            }
        }
        self.recycler.remember(&d)?;
        Ok(Some(d))
    }
}
