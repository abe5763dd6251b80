//! `dlgs seek` (seek latency, cold and warm) and `dlgs boundaries` (quality and jumps at GOP
//! boundaries).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use dlgs::container::header::ResidualMode;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_render::{metrics, render, RenderOptions};

use crate::cameras_arg::CameraArgs;
use crate::scene_io::Source;

fn stats(ms: &mut [f64]) -> String {
    ms.sort_by(|a, b| a.total_cmp(b));
    let n = ms.len();
    format!(
        "min {:.1} / median {:.1} / max {:.1} ms over {n}",
        ms[0],
        ms[n / 2],
        ms[n - 1]
    )
}

pub fn run_seek(file: &Path, count: usize, seed: u64, gop_cache: usize) -> Result<()> {
    let open = || Decoder::open_path(file).with_context(|| format!("opening {}", file.display()));
    let dec = open()?;
    let s = dec.scene().clone();
    let duration = s.frame_count as f64 * s.fps_den as f64 / s.fps_num as f64;
    let mut rng = fastrand::Rng::with_seed(seed);
    let times: Vec<f64> = (0..count.max(1))
        .map(|_| rng.f64() * duration * 0.999_999)
        .collect();
    println!(
        "{}: {} GOPs x {} frames, {} static + {} dynamic Gaussians, residual mode {:?}",
        file.display(),
        s.gop_count,
        s.gop_length,
        s.n_static,
        s.n_dynamic,
        s.residual_mode
    );
    let opts = FrameOptions {
        camera_center: [0.0, 0.0, 5.0],
        language: false,
    };
    let seek = |d: &mut Decoder<_>, t: f64| -> Result<f64> {
        let t0 = Instant::now();
        d.seek(t, &opts)
            .with_context(|| format!("seeking to t = {t:.4} s"))?;
        Ok(t0.elapsed().as_secs_f64() * 1e3)
    };
    // Cold: a fresh decoder, nothing decoded (includes reading the index).
    let mut cold = Vec::new();
    // Started: a player that has shown GOP 0 (its state cached) jumps to t.
    let mut started = Vec::new();
    for &t in &times {
        let t0 = Instant::now();
        let mut d = open()?;
        let open_ms = t0.elapsed().as_secs_f64() * 1e3;
        cold.push(open_ms + seek(&mut d, t)?);
        let mut d = open()?;
        d.gop(0)?;
        started.push(seek(&mut d, t)?);
    }
    // Warm: one decoder seeking again and again (state cache of 4 GOPs, GOP cache as asked).
    let mut d = open()?;
    d.set_gop_cache(gop_cache);
    for &t in &times {
        seek(&mut d, t)?;
    }
    let mut warm = Vec::new();
    for &t in times.iter().rev() {
        warm.push(seek(&mut d, t)?);
    }
    let chain = match s.residual_mode {
        ResidualMode::Intra => "each GOP decodes alone".to_owned(),
        ResidualMode::Parallel => "a GOP needs GOP 0 + its residual".to_owned(),
        ResidualMode::Sequential if s.refresh_interval > 0 => format!(
            "a GOP needs the residuals since the last refresh: at most {} steps",
            s.refresh_interval - 1
        ),
        ResidualMode::Sequential => "a GOP needs every residual before it".to_owned(),
    };
    println!("({chain})");
    println!(
        "cold seek (open + seek, nothing cached):     {}",
        stats(&mut cold)
    );
    println!(
        "seek after start (GOP 0 decoded and cached): {}",
        stats(&mut started)
    );
    println!(
        "warm seek (same times again, state cache 4, GOP cache {}): {}",
        gop_cache.max(1),
        stats(&mut warm)
    );
    Ok(())
}

pub fn run_boundaries(a: &Path, b: &Path, cams: &CameraArgs) -> Result<()> {
    let mut sa = Source::open(a)?;
    let mut sb = Source::open(b)?;
    let scene = match &sa {
        Source::Dlgs(d, _) => d.scene().clone(),
        Source::Scaffold(d, _) => d.scene().clone(),
        Source::Splat(_) => anyhow::bail!("{} is not a .dlgs stream", a.display()),
    };
    let cameras = cams.resolve(&sa.canonical(0.0)?)?;
    let opts = RenderOptions::default();
    let fps = scene.fps_num as f64 / scene.fps_den as f64;
    println!(
        "{:>4} {:>11} {:>11} {:>13} {:>13}",
        "GOP", "B vs A last", "B vs A next", "jump A (PSNR)", "jump B (PSNR)"
    );
    for g in 0..scene.gop_count.saturating_sub(1) {
        let boundary = (g + 1) * scene.gop_length;
        // Mid-frame times, well inside each frame.
        let t_last = (boundary as f64 - 0.5) / fps;
        let t_next = (boundary as f64 + 0.5) / fps;
        let mut sums = [0f64; 4];
        for cam in &cameras {
            let eye = cam.position.to_array();
            let img = |s: &mut Source, t| -> Result<Vec<f32>> {
                let g = s.at(t, eye, false)?;
                Ok(render(&g, cam, &opts).map_err(anyhow::Error::msg)?.color)
            };
            let (al, an) = (img(&mut sa, t_last)?, img(&mut sa, t_next)?);
            let (bl, bn) = (img(&mut sb, t_last)?, img(&mut sb, t_next)?);
            for (k, p) in [
                metrics::psnr(&al, &bl),
                metrics::psnr(&an, &bn),
                metrics::psnr(&al, &an),
                metrics::psnr(&bl, &bn),
            ]
            .into_iter()
            .enumerate()
            {
                sums[k] += p.min(200.0);
            }
        }
        let n = cameras.len() as f64;
        println!(
            "{:>4} {:>8.2} dB {:>8.2} dB {:>10.2} dB {:>10.2} dB",
            format!("{g}|{}", g + 1),
            sums[0] / n,
            sums[1] / n,
            sums[2] / n,
            sums[3] / n
        );
    }
    println!(
        "(mean over {} cameras; inf capped at 200 dB)",
        cameras.len()
    );
    Ok(())
}
