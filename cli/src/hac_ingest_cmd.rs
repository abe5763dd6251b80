//! `dlgs encode RUN_DIR -o scene.dlgs` for the reference implementation's HAC (Scaffold-GS)
//! runs: every GOP folder's bitstreams decoded as the reference's decoder does
//! (`dlgs_ingest::hac`), its time-feature video passed through (or decoded, with
//! `--exact-features`), and the anchors re-packed losslessly as a Scaffold-GS `.dlgs`
//! (format-spec §6.9-§6.12), with bytes per frame against the reference's own count. GOPs
//! after the first that the reference codes as an NTC residual are written as such (`RNTC`
//! over anchor groups, view MLPs inherited or language-only; since 1.17) unless
//! `--residual-mode intra` asks for full anchors in every GOP.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use dlgs::chunks::tfea::{TfeaBody, Tiling};
use dlgs::container::ChunkType;
use dlgs::container::ResidualMode;
use dlgs::model::scaffold::{
    AnchorDeformation, Anchors, ScaffoldCanonical, FEAT_DIM, N_OFFSETS, SCALING_DIM,
};
use dlgs_encoder::scaffold::{scaffold_scene, ResidualViewMlps, ScaffoldWriter};
use dlgs_ingest::hac::{self, HacGop, HacLimits};
use dlgs_ingest::ref_gop::FeatureSource;
use dlgs_ingest::{csv, run};

use crate::encode_cmd::bar;

/// Frames per GOP and key interval of the reference's HAC runs (../shared/reference §0).
const GOP_LENGTH: u32 = 60;
const KEY_INTERVAL: u32 = 10;

/// The `compression/best` folder of a HAC GOP, if `p` is or holds one.
fn best_dir(p: &Path) -> Option<PathBuf> {
    [p.to_path_buf(), p.join("compression/best")]
        .into_iter()
        .find(|d| d.join("bitstreams").is_dir() && d.join("png_quant").is_dir())
}

/// The GOP folders of HAC runs among `inputs` (each a GOP folder or a run holding
/// `gop{g}_*` folders), in GOP order; `None` if any input is not a HAC run.
pub fn hac_gops(inputs: &[PathBuf]) -> Option<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in inputs {
        if let Some(d) = best_dir(p) {
            out.push(d);
            continue;
        }
        let mut gops: Vec<(u32, PathBuf)> = std::fs::read_dir(p)
            .ok()?
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().into_string().ok()?;
                let g = name.strip_prefix("gop")?.split('_').next()?.parse().ok()?;
                Some((g, best_dir(&e.path())?))
            })
            .collect();
        if gops.is_empty() {
            return None;
        }
        gops.sort();
        out.extend(gops.into_iter().map(|(_, d)| d));
    }
    (!out.is_empty()).then_some(out)
}

/// The two view-MLP sets differ at most in the language MLP.
fn same_but_language(
    a: &dlgs::model::scaffold::ScaffoldMlps,
    b: &dlgs::model::scaffold::ScaffoldMlps,
) -> bool {
    a.opacity == b.opacity && a.color == b.color && a.cov == b.cov
}

fn split(a: &Anchors, n_static: usize) -> ScaffoldCanonical {
    let part = |r: std::ops::Range<usize>| Anchors {
        positions: a.positions[r.clone()].to_vec(),
        features: a.features[r.start * FEAT_DIM..r.end * FEAT_DIM].to_vec(),
        offsets: a.offsets[r.start * 3 * N_OFFSETS..r.end * 3 * N_OFFSETS].to_vec(),
        log_scalings: a.log_scalings[r.start * SCALING_DIM..r.end * SCALING_DIM].to_vec(),
    };
    ScaffoldCanonical {
        statics: part(0..n_static),
        dynamics: part(n_static..a.len()),
    }
}

/// Bytes the reference counts for a HAC GOP (§9: the whole `bitstreams/`, the mp4,
/// `mlps.pth` and the CSV).
fn reference_bytes(dir: &Path) -> u64 {
    let size = |p: PathBuf| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    let bitstreams: u64 = std::fs::read_dir(dir.join("bitstreams"))
        .map(|it| {
            it.filter_map(|e| e.ok())
                .map(|e| e.metadata().map(|m| m.len()).unwrap_or(0))
                .sum()
        })
        .unwrap_or(0);
    let q = dir.join("png_quant");
    bitstreams
        + size(q.join("_temporal_feat.mp4"))
        + size(q.join("mlps.pth"))
        + size(q.join("compression_info.csv"))
}

/// Largest |difference| between two anchor sets' features, offsets and log-scalings.
fn max_abs_diff(a: &ScaffoldCanonical, b: &ScaffoldCanonical) -> f32 {
    let values = |c: &ScaffoldCanonical| {
        [&c.statics, &c.dynamics]
            .into_iter()
            .flat_map(|s| s.features.iter().chain(&s.offsets).chain(&s.log_scalings))
            .copied()
            .collect::<Vec<f32>>()
    };
    values(a)
        .iter()
        .zip(values(b))
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

pub fn run_hac_ingest(
    dirs: &[PathBuf],
    output: &Path,
    fps: u32,
    exact_features: bool,
    residual_mode: Option<&str>,
) -> Result<()> {
    let limits = dlgs::Limits::default();
    let pb = bar(dirs.len() as u64, "decoding HAC bitstreams");
    let mut gops: Vec<HacGop> = Vec::with_capacity(dirs.len());
    for (g, d) in dirs.iter().enumerate() {
        let gop = hac::read_gop(d, gops.last(), HacLimits::default())
            .with_context(|| format!("GOP {g} ({})", d.display()))?;
        gops.push(gop);
        pb.set_position(g as u64 + 1);
    }
    pb.finish_and_clear();
    let g0 = &gops[0];
    let n_static = g0.n_static;
    let n_dynamic = g0.anchors.len() - n_static;
    let language = g0.mlps.language.is_some();
    // GOPs 1.. as the reference's NTC residuals (sequential) when every one has them.
    let all_ntc = gops.len() > 1 && gops[1..].iter().all(|g| g.ntc.is_some());
    let sequential = match residual_mode {
        None => all_ntc,
        Some("intra") => false,
        Some("sequential") if all_ntc => true,
        Some("sequential") => bail!("--residual-mode sequential: not every GOP after the first has an NTC residual (ntc_2D.b)"),
        Some(m) => bail!("a HAC run is written with --residual-mode intra or sequential, not {m}"),
    };
    let mut scene = scaffold_scene(
        n_static as u32,
        n_dynamic as u32,
        language,
        fps,
        GOP_LENGTH,
        KEY_INTERVAL,
        GOP_LENGTH * gops.len() as u32,
    );
    if sequential {
        scene.residual_mode = ResidualMode::Sequential;
    }
    let mut w = ScaffoldWriter::new(Vec::new(), scene, 19)?;
    let meta = serde_json::json!({
        "source": "DLGStream reference implementation output (HAC / Scaffold-GS variant)",
        "gop_folders": dirs.iter().map(|d| d.display().to_string()).collect::<Vec<_>>(),
        "encoder": concat!("dlgs ", env!("CARGO_PKG_VERSION")),
        "settings": { "exact_features": exact_features, "residual_mode": if sequential { "sequential" } else { "intra" } },
    });
    w.scene_chunk(ChunkType::META, &serde_json::to_vec(&meta)?)?;
    let pb = bar(gops.len() as u64, "writing");
    let (mut chunks, mut repaired, mut unverified) = (0, 0, 0);
    // The canonical anchors and view MLPs a decoder holds after each GOP (residual chain).
    let mut decoded: Option<(ScaffoldCanonical, dlgs::model::scaffold::ScaffoldMlps)> = None;
    let mut residual_notes = Vec::new();
    for (g, (gop, dir)) in gops.iter().zip(dirs).enumerate() {
        chunks += gop.report.chunks;
        repaired += gop.report.repaired.len();
        unverified += gop.report.unverified.len();
        let Some(mlps) = g0.mlps.view_mlps(Some(&gop.mlps)) else {
            bail!(
                "GOP 0 ({}) lacks the view MLPs (mlp_opacity, mlp_color, mlp_cov)",
                dirs[0].display()
            );
        };
        let canonical = split(&gop.anchors, n_static);
        let png = dir.join("png_quant");
        let deformation = AnchorDeformation {
            bound_min: gop.mlps.bounds.0,
            bound_max: gop.mlps.bounds.1,
            mlps: gop.mlps.deform.clone(),
        };
        let body = if n_dynamic > 0 {
            let text = std::fs::read_to_string(png.join("compression_info.csv"))
                .with_context(|| format!("{}/compression_info.csv", png.display()))?;
            let rows = csv::parse(
                &text,
                &png.join("compression_info.csv").display().to_string(),
            )?;
            let side = (n_dynamic as f64).sqrt().ceil() as usize;
            let (features, source) =
                run::read_feature_video(&png, "_temporal_feat", &rows, n_dynamic, side, &limits)?;
            Some(match (source, exact_features) {
                (
                    FeatureSource::Video {
                        packets,
                        side,
                        range,
                    },
                    false,
                ) => TfeaBody::Hevc {
                    tiling: Tiling {
                        n: n_dynamic,
                        keys: features.keys,
                        channels: features.channels,
                        side,
                    },
                    ranges: vec![],
                    reference: Some(range),
                    packets,
                    intra: false,
                },
                _ => TfeaBody::Exact(features),
            })
        } else {
            None
        };
        let dynamic = body.as_ref().map(|b| (&deformation, b));
        match (sequential && g > 0, decoded.take(), &gop.ntc) {
            (true, Some((prev, prev_mlps)), Some(ntc)) => {
                let mlp = gop
                    .mlps
                    .ntc
                    .as_ref()
                    .context("an NTC GOP without ntc_mlp")?;
                let field = hac::ntc::to_field(
                    &ntc.plane_bits,
                    &ntc.gate_bits,
                    mlp,
                    gop.bound_min,
                    gop.bound_max,
                )
                .with_context(|| format!("GOP {g}: the NTC is not the reference's shape"))?;
                // GOP 0's opacity/colour/cov always; the language MLP is the GOP's own.
                let view = if mlps == prev_mlps {
                    ResidualViewMlps::Inherit
                } else if same_but_language(&mlps, &prev_mlps) {
                    ResidualViewMlps::LanguageOnly(mlps.language.as_ref().expect("differs"))
                } else {
                    ResidualViewMlps::Full(&mlps)
                };
                let kind = match view {
                    ResidualViewMlps::Inherit => "inherited",
                    ResidualViewMlps::LanguageOnly(_) => "language MLP only",
                    ResidualViewMlps::Full(_) => "full",
                };
                w.push_residual_gop(&field, view, dynamic)
                    .with_context(|| format!("writing GOP {g}"))?;
                let ours = prev
                    .with_residual(&field)
                    .map_err(|e| anyhow::anyhow!("GOP {g}: {e}"))?;
                residual_notes.push(format!(
                    "GOP {g}: RNTC residual, AMLP {kind}; decoded anchors vs the reference \
                     decoder's arithmetic (dlgs-ingest): max |diff| {:.3e}",
                    max_abs_diff(&ours, &canonical)
                ));
                decoded = Some((ours, mlps));
            }
            _ => {
                w.push_gop(&canonical, &mlps, dynamic)
                    .with_context(|| format!("writing GOP {g}"))?;
                decoded = Some((canonical, mlps));
            }
        }
        pb.set_position(g as u64 + 1);
    }
    pb.finish_and_clear();
    let bytes = w.finish()?;
    std::fs::write(output, &bytes).with_context(|| format!("writing {}", output.display()))?;
    let reference: u64 = dirs.iter().map(|d| reference_bytes(d)).sum();
    let frames = (GOP_LENGTH as usize * gops.len()) as f64;
    println!(
        "{} GOPs, {n_static} static + {n_dynamic} dynamic anchors (language {}) -> {} ({} bytes)",
        gops.len(),
        if language { "yes" } else { "no" },
        output.display(),
        bytes.len()
    );
    println!(
        "bytes per frame: reference {:.1} (bitstreams, mp4, mlps.pth, csv), .dlgs {:.1} ({:.1} %; \
         GOP 0's anchors stored raw, HAC-style coding not yet)",
        reference as f64 / frames,
        bytes.len() as f64 / frames,
        100.0 * bytes.len() as f64 / reference.max(1) as f64
    );
    for n in &residual_notes {
        println!("{n}");
    }
    if chunks > 0 {
        println!(
            "entropy-coded chunks: {chunks}; {} re-encode to their bytes at once, {repaired} after \
             trying the other rounding of a CDF entry or step (consistent, not proven)",
            chunks - repaired - unverified
        );
    }
    if unverified > 0 {
        println!(
            "warning: {unverified} entropy-coded chunks did not re-encode to their bytes: their \
             values from the first wrong symbol on differ from the reference encoder's (its \
             float32 CDFs round otherwise than ours)"
        );
    }
    Ok(())
}
