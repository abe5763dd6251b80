//! Errors as the page sees them, and the "bytes missing" status of a decoder call.

use wasm_bindgen::prelude::*;

use crate::Player;

/// The decoder's error as the page sees it: `Name: message`. HEVC time features get their own
/// name and the re-encode hint (this module has no HEVC decoder, by design: no GPL code).
pub(crate) fn js_err(e: dlgs::Error) -> JsError {
    if e.name() == "NoHevcDecoder" {
        return JsError::new(
            "HevcFeatures: this file's time features are HEVC, which this GPL-free web player \
             does not decode; re-encode it with quantised time features (TFEA codec 4, about \
             HEVC's bytes at 6 bits): dlgs encode IN.dlgs -o OUT.dlgs --quantised-features 8",
        );
    }
    JsError::new(&format!("{}: {e}", e.name()))
}

pub(crate) fn status<T>(p: &Player, r: dlgs::Result<T>) -> Result<Option<T>, JsError> {
    match r {
        Ok(v) => Ok(Some(v)),
        Err(_) if p.store.borrow().missing.is_some() => Ok(None),
        Err(e) => Err(js_err(e)),
    }
}
