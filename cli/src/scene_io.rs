//! Loading a renderable set of Gaussians from any supported file.

use std::path::Path;

use anyhow::{Context, Result};
use dlgs::Gaussians;
use dlgs_decoder::Decoder;

pub fn is_dlgs(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("dlgs"))
}

/// Gaussians to render: a `.dlgs` frame at time `t`, or a PLY / .splat / SPZ scene.
pub fn load_gaussians(path: &Path, t: f64) -> Result<Gaussians> {
    if is_dlgs(path) {
        let mut dec =
            Decoder::open_path(path).with_context(|| format!("opening {}", path.display()))?;
        let frame = dec
            .frame_at(t)
            .with_context(|| format!("decoding {} at t = {t} s", path.display()))?;
        Ok(frame.merged())
    } else {
        dlgs::interop::read_splat_file(path).with_context(|| format!("reading {}", path.display()))
    }
}
