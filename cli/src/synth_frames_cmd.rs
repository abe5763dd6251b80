//! `dlgs synth-frames SCENE -o DIR`: a hard per-frame sequence from a REAL scene with
//! SYNTHETIC motion (`dlgs_testkit::motion`): large rigid or fast articulated motion, Gaussians
//! that come and go, every frame shuffled and written as its own PLY.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use dlgs_testkit::motion::{hard_sequence, peak_speed, Motion, MotionSpec};

#[derive(Args, Debug)]
pub struct SynthFramesArgs {
    /// A real splat scene (PLY, .splat, SPZ, SOG).
    pub scene: PathBuf,
    /// Folder for the frames (frame_0000.ply, ...).
    #[arg(short, long)]
    pub output: PathBuf,
    /// rigid (the whole scene swings and sways) or articulated (three parts swing like a limb).
    #[arg(long, default_value = "articulated")]
    pub motion: Motion,
    #[arg(long, default_value_t = 60)]
    pub frames: usize,
    /// Largest move of a Gaussian between two frames, in neighbour spacings.
    #[arg(long, default_value_t = 10.0)]
    pub speed: f32,
    /// Frames per swing.
    #[arg(long, default_value_t = 30.0)]
    pub period: f32,
    /// Share of Gaussians that live for only part of the sequence (0-1).
    #[arg(long, default_value_t = 0.0)]
    pub births: f32,
    /// Frames as independent per-frame reconstructions would give them: every Gaussian moved by
    /// this many neighbour spacings at random (normal, per axis), its scale, opacity and colour
    /// perturbed, a share of 0.1x this left out, drawn anew for each frame, so that no Gaussian
    /// of one frame is exactly one of the next (0: the same Gaussians moved).
    #[arg(long, default_value_t = 0.0)]
    pub independent: f32,
    /// Keep every k-th Gaussian of the scene (1: all).
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also write each frame's identities (frame_NNNN.ids: per Gaussian of the frame, the u32
    /// little-endian index of the scene Gaussian it is), for peers that need them and for tests.
    #[arg(long)]
    pub ids: bool,
}

pub fn run(a: &SynthFramesArgs) -> Result<()> {
    if a.frames < 2
        || !(a.speed >= 0.0)
        || !(0.0..=1.0).contains(&a.births)
        || !(0.0..=10.0).contains(&a.independent)
        || a.every == 0
    {
        bail!(
            "need --frames >= 2, --speed >= 0, --births in 0..=1, --independent in 0..=10 and \
             --every >= 1"
        );
    }
    let full = dlgs::interop::read_splat_file(&a.scene)
        .with_context(|| format!("reading {}", a.scene.display()))?
        .without_language();
    let mut scene = dlgs::model::Gaussians::new(full.sh_degree, 0);
    for i in (0..full.len()).step_by(a.every) {
        scene.push_from(&full, i);
    }
    let spec = MotionSpec {
        motion: a.motion,
        frames: a.frames,
        speed: a.speed,
        period: a.period,
        births: a.births,
        independent: a.independent,
        seed: a.seed,
    };
    let seq = hard_sequence(&scene, &spec);
    std::fs::create_dir_all(&a.output)?;
    for (t, f) in seq.frames.iter().enumerate() {
        let p = a.output.join(format!("frame_{t:04}.ply"));
        std::fs::write(&p, dlgs::interop::ply::write_ply(f)?)
            .with_context(|| format!("writing {}", p.display()))?;
        if a.ids {
            let p = a.output.join(format!("frame_{t:04}.ids"));
            let bytes: Vec<u8> = seq.ids[t].iter().flat_map(|i| i.to_le_bytes()).collect();
            std::fs::write(&p, bytes).with_context(|| format!("writing {}", p.display()))?;
        }
    }
    let counts: Vec<usize> = seq.frames.iter().map(|f| f.len()).collect();
    println!(
        "{} frames of {}-{} Gaussians (scene: {}), neighbour spacing {:.3e}, largest move {:.2} \
         spacings per frame -> {}",
        a.frames,
        counts.iter().min().unwrap_or(&0),
        counts.iter().max().unwrap_or(&0),
        scene.len(),
        seq.spacing,
        peak_speed(&seq),
        a.output.display()
    );
    Ok(())
}
