use std::io::Cursor;
use wasm_bindgen::prelude::*;

/// Canonical sha256 of every GOP of a .dlgs file (random-access decoder), space separated.
#[wasm_bindgen]
pub fn gop_digests(bytes: &[u8]) -> Result<String, JsError> {
    let mut dec = dlgs_decoder::Decoder::new(Cursor::new(bytes), dlgs::Limits::default())
        .map_err(|e| JsError::new(&e.to_string()))?;
    let mut out = Vec::new();
    for g in 0..dec.scene().gop_count {
        let c = dec.gop_canonical(g).map_err(|e| JsError::new(&e.to_string()))?;
        out.push(dlgs::chunks::craw::canonical_digest(&c));
    }
    Ok(out.join(" "))
}

/// Merged Gaussian positions at time t (xyz f32 per Gaussian): what a renderer would upload.
#[wasm_bindgen]
pub fn positions_at(bytes: &[u8], t: f64) -> Result<Vec<f32>, JsError> {
    let mut dec = dlgs_decoder::Decoder::new(Cursor::new(bytes), dlgs::Limits::default())
        .map_err(|e| JsError::new(&e.to_string()))?;
    dec.set_read_ahead(false);
    let opts = dlgs_decoder::FrameOptions { camera_center: [0.0, 0.0, -3.0], language: false };
    let g = dec.frame_at_merged(t, &opts).map_err(|e| JsError::new(&e.to_string()))?;
    Ok(g.positions.iter().flatten().copied().collect())
}
