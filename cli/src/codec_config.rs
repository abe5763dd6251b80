//! The [`EncoderConfig`] that [`CodecArgs`] make: residual settings, the whole encoder
//! configuration and the language decoder for queries, from the parsed options.

use anyhow::{bail, Context, Result};
use dlgs::chunks::craw::RawCodec;
use dlgs::chunks::csog::RotationCoarsening;
use dlgs::chunks::mlpw::WeightType;
use dlgs::model::lang_decoder::LangDecoder;
use dlgs::model::residual::{AttrGroup, DeltaTarget};
use dlgs_encoder::{
    CanonicalCodec, EncoderConfig, FastStart, FeatureCodec, HevcSettings, ResidualConfig,
};

use crate::codec_args::CodecArgs;

impl CodecArgs {
    fn residual(&self) -> Result<ResidualConfig> {
        // Lossy canonical coding without explicit bounds: residual GOPs as lossy as GOP 0.
        let mut cfg = ResidualConfig {
            follow_quantisation: self.residual_error.is_none()
                && !matches!(self.canonical()?, CanonicalCodec::Raw),
            ..Default::default()
        };
        for kv in self
            .residual_error
            .as_deref()
            .unwrap_or("")
            .split(',')
            .filter(|s| !s.is_empty())
        {
            let (k, v) = kv
                .split_once('=')
                .with_context(|| format!("--residual-error: `{kv}` is not group=bound"))?;
            let group = AttrGroup::from_name(k)
                .with_context(|| format!("--residual-error: unknown group `{k}`"))?;
            let target = if v == "exact" {
                DeltaTarget::Exact
            } else {
                let b: f32 = v
                    .parse()
                    .ok()
                    .filter(|b: &f32| b.is_finite() && *b > 0.0)
                    .with_context(|| {
                        format!("--residual-error {k}: `{v}` is not a positive bound or `exact`")
                    })?;
                DeltaTarget::Bound(b)
            };
            for e in cfg.groups.iter_mut().filter(|e| e.0 == group) {
                e.1 = target;
            }
        }
        Ok(cfg)
    }

    pub fn config(&self, meta: serde_json::Value) -> Result<EncoderConfig> {
        if self.target_psnr.is_some() {
            bail!(
                "--target-psnr searches the settings of a still scene (PLY, .splat, SPZ, SOG input); \
                 give --quality (and --bits, --tiers) for this input"
            );
        }
        if !(self.shape.is_finite() && self.shape >= 0.0) {
            bail!("--shape takes a tolerance >= 0, got {}", self.shape);
        }
        if let Some(f) = self
            .tiers
            .iter()
            .find(|f| !(f.is_finite() && (0.0..1.0).contains(*f)))
        {
            bail!("--tiers takes weight fractions in [0, 1), got {f}");
        }
        if self.tiers.windows(2).any(|w| w[1] > w[0]) {
            bail!("--tiers fractions must not increase (each coarser grid holds less weight)");
        }
        if self.tiers.len() >= dlgs::chunks::csog::MAX_PARTS {
            bail!(
                "--tiers: at most {} fractions",
                dlgs::chunks::csog::MAX_PARTS - 1
            );
        }
        if let Some(f) = self.coarse_rotations {
            if !(f.is_finite() && f >= 0.0) {
                bail!("--coarse-rotations takes a factor >= 0, got {f}");
            }
            if f > 0.0 && self.grid_positions {
                bail!("--coarse-rotations needs octree positions: drop --grid-positions");
            }
        }
        if self.sort_passes > 0 && !self.grid_positions {
            bail!(
                "--sort-passes orders grid positions: give --grid-positions too (octree \
                 positions fix the order themselves)"
            );
        }
        Ok(EncoderConfig {
            container: dlgs_encoder::ContainerSettings {
                zstd_level: self.zstd_level,
                meta: (!self.no_meta).then_some(meta),
            },
            coding: dlgs_encoder::CanonicalSettings {
                codec: self.canonical()?,
                raw_codec: if self.no_zstd {
                    RawCodec::None
                } else {
                    RawCodec::Zstd
                },
                compact_records: true,
                mixed_margin: self.mixed_margin()?,
                octree_positions: !self.grid_positions,
                rotation_coarsening: match self.coarse_rotations {
                    None if self.grid_positions => None,
                    None => Some(RotationCoarsening::DEFAULT),
                    Some(f) if f > 0.0 => Some(RotationCoarsening {
                        factor: f,
                        ..RotationCoarsening::DEFAULT
                    }),
                    Some(_) => None,
                },
            },
            still: dlgs_encoder::StillTools {
                canonical_orientation: !self.keep_orientation,
                drop_invisible: !self.keep_invisible,
                trim_zero_sh_bands: !self.keep_sh_degree,
                reallocate_bits: self.reallocate_bits,
                shape_tolerance: self.shape,
                tier_weights: self.tiers.iter().copied().filter(|&f| f > 0.0).collect(),
                importance: None,
            },
            refit: dlgs_encoder::RefitSettings {
                colours: self.refit_colours,
                opacities: self.refit_opacities,
                full_size: self.refit_full_size,
            },
            dynamic: dlgs_encoder::DynamicSettings {
                features: if self.exact_features {
                    FeatureCodec::Exact
                } else if let Some(bits) = self.quantised_features {
                    FeatureCodec::Quantised {
                        bits,
                        predictor: None,
                    }
                } else {
                    FeatureCodec::Hevc(HevcSettings {
                        crf: self.crf,
                        preset: self.preset.clone(),
                        lossless: self.lossless_features,
                        intra_only: self.intra_features,
                        fast_start: match self.fast_start.as_str() {
                            "all" => FastStart::EveryGop,
                            "off" => FastStart::Off,
                            _ => FastStart::FirstGop,
                        },
                    })
                },
                per_gop_range: self.per_gop_range,
                mlp_weights: if self.mlp_f16 || self.quality() == "near-lossless" {
                    WeightType::F16
                } else {
                    WeightType::F32
                },
                residual: self.residual()?,
            },
            language: dlgs_encoder::LanguageSettings {
                decoder: self.lang_decoder()?,
                weights: if self.lang_decoder_f32 {
                    WeightType::F32
                } else {
                    WeightType::F16
                },
            },
        })
    }

    /// The decoder given with `--lang-decoder` (and `--negatives`), if any.
    fn lang_decoder(&self) -> Result<Option<LangDecoder>> {
        let Some(path) = &self.lang_decoder else {
            if self.negatives.is_some() {
                bail!("--negatives is stored with the language decoder: give --lang-decoder too");
            }
            return Ok(None);
        };
        let mut d = dlgs_query::decoder_io::load_lang_decoder(path)?;
        if let Some(n) = &self.negatives {
            let e = dlgs_query::read_embeddings(n)?;
            if e.dims != d.embed_dims() {
                bail!(
                    "{}: negatives have {} dims, the decoder outputs {}",
                    n.display(),
                    e.dims,
                    d.embed_dims()
                );
            }
            d.negatives = e.to_named();
        }
        Ok(Some(d))
    }
}
