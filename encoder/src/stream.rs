//! The stream encoder: one GOP at a time, in order. Each GOP's canonical state in full (`CRAW`,
//! `CSOG`) or as a residual against its reference GOP (`RNTC`, `RDLT` closed-loop), then its
//! time features (`TFEA`) and decoders (`MLPW`).

use std::io::Write;

use crate::config::{
    bounds_like_quantisation, CanonicalCodec, EncoderConfig, FeatureCodec, GopCanonical,
};
use dlgs::chunks::craw;
use dlgs::chunks::csog::{self, QuantBits};
use dlgs::chunks::mlpw;
use dlgs::chunks::tfea::{self, TfeaBody, Tiling};
use dlgs::chunks::{decode_canonical, laed, rdlt, rntc};
use dlgs::container::gop::{GopHeader, NO_REFERENCE};
use dlgs::container::{ChunkType, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
use dlgs::model::residual::DeltaResidual;
use dlgs::model::DynamicGop;
use dlgs::{Canonical, Error, Result};

use crate::refit_stage::{self, RefitReport};
use crate::{bit_allocation, grid_sort, importance, orientation};

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

impl<W: Write> StreamEncoder<W> {
    pub fn new(out: W, scene: SceneHeader, cfg: EncoderConfig) -> Result<Self> {
        let mut writer = Writer::new(out, scene)?;
        if let Some(meta) = &cfg.container.meta {
            let bytes = serde_json::to_vec(meta).map_err(|e| Error::input(e.to_string()))?;
            writer.scene_chunk(ChunkType::META, 0, &bytes)?;
        }
        if let Some(d) = &cfg.language.decoder {
            if writer.scene().lang_levels == 0 {
                return Err(Error::input(
                    "a language decoder was given but the scene has no language features",
                ));
            }
            if d.input_dims() != writer.scene().lang_dims as usize {
                return Err(Error::input(format!(
                    "the language decoder takes {} dims, the scene has {} per level",
                    d.input_dims(),
                    writer.scene().lang_dims
                )));
            }
            let bytes = laed::encode(d, cfg.language.weights, 19)?;
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

    /// The decoded canonical state the next GOP's residual will be applied to (GOP g-1's or
    /// GOP 0's, as the decoder holds it), or `None` for intra scenes and before GOP 0.
    pub fn reference_state(&self) -> Option<&Canonical> {
        let s = self.writer.scene();
        match GopHeader::expected(s, self.next_gop).reference_gop {
            NO_REFERENCE => None,
            0 => self.first.as_ref(),
            _ => self.previous.as_ref(),
        }
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
                return Err(Error::input(
                    "the scene has dynamic Gaussians but the GOP has no deformation field",
                ))
            }
            (false, Some(_)) => {
                return Err(Error::input(
                    "a deformation field for a scene without dynamic Gaussians",
                ))
            }
        };
        let g = self.next_gop;
        let reference = GopHeader::expected(&s, g).reference_gop;
        let tracks_state = s.residual_mode != dlgs::container::header::ResidualMode::Intra;
        let (ty, payload, decoded) = if reference == NO_REFERENCE {
            // A refresh GOP of a sequential scene (§4.1 `refresh_interval`) given as a residual
            // carries the state that residual gives: the previous GOP's decoded state plus it.
            let applied;
            let (canon, caller_order) = match canonical {
                GopCanonical::State(c) => (c, true),
                GopCanonical::Ntc(f) if g > 0 && tracks_state => {
                    let prev = self.previous.as_ref().expect("GOP g-1 was encoded");
                    applied = f.apply(prev)?;
                    (&applied, false)
                }
                GopCanonical::Ntc(_) => {
                    return Err(Error::input(format!(
                    "GOP {g} has no reference GOP: it needs a full canonical state, not a residual"
                )))
                }
            };
            let (ty, payload, order) = self.canonical_payload(canon, g == 0)?;
            if tracks_state {
                // Later explicit residuals target the caller's Gaussians: keep the map from
                // this GOP's decoded order to the caller's.
                self.static_order = match (order, caller_order, self.static_order.take()) {
                    (None, true, _) => None,
                    (None, false, prev) => prev,
                    (Some(o), true, _) => Some(o),
                    (Some(o), false, None) => Some(o),
                    (Some(o), false, Some(prev)) => {
                        Some(o.iter().map(|&k| prev[k as usize]).collect())
                    }
                };
            }
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
                    let groups = match (
                        self.cfg.dynamic.residual.follow_quantisation,
                        self.cfg.coding.codec,
                    ) {
                        (true, CanonicalCodec::Sorted { bits, .. }) => {
                            bounds_like_quantisation(&bits, &target)
                        }
                        _ => self.cfg.dynamic.residual.groups.clone(),
                    };
                    let r = DeltaResidual::compute(&target, base, &groups)?;
                    let payload = rdlt::encode(&r, &s, self.cfg.container.zstd_level)?;
                    (ChunkType::RDLT, payload, Some(r.apply(base)))
                }
                GopCanonical::Ntc(field) => {
                    let payload = rntc::encode(field, &s, self.cfg.container.zstd_level)?;
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
        // Gaussians shown for only part of the GOP (§6.14, since 1.18).
        if let Some(life) = dynamic.and_then(|d| d.life.as_ref()) {
            let payload =
                dlgs::chunks::life::encode(life, s.n_dynamic, self.cfg.container.zstd_level)?;
            self.writer
                .gop_chunk(ChunkType::LIFE, FLAG_MUST_UNDERSTAND, &payload)?;
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
    ) -> Result<(ChunkType, Vec<u8>, Option<Vec<u32>>)> {
        Ok(match self.cfg.coding.codec {
            CanonicalCodec::Raw => (
                ChunkType::CRAW,
                craw::encode(
                    canon,
                    self.cfg.coding.raw_codec,
                    self.cfg.container.zstd_level,
                )?,
                None,
            ),
            CanonicalCodec::Sorted { bits, sort } => {
                // Residual GOPs add offsets to the stored rotations and scales: only scenes
                // without them may change the representative.
                let intra = self.writer.scene().residual_mode
                    == dlgs::container::header::ResidualMode::Intra;
                let oriented;
                let statics = if intra && self.cfg.still.canonical_orientation {
                    oriented = orientation::closest_to_identity(&canon.statics);
                    &oriented
                } else {
                    &canon.statics
                };
                // Octree sets are stored in an order derived from their positions: sorting
                // them first would be wasted.
                let octree = self.cfg.coding.octree_positions;
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
                if first && still && self.cfg.still.reallocate_bits > 0 {
                    let a = bit_allocation::reallocate(
                        &sorted.statics,
                        bits,
                        self.cfg.container.zstd_level,
                        self.cfg.still.reallocate_bits,
                        octree,
                        self.cfg.coding.rotation_coarsening,
                        |_| {},
                    )?;
                    bits = a.bits;
                    self.allocation = Some(a);
                }
                let tiered = first && still && !self.cfg.still.tier_weights.is_empty();
                let shaped = first && still && self.cfg.still.shape_tolerance > 0.0;
                // Blending weights, for tiers and for shaping: given, or measured once.
                let blend: Option<std::borrow::Cow<[f64]>> =
                    (tiered || shaped).then(|| match &self.cfg.still.importance {
                        Some(b) if b.len() == statics.len() => b[..].into(),
                        _ => importance::blend_weights(statics).into(),
                    });
                let (parts, order) = match &blend {
                    // Each part is sorted on its own: that order is the one stored.
                    Some(blend) if tiered => importance::tiers(
                        statics,
                        blend,
                        &self.cfg.still.tier_weights,
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
                        self.cfg.still.shape_tolerance,
                    )
                });
                let zstd_level = self.cfg.container.zstd_level;
                let coarsening = self.cfg.coding.rotation_coarsening;
                let compact_records = self.cfg.coding.compact_records;
                let mixed_margin = self.cfg.coding.mixed_margin;
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
                if first && still && self.cfg.refit.colours {
                    let (refit, report) = refit_stage::refit_colours(
                        self.writer.scene(),
                        &self.cfg.refit,
                        statics,
                        &parts,
                        &payload,
                        &stored,
                        &code,
                    )?;
                    self.refit = Some(report);
                    if let Some(better) = refit {
                        (payload, stored) = better;
                    }
                }
                let order: Vec<u32> = stored.iter().map(|&k| order[k as usize]).collect();
                (ChunkType::CSOG, payload, Some(order))
            }
        })
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
            return Err(Error::input(format!(
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
        d.mlps
            .validate(s, 0)
            .map_err(|e| Error::input(e.to_string()))?;
        let body = match (&self.cfg.dynamic.features, coded) {
            (_, Some(c)) => c.clone(),
            (FeatureCodec::Exact, None) => TfeaBody::Exact(f.clone()),
            (FeatureCodec::Quantised { bits, predictor }, None) => {
                TfeaBody::Quantised(tfea::Quantised::from_features(f, *bits, *predictor)?)
            }
            (FeatureCodec::Hevc(settings), None) => {
                let tiling = Tiling::for_count(f.n, f.keys, f.channels);
                let ranges = tfea::ranges(f, self.cfg.dynamic.per_gop_range);
                let video = dlgs_video::Gray12 {
                    width: tiling.width() as u32,
                    height: tiling.height() as u32,
                    frames: tfea::tile(f, &tiling, &ranges),
                };
                let settings = settings.for_gop(self.next_gop);
                let packets = dlgs_video::encode_gray12(&video, &settings)
                    .map_err(|e| Error::input(format!("time-feature video: {e}")))?;
                TfeaBody::Hevc {
                    tiling,
                    ranges,
                    reference: None,
                    packets,
                    intra: settings.intra_only,
                }
            }
        };
        let tfea = tfea::encode(&body, self.cfg.container.zstd_level)?;
        let mlpw = mlpw::encode(
            &d.mlps,
            self.cfg.dynamic.mlp_weights,
            self.cfg.container.zstd_level,
        )?;
        Ok((tfea, mlpw))
    }

    pub fn scene(&self) -> &SceneHeader {
        self.writer.scene()
    }

    /// The bits [`crate::StillTools::reallocate_bits`] chose, when it ran.
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

fn check_layout(canon: &Canonical, s: &SceneHeader) -> Result<()> {
    if canon.statics.len() != s.n_static as usize || canon.dynamics.len() != s.n_dynamic as usize {
        return Err(Error::input(format!(
            "GOP has {}/{} static/dynamic Gaussians, header declares {}/{}",
            canon.statics.len(),
            canon.dynamics.len(),
            s.n_static,
            s.n_dynamic
        )));
    }
    if canon.statics.sh_degree != s.sh_degree || canon.statics.lang_width != s.lang_width() {
        return Err(Error::input(
            "GOP layout differs from the header (SH degree or language width)",
        ));
    }
    Ok(())
}
