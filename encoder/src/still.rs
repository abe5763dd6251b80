//! The still pipeline: a single frame's preparation (what no renderer draws, SH bands that are
//! zero everywhere), then the stream encoder's one GOP, with what it chose reported.

use std::io::Write;

use dlgs::container::SceneHeader;
use dlgs::{Canonical, Result};

use crate::config::{CanonicalCodec, EncoderConfig};
use crate::refit_stage::RefitReport;
use crate::stream::StreamEncoder;
use crate::{bit_allocation, invisible, zero_bands};

/// Encode a single still frame (one GOP, one frame) from static Gaussians.
pub fn encode_still<W: Write>(g: &dlgs::Gaussians, cfg: EncoderConfig, out: W) -> Result<W> {
    encode_still_reporting(g, cfg, out).map(|(w, _)| w)
}

/// What a lossy still scene loses before coding, by `cfg`: the Gaussians no renderer draws
/// ([`invisible`]) and the SH bands that are zero everywhere ([`zero_bands`]); neither changes a
/// pixel. `None` when nothing changes; also the number of Gaussians left out.
pub fn prepare_still(g: &dlgs::Gaussians, cfg: &EncoderConfig) -> (Option<dlgs::Gaussians>, usize) {
    let lossy = matches!(cfg.coding.codec, CanonicalCodec::Sorted { .. });
    let mut out = None;
    let mut dropped = 0;
    if lossy && cfg.still.drop_invisible {
        let (kept, n) = invisible::drop_never_drawn(g);
        if n > 0 {
            out = Some(kept);
            dropped = n;
        }
    }
    if lossy && cfg.still.trim_zero_sh_bands {
        let cur = out.as_ref().unwrap_or(g);
        let used = zero_bands::degree_in_use(cur);
        if used < cur.sh_degree {
            out = Some(cur.with_sh_degree(used));
        }
    }
    (out, dropped)
}

/// What [`encode_still_reporting`] did besides coding.
#[derive(Debug, Clone, Default)]
pub struct StillReport {
    /// What [`crate::StillTools::reallocate_bits`] chose, when it ran.
    pub allocation: Option<bit_allocation::Allocation>,
    /// Gaussians left out because no renderer draws them ([`crate::StillTools::drop_invisible`]).
    pub dropped_invisible: usize,
    /// The SH degree stored: below the input's when [`crate::StillTools::trim_zero_sh_bands`]
    /// left out zero bands.
    pub sh_degree: u8,
    /// What the colour refit measured, when it ran ([`crate::RefitSettings::colours`]).
    pub refit: Option<RefitReport>,
}

/// [`encode_still`], also reporting what the encoder chose.
pub fn encode_still_reporting<W: Write>(
    g: &dlgs::Gaussians,
    cfg: EncoderConfig,
    out: W,
) -> Result<(W, StillReport)> {
    let (prepared, dropped_invisible) = prepare_still(g, &cfg);
    let g = prepared.as_ref().unwrap_or(g);
    let mut scene = SceneHeader::still(g.len() as u32, g.sh_degree);
    if g.has_language() {
        // DLGStream's 9-dim feature is 3 levels x 3 dims; other widths are one level.
        let (levels, dims) = if g.lang_width == 9 {
            (3, 3)
        } else {
            (1, g.lang_width as u8)
        };
        scene.lang_levels = levels;
        scene.lang_dims = dims;
    }
    let mut enc = StreamEncoder::new(out, scene, cfg)?;
    enc.push_intra_gop(&Canonical::from_static(g.clone()))?;
    let report = StillReport {
        allocation: enc.allocation().cloned(),
        dropped_invisible,
        sh_degree: g.sh_degree,
        refit: enc.refit(),
    };
    Ok((enc.finish()?, report))
}
