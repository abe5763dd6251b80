//! `CSOG`: canonical Gaussians as quantised attribute grids (format-spec §6.5). The encoder
//! sorts each set so that grid neighbours are similar (`dlgs-encoder`'s grid sort); this module
//! only quantises, lays every channel out as a `width`-wide grid in set order and codes it
//! losslessly with one of the grid codecs ([`grid_codecs`]). Decoding restores the quantised
//! values exactly.
//!
//! - [`channels`]: what each channel holds, in payload order;
//! - [`quantiser`]: ranges and levels;
//! - [`rotation_coarsening`]: layout 3's coarse rotations;
//! - [`set_coder`]: one set quantised and coded (encoder);
//! - [`writer`]: the payload's records and the encoder's entry points;
//! - [`records`]: the records read and checked, not decoded;
//! - [`reader`]: the records decoded into Gaussians;
//! - [`describe`]: the records summarised for reports;
//! - [`grid_codecs`]: the facade for writers, conformance generators and benches (the one
//!   way in to the lossless grid codecs and the layout helpers; everything else is internal).

mod adaptive_coder;
mod bit_coder;
mod cells;
mod channels;
mod colour_lattice;
mod describe;
pub mod grid_codecs;
pub(crate) mod grid_coder;
mod grid_shaping;
mod half_range;
mod kd_layout;
mod octree_positions;
mod quantiser;
mod reader;
mod records;
mod rotation_coarsening;
mod set_coder;
mod tree_walks;
mod writer;

pub use describe::{describe, CsogSummary, RecordSummary};
pub use quantiser::{
    dequantise, grid_width, quantise, robust_radius, LOG_SCALE_BELOW_RADIUS, LOG_SCALE_SPAN,
};
pub use reader::decode;
pub use rotation_coarsening::{
    cells_by_shift, rotation_shift, RotationCoarsening, MAX_ROTATION_SHIFT,
};
pub use set_coder::{quantise_set, QuantisedSet};
pub use writer::{
    breakdown, encode, encode_grid_parts, encode_octree, encode_parts, encode_shaped, PartedGop,
};

/// Largest number of parts a set may be stored in (layouts 1-4).
pub const MAX_PARTS: usize = 16;

/// Bits per attribute (1..=16 each; the rotation's dropped-component index always uses 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct QuantBits {
    pub position: u8,
    pub log_scale: u8,
    /// Each of the three smallest quaternion components.
    pub rotation: u8,
    /// Colour and language opacity, after the sigmoid.
    pub opacity: u8,
    pub sh_dc: u8,
    /// SH band 1 (coefficients 1-3).
    pub sh_rest: u8,
    /// SH bands 2 and 3 (coefficients 4-15): on real scenes their effect on the image is
    /// scene-dependent and mostly small (docs/benchmarks/canonical-levers.md "SH bands").
    pub sh_high: u8,
    pub lang: u8,
}

impl QuantBits {
    /// Renders within ~65 dB of the unquantised model (measured on the reference-run fixture,
    /// docs/benchmarks/ingest.md): for re-packing trained models at a fraction of their bytes.
    pub const NEAR_LOSSLESS: QuantBits = QuantBits {
        position: 16,
        log_scale: 11,
        rotation: 12,
        opacity: 11,
        sh_dc: 11,
        sh_rest: 9,
        sh_high: 9,
        lang: 11,
    };
    pub const HIGH: QuantBits = QuantBits {
        position: 14,
        log_scale: 8,
        rotation: 9,
        opacity: 8,
        sh_dc: 8,
        sh_rest: 6,
        sh_high: 5,
        lang: 8,
    };
    pub const MEDIUM: QuantBits = QuantBits {
        position: 13,
        log_scale: 7,
        rotation: 8,
        opacity: 7,
        sh_dc: 7,
        sh_rest: 5,
        sh_high: 4,
        lang: 7,
    };
    pub const LOW: QuantBits = QuantBits {
        position: 12,
        log_scale: 6,
        rotation: 7,
        opacity: 6,
        sh_dc: 6,
        sh_rest: 4,
        sh_high: 3,
        lang: 6,
    };
    pub fn preset(name: &str) -> Option<QuantBits> {
        match name {
            "near-lossless" => Some(Self::NEAR_LOSSLESS),
            "high" => Some(Self::HIGH),
            "medium" => Some(Self::MEDIUM),
            "low" => Some(Self::LOW),
            _ => None,
        }
    }
    /// The attribute group called `name` (`position`, `log_scale`, `rotation`, `opacity`,
    /// `sh_dc`, `sh_rest`, `sh_high`, `lang`: the `--bits` keys).
    pub fn field_mut(&mut self, name: &str) -> Option<&mut u8> {
        Some(match name {
            "position" => &mut self.position,
            "log_scale" => &mut self.log_scale,
            "rotation" => &mut self.rotation,
            "opacity" => &mut self.opacity,
            "sh_dc" => &mut self.sh_dc,
            "sh_rest" => &mut self.sh_rest,
            "sh_high" => &mut self.sh_high,
            "lang" => &mut self.lang,
            _ => return None,
        })
    }

    /// Every group `by` bits coarser, at least 1 bit.
    pub fn coarser(&self, by: u8) -> QuantBits {
        let c = |b: u8| b.saturating_sub(by).max(1);
        QuantBits {
            position: c(self.position),
            log_scale: c(self.log_scale),
            rotation: c(self.rotation),
            opacity: c(self.opacity),
            sh_dc: c(self.sh_dc),
            sh_rest: c(self.sh_rest),
            sh_high: c(self.sh_high),
            lang: c(self.lang),
        }
    }

    fn all(&self) -> [u8; 8] {
        [
            self.position,
            self.log_scale,
            self.rotation,
            self.opacity,
            self.sh_dc,
            self.sh_rest,
            self.sh_high,
            self.lang,
        ]
    }
}
