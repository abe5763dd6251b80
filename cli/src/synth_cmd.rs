//! `dlgs synth`: a dynamic test model (synthetic motion and time features) on a real scene.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use dlgs::container::header::DeformModel;
use dlgs_encoder::{GopCanonical, StreamEncoder};
use dlgs_testkit::synth::{synth_dynamic, SynthSpec};

use crate::codec_args::CodecArgs;
use crate::encode_cmd::{bar, meta, report};
use crate::pending_file::PendingFile;
use crate::residual_args::{parse_residual_mode, refresh_interval};

/// `dlgs synth`: a dynamic test model from a real scene.
#[derive(Args, Debug, Clone)]
pub struct SynthArgs {
    /// Real canonical scene (PLY, .splat, SPZ, SOG).
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
    let mode = parse_residual_mode(&a.residual_mode)?;
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
        residual_mode: mode,
        refresh_interval: refresh_interval(a.codec.refresh, mode)?,
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
    pending.commit_written(enc.finish()?)?;
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
