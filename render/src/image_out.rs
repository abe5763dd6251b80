//! Writing rendered buffers as 8-bit PNG.

use std::path::Path;

use crate::RenderError;

/// Clamp linear RGB floats to [0,1] and write an 8-bit RGB PNG.
pub fn save_rgb_png(path: &Path, rgb: &[f32], width: u32, height: u32) -> Result<(), RenderError> {
    let bytes: Vec<u8> = rgb
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8)
        .collect();
    image::save_buffer(path, &bytes, width, height, image::ColorType::Rgb8).map_err(|source| {
        RenderError::Write {
            path: path.to_path_buf(),
            source,
        }
    })
}

/// Write a single-channel float image as 8-bit gray, mapping [lo, hi] to [0, 255].
pub fn save_gray_png(
    path: &Path,
    v: &[f32],
    width: u32,
    height: u32,
    lo: f32,
    hi: f32,
) -> Result<(), RenderError> {
    let span = if hi > lo { hi - lo } else { 1.0 };
    let bytes: Vec<u8> = v
        .iter()
        .map(|x| (((x - lo) / span).clamp(0.0, 1.0) * 255.0 + 0.5) as u8)
        .collect();
    image::save_buffer(path, &bytes, width, height, image::ColorType::L8).map_err(|source| {
        RenderError::Write {
            path: path.to_path_buf(),
            source,
        }
    })
}

/// Visualise a multi-channel feature image: channels [first, first+3) mapped per channel by
/// their own min/max to RGB.
pub fn save_feature_png(
    path: &Path,
    f: &[f32],
    channels: usize,
    first: usize,
    width: u32,
    height: u32,
) -> Result<(), RenderError> {
    let n = (width * height) as usize;
    let mut rgb = vec![0f32; n * 3];
    for c in 0..3.min(channels.saturating_sub(first)) {
        let vals: Vec<f32> = (0..n).map(|p| f[p * channels + first + c]).collect();
        let lo = vals.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = vals.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let span = if hi > lo { hi - lo } else { 1.0 };
        for p in 0..n {
            rgb[p * 3 + c] = (vals[p] - lo) / span;
        }
    }
    save_rgb_png(path, &rgb, width, height)
}
