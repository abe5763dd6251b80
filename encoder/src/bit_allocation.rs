//! Rate-distortion reallocation of a preset's quantisation bits for one scene.
//!
//! Which attribute deserves its bits depends on the scene: on the real plant capture (a `.splat`
//! whose opacities are 8-bit already) one more opacity bit buys 1.5 dB for 0.8 % more bytes,
//! on the lod tiles it buys nothing, on the donut colour is what counts
//! (docs/benchmarks/canonical.md). Starting from a preset, this moves one bit at a time from the
//! attribute group whose bit costs the least quality per byte to the group whose bit buys the
//! most, as long as the rendered PSNR rises and the coded size stays within the preset's (plus
//! [`BYTES_TOLERANCE`]).
//!
//! Distortion is measured by rendering the decoded scene from cameras of its own (5 views at
//! 35 degrees elevation, 400 x 300), not the 8 benchmark views at 20 degrees, so benchmark
//! numbers are not fitted to their own cameras. Every candidate is coded and decoded for real:
//! the sizes are the payload's.

use dlgs::chunks::csog::{self, QuantBits, RotationCoarsening};
use dlgs::model::{Canonical, Gaussians};
use dlgs::{Limits, Result};
use dlgs_render::{metrics, render, Camera, RenderOptions};

/// Attribute groups whose bits are moved (language is not rendered in colour and keeps its
/// bits).
pub(crate) const GROUPS: [&str; 7] = [
    "position",
    "log_scale",
    "rotation",
    "opacity",
    "sh_dc",
    "sh_rest",
    "sh_high",
];

/// The [`GROUPS`] a scene of `g`'s SH degree has.
pub(crate) fn groups_of(g: &Gaussians) -> Vec<&'static str> {
    GROUPS
        .into_iter()
        .filter(|&n| match n {
            "sh_rest" => g.sh_degree >= 1,
            "sh_high" => g.sh_degree >= 2,
            _ => true,
        })
        .collect()
}

pub(crate) fn get(b: &QuantBits, g: &str) -> u8 {
    let mut b = *b;
    *b.field_mut(g).expect("a group name")
}

pub(crate) fn with(b: &QuantBits, g: &str, v: u8) -> QuantBits {
    let mut b = *b;
    *b.field_mut(g).expect("a group name") = v;
    b
}

/// A move may end this fraction above the preset's size: with the adaptive grid codec a move
/// that buys 2 dB may cost a few dozen bytes more (real donut: rotation 8 / SH DC 9 bits at
/// `high` is 0.01 % larger and 2.0 dB better; docs/benchmarks/canonical.md "Grid codec 5"),
/// and a strict bound would refuse
/// it.
pub const BYTES_TOLERANCE: f64 = 0.0025;

/// One accepted move.
#[derive(Debug, Clone)]
pub struct Move {
    pub from: &'static str,
    pub to: &'static str,
    pub bytes: usize,
    pub psnr: f64,
}

/// The result: the bits to use, the preset's and the result's size and PSNR on the
/// allocation cameras, and the moves made.
#[derive(Debug, Clone)]
pub struct Allocation {
    pub bits: QuantBits,
    pub start_bytes: usize,
    pub start_psnr: f64,
    pub bytes: usize,
    pub psnr: f64,
    pub moves: Vec<Move>,
}

/// Renders the reference once and scores candidates against it.
struct Judge {
    canon: Canonical,
    scene: dlgs::container::SceneHeader,
    cams: Vec<Camera>,
    reference: Vec<f32>,
    zstd_level: i32,
    /// Code as the encoder will: octree positions (layout 2, or 3 with rotation coarsening)
    /// or grid positions (layout 0).
    octree: bool,
    coarsening: Option<RotationCoarsening>,
}

/// `g` rendered from each camera: one colour image per view.
pub(crate) fn render_views(g: &Gaussians, cams: &[Camera]) -> Result<Vec<Vec<f32>>> {
    cams.iter()
        .map(|cam| {
            render(g, cam, &RenderOptions::default())
                .map(|img| img.color)
                .map_err(|e| dlgs::Error::input(format!("rendering: {e}")))
        })
        .collect()
}

/// All views of `g`, one after the other.
fn images(g: &Gaussians, cams: &[Camera]) -> Result<Vec<f32>> {
    Ok(render_views(g, cams)?.concat())
}

impl Judge {
    /// Coded bytes and PSNR (over all views' pixels at once) of `bits`.
    fn score(&self, bits: &QuantBits) -> Result<(usize, f64)> {
        let payload = if self.octree {
            let part = [(self.canon.statics.clone(), *bits)];
            let gop = csog::PartedGop {
                static_parts: &part,
                static_weight: None,
                dynamics: &self.canon.dynamics,
                dynamic_bits: bits,
                rotation_coarsening: self.coarsening,
                compact_records: true,
                // Bytes judged as the default coder makes them (fast decoding, no mixed
                // modes), also under `--max-compression` or `--mixed-margin` (which take a few
                // percent off every candidate alike).
                mixed_margin: None,
            };
            csog::encode_octree(&gop, self.zstd_level)?.0
        } else {
            csog::encode(&self.canon, bits, self.zstd_level)?
        };
        let decoded = csog::decode(&payload, 0, &self.scene, &Limits::default())?.statics;
        let psnr = metrics::psnr(&self.reference, &images(&decoded, &self.cams)?);
        Ok((payload.len(), psnr))
    }
}

/// Reallocate `start`'s bits for the still scene `g` (already oriented and sorted as it will be
/// coded). `progress` sees each accepted move. At most `max_moves` moves (each scores about
/// 15 candidates).
pub fn reallocate(
    g: &Gaussians,
    start: QuantBits,
    zstd_level: i32,
    max_moves: usize,
    octree: bool,
    coarsening: Option<RotationCoarsening>,
    mut progress: impl FnMut(&Move),
) -> Result<Allocation> {
    let cams = crate::judge_views::allocation_views(g);
    let judge = Judge {
        canon: Canonical::from_static(g.clone()),
        scene: dlgs::container::SceneHeader::still(g.len() as u32, g.sh_degree),
        reference: images(g, &cams)?,
        cams,
        zstd_level,
        octree,
        coarsening,
    };
    let groups = groups_of(g);
    let (start_bytes, start_psnr) = judge.score(&start)?;
    let (mut bits, mut bytes, mut psnr) = (start, start_bytes, start_psnr);
    let mut moves = Vec::new();
    let mut tried = std::collections::HashSet::new();
    tried.insert(format!("{bits:?}"));
    while moves.len() < max_moves {
        // Quality per byte of one more bit, and quality lost per byte saved by one fewer.
        let mut ups: Vec<(&'static str, f64)> = Vec::new();
        let mut downs: Vec<(&'static str, f64)> = Vec::new();
        for &grp in &groups {
            let v = get(&bits, grp);
            if v < 16 {
                let (b, p) = judge.score(&with(&bits, grp, v + 1))?;
                ups.push((grp, (p - psnr) / (b as f64 - bytes as f64).max(1.0)));
            }
            if v > 1 {
                let (b, p) = judge.score(&with(&bits, grp, v - 1))?;
                downs.push((grp, (psnr - p) / (bytes as f64 - b as f64).max(1.0)));
            }
        }
        ups.sort_by(|a, b| b.1.total_cmp(&a.1));
        downs.sort_by(|a, b| a.1.total_cmp(&b.1));
        // The best pairs first: the two best buys against the two cheapest sales.
        let mut accepted = None;
        'pairs: for &(to, _) in ups.iter().take(2) {
            for &(from, _) in downs.iter().take(2) {
                if to == from {
                    continue;
                }
                let cand = with(
                    &with(&bits, to, get(&bits, to) + 1),
                    from,
                    get(&bits, from) - 1,
                );
                if !tried.insert(format!("{cand:?}")) {
                    continue;
                }
                let (b, p) = judge.score(&cand)?;
                if p > psnr && b as f64 <= start_bytes as f64 * (1.0 + BYTES_TOLERANCE) {
                    accepted = Some((
                        cand,
                        Move {
                            from,
                            to,
                            bytes: b,
                            psnr: p,
                        },
                    ));
                    break 'pairs;
                }
            }
        }
        let Some((cand, m)) = accepted else {
            break;
        };
        progress(&m);
        (bits, bytes, psnr) = (cand, m.bytes, m.psnr);
        moves.push(m);
    }
    Ok(Allocation {
        bits,
        start_bytes,
        start_psnr,
        bytes,
        psnr,
        moves,
    })
}
