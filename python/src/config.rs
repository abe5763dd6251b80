//! The encoder settings a Python caller picks, mapped to [`EncoderConfig`] exactly as the
//! CLI's `CodecArgs::config` maps the same options (so the bytes are the CLI's).

use dlgs::chunks::csog::grid_codecs::MIXED_MARGIN;
use dlgs::chunks::csog::QuantBits;
use dlgs::chunks::mlpw::WeightType;
use dlgs::model::lang_decoder::LangDecoder;
use dlgs_encoder::{
    CanonicalCodec, CanonicalSettings, DynamicSettings, EncoderConfig, FastStart, FeatureCodec,
    HevcSettings, ResidualConfig, SortSpec,
};

use crate::errors::{request, Res};

/// The options of `dlgs encode` the bindings expose (the others keep the CLI's defaults).
#[derive(Clone)]
pub struct CodecOptions {
    pub quality: String,
    pub crf: u8,
    pub preset: String,
    pub exact_features: bool,
    /// `TFEA` codec 4 at this many bits (6-12), the web player's codec.
    pub quantised_features: Option<u8>,
    pub lossless_features: bool,
    pub intra_features: bool,
    pub fast_start: FastStart,
    pub per_gop_range: bool,
    pub mlp_f16: bool,
    /// Codec 5's mixed-context modes (`dlgs encode --max-compression`): 2 % smaller canonical
    /// chunks that decode about half as fast. Off by default, as in the CLI.
    pub max_compression: bool,
    pub zstd_level: i32,
    pub meta: Option<serde_json::Value>,
    pub lang_decoder: Option<LangDecoder>,
}

impl CodecOptions {
    fn canonical(&self) -> Res<CanonicalCodec> {
        if self.quality == "lossless" {
            return Ok(CanonicalCodec::Raw);
        }
        let bits = QuantBits::preset(&self.quality).ok_or_else(|| {
            request(format!(
                "quality `{}`: expected lossless, near-lossless, high, medium or low",
                self.quality
            ))
        })?;
        Ok(CanonicalCodec::Sorted {
            bits,
            sort: SortSpec { passes: 0 },
        })
    }

    pub fn config(&self) -> Res<EncoderConfig> {
        let codec = self.canonical()?;
        if !(1..=22).contains(&self.zstd_level) {
            return Err(request("zstd_level: 1..=22"));
        }
        Ok(EncoderConfig {
            container: dlgs_encoder::ContainerSettings {
                zstd_level: self.zstd_level,
                meta: self.meta.clone(),
            },
            coding: CanonicalSettings {
                codec,
                // `--max-compression`'s margin, a percentage in the CLI: the same arithmetic.
                mixed_margin: self.max_compression.then_some(100.0 * MIXED_MARGIN / 100.0),
                ..CanonicalSettings::default()
            },
            dynamic: DynamicSettings {
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
                        fast_start: self.fast_start,
                    })
                },
                per_gop_range: self.per_gop_range,
                mlp_weights: if self.mlp_f16 || self.quality == "near-lossless" {
                    WeightType::F16
                } else {
                    WeightType::F32
                },
                residual: ResidualConfig {
                    follow_quantisation: !matches!(codec, CanonicalCodec::Raw),
                    ..Default::default()
                },
            },
            language: dlgs_encoder::LanguageSettings {
                decoder: self.lang_decoder.clone(),
                ..Default::default()
            },
            ..EncoderConfig::default()
        })
    }
}

/// `meta` (any JSON-serialisable object) as the `META` chunk's JSON.
pub fn meta_from_py(
    py: pyo3::Python<'_>,
    meta: Option<&pyo3::Bound<'_, pyo3::PyAny>>,
) -> Res<Option<serde_json::Value>> {
    use pyo3::types::PyAnyMethods;
    let Some(m) = meta else { return Ok(None) };
    let text: String = py.import("json")?.call_method1("dumps", (m,))?.extract()?;
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| request(format!("meta: {e}")))
}

/// The language decoder at `path` (safetensors, as `--lang-decoder`) with `negatives` (K, D).
pub fn lang_decoder_from_py(
    path: Option<std::path::PathBuf>,
    negatives: Option<&pyo3::Bound<'_, pyo3::PyAny>>,
) -> Res<Option<LangDecoder>> {
    let Some(p) = path else {
        if negatives.is_some() {
            return Err(request(
                "negatives are stored with the language decoder: give lang_decoder",
            ));
        }
        return Ok(None);
    };
    let mut d = dlgs_query::decoder_io::load_lang_decoder(&p).map_err(crate::errors::other)?;
    if let Some(n) = negatives {
        let (v, s) = crate::arrays::read_f32(n, "negatives")?;
        let e = crate::view::embeddings(v, &s, "negatives")?;
        if e.dims != d.embed_dims() {
            return Err(request(format!(
                "negatives have {} dims, the decoder outputs {}",
                e.dims,
                d.embed_dims()
            )));
        }
        d.negatives = e.to_named();
    }
    Ok(Some(d))
}

/// Frames per second as the header's fraction: integers exactly, NTSC rates as /1001.
pub fn fps_fraction(fps: f64) -> Res<(u32, u32)> {
    if !(fps.is_finite() && fps > 0.0 && fps < 1e6) {
        return Err(request(format!("fps {fps}: expected a positive rate")));
    }
    if fps.fract() == 0.0 {
        return Ok((fps as u32, 1));
    }
    let ntsc = fps * 1001.0;
    if (ntsc - ntsc.round()).abs() < 1e-6 {
        return Ok((ntsc.round() as u32, 1001));
    }
    Ok(((fps * 1000.0).round() as u32, 1000))
}

/// `fast_start` as the CLI's `--fast-start` spells it.
pub fn parse_fast_start(s: &str) -> Res<FastStart> {
    Ok(match s {
        "first" => FastStart::FirstGop,
        "all" => FastStart::EveryGop,
        "off" => FastStart::Off,
        _ => return Err(request(format!("fast_start `{s}`: first, all or off"))),
    })
}
