//! JPEG XL attribute images as the reference writes them with `imagecodecs.imwrite`:
//! a `(H, W, C)` float32 array is one frame of `C` channels (gray, gray+alpha, RGB, RGBA), and
//! an array with `C > 4` is an animation of `H` gray frames of `W x C` samples. Decoded with
//! `jxl-oxide` to f32 in the array's row-major order, without colour conversion (the reference
//! writes linear, original-profile images), so lossless float images come back bit for bit.

use crate::IngestError;

/// Decoded samples in `imagecodecs.imread` order: frames, rows, columns, channels.
#[derive(Debug, Clone, PartialEq)]
pub struct JxlArray {
    pub frames: usize,
    pub height: usize,
    pub width: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

/// Largest array accepted (samples over all frames and channels, 1 GiB of f32): far above the
/// reference's 200k-Gaussian grids, far below what exhausts memory.
const MAX_SAMPLES: u64 = 1 << 28;
/// What the decoder itself may allocate (its tracker refuses beyond): a few copies of the
/// largest accepted array, so a small hostile file cannot declare its way to any size.
const MAX_DECODER_BYTES: usize = 1 << 31;

pub fn decode(bytes: &[u8], what: &str) -> Result<JxlArray, IngestError> {
    let err = |r: String| IngestError::format(what, r);
    let image = jxl_oxide::JxlImage::builder()
        .alloc_tracker(jxl_oxide::AllocTracker::with_limit(MAX_DECODER_BYTES))
        .read(bytes)
        .map_err(|e| err(format!("JPEG XL: {e}")))?;
    let (w, h) = (image.width() as usize, image.height() as usize);
    if (w as u64) * (h as u64) > MAX_SAMPLES {
        return Err(err(format!("{w}x{h} picture is larger than the limit")));
    }
    let frames = image.num_loaded_keyframes();
    if frames == 0 {
        return Err(err("no complete frame".into()));
    }
    let mut channels = 0;
    let mut data = Vec::new();
    for k in 0..frames {
        let render = image
            .render_frame(k)
            .map_err(|e| err(format!("JPEG XL frame {k}: {e}")))?;
        let planes = render.image_planar();
        if k == 0 {
            channels = planes.len();
            let total = (frames as u64) * (w as u64) * (h as u64) * (channels as u64);
            if total > MAX_SAMPLES {
                return Err(err(format!(
                    "{frames} frame(s) of {w}x{h}x{channels} is larger than the limit"
                )));
            }
            data.reserve(frames * w * h * channels);
        } else if planes.len() != channels {
            return Err(err("frames with different channel counts".into()));
        }
        let start = data.len();
        data.resize(start + w * h * channels, 0.0);
        for (c, p) in planes.iter().enumerate() {
            if p.width() != w || p.height() != h || p.channels() != 1 {
                return Err(err(format!("frame {k} plane {c} has another size")));
            }
            for (i, &v) in p.buf().iter().enumerate() {
                data[start + i * channels + c] = v;
            }
        }
    }
    Ok(JxlArray {
        frames,
        height: h,
        width: w,
        channels,
        data,
    })
}
