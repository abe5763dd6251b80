//! `dlgs ahac-bench`: decode (and, with `--fit-steps`, context-fit) times of `AHAC` payloads
//! on a reference HAC run's GOP 0 and on synthetic content with real positions.

use std::path::Path;

use anyhow::{Context, Result};
use dlgs_encoder::scaffold::scaffold_scene;
use dlgs_encoder::scaffold_fit::{fit_anchors, ContextFitSettings};
use dlgs_ingest::hac::{self, HacLimits};

use crate::hac_ingest_cmd::{hac_gops, ZSTD_LEVEL};

/// `dlgs ahac-bench`: decode times of `AHAC` payloads (median of `repeat`), 1 and 2 threads;
/// with `fit_steps`, each content's anchors also get a fitted context model at those steps
/// (fit time, bytes against the prior) and its payload is timed too.
pub fn run_ahac_bench(
    run: &Path,
    ply: Option<&Path>,
    anchors: usize,
    repeat: usize,
    fit_steps: Option<[f32; 3]>,
) -> Result<()> {
    let dirs = hac_gops(&[run.to_path_buf()]).context("not a HAC run")?;
    let g = hac::read_gop(&dirs[0], None, HacLimits::default())?;
    let fixture = g.hac_anchors().context("GOP 0 has no anchors")?;
    let mut cases = vec![("reference run GOP 0".to_string(), fixture.clone())];
    if let Some(p) = ply {
        let data = std::fs::read(p).with_context(|| p.display().to_string())?;
        let t = std::time::Instant::now();
        let s = hac::synthetic::synthetic_anchors(&fixture, &data, anchors, 1)
            .context("the scene does not give that many voxels")?;
        println!(
            "synthetic content built in {:.1} s",
            t.elapsed().as_secs_f64()
        );
        cases.push((format!("synthetic, positions from {}", p.display()), s));
    }
    if let Some(steps) = fit_steps {
        for (name, h) in cases.clone() {
            let settings = ContextFitSettings::new(steps);
            let t = std::time::Instant::now();
            let (fitted, rep) = fit_anchors(&h.canonical(), &settings, |_, _| {})?;
            let s = t.elapsed().as_secs_f64();
            let n = fitted.quantized.len();
            println!(
                "{name}: context model fitted at steps {steps:?} in {s:.1} s ({:.1} s per 10k \
                 anchors, {} iterations): {} bytes against {} with the per-channel prior",
                s * 1e4 / n.max(1) as f64,
                settings.iterations,
                rep.fitted_bytes,
                rep.prior_bytes
            );
            cases.push((format!("{name}, fitted context model"), fitted));
        }
    }
    for (name, h) in cases {
        let scene = scaffold_scene(h.n_static, h.n_dynamic, true, 30, 60, 10, 60);
        let (payload, sizes) = dlgs::chunks::ahac::encode(&h, &scene, ZSTD_LEVEL)?;
        println!(
            "{name}: {} anchors, {} bytes ({} in the symbol streams)",
            h.quantized.len(),
            payload.len(),
            sizes.streams.iter().sum::<usize>()
        );
        let mut cpu = Vec::new();
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?;
            let mut ms: Vec<f64> = (0..repeat.max(1))
                .map(|_| {
                    pool.install(|| {
                        let (t, c) = (std::time::Instant::now(), cpu_ms());
                        let r = dlgs::chunks::ahac::decode(
                            &payload,
                            0,
                            &scene,
                            &dlgs::Limits::default(),
                        );
                        let dt = t.elapsed().as_secs_f64() * 1e3;
                        r.map(|_| (dt, cpu_ms() - c))
                    })
                })
                .collect::<dlgs::Result<Vec<(f64, f64)>>>()?
                .into_iter()
                .map(|(w, c)| {
                    cpu.push(c);
                    w
                })
                .collect();
            ms.sort_by(f64::total_cmp);
            cpu.sort_by(f64::total_cmp);
            println!(
                "  decode on {threads} thread(s): wall median {:.1} ms (min {:.1}, max {:.1}); \
                 process CPU median {:.0} ms (load average {})",
                ms[ms.len() / 2],
                ms[0],
                ms[ms.len() - 1],
                cpu[cpu.len() / 2],
                std::fs::read_to_string("/proc/loadavg")
                    .unwrap_or_default()
                    .split(' ')
                    .next()
                    .unwrap_or("?")
            );
            cpu.clear();
        }
    }
    Ok(())
}

/// This process's user + system CPU time in ms (Linux `/proc/self/stat`, 10 ms ticks; 0
/// elsewhere).
fn cpu_ms() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let f: Vec<&str> = s
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let tick = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (tick(11) + tick(12)) * 10.0
}
