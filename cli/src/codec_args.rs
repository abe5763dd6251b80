//! The encoder settings `dlgs encode`, `dlgs synth`, `dlgs ingest` and `dlgs rd` share (the
//! encoder configuration they make is in `codec_config.rs`).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use dlgs::chunks::csog::grid_codecs as grid_coder;
use dlgs::chunks::csog::QuantBits;
use dlgs_encoder::{CanonicalCodec, SortSpec};

/// Encoder settings shared by `encode`, `synth`, `ingest` and `rd`.
#[derive(Args, Debug, Clone, serde::Serialize)]
pub struct CodecArgs {
    /// Canonical Gaussians: `lossless` (f32, CRAW) or sorted quantised grids (CSOG) at preset
    /// `near-lossless`, `high`, `medium` or `low` (bits per attribute in format-spec §6.5).
    /// Default: `high` for a still scene (PLY, SPZ, .splat or SOG in: 41-68 dB against the
    /// source on the real scenes of docs/benchmarks/canonical.md, 54-55 dB at 56-79 % of
    /// PlayCanvas SOG's bytes on the four tiles), `lossless` when re-encoding a `.dlgs`, for `ingest` and
    /// for `synth` (the model's own values). `near-lossless` also stores the
    /// decoders in f16 (as `--mlp-f16`): on the reference-run fixture it renders at >= 64 dB
    /// against the lossless model (docs/benchmarks/ingest.md).
    #[arg(long, value_name = "QUALITY")]
    pub quality: Option<String>,
    /// Override quantisation bits, e.g. `position=15,sh_rest=5` (keys: position, log_scale,
    /// rotation, opacity, sh_dc, sh_rest (SH band 1), sh_high (SH bands 2-3), lang). Implies grid coding (preset `high` if
    /// `--quality lossless`).
    #[arg(long)]
    pub bits: Option<String>,
    /// Grid sort refinement passes per radius (PLAS-style, after the k-d layout). 0 (default)
    /// = the k-d layout only: fastest and, on every real scene measured, the smallest files;
    /// refinement smooths colours at the cost of position coherence
    /// (docs/benchmarks/canonical-levers.md "Grid sort").
    #[arg(help_heading = "Canonical coding (expert)", long, default_value_t = 0)]
    pub sort_passes: u32,
    /// Keep each static Gaussian's rotation as given. By default, scenes without residual GOPs
    /// store, among the 24 (rotation, axis order) pairs that give the same ellipsoid, the one
    /// closest to the identity: same rendering, 2-4 bits less per Gaussian.
    #[arg(help_heading = "Canonical coding (expert)", long)]
    pub keep_orientation: bool,
    /// Store the static Gaussians' positions as grid channels, in the grid sort's order
    /// (layout 1), as files before format 1.10. By default they are an octree and the
    /// Gaussians are stored in an order every reader derives from the positions (layouts 2-4,
    /// format-spec §6.5.5): 13-14 % fewer position bytes on the real scenes (2-5 % of the file);
    /// grid positions decode faster (273k Gaussians at `high`: 161-186 ms instead of 238-253,
    /// in a 6.5 % larger file that also keeps every rotation at full bits;
    /// docs/benchmarks/decode.md "The 273k scene by format")
    #[arg(help_heading = "Canonical coding (expert)", long)]
    pub grid_positions: bool,
    /// Octree positions: store the rotation of each Gaussian too small for one rotation step
    /// to move its surface by FACTOR position steps up to 4 bits coarser, one bit per halving
    /// of its largest scale (layout 3, format-spec §6.5.6). 0 = every rotation at the preset's
    /// bits (layout 2, as files of format 1.10). The default, 1, makes SH 0 scenes and gsplat
    /// 1-4 % smaller for 0.00-0.33 dB (docs/benchmarks/canonical-levers.md "Coarse rotations");
    /// 2 saves about twice
    /// as much for up to 1.7 dB. [default: 1, or 0 with --grid-positions]
    #[arg(
        help_heading = "Canonical coding (expert)",
        long,
        value_name = "FACTOR"
    )]
    pub coarse_rotations: Option<f32>,
    /// Keep the Gaussians no renderer draws. By default a lossy (`--quality` other than
    /// `lossless`) still scene leaves out every Gaussian whose opacities are below 1/255: they
    /// never reach the 1/255 alpha at which 3DGS compositing starts, so no pixel changes.
    #[arg(help_heading = "Canonical coding (expert)", long)]
    pub keep_invisible: bool,
    /// Keep the input's SH degree. By default a lossy still scene is stored only up to the
    /// highest SH band that holds a non-zero coefficient (the gs3d tiles declare degree 3 with
    /// bands 1-3 zero everywhere): zero bands add nothing to any colour, so no pixel changes.
    #[arg(help_heading = "Canonical coding (expert)", long)]
    pub keep_sh_degree: bool,
    /// Write no `META` chunk: no encoder name, input file name or settings in the file (about
    /// 200 bytes on a still scene; nothing a reader needs to decode). For files whose source
    /// name should not travel with them, or where every byte counts.
    #[arg(long)]
    pub no_meta: bool,
    /// Lossy canonical coding: kept for scripts; fast decoding is the default since 2026-12-02
    /// (codec 5's mixed-context modes left out). Conflicts with --max-compression.
    #[arg(
        help_heading = "Canonical coding (expert)",
        long,
        conflicts_with_all = ["mixed_margin", "max_compression"]
    )]
    pub fast_decode: bool,
    /// Lossy canonical coding for archives: let channels take codec 5's mixed-context modes,
    /// which code some channels 1-5 % smaller but decode about 3 times slower per channel. The
    /// same quantised values (so the same PSNR) in files 2.0-2.1 % smaller that decode in about
    /// twice the time (273k Gaussians on 2 cores: 192 instead of 100 ms;
    /// docs/benchmarks/decode.md "Decode time against SOG and SPZ"). Format unchanged: every
    /// reader decodes both.
    #[arg(help_heading = "Canonical coding (expert)", long)]
    pub max_compression: bool,
    /// Lossy canonical coding: codec 5's mixed-context modes only where they are this many
    /// percent smaller than a channel's best other coding (implies the modes; between the
    /// default and --max-compression, which is 1). The plant's goal row is 0.3 % larger with 2
    /// than with --max-compression and decodes 27 % faster, 1.2 % larger with 5 and 43 % faster;
    /// the 273k scene's 0.2 % and 16 %, 1.1 % and 35 % (docs/benchmarks/decode.md). Same values,
    /// same PSNR.
    #[arg(
        help_heading = "Canonical coding (expert)",
        long,
        value_name = "PERCENT",
        conflicts_with = "max_compression"
    )]
    pub mixed_margin: Option<f64>,
    /// Still scenes: move up to MOVES bits between attribute groups, one at a time, where
    /// rendering the decoded scene (5 views of its own, not the benchmark's) says quality rises
    /// within the preset's bytes (0.25 % tolerance). Each move codes and renders about 15
    /// candidates.
    #[arg(
        help_heading = "Still scenes: smaller files at the same quality (slower encodes)",
        long,
        value_name = "MOVES",
        default_value_t = 0
    )]
    pub reallocate_bits: usize,
    /// Lossy still scenes: store each quantised level, among the 9 nearest the value, with the
    /// least estimated bits plus squared error weighted by the Gaussian's importance (blending
    /// weight over 36 views of its own, relative to the mean) over TOL (format-spec §6.5.4).
    /// 0 = nearest levels. 0.1 halves SH 3 scenes like gsplat at -0.02 dB on the benchmark's
    /// views; views unlike the importance pass's lose more
    /// (docs/benchmarks/canonical.md "Level shaping"). Costs 36 renders
    /// at 640x480.
    #[arg(
        help_heading = "Still scenes: smaller files at the same quality (slower encodes)",
        long,
        value_name = "TOL",
        default_value_t = 0.0
    )]
    pub shape: f64,
    /// Lossy still scenes: store the least important Gaussians (blending weight over 36 views
    /// of its own), which together hold at most FRACTION of the total weight, as a second grid
    /// one bit coarser in every group (format-spec §6.5.2, layout 1). More fractions, each
    /// smaller, add grids 2, 3, .. bits coarser (`0.04,0.004`). 0 = one grid. Costs 36 renders
    /// at 640x480. With --shape, every grid is shaped.
    #[arg(
        help_heading = "Still scenes: smaller files at the same quality (slower encodes)",
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
    /// positions, shapes and opacities (docs/benchmarks/canonical-levers.md "Colour refit").
    /// Codes the scene three
    /// times, plus the fit. With --target-psnr: the search's closest candidates below the target are
    /// also tried with the refit (at most 4, each with the cost above).
    #[arg(
        help_heading = "Still scenes: smaller files at the same quality (slower encodes)",
        long
    )]
    pub refit_colours: bool,
    /// With --refit-colours: before the colours, move each Gaussian's stored opacity along its
    /// quantiser's levels so the decoded scene renders closer to the source from the same 36
    /// views (a Gauss-Newton search, four sweeps, each view rendered 33 times), then fit the
    /// colours to those opacities. The judge weighs this refit and the colours refit alone and
    /// stores the best, if it beats the first coding
    /// (docs/benchmarks/canonical-levers.md "Opacity refit").
    #[arg(
        help_heading = "Still scenes: smaller files at the same quality (slower encodes)",
        long,
        requires = "refit_colours"
    )]
    pub refit_opacities: bool,
    /// With --refit-colours: fit to the 36 views at 640x480 instead of 320x240: about 5x the
    /// fit's time, 0.1-0.3 dB on the real scenes' goal rows
    /// (docs/benchmarks/canonical-levers.md "Opacity refit").
    #[arg(
        help_heading = "Still scenes: smaller files at the same quality (slower encodes)",
        long,
        requires = "refit_colours"
    )]
    pub refit_full_size: bool,
    /// Still scenes: the smallest file whose PSNR reaches DB. Codes the scene at every preset
    /// under 6 tier settings (none to `0.5,0.2`), decodes and renders each candidate from 12
    /// views of its own (not those of `dlgs compare`), gives the two closest below DB more
    /// bits one group at a time, and keeps the smallest at or above DB; on scenes with SH bands
    /// above the DC, level shaping (--shape) is searched the same way, and with octree
    /// positions the --coarse-rotations factor (0, 1, 1.5, 2, 3 and the one given). If none
    /// gets there, the scene is stored lossless (at once for DB above 100, the cap each view's
    /// PSNR counts at). Prints the options of the file kept.
    /// Replaces --quality, --bits, --tiers, --shape and --reallocate-bits; 50-380 s on the
    /// real scenes, 500 s on 273k Gaussians (docs/benchmarks/canonical-levers.md "Target PSNR").
    #[arg(
        long,
        value_name = "DB",
        conflicts_with_all = ["quality", "bits", "tiers", "shape", "reallocate_bits"]
    )]
    pub target_psnr: Option<f64>,
    /// Store raw canonical floats without zstd.
    #[arg(help_heading = "Canonical coding (expert)", long)]
    pub no_zstd: bool,
    /// zstd level for raw canonical, exact features and MLP chunks.
    #[arg(help_heading = "Canonical coding (expert)", long, default_value_t = 9)]
    pub zstd_level: i32,
    /// x265 constant rate factor for the time-feature video (the reference uses 6).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        default_value_t = 6
    )]
    pub crf: u8,
    /// x265 preset (ultrafast .. placebo).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        default_value = "medium"
    )]
    pub preset: String,
    /// Lossless HEVC: the 12-bit quantised features exactly.
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long
    )]
    pub lossless_features: bool,
    /// Code every time-feature key as its own intra picture (`TFEA` codec 3), so a seek decodes
    /// the 2 keys around t instead of the GOP's 7. Bytes and error at the same crf, and the
    /// seek time it buys, are in docs/benchmarks/residuals-seek.md ("Seek latency").
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long
    )]
    pub intra_features: bool,
    /// Which GOPs' time-feature streams start with their first key interval (their second
    /// picture forced to P, coded second), so that it decodes from their first 2 packets:
    /// `first` (default: playback starts after 2 of GOP 0's 7 key pictures), `all` (cold
    /// seeks into a GOP's first interval too), or `off`. About +0.1 % bytes on the real
    /// 200-frame sequence (docs/benchmarks/dynamic.md "Fast start").
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        default_value = "first",
        value_parser = ["first", "all", "off"]
    )]
    pub fast_start: String,
    /// Store time features as exact f32 (zstd) instead of HEVC.
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long
    )]
    pub exact_features: bool,
    /// Store time features quantised per channel to BITS (6-12, default 12: the HEVC path's
    /// quantisation) and coded with zstd (`TFEA` codec 4, format 1.19): no video codec, so the
    /// web player decodes them; about 2.9x fewer bytes than --exact-features on the demo scene
    /// (docs/web-player.md).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        value_name = "BITS",
        num_args = 0..=1,
        default_missing_value = "12",
        value_parser = clap::value_parser!(u8).range(6..=12),
        conflicts_with = "exact_features"
    )]
    pub quantised_features: Option<u8>,
    /// Reference HAC runs: store GOP 0's anchors raw (`ANCR`, f32 + zstd) instead of
    /// HAC-coded (`AHAC`, format-spec §6.13, the default).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long
    )]
    pub raw_anchors: bool,
    /// Reference HAC runs, near-lossless: `AHAC` steps this many times the reference's, the
    /// anchors' integers requantised (1 = lossless in symbols). Re-encoding a Scaffold-GS
    /// `.dlgs`: its `AHAC` steps times this, and raw `ANCR` anchors HAC-coded with a
    /// per-channel prior at this times its default steps (0.01, 0.001, 0.002).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        default_value_t = 1.0
    )]
    pub anchor_step_scale: f32,
    /// Re-encoding a Scaffold-GS `.dlgs` with raw anchors (`ANCR`): their steps of feature,
    /// log-scaling and offsets, e.g. `0.3,0.004,0.04` (default: the coarsest within
    /// `--anchor-budget-db`, searched on judge views).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        value_name = "F,S,O"
    )]
    pub anchor_steps: Option<String>,
    /// Raw anchors: rendered-quality budget of the step search, colour and language PSNR (dB)
    /// against the uncoded anchors on judge views.
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        default_value_t = 45.0
    )]
    pub anchor_budget_db: f64,
    /// Raw anchors: code them with the per-channel prior (fast, larger) instead of a context
    /// model fitted to them; steps `--anchor-steps` or `--anchor-step-scale` times
    /// 0.01, 0.001, 0.002 (no search).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long
    )]
    pub anchor_prior: bool,
    /// Raw anchors: gradient steps of the context model's fit (more: smaller, slower).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        default_value_t = 300
    )]
    pub anchor_fit_iterations: usize,
    /// One quantisation range for all 16 channels, as the reference (default: per channel).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long
    )]
    pub per_gop_range: bool,
    /// Store MLP weights as f16 (default f32).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long
    )]
    pub mlp_f16: bool,
    /// Error bounds of explicit residuals (RDLT) per attribute group, e.g.
    /// `position=1e-4,sh_rest=0.01,lang=exact` (groups: position, log_scale, rotation, sh_dc,
    /// sh_rest, opacity, lang_opacity, lang). Unlisted groups are exact (bit-identical).
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long
    )]
    pub residual_error: Option<String>,
    /// Binary voxel residual fields (RNTC) of the input: `keep` them, `recode` residual GOPs
    /// as explicit residuals against the input's decoded states, or `auto` (default): keep
    /// when the canonical coding is lossless; recode when it is lossy, because a field is a
    /// function of position and GOP 0's quantised positions would query it elsewhere.
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        default_value = "auto"
    )]
    pub ntc: String,
    /// Sequential scenes: every K-th GOP carries its full canonical state, like a video
    /// codec's keyframe interval, so a cold seek walks at most K-1 residual GOPs (0: only GOP
    /// 0 does). Each refresh costs a canonical GOP's bytes; docs/benchmarks/residuals-seek.md
    /// has bytes against seek time for several K.
    #[arg(
        help_heading = "Dynamic streams: time features, decoders and residuals",
        long,
        value_name = "K",
        default_value_t = 0
    )]
    pub refresh: u32,
    /// The scene's language autoencoder decoder (safetensors with `decoder.<i>.weight/bias`,
    /// see docs/queries.md), stored in the file (LAED chunk) so that players can answer text
    /// queries. When re-encoding a .dlgs, its decoder is kept unless this is given.
    #[arg(help_heading = "Language (queries)", long)]
    pub lang_decoder: Option<PathBuf>,
    /// Canonical negative text embeddings (.npy (K, D) or JSON) stored with the decoder
    /// (the reference uses CLIP's "object", "things", "stuff", "texture").
    #[arg(help_heading = "Language (queries)", long)]
    pub negatives: Option<PathBuf>,
    /// Store the language decoder in f32 (default f16: half the bytes; effect on relevance
    /// in docs/benchmarks/queries.md).
    #[arg(help_heading = "Language (queries)", long)]
    pub lang_decoder_f32: bool,
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

    /// Whether codec 5's mixed modes were asked for (`--max-compression` or `--mixed-margin`).
    pub(crate) fn mixed_margin_given(&self) -> bool {
        self.max_compression || self.mixed_margin.is_some()
    }

    /// The encoder's margin for codec 5's mixed modes: `None` (fast decoding, the default)
    /// unless `--max-compression` or `--mixed-margin` asks for them.
    pub(crate) fn mixed_margin(&self) -> Result<Option<f64>> {
        if self.max_compression {
            return Ok(Some(grid_coder::MIXED_MARGIN));
        }
        let Some(m) = self.mixed_margin else {
            return Ok(None);
        };
        if !(0.0..=100.0).contains(&m) {
            bail!("--mixed-margin {m}: expected a percentage from 0 to 100");
        }
        Ok(Some(m / 100.0))
    }

    /// The `--quality` given, or `lossless` (the default but for still scenes; see
    /// [`Self::defaulting_quality`]).
    pub fn quality(&self) -> &str {
        self.quality.as_deref().unwrap_or("lossless")
    }

    /// These settings with `quality` where `--quality` was not given (still scenes: `high`).
    pub fn defaulting_quality(&self, quality: &str) -> CodecArgs {
        CodecArgs {
            quality: self.quality.clone().or_else(|| Some(quality.to_owned())),
            ..self.clone()
        }
    }

    /// Whether `--tiers` asks for more than one grid.
    pub(crate) fn tiered(&self) -> bool {
        self.tiers.iter().any(|&f| f > 0.0)
    }

    pub(crate) fn canonical(&self) -> Result<CanonicalCodec> {
        let mut bits = match (self.quality(), &self.bits) {
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
                    "--max-compression and --mixed-margin choose among the lossy grid codings: \
                     give a lossy --quality (or --bits, or --target-psnr)"
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
}
