//! Query outputs as PNG: the mask, the relevance heat map (turbo colour map of `o`), and the
//! colour render with the mask tinted.

use std::path::Path;

use crate::error::{QueryError, Result};

fn save(path: &Path, w: usize, h: usize, rgb: Vec<u8>) -> Result<()> {
    image::RgbImage::from_raw(w as u32, h as u32, rgb)
        .ok_or_else(|| QueryError::Invalid("image buffer size".into()))?
        .save(path)
        .map_err(|e| QueryError::Io {
            path: path.display().to_string(),
            reason: e.to_string(),
        })
}

/// White where selected, black elsewhere.
pub fn save_mask(path: &Path, mask: &[bool], w: usize, h: usize) -> Result<()> {
    image::GrayImage::from_raw(
        w as u32,
        h as u32,
        mask.iter().map(|&m| if m { 255 } else { 0 }).collect(),
    )
    .ok_or_else(|| QueryError::Invalid("image buffer size".into()))?
    .save(path)
    .map_err(|e| QueryError::Io {
        path: path.display().to_string(),
        reason: e.to_string(),
    })
}

/// Values in [0, 1] through the turbo colour map.
pub fn save_heatmap(path: &Path, values: &[f32], w: usize, h: usize) -> Result<()> {
    let rgb = values
        .iter()
        .flat_map(|&v| {
            let c = colorous::TURBO.eval_continuous(v.clamp(0.0, 1.0) as f64);
            [c.r, c.g, c.b]
        })
        .collect();
    save(path, w, h, rgb)
}

/// The colour image (linear RGB floats) darkened outside the mask and tinted red inside.
pub fn save_overlay(path: &Path, color: &[f32], mask: &[bool], w: usize, h: usize) -> Result<()> {
    let to8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    let rgb = color
        .chunks_exact(3)
        .zip(mask)
        .flat_map(|(c, &m)| {
            if m {
                [to8(0.5 * c[0] + 0.5), to8(0.5 * c[1]), to8(0.5 * c[2])]
            } else {
                [to8(0.4 * c[0]), to8(0.4 * c[1]), to8(0.4 * c[2])]
            }
        })
        .collect();
    save(path, w, h, rgb)
}
