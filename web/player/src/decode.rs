//! Opening the file (either variant) and decoding its GOPs: the scene header and GOP index
//! (`info`), the GOP at a time, a GOP's decode and its canonical digest.

use dlgs::container::Variant;
use dlgs::{FileReader, Limits};
use dlgs_decoder::scaffold::ScaffoldDecoder;
use dlgs_decoder::Decoder;
use wasm_bindgen::prelude::*;

use crate::errors::{js_err, status};
use crate::sparse::Sparse;
use crate::{Player, DONE, NEED_BYTES};

#[wasm_bindgen]
impl Player {
    /// Parse the signature, `HEAD`, the scene-level chunk headers, `TAIL` and the GOP index,
    /// and open the decoder of the file's variant (3DGS, or Scaffold-GS: camera-dependent).
    pub fn open(&mut self) -> Result<u32, JsError> {
        self.store.borrow_mut().missing = None;
        let variant = FileReader::open_with_limits(self.source(), Limits::default())
            .map(|r| r.scene().variant);
        let Some(variant) = status(self, variant)? else {
            return Ok(NEED_BYTES);
        };
        if variant == Variant::Scaffold {
            let r = ScaffoldDecoder::new(self.source(), Limits::default());
            return Ok(match status(self, r)? {
                Some(d) => {
                    self.scaffold = Some(d);
                    DONE
                }
                None => NEED_BYTES,
            });
        }
        let r = Decoder::new(self.source(), Limits::default());
        match status(self, r)? {
            Some(mut d) => {
                d.set_read_ahead(false);
                self.dec = Some(d);
                Ok(DONE)
            }
            None => Ok(NEED_BYTES),
        }
    }
}

impl Player {
    /// A reader over the bytes fetched so far, from the file's start.
    fn source(&self) -> Sparse {
        Sparse {
            store: self.store.clone(),
            pos: 0,
        }
    }

    /// The 3DGS decoder (variant 0).
    pub(crate) fn dec(&mut self) -> Result<&mut Decoder<Sparse>, JsError> {
        self.dec.as_mut().ok_or_else(|| {
            JsError::new("Request: open() the file first (a 3DGS file for this call)")
        })
    }

    /// The container reader of the open file, either variant.
    pub(crate) fn reader(&mut self) -> Result<&mut FileReader<Sparse>, JsError> {
        match (&mut self.scaffold, &mut self.dec) {
            (Some(s), _) => Ok(s.reader()),
            (None, Some(d)) => Ok(d.reader()),
            (None, None) => Err(JsError::new("Request: open() the file first")),
        }
    }
}

#[wasm_bindgen]
impl Player {
    /// The scene header and GOP index as JSON.
    pub fn info(&mut self) -> Result<String, JsError> {
        let r = self.reader()?;
        let s = r.scene().clone();
        let idx = r.index().clone();
        let file_len = r.file_len();
        let gidx_at = file_len - r.index_bytes();
        let gops: Vec<String> = idx
            .entries
            .iter()
            .map(|e| format!("[{},{}]", e.offset, e.length))
            .collect();
        Ok(format!(
            "{{\"variant\":\"{:?}\",\"fps\":{},\"frame_count\":{},\"duration\":{},\"gop_count\":{},\
             \"gop_length\":{},\"key_interval\":{},\"n_static\":{},\"n_dynamic\":{},\"sh_degree\":{},\
             \"lang_levels\":{},\"lang_dims\":{},\"residual_mode\":\"{:?}\",\"file_len\":{},\
             \"index_offset\":{},\"gops\":[{}]}}",
            s.variant,
            s.fps(),
            s.frame_count,
            s.duration_seconds(),
            s.gop_count,
            s.gop_length,
            s.key_interval,
            s.n_static,
            s.n_dynamic,
            s.sh_degree,
            s.lang_levels,
            s.lang_dims,
            s.residual_mode,
            file_len,
            gidx_at,
            gops.join(",")
        ))
    }

    /// The GOP that holds time `t`.
    pub fn gop_at(&mut self, t: f64) -> Result<u32, JsError> {
        let r = self.reader()?;
        r.scene().locate(t).map(|p| p.gop).map_err(js_err)
    }

    /// Decode GOP `g` (canonical state, time features, decoders).
    pub fn decode_gop(&mut self, g: u32) -> Result<u32, JsError> {
        self.store.borrow_mut().missing = None;
        if self.is_scaffold() {
            return self.scaffold_gop(g);
        }
        let d = self.dec()?;
        // The GOP as the native decoder's `gop(g)` decodes it (canonical state, time features,
        // decoders); key geometry is computed when frames first need it.
        let r = d.gop(g).map(|_| ());
        Ok(match status(self, r)? {
            Some(()) => DONE,
            None => NEED_BYTES,
        })
    }

    /// Canonical sha256 of GOP `g` (the conformance vectors' expected.txt), or "" when bytes
    /// are missing.
    pub fn gop_digest(&mut self, g: u32) -> Result<String, JsError> {
        self.store.borrow_mut().missing = None;
        let d = self.dec()?;
        let r = d.gop_canonical(g);
        Ok(status(self, r)?
            .map(|c| dlgs::chunks::craw::canonical_digest(&c))
            .unwrap_or_default())
    }
}
