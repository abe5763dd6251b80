//! `dlgs encode` (splat scene -> still, or .dlgs -> re-encoded .dlgs) and `dlgs synth`.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use dlgs::container::header::{DeformModel, ResidualMode};
use dlgs::model::lang_decoder::LangDecoder;
use dlgs::model::residual::{AttrGroup, DeltaTarget};
use dlgs::payload::grid_coder;
use dlgs::payload::mlp_weights::WeightType;
use dlgs::payload::raw_canonical::RawCodec;
use dlgs::payload::sorted_grid::{QuantBits, RotationCoarsening};
use dlgs_decoder::Decoder;
use dlgs_encoder::synth::{synth_dynamic, SynthSpec};
use dlgs_encoder::{
    CanonicalCodec, EncoderConfig, FeatureCodec, GopCanonical, HevcSettings, ResidualConfig,
    SortSpec, StreamEncoder,
};
use indicatif::{ProgressBar, ProgressStyle};

use crate::pending_file::PendingFile;
use crate::scene_io::is_dlgs;

/// Encoder settings shared by `encode` and `synth`.
#[derive(Args, Debug, Clone, serde::Serialize)]
pub struct CodecArgs {
    /// Canonical Gaussians: `lossless` (f32, CRAW) or sorted quantised grids (CSOG) at preset
    /// `near-lossless`, `high`, `medium` or `low` (bits per attribute in format-spec §6.5).
    /// `near-lossless` also stores the decoders in f16 (as `--mlp-f16`): on the reference-run
    /// fixture it renders at >= 64 dB against the lossless model (BENCHMARKS.md "Ingest").
    #[arg(long, default_value = "lossless")]
    pub quality: String,
    /// Override quantisation bits, e.g. `position=15,sh_rest=5` (keys: position, log_scale,
    /// rotation, opacity, sh_dc, sh_rest (SH band 1), sh_high (SH bands 2-3), lang). Implies grid coding (preset `high` if
    /// `--quality lossless`).
    #[arg(long)]
    pub bits: Option<String>,
    /// Grid sort refinement passes per radius (PLAS-style, after the k-d layout). 0 (default)
    /// = the k-d layout only: fastest and, on every real scene measured, the smallest files;
    /// refinement smooths colours at the cost of position coherence (BENCHMARKS.md "Grid sort").
    #[arg(long, default_value_t = 0)]
    pub sort_passes: u32,
    /// Keep each static Gaussian's rotation as given. By default, scenes without residual GOPs
    /// store, among the 24 (rotation, axis order) pairs that give the same ellipsoid, the one
    /// closest to the identity: same rendering, 2-4 bits less per Gaussian.
    #[arg(long)]
    pub keep_orientation: bool,
    /// Store the static Gaussians' positions as grid channels, in the grid sort's order
    /// (layout 1), as files before format 1.10. By default they are an octree and the
    /// Gaussians are stored in an order every reader derives from the positions (layouts 2-4,
    /// format-spec §6.5.5): 13-14 % fewer position bytes on the real scenes (2-5 % of the file);
    /// grid positions decode faster (273k Gaussians at `high`: 161-186 ms instead of 238-253,
    /// in a 6.5 % larger file that also keeps every rotation at full bits; BENCHMARKS.md
    /// "Decode time")
    #[arg(long)]
    pub grid_positions: bool,
    /// Octree positions: store the rotation of each Gaussian too small for one rotation step
    /// to move its surface by FACTOR position steps up to 4 bits coarser, one bit per halving
    /// of its largest scale (layout 3, format-spec §6.5.6). 0 = every rotation at the preset's
    /// bits (layout 2, as files of format 1.10). The default, 1, makes SH 0 scenes and gsplat
    /// 1-4 % smaller for 0.00-0.33 dB (BENCHMARKS.md "Coarse rotations"); 2 saves about twice
    /// as much for up to 1.7 dB. [default: 1, or 0 with --grid-positions]
    #[arg(long, value_name = "FACTOR")]
    pub coarse_rotations: Option<f32>,
    /// Keep the Gaussians no renderer draws. By default a lossy (`--quality` other than
    /// `lossless`) still scene leaves out every Gaussian whose opacities are below 1/255: they
    /// never reach the 1/255 alpha at which 3DGS compositing starts, so no pixel changes.
    #[arg(long)]
    pub keep_invisible: bool,
    /// Keep the input's SH degree. By default a lossy still scene is stored only up to the
    /// highest SH band that holds a non-zero coefficient (the gs3d tiles declare degree 3 with
    /// bands 1-3 zero everywhere): zero bands add nothing to any colour, so no pixel changes.
    #[arg(long)]
    pub keep_sh_degree: bool,
    /// Write no `META` chunk: no encoder name, input file name or settings in the file (about
    /// 200 bytes on a still scene; nothing a reader needs to decode). For files whose source
    /// name should not travel with them, or where every byte counts.
    #[arg(long)]
    pub no_meta: bool,
    /// Lossy canonical coding: leave out codec 5's mixed-context modes, which code some
    /// channels 1-5 % smaller but decode about 3 times slower per channel. The same quantised
    /// values (so the same PSNR) in files 1.5-3.1 % larger that decode in about half the time
    /// or less (273k Gaussians: 105-136 instead of 237-331 ms on 2 cores; BENCHMARKS.md
    /// "Decode time against SOG and SPZ"). Format unchanged: every reader decodes both.
    #[arg(long, conflicts_with = "mixed_margin")]
    pub fast_decode: bool,
    /// Lossy canonical coding: a channel takes codec 5's mixed-context modes only where they
    /// are this many percent smaller than its best other coding. Between the default and
    /// `--fast-decode`: the plant's goal row is 0.3 % larger with 2 and decodes 27 % faster,
    /// 1.2 % larger with 5 and 43 % faster; the 273k scene's 0.2 % and 16 %, 1.1 % and 35 %
    /// (BENCHMARKS.md "Decode time against SOG and SPZ"). Same values, same PSNR.
    #[arg(long, value_name = "PERCENT", default_value_t = 100.0 * grid_coder::MIXED_MARGIN)]
    pub mixed_margin: f64,
    /// Still scenes: move up to MOVES bits between attribute groups, one at a time, where
    /// rendering the decoded scene (5 views of its own, not the benchmark's) says quality rises
    /// within the preset's bytes (0.25 % tolerance). Each move codes and renders about 15
    /// candidates.
    #[arg(long, value_name = "MOVES", default_value_t = 0)]
    pub reallocate_bits: usize,
    /// Lossy still scenes: store each quantised level, among the 9 nearest the value, with the
    /// least estimated bits plus squared error weighted by the Gaussian's importance (blending
    /// weight over 36 views of its own, relative to the mean) over TOL (format-spec §6.5.4).
    /// 0 = nearest levels. 0.1 halves SH 3 scenes like gsplat at -0.02 dB on the benchmark's
    /// views; views unlike the importance pass's lose more (BENCHMARKS.md). Costs 36 renders
    /// at 640x480.
    #[arg(long, value_name = "TOL", default_value_t = 0.0)]
    pub shape: f64,
    /// Lossy still scenes: store the least important Gaussians (blending weight over 36 views
    /// of its own), which together hold at most FRACTION of the total weight, as a second grid
    /// one bit coarser in every group (format-spec §6.5.2, layout 1). More fractions, each
    /// smaller, add grids 2, 3, .. bits coarser (`0.04,0.004`). 0 = one grid. Costs 36 renders
    /// at 640x480. With --shape, every grid is shaped.
    #[arg(
        long,
        value_name = "FRACTION[,FRACTION..]",
        value_delimiter = ',',
        default_value = "0"
    )]
    pub tiers: Vec<f64>,
    /// Lossy still scenes: after coding, decode what was stored, fit every Gaussian's colour
    /// (SH DC) so the decoded scene renders like the source from 36 views of its own (320x240),
    /// and code the colours again, both as fitted and put on the quantiser's levels; the one
    /// that 12 other views of its own render closest to the source is stored if it beats the
    /// first coding (format unchanged). The colours absorb part of the error of the quantised
    /// positions, shapes and opacities (BENCHMARKS.md "Colour refit"). Codes the scene three
    /// times, plus the fit. With --target-psnr: the search's closest candidates below the target are
    /// also tried with the refit (at most 4, each with the cost above).
    #[arg(long)]
    pub refit_colours: bool,
    /// Still scenes: the smallest file whose PSNR reaches DB. Codes the scene at every preset
    /// under 6 tier settings (none to `0.5,0.2`), decodes and renders each candidate from 12
    /// views of its own (not those of `dlgs compare`), gives the two closest below DB more
    /// bits one group at a time, and keeps the smallest at or above DB; on scenes with SH bands
    /// above the DC, level shaping (--shape) is searched the same way, and with octree
    /// positions the --coarse-rotations factor (0, 1, 1.5, 2, 3 and the one given). If none
    /// gets there, the scene is stored lossless. Prints the options of the file kept.
    /// Replaces --quality, --bits, --tiers, --shape and --reallocate-bits; 50-380 s on the
    /// real scenes, 500 s on 273k Gaussians (BENCHMARKS.md "Target PSNR").
    #[arg(
        long,
        value_name = "DB",
        conflicts_with_all = ["quality", "bits", "tiers", "shape", "reallocate_bits"]
    )]
    pub target_psnr: Option<f64>,
    /// Store raw canonical floats without zstd.
    #[arg(long)]
    pub no_zstd: bool,
    /// zstd level for raw canonical, exact features and MLP chunks.
    #[arg(long, default_value_t = 9)]
    pub zstd_level: i32,
    /// x265 constant rate factor for the time-feature video (the reference uses 6).
    #[arg(long, default_value_t = 6)]
    pub crf: u8,
    /// x265 preset (ultrafast .. placebo).
    #[arg(long, default_value = "medium")]
    pub preset: String,
    /// Lossless HEVC: the 12-bit quantised features exactly.
    #[arg(long)]
    pub lossless_features: bool,
    /// Code every time-feature key as its own intra picture (`TFEA` codec 3), so a seek decodes
    /// the 2 keys around t instead of the GOP's 7. Bytes and error at the same crf, and the
    /// seek time it buys, are in BENCHMARKS.md ("Seeking").
    #[arg(long)]
    pub intra_features: bool,
    /// Store time features as exact f32 (zstd) instead of HEVC.
    #[arg(long)]
    pub exact_features: bool,
    /// One quantisation range for all 16 channels, as the reference (default: per channel).
    #[arg(long)]
    pub per_gop_range: bool,
    /// Store MLP weights as f16 (default f32).
    #[arg(long)]
    pub mlp_f16: bool,
    /// Error bounds of explicit residuals (RDLT) per attribute group, e.g.
    /// `position=1e-4,sh_rest=0.01,lang=exact` (groups: position, log_scale, rotation, sh_dc,
    /// sh_rest, opacity, lang_opacity, lang). Unlisted groups are exact (bit-identical).
    #[arg(long)]
    pub residual_error: Option<String>,
    /// Binary voxel residual fields (RNTC) of the input: `keep` them, `recode` residual GOPs
    /// as explicit residuals against the input's decoded states, or `auto` (default): keep
    /// when the canonical coding is lossless; recode when it is lossy, because a field is a
    /// function of position and GOP 0's quantised positions would query it elsewhere.
    #[arg(long, default_value = "auto")]
    pub ntc: String,
    /// The scene's language autoencoder decoder (safetensors with `decoder.<i>.weight/bias`,
    /// see docs/queries.md), stored in the file (LAED chunk) so that players can answer text
    /// queries. When re-encoding a .dlgs, its decoder is kept unless this is given.
    #[arg(long)]
    pub lang_decoder: Option<PathBuf>,
    /// Canonical negative text embeddings (.npy (K, D) or JSON) stored with the decoder
    /// (the reference uses CLIP's "object", "things", "stuff", "texture").
    #[arg(long)]
    pub negatives: Option<PathBuf>,
    /// Store the language decoder in f32 (default f16: half the bytes; effect on relevance
    /// in BENCHMARKS.md).
    #[arg(long)]
    pub lang_decoder_f32: bool,
}

/// `intra`, `sequential` or `parallel` (format-spec §4.1).
pub fn parse_residual_mode(s: &str) -> Result<ResidualMode> {
    Ok(match s {
        "intra" => ResidualMode::Intra,
        "sequential" => ResidualMode::Sequential,
        "parallel" => ResidualMode::Parallel,
        _ => bail!("residual mode `{s}`: expected intra, sequential or parallel"),
    })
}

/// `CodecArgs` alone, to read its defaults the way clap fills them.
#[derive(clap::Parser)]
struct DefaultCodecArgs {
    #[command(flatten)]
    codec: CodecArgs,
}

impl CodecArgs {
    /// The options that differ from their defaults, by field name (e.g. `{"quality": "high",
    /// "tiers": [0.3, 0.05]}`): what `META` records. Every field's Debug form was 570 bytes,
    /// 2.7 % of a small still scene's file.
    pub fn changed_settings(&self) -> serde_json::Value {
        use clap::Parser;
        let given = serde_json::to_value(self).expect("plain fields serialise");
        let defaults = DefaultCodecArgs::try_parse_from(["dlgs"])
            .map(|d| serde_json::to_value(d.codec).expect("plain fields serialise"))
            .expect("every codec option has a default");
        match (given, defaults) {
            (serde_json::Value::Object(g), serde_json::Value::Object(d)) => g
                .into_iter()
                .filter(|(k, v)| d.get(k) != Some(v))
                .collect::<serde_json::Map<_, _>>()
                .into(),
            (g, _) => g,
        }
    }

    /// Whether `--mixed-margin` was given a value other than its default.
    fn mixed_margin_given(&self) -> bool {
        self.mixed_margin != 100.0 * grid_coder::MIXED_MARGIN
    }

    /// The encoder's margin for codec 5's mixed modes: `None` with `--fast-decode`.
    fn mixed_margin(&self) -> Result<Option<f64>> {
        if self.fast_decode {
            return Ok(None);
        }
        let m = self.mixed_margin;
        if !(0.0..=100.0).contains(&m) {
            bail!("--mixed-margin {m}: expected a percentage from 0 to 100");
        }
        Ok(Some(m / 100.0))
    }

    /// Whether `--tiers` asks for more than one grid.
    fn tiered(&self) -> bool {
        self.tiers.iter().any(|&f| f > 0.0)
    }

    fn canonical(&self) -> Result<CanonicalCodec> {
        let mut bits = match (self.quality.as_str(), &self.bits) {
            ("lossless", None) if self.shape > 0.0 => {
                bail!("--shape chooses quantised levels: give a lossy --quality (or --bits)")
            }
            ("lossless", None) if self.tiered() => {
                bail!("--tiers stores coarser levels: give a lossy --quality (or --bits)")
            }
            ("lossless", None) if self.refit_colours => {
                bail!(
                    "--refit-colours refits the colours of a lossy coding: give a lossy \
                     --quality (or --bits, or --target-psnr)"
                )
            }
            ("lossless", None) if self.fast_decode => {
                bail!(
                    "--fast-decode chooses among the lossy grid codings: give a lossy --quality \
                     (or --bits, or --target-psnr)"
                )
            }
            ("lossless", None) if self.mixed_margin_given() => {
                bail!(
                    "--mixed-margin chooses among the lossy grid codings: give a lossy --quality \
                     (or --bits, or --target-psnr)"
                )
            }
            ("lossless", None) => return Ok(CanonicalCodec::Raw),
            ("lossless", Some(_)) => QuantBits::HIGH,
            (q, _) => QuantBits::preset(q).with_context(|| {
                format!("--quality {q}: expected lossless, near-lossless, high, medium or low")
            })?,
        };
        if let Some(spec) = &self.bits {
            for kv in spec.split(',').filter(|s| !s.is_empty()) {
                let (k, v) = kv
                    .split_once('=')
                    .with_context(|| format!("--bits: `{kv}` is not key=value"))?;
                let v: u8 = v
                    .parse()
                    .ok()
                    .filter(|b| (1..=16).contains(b))
                    .with_context(|| format!("--bits {k}: `{v}` is not 1..=16"))?;
                *bits
                    .field_mut(k)
                    .with_context(|| format!("--bits: unknown attribute `{k}`"))? = v;
            }
        }
        Ok(CanonicalCodec::Sorted {
            bits,
            sort: SortSpec {
                passes: self.sort_passes,
            },
        })
    }

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
                "--target-psnr searches the settings of a still scene (PLY, .splat, SPZ input); \
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
        if self.tiers.len() >= dlgs::payload::sorted_grid::MAX_PARTS {
            bail!(
                "--tiers: at most {} fractions",
                dlgs::payload::sorted_grid::MAX_PARTS - 1
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
            canonical: self.canonical()?,
            raw_codec: if self.no_zstd {
                RawCodec::None
            } else {
                RawCodec::Zstd
            },
            zstd_level: self.zstd_level,
            meta: (!self.no_meta).then_some(meta),
            features: if self.exact_features {
                FeatureCodec::Exact
            } else {
                FeatureCodec::Hevc(HevcSettings {
                    crf: self.crf,
                    preset: self.preset.clone(),
                    lossless: self.lossless_features,
                    intra_only: self.intra_features,
                })
            },
            per_gop_range: self.per_gop_range,
            mlp_weights: if self.mlp_f16 || self.quality == "near-lossless" {
                WeightType::F16
            } else {
                WeightType::F32
            },
            residual: self.residual()?,
            lang_decoder: self.lang_decoder()?,
            lang_decoder_weights: if self.lang_decoder_f32 {
                WeightType::F32
            } else {
                WeightType::F16
            },
            canonical_orientation: !self.keep_orientation,
            drop_invisible: !self.keep_invisible,
            trim_zero_sh_bands: !self.keep_sh_degree,
            compact_records: true,
            mixed_margin: self.mixed_margin()?,
            reallocate_bits: self.reallocate_bits,
            shape_tolerance: self.shape,
            tier_weights: self.tiers.iter().copied().filter(|&f| f > 0.0).collect(),
            importance: None,
            octree_positions: !self.grid_positions,
            refit_colours: self.refit_colours,
            rotation_coarsening: match self.coarse_rotations {
                None if self.grid_positions => None,
                None => Some(RotationCoarsening::DEFAULT),
                Some(f) if f > 0.0 => Some(RotationCoarsening {
                    factor: f,
                    ..RotationCoarsening::DEFAULT
                }),
                Some(_) => None,
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

fn meta(input: &Path, extra: serde_json::Value) -> serde_json::Value {
    serde_json::json!({
        "source": input.file_name().map(|s| s.to_string_lossy().to_string()),
        "encoder": concat!("dlgs ", env!("CARGO_PKG_VERSION")),
        "settings": extra,
    })
}

pub(crate) fn bar(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} GOPs, {elapsed}")
            .expect("static template"),
    );
    pb.set_message(what.to_string());
    pb
}

/// `in_size`: the input's size, taken before encoding (the output may replace the input).
fn report(input: &Path, in_size: u64, output: &Path, frames: u32) -> Result<()> {
    let size = std::fs::metadata(output)?.len();
    println!(
        "{} -> {}: {size} bytes ({:.1}% of input), {:.0} bytes/frame over {frames} frames",
        input.display(),
        output.display(),
        100.0 * size as f64 / in_size.max(1) as f64,
        size as f64 / frames.max(1) as f64
    );
    Ok(())
}

pub fn run_encode(
    input: &Path,
    output: &Path,
    codec: &CodecArgs,
    residual_mode: Option<&str>,
) -> Result<()> {
    let in_size = std::fs::metadata(input)
        .with_context(|| format!("reading {}", input.display()))?
        .len();
    let frames = encode_file(input, output, codec, residual_mode, true)?;
    report(input, in_size, output, frames)
}

/// `--target-psnr`: the smallest candidate of [`dlgs_encoder::quality_search`] reaching
/// `target` dB on the search's views, or the lossless file when none does.
fn encode_to_target(
    g: &dlgs::Gaussians,
    target: f64,
    codec: &CodecArgs,
    meta: serde_json::Value,
    out: &mut impl std::io::Write,
    verbose: bool,
) -> Result<()> {
    use dlgs_encoder::quality_search::{compare_views_psnr, smallest_at};
    if !(target.is_finite() && target > 0.0) {
        bail!("--target-psnr takes a PSNR in dB > 0, got {target}");
    }
    // The search sets the bits itself; a lossy preset here only lets the rest be checked.
    let base = CodecArgs {
        target_psnr: None,
        quality: "high".into(),
        ..codec.clone()
    };
    let cfg = base.config(meta)?;
    let bar = if verbose {
        ProgressBar::new_spinner().with_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} [{elapsed}] {pos} candidates; {msg}",
            )
            .expect("a valid template"),
        )
    } else {
        ProgressBar::hidden()
    };
    bar.set_message("measuring importance (36 renders)");
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let found = smallest_at(g, target, &cfg, |t| {
        bar.inc(1);
        bar.set_message(format!(
            "{} tiers {:?}: {} B, {:.2} dB",
            t.label, t.tiers, t.bytes, t.psnr
        ));
    })?;
    bar.finish_and_clear();
    if verbose {
        println!("target {target:.2} dB on the search's 12 views:");
        let width = found
            .trials
            .iter()
            .map(|t| t.label.len())
            .max()
            .unwrap_or(0);
        for (i, t) in found.trials.iter().enumerate() {
            let mark = if found.best.as_ref().is_some_and(|b| b.0 == i) {
                "  <- chosen"
            } else {
                ""
            };
            println!(
                "  {:<width$} --tiers {:<12} {:>10} B  {:6.2} dB{mark}",
                t.label,
                t.tiers
                    .iter()
                    .map(|f| f.to_string())
                    .collect::<Vec<_>>()
                    .join(","),
                t.bytes,
                t.psnr
            );
        }
    }
    match found.best {
        Some((i, file)) => {
            if verbose {
                println!(
                    "  the same file from options: {}{}",
                    found.trials[i].options(&found.groups),
                    if codec.fast_decode {
                        " --fast-decode".to_owned()
                    } else if codec.mixed_margin_given() {
                        format!(" --mixed-margin {}", codec.mixed_margin)
                    } else {
                        String::new()
                    }
                );
                let held_out = compare_views_psnr(g, &file)?;
                println!("  on `dlgs compare`'s 8 default views (not searched): {held_out:.2} dB");
                if held_out < target {
                    println!(
                        "  (under the target there: the smallest file to clear it on the search's \
                         views is, by selection, lucky on them: a slightly higher target leaves a margin)"
                    );
                }
            }
            out.write_all(&file)?
        }
        None => {
            if verbose {
                println!("  no candidate reaches {target:.2} dB: storing the scene lossless");
            }
            let lossless = EncoderConfig {
                canonical: CanonicalCodec::Raw,
                ..cfg
            };
            dlgs_encoder::encode_still(g, lossless, out)?;
        }
    }
    Ok(())
}

/// Encode `input` (a splat scene, or a `.dlgs` to re-encode) into `output`; returns the
/// number of frames. `verbose`: progress bar and a line for still scenes.
pub fn encode_file(
    input: &Path,
    output: &Path,
    codec: &CodecArgs,
    residual_mode: Option<&str>,
    verbose: bool,
) -> Result<u32> {
    let settings = codec.changed_settings();
    let pending = PendingFile::create(output)?;
    let mut out = pending.writer()?;
    if !is_dlgs(input) {
        let g = dlgs::interop::read_splat_file(input)
            .with_context(|| format!("reading {}", input.display()))?;
        if let Some(target) = codec.target_psnr {
            encode_to_target(&g, target, codec, meta(input, settings), &mut out, verbose)?;
            std::io::Write::flush(&mut out)?;
            drop(out);
            pending.commit()?;
            return Ok(1);
        }
        let spinner = if verbose
            && (codec.reallocate_bits > 0
                || codec.shape > 0.0
                || codec.tiered()
                || codec.refit_colours)
        {
            let s = ProgressBar::new_spinner().with_message(if codec.reallocate_bits > 0 {
                "reallocating bits (coding and rendering candidates)"
            } else if codec.refit_colours {
                "refitting colours (coding three times, fitting on 36 renders, judging on 12)"
            } else {
                "measuring importance (36 renders)"
            });
            s.enable_steady_tick(std::time::Duration::from_millis(200));
            s
        } else {
            ProgressBar::hidden()
        };
        let (_, report) = dlgs_encoder::encode_still_reporting(
            &g,
            codec.config(meta(input, settings))?,
            &mut out,
        )?;
        spinner.finish_and_clear();
        std::io::Write::flush(&mut out)?;
        drop(out);
        pending.commit()?;
        if verbose {
            println!("{} Gaussians (SH {}), still frame", g.len(), g.sh_degree);
            if report.dropped_invisible > 0 {
                println!(
                    "  left out {} Gaussians no renderer draws (opacity below 1/255; --keep-invisible keeps them)",
                    report.dropped_invisible
                );
            }
            if report.sh_degree < g.sh_degree {
                println!(
                    "  stored SH degree {}: the bands above it are zero in every Gaussian (--keep-sh-degree keeps them)",
                    report.sh_degree
                );
            }
            if let Some(a) = report.allocation {
                for m in &a.moves {
                    println!(
                        "  moved a bit from {} to {}: {} bytes, {:.2} dB on the allocation views",
                        m.from, m.to, m.bytes, m.psnr
                    );
                }
                println!(
                    "  bits {:?}: {} -> {} bytes, {:.2} -> {:.2} dB on the allocation views",
                    a.bits, a.start_bytes, a.bytes, a.start_psnr, a.psnr
                );
            }
            if let Some(r) = report.refit {
                println!(
                    "  colour refit {} ({}): {:.2} -> {:.2} dB on the encoder's held-out views",
                    if r.kept { "stored" } else { "not stored" },
                    if r.on_levels {
                        "on the quantiser's levels"
                    } else {
                        "offsets rounded by the coder"
                    },
                    r.before_db,
                    r.after_db
                );
            }
        }
        return Ok(1);
    }
    // Re-encode every GOP of an existing stream with new settings.
    let mut dec =
        Decoder::open_path(input).with_context(|| format!("opening {}", input.display()))?;
    let mut scene = dec.scene().clone();
    let input_mode = scene.residual_mode;
    if let Some(m) = residual_mode {
        scene.residual_mode = parse_residual_mode(m)?;
    }
    let keep_ntc = match codec.ntc.as_str() {
        "keep" => true,
        "recode" => false,
        "auto" => matches!(codec.canonical()?, CanonicalCodec::Raw),
        v => bail!("--ntc {v}: expected keep, recode or auto"),
    };
    let mut cfg = codec.config(meta(input, settings))?;
    if cfg.lang_decoder.is_none() {
        cfg.lang_decoder = dec
            .lang_decoder()
            .with_context(|| format!("reading the language decoder of {}", input.display()))?;
    }
    let mut enc = StreamEncoder::new(out, scene.clone(), cfg)?;
    let pb = if verbose {
        bar(scene.gop_count as u64, "encoding")
    } else {
        ProgressBar::hidden()
    };
    for g in 0..scene.gop_count {
        let gop = dec.gop(g).with_context(|| format!("decoding GOP {g}"))?;
        // A binary voxel residual is kept as it is when the reference structure is unchanged
        // (it is the model's own representation); otherwise the decoded state is re-coded.
        let canonical = match (&gop.ntc, scene.residual_mode == input_mode && keep_ntc) {
            (Some(f), true) => GopCanonical::Ntc(f),
            _ => GopCanonical::State(&gop.canonical),
        };
        let dynamic = gop
            .dynamic()
            .with_context(|| format!("decoding GOP {g}'s time features"))?;
        enc.push(canonical, dynamic.as_ref())
            .with_context(|| format!("encoding GOP {g}"))?;
        pb.inc(1);
    }
    pb.finish_and_clear();
    let mut w = enc.finish()?;
    std::io::Write::flush(&mut w)?;
    drop(w);
    pending.commit()?;
    Ok(scene.frame_count)
}

/// `dlgs synth`: a dynamic test model from a real scene.
#[derive(Args, Debug, Clone)]
pub struct SynthArgs {
    /// Real canonical scene (PLY, .splat, SPZ).
    pub input: PathBuf,
    #[arg(short, long)]
    pub output: PathBuf,
    /// Fraction of Gaussians that move.
    #[arg(long, default_value_t = 0.3)]
    pub dynamic_fraction: f32,
    /// Cap on the number of dynamic Gaussians (0 = none).
    #[arg(long, default_value_t = 0)]
    pub max_dynamic: usize,
    #[arg(long, default_value_t = 1)]
    pub gops: u32,
    #[arg(long, default_value_t = 60)]
    pub gop_length: u32,
    #[arg(long, default_value_t = 10)]
    pub key_interval: u32,
    #[arg(long, default_value_t = 30)]
    pub fps: u32,
    /// Motion amplitude relative to the scene size.
    #[arg(long, default_value_t = 0.03)]
    pub motion: f32,
    /// Add 9-dim language (synthetic if the scene has none) and a language decoder.
    #[arg(long)]
    pub language: bool,
    /// Typical offset the generated language MLP adds to the (unit-scale) language codes;
    /// 0 = language constant over time.
    #[arg(long, default_value_t = 0.1)]
    pub language_motion: f32,
    /// Use the paper's plain lerp deformation instead of the reference code's.
    #[arg(long)]
    pub paper_lerp: bool,
    #[arg(long, default_value_t = 6666)]
    pub seed: u64,
    /// `intra` (every GOP repeats GOP 0's canonical state), or `sequential` / `parallel`:
    /// GOPs 1.. carry a generated binary voxel residual field (RNTC) against GOP g-1 / GOP 0.
    #[arg(long, default_value = "intra")]
    pub residual_mode: String,
    #[command(flatten)]
    pub codec: CodecArgs,
}

pub fn run_synth(a: &SynthArgs) -> Result<()> {
    let g = dlgs::interop::read_splat_file(&a.input)
        .with_context(|| format!("reading {}", a.input.display()))?;
    if a.gop_length == 0 || a.key_interval == 0 || !a.gop_length.is_multiple_of(a.key_interval) {
        bail!("--gop-length must be a positive multiple of --key-interval");
    }
    let spec = SynthSpec {
        dynamic_fraction: a.dynamic_fraction,
        max_dynamic: a.max_dynamic,
        gops: a.gops,
        gop_length: a.gop_length,
        key_interval: a.key_interval,
        fps: a.fps,
        motion: a.motion,
        language: a.language,
        language_motion: a.language_motion,
        deform_model: if a.paper_lerp {
            DeformModel::PaperLerp
        } else {
            DeformModel::Reference
        },
        seed: a.seed,
        residual_mode: parse_residual_mode(&a.residual_mode)?,
    };
    let model = synth_dynamic(&g, &spec)?;
    let settings =
        serde_json::json!({"synthetic": format!("{spec:?}"), "codec": a.codec.changed_settings()});
    let mut m = meta(&a.input, settings);
    m["note"] = serde_json::json!("SYNTHETIC motion and time features on a real canonical scene; not a trained DLGStream model");
    let pending = PendingFile::create(&a.output)?;
    let pb = bar(model.gops.len() as u64, "encoding");
    let mut enc = StreamEncoder::new(pending.writer()?, model.scene.clone(), a.codec.config(m)?)?;
    for (i, (d, r)) in model.gops.iter().zip(&model.residuals).enumerate() {
        let canonical = match r {
            Some(f) => GopCanonical::Ntc(f),
            None => GopCanonical::State(&model.canonical),
        };
        enc.push(canonical, Some(d))
            .with_context(|| format!("encoding GOP {i}"))?;
        pb.inc(1);
    }
    pb.finish_and_clear();
    let mut w = enc.finish()?;
    std::io::Write::flush(&mut w)?;
    drop(w);
    pending.commit()?;
    println!(
        "synthetic dynamic model: {} static + {} dynamic Gaussians, {} GOPs x {} frames at {} FPS, keys every {} frames, residual mode {:?}",
        model.scene.n_static,
        model.scene.n_dynamic,
        model.scene.gop_count,
        model.scene.gop_length,
        model.scene.fps_num,
        model.scene.key_interval,
        model.scene.residual_mode
    );
    let in_size = std::fs::metadata(&a.input)?.len();
    report(&a.input, in_size, &a.output, model.scene.frame_count)
}
