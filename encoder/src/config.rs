//! What the encoder is asked to do, grouped by what it concerns: the container, the canonical
//! coding, the tools of still scenes, the colour refit, dynamic streams and language.

use dlgs::chunks::craw::RawCodec;
use dlgs::chunks::csog::{QuantBits, RotationCoarsening};
use dlgs::chunks::mlpw::WeightType;
use dlgs::model::lang_decoder::LangDecoder;
use dlgs::model::ntc::NtcField;
use dlgs::model::residual::{AttrGroup, DeltaTarget};
use dlgs::Canonical;
use dlgs_video::HevcSettings;

pub use crate::grid_sort::SortSpec;

/// How key time features are stored.
#[derive(Debug, Clone, PartialEq)]
pub enum FeatureCodec {
    /// Exact f32 (zstd): the lossless interchange form.
    Exact,
    /// Tiled 12-bit images coded with libx265 (the reference's feature video).
    Hevc(HevcSettings),
    /// `TFEA` codec 4 (since 1.19): quantised per channel to `bits` (6-12) and coded with zstd;
    /// no video codec, so any player decodes it (the web player).
    /// `predictor`: `None` picks per GOP the one that codes smaller; `Some(0)` none, `Some(1)`
    /// the previous key.
    Quantised { bits: u8, predictor: Option<u8> },
}

/// How canonical Gaussians are stored.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CanonicalCodec {
    /// `CRAW`: f32, lossless (zstd or not, see `raw_codec`).
    Raw,
    /// `CSOG`: the static set sorted into a grid, every attribute quantised to `bits` and coded
    /// losslessly. The dynamic set keeps its order (its time features are tied to it).
    Sorted { bits: QuantBits, sort: SortSpec },
}

/// What a GOP carries for its canonical state.
#[derive(Debug, Clone, Copy)]
pub enum GopCanonical<'a> {
    /// The full canonical state. Residual GOPs of sequential/parallel scenes code it as an
    /// explicit residual (`RDLT`) against the reference GOP's decoded state.
    State(&'a Canonical),
    /// A binary voxel residual field (`RNTC`) applied to the reference GOP's decoded state.
    Ntc(&'a NtcField),
}

/// How explicit residuals (`RDLT`) are made: the error asked for each attribute group.
/// Groups not listed are not changed by residuals (their reference value is kept).
#[derive(Debug, Clone, PartialEq)]
pub struct ResidualConfig {
    pub groups: Vec<(AttrGroup, DeltaTarget)>,
    /// With sorted-grid canonical coding, replace `groups` by bounds of half a quantisation
    /// step of the canonical codec's bits over each group's range in the GOP (the error GOP 0
    /// already has), so residual GOPs are as lossy as the first one, not more exact.
    pub follow_quantisation: bool,
}

impl Default for ResidualConfig {
    /// Every group, bit-exact.
    fn default() -> Self {
        ResidualConfig {
            groups: AttrGroup::ALL
                .into_iter()
                .map(|g| (g, DeltaTarget::Exact))
                .collect(),
            follow_quantisation: false,
        }
    }
}

/// Error bounds matching sorted-grid quantisation at `bits` for the values of `c`: half a
/// step over each group's range (for opacities, quantised after the sigmoid, half a step at
/// the sigmoid's steepest point). Constant groups are exact.
pub fn bounds_like_quantisation(bits: &QuantBits, c: &Canonical) -> Vec<(AttrGroup, DeltaTarget)> {
    AttrGroup::ALL
        .into_iter()
        .map(|g| {
            let b = match g {
                AttrGroup::Position => bits.position,
                AttrGroup::LogScale => bits.log_scale,
                AttrGroup::Rotation => bits.rotation,
                AttrGroup::ShDc => bits.sh_dc,
                // Bands 2-3 are coded with `sh_high <= sh_rest` bits: the finer band-1 step
                // bounds the whole group (stricter, never looser, than the canonical error).
                AttrGroup::ShRest => bits.sh_rest,
                AttrGroup::Opacity | AttrGroup::LangOpacity => bits.opacity,
                AttrGroup::Lang => bits.lang,
            };
            let levels = (1u32 << b) as f32;
            if matches!(g, AttrGroup::Opacity | AttrGroup::LangOpacity) {
                // d logit / d sigmoid = 4 at 0.5: a sigmoid step of 1/levels.
                return (g, DeltaTarget::Bound(2.0 / levels));
            }
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for set in [&c.statics, &c.dynamics] {
                for i in 0..set.len() {
                    if g.width(set.sh_degree, set.lang_width) == 0 {
                        break;
                    }
                    for &v in g.values(set, i) {
                        lo = lo.min(v);
                        hi = hi.max(v);
                    }
                }
            }
            let range = hi - lo;
            if range.is_finite() && range > 0.0 {
                (g, DeltaTarget::Bound(range / (2.0 * levels)))
            } else {
                (g, DeltaTarget::Exact)
            }
        })
        .collect()
}

/// Encoder settings, grouped.
#[derive(Debug, Clone, Default)]
pub struct EncoderConfig {
    /// The file around the payloads.
    pub container: ContainerSettings,
    /// How canonical Gaussians are coded.
    pub coding: CanonicalSettings,
    /// What lossy still scenes (no dynamic Gaussians, one GOP) may change before coding.
    pub still: StillTools,
    /// Fitting the stored colours (and opacities) to what the rest decodes to.
    pub refit: RefitSettings,
    /// Time features, decoders and residuals of dynamic streams.
    pub dynamic: DynamicSettings,
    /// The language decoder for queries.
    pub language: LanguageSettings,
}

/// The file around the payloads.
#[derive(Debug, Clone)]
pub struct ContainerSettings {
    /// zstd level for `CRAW` when its codec is zstd, exact features and MLP chunks (1..=22).
    pub zstd_level: i32,
    /// Free-form JSON written as the scene-level `META` chunk (provenance, credits).
    pub meta: Option<serde_json::Value>,
}

impl Default for ContainerSettings {
    fn default() -> Self {
        ContainerSettings {
            zstd_level: 9,
            meta: None,
        }
    }
}

/// How canonical Gaussians are coded.
#[derive(Debug, Clone)]
pub struct CanonicalSettings {
    /// Raw or sorted quantised grids.
    pub codec: CanonicalCodec,
    /// How `CRAW` bodies are stored.
    pub raw_codec: RawCodec,
    /// `CSOG`: code the static set's positions as an octree and store it in the order readers
    /// derive from them (layout 2, §6.5.5) instead of as grid channels in the encoder's sort
    /// order (layouts 0 and 1). 13-14 % fewer position bytes on the real scenes; the grid sort
    /// (`CanonicalCodec::Sorted`'s `sort`) then does not apply to the static set.
    pub octree_positions: bool,
    /// With `octree_positions`: store the rotations of Gaussians too small for a rotation
    /// step to move their surface by `factor` position steps up to `max_shift` bits coarser
    /// (layout 3, §6.5.6); `None` = every rotation at its group's bits (layout 2).
    pub rotation_coarsening: Option<RotationCoarsening>,
    /// With `octree_positions`: layout 4's compact records (§6.5.7, since 1.14: varint
    /// lengths, no redundant counts, binary16 ranges where they hold) instead of layouts 2
    /// and 3's; about 120 bytes fewer per part at SH 0. `false` only to write the older
    /// layouts (the conformance vectors).
    pub compact_records: bool,
    /// Lossy (`CSOG`) scenes: let channels take codec 5's mixed-context modes where they code
    /// smaller than any other coding by this fraction (format 1.13; `dlgs encode
    /// --max-compression` gives [`MIXED_MARGIN`](dlgs::chunks::csog::grid_codecs::MIXED_MARGIN),
    /// `--mixed-margin` any other). `None`, the default since 2026-12-02 (issue 66): the same
    /// values in files 1.5-3.1 % larger that decode in about half the time
    /// (docs/benchmarks/decode.md "Decode time against SOG and SPZ").
    pub mixed_margin: Option<f64>,
}

impl Default for CanonicalSettings {
    fn default() -> Self {
        CanonicalSettings {
            codec: CanonicalCodec::Raw,
            raw_codec: RawCodec::Zstd,
            octree_positions: true,
            rotation_coarsening: Some(RotationCoarsening::DEFAULT),
            compact_records: true,
            // Fast decoding by default (decided 2026-12-02, issue 66): codec 5's mixed modes
            // save 2.0-2.1 % of the canonical bytes but halve the decode speed.
            mixed_margin: None,
        }
    }
}

/// What lossy (`CSOG`) still scenes may change before and while coding. None of the first
/// three changes a pixel; the others trade bytes for PSNR.
#[derive(Debug, Clone)]
pub struct StillTools {
    /// Scenes without residual GOPs: store each static Gaussian with the rotation, among the
    /// 24 that give the same ellipsoid, closest to the identity (see [`crate::orientation`]).
    /// Renders the same, codes smaller.
    pub canonical_orientation: bool,
    /// Leave out the Gaussians no renderer draws (both opacities below 1/255,
    /// [`crate::invisible`]). No pixel changes.
    pub drop_invisible: bool,
    /// Store SH only up to the highest band that holds a non-zero coefficient
    /// ([`crate::zero_bands`]). No pixel changes.
    pub trim_zero_sh_bands: bool,
    /// Move up to this many bits between attribute groups where rendering says it pays
    /// ([`crate::bit_allocation`]); 0 = use the bits as given.
    pub reallocate_bits: usize,
    /// Choose each level by estimated bits plus error weighted by the Gaussian's importance
    /// over this tolerance ([`crate::importance`]), so Gaussians that add little to any image
    /// take levels that code smaller; 0 = nearest levels. Larger = smaller files, lower PSNR.
    pub shape_tolerance: f64,
    /// The least important static Gaussians (by blending weight over
    /// [`crate::importance::importance_views`]) that together hold at most `tier_weights[j]`
    /// of the total weight are stored in a part `j + 1` bits coarser in every group (layout 1,
    /// §6.5.2, [`crate::importance::tiers`]); empty = one part. With `shape_tolerance`, every
    /// part is shaped ([`crate::importance::part_shaping_weights`]).
    pub tier_weights: Vec<f64>,
    /// With `tier_weights` or `shape_tolerance`: the static Gaussians' blending weights as
    /// [`crate::importance::blend_weights`] measures them on the set the encoder codes (after
    /// [`crate::prepare_still`] and, with `canonical_orientation`, [`crate::orientation`]);
    /// `None` (or a length that does not match) = measure them. Lets a search code one scene
    /// many times without 36 renders each ([`crate::quality_search`]).
    pub importance: Option<std::sync::Arc<[f64]>>,
}

impl Default for StillTools {
    fn default() -> Self {
        StillTools {
            canonical_orientation: true,
            drop_invisible: true,
            trim_zero_sh_bands: true,
            reallocate_bits: 0,
            shape_tolerance: 0.0,
            tier_weights: Vec::new(),
            importance: None,
        }
    }
}

/// Fitting a lossy still scene's stored colours to what the rest decodes to.
#[derive(Debug, Clone, Default)]
pub struct RefitSettings {
    /// Fit the stored colours ([`crate::colour_refit`]), kept only if the encoder's held-out
    /// views render closer to the source. Codes the scene three times (first, then each of
    /// the two refits), plus the fit.
    pub colours: bool,
    /// With `colours`: first move the stored opacities along their quantiser's levels so the
    /// decoded scene renders closer to the source ([`dlgs_render::opacity_fit`]), then fit the
    /// colours to that. The judge sees this refit and the colours refit alone, and stores the
    /// one that renders closest: two fits, and the scene coded five times.
    pub opacities: bool,
    /// With `colours`: fit to views of 640x480 instead of 320x240
    /// ([`crate::colour_refit::fit_views`]): about 5x the fit's time for 0.1-0.3 dB.
    pub full_size: bool,
}

/// Time features, decoders and residuals of dynamic streams.
#[derive(Debug, Clone)]
pub struct DynamicSettings {
    /// Time-feature coding.
    pub features: FeatureCodec,
    /// One quantisation range for all channels (the reference) instead of one per channel.
    pub per_gop_range: bool,
    /// Storage type of the MLP weights.
    pub mlp_weights: WeightType,
    /// Explicit residuals of sequential/parallel scenes.
    pub residual: ResidualConfig,
}

impl Default for DynamicSettings {
    fn default() -> Self {
        DynamicSettings {
            features: FeatureCodec::Hevc(HevcSettings::default()),
            per_gop_range: false,
            mlp_weights: WeightType::F32,
            residual: ResidualConfig::default(),
        }
    }
}

/// The language decoder for queries.
#[derive(Debug, Clone)]
pub struct LanguageSettings {
    /// The scene's language autoencoder decoder (and canonical negatives), written as the
    /// scene-level `LAED` chunk so players can answer text queries (§6.8).
    pub decoder: Option<LangDecoder>,
    /// Storage type of the language decoder's values.
    pub weights: WeightType,
}

impl Default for LanguageSettings {
    fn default() -> Self {
        LanguageSettings {
            decoder: None,
            // f16 halves the chunk; the relevance it changes is measured in
            // docs/benchmarks/queries.md.
            weights: WeightType::F16,
        }
    }
}
