//! `dlgs-encoder`: turns scene models into `.dlgs` streams.
//!
//! Every GOP carries its canonical state, either in full (raw `CRAW`, or sorted quantised grids
//! `CSOG`) or, in sequential and parallel scenes from GOP 1 on, as a residual against the
//! reference GOP (binary voxel field `RNTC`, or explicit deltas `RDLT` computed closed-loop
//! against what the decoder will reconstruct); and, for dynamic scenes, the key time features
//! (`TFEA`, 12-bit HEVC or exact) and the deformation decoders (`MLPW`).

pub mod bit_allocation;
pub mod colour_refit;
pub mod grid_sort;
pub mod importance;
pub mod invisible;
pub mod orientation;
pub mod quality_search;
pub mod zero_bands;

use std::io::Write;

use dlgs::chunks::craw::{self, RawCodec};
use dlgs::chunks::csog::{self, QuantBits, RotationCoarsening};
use dlgs::chunks::mlpw::{self, WeightType};
use dlgs::chunks::tfea::{self, TfeaBody, Tiling};
use dlgs::chunks::{decode_canonical, laed, rdlt, rntc};
use dlgs::container::gop::{GopHeader, NO_REFERENCE};
use dlgs::container::{ChunkType, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
use dlgs::model::lang_decoder::LangDecoder;
use dlgs::model::ntc::NtcField;
use dlgs::model::residual::{AttrGroup, DeltaResidual, DeltaTarget};
use dlgs::model::DynamicGop;
use dlgs::{Canonical, Error, ErrorKind, Result};
pub use dlgs_video::HevcSettings;

/// How key time features are stored.
#[derive(Debug, Clone, PartialEq)]
pub enum FeatureCodec {
    /// Exact f32 (zstd): the lossless interchange form.
    Exact,
    /// Tiled 12-bit images coded with libx265 (the reference's feature video).
    Hevc(HevcSettings),
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

pub use grid_sort::SortSpec;

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

/// Encoder settings.
#[derive(Debug, Clone)]
pub struct EncoderConfig {
    /// Canonical Gaussians: raw or sorted quantised grids.
    pub canonical: CanonicalCodec,
    /// How `CRAW` bodies are stored.
    pub raw_codec: RawCodec,
    /// zstd level for `CRAW` when `raw_codec` is zstd (1..=22).
    pub zstd_level: i32,
    /// Free-form JSON written as the scene-level `META` chunk (provenance, credits).
    pub meta: Option<serde_json::Value>,
    /// Time-feature coding.
    pub features: FeatureCodec,
    /// One quantisation range for all channels (the reference) instead of one per channel.
    pub per_gop_range: bool,
    /// Storage type of the MLP weights.
    pub mlp_weights: WeightType,
    /// Explicit residuals of sequential/parallel scenes.
    pub residual: ResidualConfig,
    /// The scene's language autoencoder decoder (and canonical negatives), written as the
    /// scene-level `LAED` chunk so players can answer text queries (§6.8).
    pub lang_decoder: Option<LangDecoder>,
    /// Storage type of the language decoder's values.
    pub lang_decoder_weights: WeightType,
    /// `CSOG` of scenes without residual GOPs: store each static Gaussian with the rotation,
    /// among the 24 that give the same ellipsoid, closest to the identity (see
    /// [`orientation`]). Renders the same, codes smaller.
    pub canonical_orientation: bool,
    /// `CSOG` of still scenes (no dynamic Gaussians, one GOP): move up to this many bits
    /// between attribute groups where rendering says it pays ([`bit_allocation`]); 0 = use the
    /// bits as given.
    pub reallocate_bits: usize,
    /// Lossy (`CSOG`) still scenes: leave out the Gaussians no renderer draws (both opacities
    /// below 1/255, [`invisible`]). No pixel changes.
    pub drop_invisible: bool,
    /// Lossy (`CSOG`) still scenes: store SH only up to the highest band that holds a non-zero
    /// coefficient ([`zero_bands`]). No pixel changes.
    pub trim_zero_sh_bands: bool,
    /// Lossy (`CSOG`) still scenes: choose each level by estimated bits plus error weighted by
    /// the Gaussian's importance over this tolerance ([`importance`]), so Gaussians that add
    /// little to any image take levels that code smaller; 0 = nearest levels. Larger = smaller
    /// files, lower PSNR.
    pub shape_tolerance: f64,
    /// Lossy (`CSOG`) still scenes: the least important static Gaussians (by blending weight
    /// over [`importance::importance_views`]) that together hold at most `tier_weights[j]` of
    /// the total weight are stored in a part `j + 1` bits coarser in every group (layout 1,
    /// §6.5.2, [`importance::tiers`]); empty = one part. With `shape_tolerance`, every part
    /// is shaped ([`importance::part_shaping_weights`]).
    pub tier_weights: Vec<f64>,
    /// With `tier_weights` or `shape_tolerance`: the static Gaussians' blending weights as
    /// [`importance::blend_weights`] measures them on the set the encoder codes (after
    /// [`prepare_still`] and, with `canonical_orientation`, [`orientation`]); `None` (or a
    /// length that does not match) = measure them. Lets a search code one scene many times
    /// without 36 renders each ([`quality_search`]).
    pub importance: Option<std::sync::Arc<[f64]>>,
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
    /// smaller than any other coding by this fraction (format 1.13; default
    /// [`MIXED_MARGIN`](dlgs::chunks::csog::grid_coder::MIXED_MARGIN), `dlgs encode
    /// --mixed-margin`). `None` (`dlgs encode --fast-decode`): the same values in files 1.5-3.1 %
    /// larger that decode in about half the time (docs/benchmarks/decode.md "Decode time
    /// against SOG and SPZ").
    pub mixed_margin: Option<f64>,
    /// Lossy (`CSOG`) still scenes: fit the stored colours to what the rest decodes to
    /// ([`colour_refit`]), kept only if the encoder's held-out views render closer to the
    /// source. Codes the scene three times (first, then each of the two refits), plus the fit.
    pub refit_colours: bool,
    /// With [`Self::refit_colours`]: first move the stored opacities along their quantiser's
    /// levels so the decoded scene renders closer to the source
    /// ([`dlgs_render::opacity_fit`]), then fit the colours to that. The judge sees this refit
    /// and the colours refit alone, and stores the one that renders closest: two fits, and the
    /// scene coded five times.
    pub refit_opacities: bool,
    /// With [`Self::refit_colours`]: fit to views of 640x480 instead of 320x240
    /// ([`colour_refit::fit_views`]): about 5x the fit's time for 0.1-0.3 dB.
    pub refit_full_size: bool,
}

impl Default for EncoderConfig {
    fn default() -> Self {
        EncoderConfig {
            canonical: CanonicalCodec::Raw,
            raw_codec: RawCodec::Zstd,
            zstd_level: 9,
            meta: None,
            features: FeatureCodec::Hevc(HevcSettings::default()),
            per_gop_range: false,
            mlp_weights: WeightType::F32,
            residual: ResidualConfig::default(),
            lang_decoder: None,
            // f16 halves the chunk; the relevance it changes is measured in
            // docs/benchmarks/queries.md.
            lang_decoder_weights: WeightType::F16,
            canonical_orientation: true,
            reallocate_bits: 0,
            drop_invisible: true,
            trim_zero_sh_bands: true,
            shape_tolerance: 0.0,
            tier_weights: Vec::new(),
            importance: None,
            octree_positions: true,
            rotation_coarsening: Some(RotationCoarsening::DEFAULT),
            compact_records: true,
            mixed_margin: Some(dlgs::chunks::csog::grid_coder::MIXED_MARGIN),
            refit_colours: false,
            refit_opacities: false,
            refit_full_size: false,
        }
    }
}

/// Codes a canonical GOP's static parts: the `CSOG` payload and, per decoded static Gaussian,
/// its index in the parts' concatenation.
type CodeParts<'a> = dyn Fn(&[(dlgs::Gaussians, QuantBits)]) -> Result<(Vec<u8>, Vec<u32>)> + 'a;

/// Writes one GOP at a time, in order.
pub struct StreamEncoder<W: Write> {
    writer: Writer<W>,
    cfg: EncoderConfig,
    next_gop: u32,
    /// Decoded canonical state of the previous GOP and of GOP 0 (residual scenes only): what
    /// the decoder will hold, so residuals are computed closed-loop and errors do not drift.
    previous: Option<Canonical>,
    first: Option<Canonical>,
    /// The grid order GOP 0's static set was stored in (`CSOG`), applied to later full states.
    static_order: Option<Vec<u32>>,
    /// What [`bit_allocation::reallocate`] chose for GOP 0, when it ran.
    allocation: Option<bit_allocation::Allocation>,
    /// What the colour refit measured, when it ran.
    refit: Option<RefitReport>,
}

/// The colour refit's judgement ([`EncoderConfig::refit_colours`]): mean PSNR against the
/// source over [`colour_refit::holdout_views`], without and with the best refit (colours alone or,
/// with [`EncoderConfig::refit_opacities`], opacities and colours; each as offsets or on levels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefitReport {
    pub before_db: f64,
    pub after_db: f64,
    /// Whether the refit coding was stored (it rendered closer).
    pub kept: bool,
    /// Whether the better refit (`after_db`) was the one on the quantiser's levels, not the
    /// continuous offsets rounded by the coder.
    pub on_levels: bool,
    /// Whether the better refit moved opacities too ([`EncoderConfig::refit_opacities`]),
    /// not the colours alone.
    pub opacities_moved: bool,
}

/// One refit candidate: a fit's colours as continuous offsets or on the quantiser's levels,
/// with its opacity moves when the fit made them.
struct RefitChoice<'a> {
    fit: &'a colour_refit::Refits,
    opacity: Option<&'a colour_refit::OpacityLevels>,
    on_levels: bool,
}

impl RefitChoice<'_> {
    /// `parts` with this candidate's colours (and opacities) on the Gaussians `decoded` holds
    /// (`stored[k]`: Gaussian `k`'s index in the parts' concatenation, `place`: its part and
    /// index there).
    fn apply(
        &self,
        parts: &[(dlgs::Gaussians, QuantBits)],
        decoded: &dlgs::Gaussians,
        stored: &[u32],
        place: &[(usize, usize)],
        lattice: &colour_refit::DcLattice,
    ) -> Vec<(dlgs::Gaussians, QuantBits)> {
        let mut refit = parts.to_vec();
        for (k, &j) in stored.iter().enumerate() {
            let (p, i) = place[j as usize];
            if self.on_levels {
                lattice.set_dc(&mut refit[p].0, i, p, decoded, k, self.fit.on_levels[k]);
            } else {
                colour_refit::set_refit_dc(&mut refit[p].0, i, decoded, k, self.fit.offsets[k]);
            }
            if let Some(levels) = self.opacity {
                levels.set(&mut refit[p].0, i, k, self.fit.opacity_moves[k]);
            }
        }
        refit
    }
}

impl<W: Write> StreamEncoder<W> {
    pub fn new(out: W, scene: SceneHeader, cfg: EncoderConfig) -> Result<Self> {
        let mut writer = Writer::new(out, scene)?;
        if let Some(meta) = &cfg.meta {
            let bytes = serde_json::to_vec(meta)
                .map_err(|e| Error::new(ErrorKind::InvalidInput(e.to_string()), 0))?;
            writer.scene_chunk(ChunkType::META, 0, &bytes)?;
        }
        if let Some(d) = &cfg.lang_decoder {
            if writer.scene().lang_levels == 0 {
                return Err(Error::new(
                    ErrorKind::InvalidInput(
                        "a language decoder was given but the scene has no language features"
                            .into(),
                    ),
                    0,
                ));
            }
            if d.input_dims() != writer.scene().lang_dims as usize {
                return Err(Error::new(
                    ErrorKind::InvalidInput(format!(
                        "the language decoder takes {} dims, the scene has {} per level",
                        d.input_dims(),
                        writer.scene().lang_dims
                    )),
                    0,
                ));
            }
            let bytes = laed::encode(d, cfg.lang_decoder_weights, 19)?;
            writer.scene_chunk(ChunkType::LAED, 0, &bytes)?;
        }
        Ok(StreamEncoder {
            writer,
            cfg,
            next_gop: 0,
            previous: None,
            first: None,
            static_order: None,
            allocation: None,
            refit: None,
        })
    }

    /// Append the next GOP, coded intra from its canonical Gaussians (static scenes).
    pub fn push_intra_gop(&mut self, canon: &Canonical) -> Result<()> {
        self.push_gop(canon, None)
    }

    /// Append the next GOP: canonical Gaussians plus, when the scene has dynamic Gaussians,
    /// its deformation field.
    pub fn push_gop(&mut self, canon: &Canonical, dynamic: Option<&DynamicGop>) -> Result<()> {
        self.push(GopCanonical::State(canon), dynamic)
    }

    /// Append the next GOP from its canonical state or residual field.
    pub fn push(&mut self, canonical: GopCanonical, dynamic: Option<&DynamicGop>) -> Result<()> {
        self.push_coded(canonical, dynamic, None)
    }

    /// As [`Self::push`], with the time features already coded (`coded`, e.g. a trained model's
    /// own HEVC stream passed through unchanged); `dynamic.features` must be what `coded`
    /// decodes to, for the caller's own checks.
    pub fn push_coded(
        &mut self,
        canonical: GopCanonical,
        dynamic: Option<&DynamicGop>,
        coded: Option<&TfeaBody>,
    ) -> Result<()> {
        let s = self.writer.scene().clone();
        if let GopCanonical::State(canon) = canonical {
            check_layout(canon, &s)?;
        }
        let dyn_chunks = match (s.n_dynamic > 0, dynamic) {
            (false, None) => None,
            (true, Some(d)) => Some(self.dynamic_payloads(d, coded)?),
            (true, None) => {
                return Err(invalid(
                    "the scene has dynamic Gaussians but the GOP has no deformation field".into(),
                ))
            }
            (false, Some(_)) => {
                return Err(invalid(
                    "a deformation field for a scene without dynamic Gaussians".into(),
                ))
            }
        };
        let g = self.next_gop;
        let reference = GopHeader::expected(&s, g).reference_gop;
        let tracks_state = s.residual_mode != dlgs::container::header::ResidualMode::Intra;
        let (ty, payload, decoded) = if reference == NO_REFERENCE {
            let GopCanonical::State(canon) = canonical else {
                return Err(invalid(format!(
                    "GOP {g} has no reference GOP: it needs a full canonical state, not a residual"
                )));
            };
            let (ty, payload) = self.canonical_payload(canon, g == 0)?;
            let decoded = if tracks_state {
                let limits = dlgs::Limits::default();
                Some(decode_canonical(ty, &payload, 0, &s, &limits).expect("canonical chunk")?)
            } else {
                None
            };
            (ty, payload, decoded)
        } else {
            let base = if reference == 0 {
                self.first.as_ref()
            } else {
                self.previous.as_ref()
            }
            .expect("the reference GOP was encoded before");
            match canonical {
                GopCanonical::State(target) => {
                    let target = match &self.static_order {
                        Some(order) => Canonical {
                            statics: grid_sort::permute(&target.statics, order),
                            dynamics: target.dynamics.clone(),
                        },
                        None => target.clone(),
                    };
                    let groups = match (self.cfg.residual.follow_quantisation, self.cfg.canonical) {
                        (true, CanonicalCodec::Sorted { bits, .. }) => {
                            bounds_like_quantisation(&bits, &target)
                        }
                        _ => self.cfg.residual.groups.clone(),
                    };
                    let r = DeltaResidual::compute(&target, base, &groups)?;
                    let payload = rdlt::encode(&r, &s, self.cfg.zstd_level)?;
                    (ChunkType::RDLT, payload, Some(r.apply(base)))
                }
                GopCanonical::Ntc(field) => {
                    let payload = rntc::encode(field, &s, self.cfg.zstd_level)?;
                    (ChunkType::RNTC, payload, Some(field.apply(base)?))
                }
            }
        };
        self.writer.begin_gop()?;
        self.writer.gop_chunk(ty, FLAG_MUST_UNDERSTAND, &payload)?;
        if let Some((tfea, mlpw)) = dyn_chunks {
            self.writer
                .gop_chunk(ChunkType::TFEA, FLAG_MUST_UNDERSTAND, &tfea)?;
            self.writer
                .gop_chunk(ChunkType::MLPW, FLAG_MUST_UNDERSTAND, &mlpw)?;
        }
        if g == 0 {
            self.first = decoded.clone();
        }
        self.previous = decoded;
        self.next_gop += 1;
        Ok(())
    }

    /// A full canonical chunk (`CRAW` or `CSOG`); remembers GOP 0's grid order.
    fn canonical_payload(
        &mut self,
        canon: &Canonical,
        first: bool,
    ) -> Result<(ChunkType, Vec<u8>)> {
        Ok(match self.cfg.canonical {
            CanonicalCodec::Raw => (
                ChunkType::CRAW,
                craw::encode(canon, self.cfg.raw_codec, self.cfg.zstd_level)?,
            ),
            CanonicalCodec::Sorted { bits, sort } => {
                // Residual GOPs add offsets to the stored rotations and scales: only scenes
                // without them may change the representative.
                let intra = self.writer.scene().residual_mode
                    == dlgs::container::header::ResidualMode::Intra;
                let oriented;
                let statics = if intra && self.cfg.canonical_orientation {
                    oriented = orientation::closest_to_identity(&canon.statics);
                    &oriented
                } else {
                    &canon.statics
                };
                // Octree sets are stored in an order derived from their positions: sorting
                // them first would be wasted.
                let octree = self.cfg.octree_positions;
                let order = if octree {
                    (0..statics.len() as u32).collect()
                } else {
                    grid_sort::grid_order(statics, sort)
                };
                let sorted = Canonical {
                    statics: grid_sort::permute(statics, &order),
                    dynamics: canon.dynamics.clone(),
                };
                let mut bits = bits;
                let still = sorted.dynamics.is_empty() && self.writer.scene().gop_count == 1;
                if first && still && self.cfg.reallocate_bits > 0 {
                    let a = bit_allocation::reallocate(
                        &sorted.statics,
                        bits,
                        self.cfg.zstd_level,
                        self.cfg.reallocate_bits,
                        octree,
                        self.cfg.rotation_coarsening,
                        |_| {},
                    )?;
                    bits = a.bits;
                    self.allocation = Some(a);
                }
                let tiered = first && still && !self.cfg.tier_weights.is_empty();
                let shaped = first && still && self.cfg.shape_tolerance > 0.0;
                // Blending weights, for tiers and for shaping: given, or measured once.
                let blend: Option<std::borrow::Cow<[f64]>> =
                    (tiered || shaped).then(|| match &self.cfg.importance {
                        Some(b) if b.len() == statics.len() => b[..].into(),
                        _ => importance::blend_weights(statics).into(),
                    });
                let (parts, order) = match &blend {
                    // Each part is sorted on its own: that order is the one stored.
                    Some(blend) if tiered => importance::tiers(
                        statics,
                        blend,
                        &self.cfg.tier_weights,
                        sort,
                        bits,
                        !octree,
                    ),
                    _ => (vec![(sorted.statics, bits)], order),
                };
                let weights = blend.filter(|_| shaped).map(|blend| {
                    importance::part_shaping_weights(
                        &blend,
                        &order,
                        &parts,
                        self.cfg.shape_tolerance,
                    )
                });
                let zstd_level = self.cfg.zstd_level;
                let coarsening = self.cfg.rotation_coarsening;
                let compact_records = self.cfg.compact_records;
                let mixed_margin = self.cfg.mixed_margin;
                // The payload of `parts`, and per decoded static Gaussian its index in the
                // parts' concatenation.
                let code = |parts: &[(dlgs::Gaussians, QuantBits)]| -> Result<(Vec<u8>, Vec<u32>)> {
                    let gop = csog::PartedGop {
                        static_parts: parts,
                        static_weight: weights.as_deref(),
                        dynamics: &sorted.dynamics,
                        dynamic_bits: &bits,
                        rotation_coarsening: coarsening,
                        compact_records,
                        mixed_margin,
                    };
                    let identity = || (0..statics.len() as u32).collect();
                    Ok(if octree {
                        csog::encode_octree(&gop, zstd_level)?
                    } else {
                        // Layout 1 even for one part: since 1.12 it stores an empty dynamic set
                        // as no parts, where layout 0 writes every channel's record for it.
                        (csog::encode_grid_parts(&gop, zstd_level)?, identity())
                    })
                };
                let (mut payload, mut stored) = code(&parts)?;
                if first && still && self.cfg.refit_colours {
                    let refit = self.refit_colours(statics, &parts, &payload, &stored, &code)?;
                    if let Some(better) = refit {
                        (payload, stored) = better;
                    }
                }
                let order: Vec<u32> = stored.iter().map(|&k| order[k as usize]).collect();
                if first {
                    self.static_order = Some(order);
                }
                (ChunkType::CSOG, payload)
            }
        })
    }

    /// [`colour_refit`]: decode `payload` (the coding of `parts`), fit colour offsets to what
    /// it stores, code the parts again with the refit colours; `Some` (the new payload and
    /// stored order) only if the held-out views render closer to `source`. Records the
    /// held-out PSNRs in `self.refit`.
    fn refit_colours(
        &mut self,
        source: &dlgs::Gaussians,
        parts: &[(dlgs::Gaussians, QuantBits)],
        payload: &[u8],
        stored: &[u32],
        code: &CodeParts<'_>,
    ) -> Result<Option<(Vec<u8>, Vec<u32>)>> {
        let limits = dlgs::limits::Limits::default();
        let scene = self.writer.scene();
        let decoded = csog::decode(payload, 0, scene, &limits)?.statics;
        // Part, and index within it, of each Gaussian of the parts' concatenation.
        let mut place = Vec::with_capacity(stored.len());
        for (p, (g, _)) in parts.iter().enumerate() {
            place.extend((0..g.len()).map(|i| (p, i)));
        }
        let lattice = colour_refit::DcLattice::of_parts(parts);
        let (steps, moves) = lattice.steps_and_moves(&decoded, stored, &place);
        let opacity = self
            .cfg
            .refit_opacities
            .then(|| colour_refit::OpacityLevels::of(parts, &decoded, stored, &place));
        // The colours alone, then (when asked) the opacities and colours: the opacity search
        // can render worse on unseen views than the colours alone (gsplat's goal row), so the
        // judge sees both.
        let views = colour_refit::FitTargets::of(source, self.cfg.refit_full_size);
        let mut fits = vec![(
            colour_refit::fit(&views, &decoded, &steps, &moves, None),
            None,
        )];
        if let Some(levels) = &opacity {
            let with_opacity = colour_refit::fit(&views, &decoded, &steps, &moves, Some(levels));
            fits.push((with_opacity, Some(levels)));
        }
        // Each fit as continuous offsets rounded by the coder, then on the quantiser's levels.
        let mut codings = Vec::with_capacity(2 * fits.len());
        let mut redecoded = Vec::with_capacity(2 * fits.len());
        // Per coding: (on the quantiser's levels, opacities moved), for the report.
        let mut kinds = Vec::with_capacity(2 * fits.len());
        for (fit, levels) in &fits {
            for on_levels in [false, true] {
                let refit = RefitChoice {
                    fit,
                    opacity: *levels,
                    on_levels,
                };
                let coding = code(&refit.apply(parts, &decoded, stored, &place, &lattice))?;
                redecoded.push(csog::decode(&coding.0, 0, scene, &limits)?.statics);
                codings.push(coding);
                kinds.push((on_levels, levels.is_some()));
            }
        }
        let mut candidates = vec![&decoded];
        candidates.extend(redecoded.iter());
        let scores = colour_refit::holdout_psnr(source, &candidates);
        // The best refit, the later one on a tie (levels before offsets, opacities and colours
        // before colours alone); stored only if it beats the first coding.
        let best = (2..scores.len()).fold(1, |b, c| if scores[c] >= scores[b] { c } else { b });
        let kept = scores[best] > scores[0];
        self.refit = Some(RefitReport {
            before_db: scores[0],
            after_db: scores[best],
            kept,
            on_levels: kinds[best - 1].0,
            opacities_moved: kinds[best - 1].1,
        });
        Ok(kept.then(|| codings.swap_remove(best - 1)))
    }

    fn dynamic_payloads(
        &self,
        d: &DynamicGop,
        coded: Option<&TfeaBody>,
    ) -> Result<(Vec<u8>, Vec<u8>)> {
        let s = self.writer.scene();
        let f = &d.features;
        if f.n != s.n_dynamic as usize
            || f.keys != s.keys_per_gop() as usize
            || f.channels != s.time_channels as usize
            || f.data.len() != f.n * f.keys * f.channels
        {
            return Err(invalid(format!(
                "time features ({}, {}, {}) do not match the scene ({}, {}, {})",
                f.n,
                f.keys,
                f.channels,
                s.n_dynamic,
                s.keys_per_gop(),
                s.time_channels
            )));
        }
        dlgs::model::dynamic::check_finite("time features", &f.data)?;
        d.mlps.validate(s, 0).map_err(|e| invalid(e.to_string()))?;
        let body = match (&self.cfg.features, coded) {
            (_, Some(c)) => c.clone(),
            (FeatureCodec::Exact, None) => TfeaBody::Exact(f.clone()),
            (FeatureCodec::Hevc(settings), None) => {
                let tiling = Tiling::for_count(f.n, f.keys, f.channels);
                let ranges = tfea::ranges(f, self.cfg.per_gop_range);
                let video = dlgs_video::Gray12 {
                    width: tiling.width() as u32,
                    height: tiling.height() as u32,
                    frames: tfea::tile(f, &tiling, &ranges),
                };
                let packets = dlgs_video::encode_gray12(&video, settings)
                    .map_err(|e| invalid(format!("time-feature video: {e}")))?;
                TfeaBody::Hevc {
                    tiling,
                    ranges,
                    reference: None,
                    packets,
                    intra: settings.intra_only,
                }
            }
        };
        let tfea = tfea::encode(&body, self.cfg.zstd_level)?;
        let mlpw = mlpw::encode(&d.mlps, self.cfg.mlp_weights, self.cfg.zstd_level)?;
        Ok((tfea, mlpw))
    }

    pub fn scene(&self) -> &SceneHeader {
        self.writer.scene()
    }

    /// The bits [`EncoderConfig::reallocate_bits`] chose, when it ran.
    pub fn allocation(&self) -> Option<&bit_allocation::Allocation> {
        self.allocation.as_ref()
    }

    /// What the colour refit measured for GOP 0, when it ran.
    pub fn refit(&self) -> Option<RefitReport> {
        self.refit
    }

    pub fn finish(self) -> Result<W> {
        self.writer.finish()
    }
}

/// Encode a single still frame (one GOP, one frame) from static Gaussians.
pub fn encode_still<W: Write>(g: &dlgs::Gaussians, cfg: EncoderConfig, out: W) -> Result<W> {
    encode_still_reporting(g, cfg, out).map(|(w, _)| w)
}

/// What a lossy still scene loses before coding, by `cfg`: the Gaussians no renderer draws
/// ([`invisible`]) and the SH bands that are zero everywhere ([`zero_bands`]); neither changes a
/// pixel. `None` when nothing changes; also the number of Gaussians left out.
pub fn prepare_still(g: &dlgs::Gaussians, cfg: &EncoderConfig) -> (Option<dlgs::Gaussians>, usize) {
    let lossy = matches!(cfg.canonical, CanonicalCodec::Sorted { .. });
    let mut out = None;
    let mut dropped = 0;
    if lossy && cfg.drop_invisible {
        let (kept, n) = invisible::drop_never_drawn(g);
        if n > 0 {
            out = Some(kept);
            dropped = n;
        }
    }
    if lossy && cfg.trim_zero_sh_bands {
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
    /// What [`EncoderConfig::reallocate_bits`] chose, when it ran.
    pub allocation: Option<bit_allocation::Allocation>,
    /// Gaussians left out because no renderer draws them ([`EncoderConfig::drop_invisible`]).
    pub dropped_invisible: usize,
    /// The SH degree stored: below the input's when [`EncoderConfig::trim_zero_sh_bands`]
    /// left out zero bands.
    pub sh_degree: u8,
    /// What the colour refit measured, when it ran ([`EncoderConfig::refit_colours`]).
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

fn check_layout(canon: &Canonical, s: &SceneHeader) -> Result<()> {
    if canon.statics.len() != s.n_static as usize || canon.dynamics.len() != s.n_dynamic as usize {
        return Err(invalid(format!(
            "GOP has {}/{} static/dynamic Gaussians, header declares {}/{}",
            canon.statics.len(),
            canon.dynamics.len(),
            s.n_static,
            s.n_dynamic
        )));
    }
    if canon.statics.sh_degree != s.sh_degree || canon.statics.lang_width != s.lang_width() {
        return Err(invalid(
            "GOP layout differs from the header (SH degree or language width)".into(),
        ));
    }
    Ok(())
}

fn invalid(msg: String) -> Error {
    Error::new(ErrorKind::InvalidInput(msg), 0)
}
