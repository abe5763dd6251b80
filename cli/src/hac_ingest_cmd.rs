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
use dlgs::model::scaffold::{AnchorDeformation, ScaffoldCanonical};
use dlgs_encoder::scaffold::{scaffold_scene, ResidualViewMlps, ScaffoldWriter};
use dlgs_ingest::hac::{self, HacGop, HacLimits};
use dlgs_ingest::ref_gop::FeatureSource;
use dlgs_ingest::{csv, run};

use crate::encode_cmd::bar;

/// Frames per GOP and key interval of the reference's HAC runs (../shared/reference §0).
const GOP_LENGTH: u32 = 60;
const KEY_INTERVAL: u32 = 10;
/// zstd level of the chunks written (`dlgs rd` re-codes anchors with the same).
pub const ZSTD_LEVEL: i32 = 19;

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
    quantised_features: Option<u8>,
    residual_mode: Option<&str>,
    raw_anchors: bool,
    anchor_step_scale: f32,
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
    let mut w = ScaffoldWriter::new(Vec::new(), scene, ZSTD_LEVEL)?;
    let mut meta = serde_json::json!({
        "source": "DLGStream reference implementation output (HAC / Scaffold-GS variant)",
        "gop_folders": dirs.iter().map(|d| d.display().to_string()).collect::<Vec<_>>(),
        "encoder": concat!("dlgs ", env!("CARGO_PKG_VERSION")),
        "settings": {
            "exact_features": exact_features,
            "residual_mode": if sequential { "sequential" } else { "intra" },
            "raw_anchors": raw_anchors,
            "anchor_step_scale": anchor_step_scale,
        },
    });
    if let Some(bits) = quantised_features {
        meta["settings"]["quantised_features"] = bits.into();
    }
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
        let canonical = ScaffoldCanonical::split_at(gop.anchors.clone(), n_static);
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
                // TFEA codec 4 (format 1.19): the decoded features quantised again.
                _ if quantised_features.is_some() => {
                    TfeaBody::Quantised(dlgs::chunks::tfea::Quantised::from_features(
                        &features,
                        quantised_features.unwrap_or(12),
                        None,
                    )?)
                }
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
            _ => match gop.hac_anchors().filter(|_| !raw_anchors) {
                Some(h) => {
                    let h = h.requantized(anchor_step_scale)?;
                    let t = std::time::Instant::now();
                    let sizes = w
                        .push_gop_hac(&h, &mlps, dynamic)
                        .with_context(|| format!("writing GOP {g}"))?;
                    let ms = t.elapsed().as_secs_f64() * 1e3;
                    ahac_report(dir, &h, &sizes, &canonical, ms);
                    // Later residuals apply to what the decoder holds: the AHAC anchors.
                    decoded = Some((h.canonical(), mlps));
                }
                None => {
                    w.push_gop(&canonical, &mlps, dynamic)
                        .with_context(|| format!("writing GOP {g}"))?;
                    decoded = Some((canonical, mlps));
                }
            },
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
        "bytes per frame: reference {:.1} (bitstreams, mp4, mlps.pth, csv), .dlgs {:.1} ({:.1} %)",
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

/// Bytes of the reference's files for the anchors of one GOP: `anchor.npy`, `hash.b` and the
/// Gaussian-coded files of each attribute (prefix `feat_`, `scaling_`, `offsets_`), and
/// `patched_infos.npy` (counts, batch size, box).
fn reference_anchor_files(dir: &Path) -> [(String, u64); 6] {
    let bs = dir.join("bitstreams");
    let size = |p: PathBuf| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    let prefixed = |pre: &str| -> u64 {
        std::fs::read_dir(&bs)
            .map(|it| {
                it.filter_map(|e| e.ok())
                    .filter(|e| e.file_name().to_string_lossy().starts_with(pre))
                    .map(|e| e.metadata().map(|m| m.len()).unwrap_or(0))
                    .sum()
            })
            .unwrap_or(0)
    };
    [
        ("anchor.npy".into(), size(bs.join("anchor.npy"))),
        ("hash.b".into(), size(bs.join("hash.b"))),
        ("feat_*.b".into(), prefixed("feat_")),
        ("scaling_*.b".into(), prefixed("scaling_")),
        ("offsets_*.b".into(), prefixed("offsets_")),
        (
            "patched_infos.npy".into(),
            size(bs.join("patched_infos.npy")),
        ),
    ]
}

/// The byte table of an `AHAC` chunk against the reference's files, and the largest difference
/// of the values we decode from the reference decoder's (the ingest's).
fn ahac_report(
    dir: &Path,
    h: &dlgs::chunks::ahac::HacAnchors,
    sizes: &dlgs::chunks::ahac::AhacSizes,
    reference: &ScaffoldCanonical,
    ms: f64,
) {
    let r = reference_anchor_files(dir);
    // mlp_grid in mlps.pth: its float32 parameters (the share of the pickle's tensor data).
    let mlp_ref = 4
        * (h.context.w1.len() + h.context.b1.len() + h.context.w2.len() + h.context.b2.len())
            as u64;
    let rows: [(&str, u64, String); 6] = [
        (
            "positions",
            sizes.positions as u64,
            format!("{} {}", r[0].0, r[0].1),
        ),
        (
            "grids",
            sizes.grids as u64,
            format!("{} {}", r[1].0, r[1].1),
        ),
        (
            "mlp_grid",
            sizes.mlp as u64,
            format!("mlps.pth share (f32 raw) {mlp_ref}"),
        ),
        (
            "feature",
            sizes.streams[0] as u64,
            format!("{} {}", r[2].0, r[2].1),
        ),
        (
            "log-scaling",
            sizes.streams[1] as u64,
            format!("{} {}", r[3].0, r[3].1),
        ),
        (
            "offsets",
            sizes.streams[2] as u64,
            format!("{} {}", r[4].0, r[4].1),
        ),
    ];
    let head = sizes.header + sizes.batch_headers;
    let ours: u64 = rows.iter().map(|r| r.1).sum::<u64>() + head as u64;
    let theirs: u64 = r.iter().map(|x| x.1).sum::<u64>() + mlp_ref;
    println!(
        "AHAC ({} anchors, encoded in {ms:.0} ms): part, ours, reference",
        h.quantized.len()
    );
    for (name, b, rf) in &rows {
        println!("  {name:<12} {b:>9}   {rf}");
    }
    println!(
        "  {:<12} {head:>9}   {} {} (ours: header, batch headers)",
        "headers", r[5].0, r[5].1
    );
    println!(
        "  {:<12} {ours:>9}   {theirs} ({:.1} %)",
        "total",
        100.0 * ours as f64 / theirs.max(1) as f64
    );
    let ours = h.canonical();
    let diff = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0f32, f32::max)
    };
    let both = |f: fn(&dlgs::model::scaffold::Anchors) -> &[f32]| {
        diff(f(&ours.statics), f(&reference.statics))
            .max(diff(f(&ours.dynamics), f(&reference.dynamics)))
    };
    println!(
        "  max |ours - reference decoder|: feature {:e}, log-scaling {:e}, offsets {:e}, positions {:e}",
        both(|a| &a.features),
        both(|a| &a.log_scalings),
        both(|a| &a.offsets),
        {
            let p = |a: &dlgs::model::scaffold::Anchors| -> Vec<f32> {
                a.positions.iter().flatten().copied().collect()
            };
            diff(&p(&ours.statics), &p(&reference.statics))
                .max(diff(&p(&ours.dynamics), &p(&reference.dynamics)))
        }
    );
}
