//! What the renderer refuses, and why: typed so callers can tell a bad request (image size,
//! language asked of a scene without it) from a bad scene or a failed write.

use std::path::PathBuf;

use crate::MAX_SIDE;

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The camera's image is empty or larger than [`MAX_SIDE`] on a side.
    #[error("image size {width}x{height} outside 1..={MAX_SIDE}")]
    ImageSize { width: u32, height: u32 },
    /// The Gaussians' attribute arrays disagree in length.
    #[error("the scene's attribute arrays disagree: {0}")]
    Scene(dlgs::Error),
    /// Language features were asked of a scene that has none.
    #[error("language features requested but the scene has none")]
    NoLanguage,
    /// A `cameras.json` that does not parse, or a camera it holds that cannot be used.
    #[error("cameras.json: {0}")]
    Cameras(String),
    /// Writing an image failed.
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: image::ImageError,
    },
}
