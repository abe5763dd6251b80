//! `dlgs-web`: the `.dlgs` decoder for the web player (issue 67), GPL-free (`dlgs-decoder`
//! without `hevc`: no FFmpeg in the module).
//!
//! The page owns the network. The decoder reads a *sparse* copy of the file: the byte ranges the
//! page has fetched so far (`add_bytes`). A call that reads a byte not fetched yet returns
//! [`NEED_BYTES`] and `need_offset()/need_len()` name the range to fetch; the page fetches it
//! (HTTP Range) and calls again. So the page fetches the header and the GOP index first, then
//! each GOP's byte range from the index (`gop_offset/gop_length`), and a server that ignores
//! Range simply gives the whole file as one segment.
//!
//! Per frame: `frame(t, ..)` decodes the Gaussians at `t` (static then dynamic rows, the
//! decoder's `frame_at_merged_into`: the native decoder's bits) into buffers the page views
//! in wasm memory (`*_ptr`), and `prepare_draw(..)` sorts the visible Gaussians back to front
//! by view depth and packs, per Gaussian, what the WebGL2 vertex shader needs (16 floats: mean
//! and opacity, 3D covariance, colour from the SH at the view direction).

mod colour;
mod decode;
mod draw;
mod errors;
mod frame;
mod query;
mod scaffold;
mod sparse;

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::rc::Rc;

use dlgs::model::lang_decoder::LangDecoder;
use dlgs_decoder::scaffold::ScaffoldDecoder;
use dlgs_decoder::Decoder;
use wasm_bindgen::prelude::*;

use frame::Buffers;
use query::Query;
use sparse::{Sparse, Store};

/// Status: done.
pub const DONE: u32 = 0;
/// Status: bytes missing; fetch `need_offset()..+need_len()`, `add_bytes`, call again.
pub const NEED_BYTES: u32 = 1;

#[wasm_bindgen]
pub struct Player {
    store: Rc<RefCell<Store>>,
    dec: Option<Decoder<Sparse>>,
    /// Scaffold-GS files: the camera-dependent decoder (opened on first use).
    scaffold: Option<ScaffoldDecoder<Sparse>>,
    buf: Buffers,
    rows: usize,
    splats: Vec<f32>,
    keys: Vec<u32>,
    order: Vec<u32>,
    tmp: Vec<u32>,
    relevance: Vec<f32>,
    query: Option<Query>,
    lang_dec: Option<Option<LangDecoder>>,
}

#[wasm_bindgen]
impl Player {
    /// A player for a file of `total_len` bytes (from Content-Range or Content-Length).
    #[wasm_bindgen(constructor)]
    pub fn new(total_len: f64) -> Player {
        Player {
            store: Rc::new(RefCell::new(Store {
                len: total_len as u64,
                segs: BTreeMap::new(),
                missing: None,
            })),
            dec: None,
            scaffold: None,
            buf: Buffers::default(),
            rows: 0,
            splats: Vec::new(),
            keys: Vec::new(),
            order: Vec::new(),
            tmp: Vec::new(),
            relevance: Vec::new(),
            query: None,
            lang_dec: None,
        }
    }
}

/// Whole-file helper for tests and small files: a player with every byte present.
#[wasm_bindgen]
pub fn open_bytes(bytes: &[u8]) -> Result<Player, JsError> {
    let mut p = Player::new(bytes.len() as f64);
    p.add_bytes(0.0, bytes);
    p.open()?;
    Ok(p)
}
