//! The sorted-grid canonical codec (`CSOG`, format-spec §6.5) on real scenes: exact restoration
//! of the quantised values, error bounds, ordering rules, degenerate Gaussians, determinism and
//! damaged payloads.
//!
//! One module per group of checks; the helpers several of them share are here.

mod colour_refit;
mod octree_sets;
mod parted_sets;
mod sorted_grid;
mod still_tools;

use std::io::Cursor;

use dlgs::chunks::csog::{self, QuantBits};
use dlgs::container::SceneHeader;
use dlgs::model::{Canonical, Gaussians};
use dlgs::Limits;
use dlgs_decoder::Decoder;
use dlgs_encoder::grid_sort::{permute, SortSpec};
use dlgs_encoder::{CanonicalCodec, EncoderConfig, StreamEncoder};
use dlgs_render::{metrics, orbit_cameras, render, OrbitSpec, RenderOptions};
use dlgs_tests::load;

/// Every `n`-th Gaussian of `g`: a real scene's kind of Gaussians at a fraction of the cost.
fn every_nth(g: &Gaussians, n: usize) -> Gaussians {
    permute(g, &(0..g.len() as u32).step_by(n).collect::<Vec<_>>())
}

fn scene_of(c: &Canonical) -> SceneHeader {
    let mut s = SceneHeader::still(c.statics.len() as u32, c.statics.sh_degree);
    s.n_dynamic = c.dynamics.len() as u32;
    if c.statics.has_language() {
        s.lang_levels = 3;
        s.lang_dims = 3;
    }
    s
}

fn round_trip(c: &Canonical, bits: &QuantBits) -> Canonical {
    let p = csog::encode(c, bits, 3).unwrap();
    csog::decode(&p, 0, &scene_of(c), &Limits::default()).unwrap()
}

/// The lod3 tile with its first 50 Gaussians degenerate (zero quaternions, collapsed e^-30 and
/// huge e^12 scales, opacity saturated both ways) and a constant channel (every x equal).
fn degenerate_lod3() -> Gaussians {
    let mut g = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    for i in 0..50 {
        g.rotations[i] = [0.0; 4];
        g.log_scales[i] = [if i % 2 == 0 { -30.0 } else { 12.0 }; 3];
        g.opacity[i] = if i % 2 == 0 { -1e4 } else { 1e4 };
    }
    for p in &mut g.positions {
        p[0] = 0.25;
    }
    g
}

/// A still scene through the encoder with the given orientation setting: bytes and decoded
/// static set.
fn encode_still(g: &Gaussians, orient: bool) -> (usize, Gaussians) {
    let cfg = EncoderConfig {
        coding: dlgs_encoder::CanonicalSettings {
            codec: CanonicalCodec::Sorted {
                bits: QuantBits::MEDIUM,
                sort: SortSpec::DEFAULT,
            },
            ..Default::default()
        },
        still: dlgs_encoder::StillTools {
            canonical_orientation: orient,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut enc = StreamEncoder::new(
        Vec::new(),
        SceneHeader::still(g.len() as u32, g.sh_degree),
        cfg,
    )
    .unwrap();
    enc.push_intra_gop(&Canonical::from_static(g.clone()))
        .unwrap();
    let bytes = enc.finish().unwrap();
    let mut dec = Decoder::new(Cursor::new(bytes.as_slice()), Limits::default()).unwrap();
    (bytes.len(), dec.gop_canonical(0).unwrap().statics.clone())
}

/// Mean PSNR of `decoded` against `source` over `count` views of the default orbit at 320x240.
fn orbit_psnr(source: &Gaussians, decoded: &Gaussians, count: usize) -> f64 {
    let cams = orbit_cameras(
        source,
        &OrbitSpec {
            width: 320,
            height: 240,
            count,
            ..Default::default()
        },
    );
    let img = |g: &Gaussians, c| render(g, c, &RenderOptions::default()).unwrap().color;
    cams.iter()
        .map(|c| metrics::psnr(&img(source, c), &img(decoded, c)))
        .sum::<f64>()
        / cams.len() as f64
}
