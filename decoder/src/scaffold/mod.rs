//! Decoding the Scaffold-GS variant (issue 51; ../shared/reference §5.2): dynamic anchors at a
//! time, then the neural Gaussians a camera sees. Every step is row-independent with fixed
//! block sizes, so frames are the same on any thread count.

mod anchor_deform;
mod file;
mod gop_decode;
mod mlp;
mod neural;
mod stream;

pub use anchor_deform::deform_anchors;
pub use file::{InView, ScaffoldDecoder, ScaffoldGop};
pub use mlp::{activate, eval as eval_mlp};
pub use neural::{anchor_reach, neural_gaussians, NeuralGaussians, ViewRequest};
pub use stream::ScaffoldStreamDecoder;
