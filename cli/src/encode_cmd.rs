//! `dlgs encode` (splat scene -> still, or .dlgs -> re-encoded .dlgs).

use std::path::Path;

use anyhow::{bail, Context, Result};
use dlgs::container::header::ResidualMode;
use dlgs_decoder::Decoder;
use dlgs_encoder::{CanonicalCodec, EncoderConfig, GopCanonical, StreamEncoder};
use indicatif::{ProgressBar, ProgressStyle};

use crate::pending_file::PendingFile;
use crate::scene_io::is_dlgs;

pub use crate::codec_args::CodecArgs;
use crate::residual_args::{parse_residual_mode, refresh_interval};

pub(crate) fn meta(input: &Path, extra: serde_json::Value) -> serde_json::Value {
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
pub(crate) fn report(input: &Path, in_size: u64, output: &Path, frames: u32) -> Result<()> {
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
    let in_size = input_size(input).with_context(|| format!("reading {}", input.display()))?;
    let frames = encode_file(input, output, codec, residual_mode, true)?;
    report(input, in_size, output, frames)
}

/// Bytes of the input: for an unbundled SOG (`meta.json`), with the WebP textures beside it.
fn input_size(input: &Path) -> std::io::Result<u64> {
    let own = std::fs::metadata(input)?.len();
    if input.file_name().and_then(|n| n.to_str()) != Some("meta.json") {
        return Ok(own);
    }
    let dir = input.parent().unwrap_or(Path::new("."));
    let mut total = own;
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.extension().and_then(|e| e.to_str()) == Some("webp") {
            total += std::fs::metadata(&path)?.len();
        }
    }
    Ok(total)
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
    use dlgs_encoder::quality_search::{compare_views_psnr, smallest_at, PSNR_CAP};
    if !(target.is_finite() && target > 0.0) {
        bail!("--target-psnr takes a PSNR in dB > 0, got {target}");
    }
    // The search sets the bits itself; a lossy preset here only lets the rest be checked.
    let base = CodecArgs {
        target_psnr: None,
        quality: Some("high".into()),
        ..codec.clone()
    };
    let cfg = base.config(meta)?;
    if target > PSNR_CAP {
        // The search counts each view at most PSNR_CAP: no candidate could reach the target,
        // and coding them all would take minutes.
        if verbose {
            println!(
                "  {target:.2} dB is above the search's cap of {PSNR_CAP} dB per view: \
                 storing the scene lossless"
            );
        }
        let lossless = EncoderConfig {
            coding: dlgs_encoder::CanonicalSettings {
                codec: CanonicalCodec::Raw,
                ..cfg.coding
            },
            ..cfg
        };
        dlgs_encoder::encode_still(g, lossless, out)?;
        return Ok(());
    }
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
                    match (codec.max_compression, codec.mixed_margin) {
                        (true, _) => " --max-compression".to_owned(),
                        (false, Some(m)) => format!(" --mixed-margin {m}"),
                        (false, None) => String::new(),
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
                coding: dlgs_encoder::CanonicalSettings {
                    codec: CanonicalCodec::Raw,
                    ..cfg.coding
                },
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
    let mut settings = codec.changed_settings();
    let pending = PendingFile::create(output)?;
    let mut out = pending.writer()?;
    if !is_dlgs(input) {
        // A still scene is coded lossy unless asked otherwise (`--quality lossless`); META
        // records the preset used either way.
        let codec = &codec.defaulting_quality("high");
        if let (Some(q), serde_json::Value::Object(m)) = (&codec.quality, &mut settings) {
            m.entry("quality").or_insert_with(|| q.clone().into());
        }
        let g = dlgs::interop::read_splat_file(input)
            .with_context(|| format!("reading {}", input.display()))?;
        if let Some(target) = codec.target_psnr {
            encode_to_target(&g, target, codec, meta(input, settings), &mut out, verbose)?;
            pending.commit_written(out)?;
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
        pending.commit_written(out)?;
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
                    "  colour refit {} ({}{}): {:.2} -> {:.2} dB on the encoder's held-out views",
                    if r.kept { "stored" } else { "not stored" },
                    if r.on_levels {
                        "on the quantiser's levels"
                    } else {
                        "offsets rounded by the coder"
                    },
                    if r.opacities_moved {
                        ", opacities moved"
                    } else {
                        ""
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
    if codec.refresh != 0 || scene.residual_mode != ResidualMode::Sequential {
        scene.refresh_interval = refresh_interval(codec.refresh, scene.residual_mode)?;
    }
    let keep_ntc = match codec.ntc.as_str() {
        "keep" => true,
        "recode" => false,
        "auto" => matches!(codec.canonical()?, CanonicalCodec::Raw),
        v => bail!("--ntc {v}: expected keep, recode or auto"),
    };
    let mut cfg = codec.config(meta(input, settings))?;
    if cfg.language.decoder.is_none() {
        cfg.language.decoder = dec
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
    pending.commit_written(enc.finish()?)?;
    Ok(scene.frame_count)
}
