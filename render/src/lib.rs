//! `dlgs-render`: a CPU renderer for DLGStream Gaussians (colour and 9-channel language
//! feature images with two opacities), cameras, and image metrics.
//!
//! Deterministic: the same Gaussians and camera give bit-identical images on any thread count
//! (projection is per Gaussian, binning is sequential in depth order, each tile is composited
//! by one thread).

pub mod camera;
pub mod colour_fit;
pub mod contribution;
pub mod cull;
mod error;
pub mod fastexp;
pub mod image_out;
pub mod metrics;
pub mod opacity_fit;
pub mod project;
pub mod raster;
pub mod sh;

pub use error::RenderError;
use std::time::Instant;

pub use camera::{cameras_from_json, orbit_cameras, Camera, OrbitSpec};
use dlgs::Gaussians;

/// Speed against accuracy of the compositor.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Accuracy {
    /// The exact rule of [`raster`]'s module comment, bit-identical on any thread count and to
    /// the renderers before it (`tests/exact_compositing.rs`).
    #[default]
    Exact,
    /// Cheaper per-pixel work that moves pixels slightly: the Gaussian's exponent as a
    /// polynomial in the pixel's x with base-2 coefficients set once per row, a degree-3 `2^x`
    /// (relative error < 1e-4) instead of the degree-6 `exp`, no per-lane span mask (the row span
    /// only picks half or whole rows, multiplied by 1/A instead of two divisions), and a
    /// pixel finished once its transmittance would fall below 1e-3 (exact: 1e-4). At least
    /// 60 dB PSNR against [`Accuracy::Exact`] on the plant (`tests/fast_render.rs`: 72.6 dB
    /// colour); still bit-identical on any thread count.
    Fast,
}

/// What to render.
#[derive(Debug, Clone)]
pub struct RenderOptions {
    pub background: [f32; 3],
    /// Also render the language feature image (needs language in the Gaussians).
    pub features: bool,
    /// Exact (default) or fast compositing.
    pub accuracy: Accuracy,
}

impl Default for RenderOptions {
    fn default() -> Self {
        // DLGStream trains with a white background.
        RenderOptions {
            background: [1.0, 1.0, 1.0],
            features: false,
            accuracy: Accuracy::Exact,
        }
    }
}

/// Milliseconds spent per stage, for benchmarks.
#[derive(Debug, Clone, Copy, Default)]
pub struct RenderTimings {
    pub project_ms: f64,
    pub raster_ms: f64,
}

/// A rendered frame.
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// RGB row-major, linear, not clamped (SH colour can exceed 1).
    pub color: Vec<f32>,
    /// Colour transmittance left per pixel (1 = nothing drawn).
    pub transmittance: Vec<f32>,
    /// Language features, `lang_width` per pixel, when asked for.
    pub features: Option<Vec<f32>>,
    pub lang_width: usize,
    /// Gaussians that survived culling.
    pub visible: usize,
    /// Tile-Gaussian pairs composited.
    pub pairs: usize,
    pub timings: RenderTimings,
}

/// Largest image side the renderer accepts.
pub const MAX_SIDE: u32 = 16384;

/// Render `g` from `cam`. Language is rendered only if `opts.features` and the Gaussians
/// carry language.
pub fn render(g: &Gaussians, cam: &Camera, opts: &RenderOptions) -> Result<Image, RenderError> {
    if cam.width == 0 || cam.height == 0 || cam.width > MAX_SIDE || cam.height > MAX_SIDE {
        return Err(RenderError::ImageSize {
            width: cam.width,
            height: cam.height,
        });
    }
    g.check_shapes().map_err(RenderError::Scene)?;
    let with_lang = opts.features && g.has_language();
    if opts.features && !g.has_language() {
        return Err(RenderError::NoLanguage);
    }
    let t0 = Instant::now();
    let splats = project::project_all(g, cam, with_lang);
    let t1 = Instant::now();
    let lang = with_lang.then_some((g.lang.as_slice(), g.lang_width));
    let acc = raster::rasterize_with(
        &splats,
        cam.width,
        cam.height,
        opts.background,
        lang,
        opts.accuracy,
    );
    let t2 = Instant::now();
    Ok(Image {
        width: cam.width,
        height: cam.height,
        color: acc.color,
        transmittance: acc.transmittance,
        features: acc.features,
        lang_width: acc.lang_width,
        visible: splats.len(),
        pairs: acc.pairs,
        timings: RenderTimings {
            project_ms: (t1 - t0).as_secs_f64() * 1e3,
            raster_ms: (t2 - t1).as_secs_f64() * 1e3,
        },
    })
}
