//! `dlgs encode FRAME_FILES... | SEQ_DIR`: a sequence of per-frame splat scenes fitted into a
//! dynamic .dlgs (`dlgs_encoder::sequence`), then checked against its source frames.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use dlgs::container::header::ResidualMode;
use dlgs_encoder::sequence::{self, Fallback, NtcFitSettings, SequenceReport, SequenceSettings};
use dlgs_render::{metrics, render, RenderOptions};
use indicatif::{ProgressBar, ProgressStyle};

use crate::cameras_arg::CameraArgs;
use crate::codec_args::CodecArgs;
use crate::residual_args::{parse_residual_mode, refresh_interval};
use crate::scene_io::Source;

/// Options of per-frame sequences (several splat files, or a folder of them).
#[derive(Args, Debug, Clone)]
pub struct SequenceArgs {
    /// Frames per GOP of a sequence.
    #[arg(
        help_heading = "Sequences (per-frame files)",
        long,
        default_value_t = 60
    )]
    pub gop_length: u32,
    /// Frames between key time features of a sequence (divides --gop-length). Default 10, or 5
    /// where the motion is large (a median move of more than one neighbour spacing between two
    /// frames: 50.6 dB instead of 39.8 on a hard sequence, for 34 % more bytes).
    #[arg(help_heading = "Sequences (per-frame files)", long)]
    pub key_interval: Option<u32>,
    /// Two consecutive frames whose matched Gaussians match confidently less often than this
    /// share (0-1), or that match less than half their Gaussians, have no consistent
    /// correspondence: the --fallback takes over there (reported), or with --no-cuts the
    /// sequence is refused.
    #[arg(
        help_heading = "Sequences (per-frame files)",
        long,
        default_value_t = 0.9
    )]
    pub min_confident: f64,
    /// Refuse a sequence with a pair of frames that cannot be matched, instead of starting new
    /// tracks there.
    #[arg(help_heading = "Sequences (per-frame files)", long)]
    pub no_cuts: bool,
    /// Where two frames have no consistent correspondence: `resample` (the tracks go on carried
    /// by the displacement field fitted between the frames until the next GOP, whose first frame
    /// begins new tracks: one set of Gaussians per GOP) or `cut` (every track ends and the
    /// frame's own Gaussians begin new ones: as many Gaussians as coding each frame on its own,
    /// every frame exact). A sequence with cuts is coded with intra GOPs.
    #[arg(
        help_heading = "Sequences (per-frame files)",
        long,
        default_value = "resample",
        value_parser = ["resample", "cut"]
    )]
    pub fallback: String,
    /// GOPs after the first carry explicit residuals (RDLT) instead of the default fitted
    /// binary voxel residual field (RNTC). `--residual-mode intra` sends every GOP's canonical
    /// Gaussians instead (random access without a residual chain, more bytes).
    #[arg(help_heading = "Sequences (per-frame files)", long)]
    pub explicit_residuals: bool,
    /// Adam steps of each residual field's fit (more: a closer field, smaller time-feature
    /// offsets, longer encode).
    #[arg(
        help_heading = "Sequences (per-frame files)",
        long,
        default_value_t = 600
    )]
    pub field_iterations: usize,
    /// Time features of a sequence: `auto` codes them losslessly in 12 bits where the motion is
    /// large (a median move of more than one neighbour spacing between some two frames: there
    /// HEVC's lossy coding at crf 6 cost 11 dB for 1.7x fewer bytes on the hard sequences,
    /// docs/benchmarks/sequences.md) and lossy (--crf) elsewhere; `lossy` and `lossless` force
    /// one (--lossless-features is `lossless`).
    #[arg(
        help_heading = "Sequences (per-frame files)",
        long,
        default_value = "auto",
        value_parser = ["auto", "lossy", "lossless"]
    )]
    pub features: String,
    /// After encoding, decode every source frame's time and render it against the source
    /// frame from 8 orbit cameras around frame 0 (`dlgs compare`'s defaults): mean and worst
    /// PSNR over the frames.
    #[arg(help_heading = "Sequences (per-frame files)", long)]
    pub check: bool,
    /// With --check: write the PSNR of every frame here (CSV: frame, file, psnr_db).
    #[arg(help_heading = "Sequences (per-frame files)", long, value_name = "CSV")]
    pub check_csv: Option<PathBuf>,
}

const SPLAT_EXTENSIONS: [&str; 4] = ["ply", "sog", "spz", "splat"];

fn is_splat_file(p: &Path) -> bool {
    p.is_file()
        && p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| SPLAT_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// A folder that holds splat frames directly (not a reference run's GOP folders).
pub fn is_sequence_dir(p: &Path) -> bool {
    p.is_dir()
        && std::fs::read_dir(p).is_ok_and(|entries| {
            entries
                .filter_map(|e| e.ok())
                .filter(|e| is_splat_file(&e.path()))
                .take(2)
                .count()
                == 2
        })
}

/// Natural order: digit runs compare as numbers (`frame_9` before `frame_10`).
fn natural_key(s: &str) -> Vec<(bool, String, u128)> {
    let mut out = Vec::new();
    let mut chars = s.chars().peekable();
    while let Some(&c) = chars.peek() {
        let digit = c.is_ascii_digit();
        let mut run = String::new();
        while let Some(&c) = chars.peek() {
            if c.is_ascii_digit() != digit {
                break;
            }
            run.push(c);
            chars.next();
        }
        let n = if digit {
            run.parse().unwrap_or(u128::MAX)
        } else {
            0
        };
        out.push((digit, if digit { String::new() } else { run }, n));
    }
    out
}

/// The frame files of the inputs: files as given (in natural order of their names), folders
/// expanded to the splat files they hold.
pub fn frame_files(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for p in inputs {
        if p.is_dir() {
            for e in std::fs::read_dir(p).with_context(|| format!("reading {}", p.display()))? {
                let path = e?.path();
                if is_splat_file(&path) {
                    files.push(path);
                }
            }
        } else {
            files.push(p.clone());
        }
    }
    files.sort_by_cached_key(|p| {
        natural_key(
            &p.file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default(),
        )
    });
    if files.len() < 2 {
        bail!(
            "a sequence needs at least 2 frame files, found {}",
            files.len()
        );
    }
    Ok(files)
}

fn bar(len: usize, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len as u64);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len}, {elapsed}")
            .expect("static template"),
    );
    pb.set_message(what.to_string());
    pb
}

pub fn run_sequence(
    inputs: &[PathBuf],
    output: &Path,
    codec: &CodecArgs,
    fps: u32,
    residual_mode: Option<&str>,
    seq: &SequenceArgs,
) -> Result<()> {
    if seq.check_csv.is_some() && !seq.check {
        bail!("--check-csv writes what --check measures: give --check too");
    }
    let files = frame_files(inputs)?;
    let started = std::time::Instant::now();
    let pb = bar(files.len(), "reading frames");
    let mut frames = Vec::with_capacity(files.len());
    let mut in_bytes = 0u64;
    for (t, f) in files.iter().enumerate() {
        let g = dlgs::interop::read_splat_file(f)
            .with_context(|| format!("frame {t} ({})", f.display()))?;
        in_bytes += std::fs::metadata(f).map(|m| m.len()).unwrap_or(0);
        frames.push(g);
        pb.set_position(t as u64 + 1);
    }
    pb.finish_and_clear();
    let mode = match residual_mode {
        Some(m) => parse_residual_mode(m)?,
        None => SequenceSettings::default().residual_mode,
    };
    let settings = SequenceSettings {
        fps_num: fps,
        fps_den: 1,
        gop_length: seq.gop_length,
        key_interval: seq.key_interval.unwrap_or(10),
        large_motion_key_interval: if seq.key_interval.is_some() {
            None
        } else {
            SequenceSettings::default().large_motion_key_interval
        },
        min_confident: seq.min_confident,
        allow_cuts: !seq.no_cuts,
        fallback: if seq.fallback == "cut" {
            Fallback::Cut
        } else {
            Fallback::Resample
        },
        residual_mode: mode,
        refresh_interval: refresh_interval(codec.refresh, mode)?,
        residual_field: (!seq.explicit_residuals).then(|| NtcFitSettings {
            iterations: seq.field_iterations,
            ..NtcFitSettings::default()
        }),
    };
    if seq.explicit_residuals && settings.residual_mode == ResidualMode::Intra {
        bail!("--explicit-residuals needs a residual mode: sequential or parallel, not intra");
    }
    let pb = bar(files.len(), "matching frames");
    let mut stage = String::new();
    let (model, report) = sequence::build(frames, &settings, &mut |what, done, total| {
        if what != stage {
            stage = what.to_owned();
            pb.set_message(stage.clone());
            pb.set_length(total as u64);
        }
        pb.set_position(done as u64);
    })
    .map_err(|e| {
        // Say which file a frame number is.
        anyhow::anyhow!("{e}").context(format!(
            "{} frames from {}",
            files.len(),
            files[0].display()
        ))
    })?;
    pb.finish_and_clear();
    let fit_seconds = started.elapsed().as_secs_f64();
    let mut codec = codec.defaulting_quality("high");
    let large = report.motion;
    if large > sequence::LARGE_MOTION && seq.key_interval.is_none() {
        println!(
            "large motion (median move up to {large:.1}x the neighbour spacing): keys every {} \
             frames (--key-interval to choose)",
            report.key_interval
        );
    }
    match seq.features.as_str() {
        "lossless" => codec.lossless_features = true,
        "lossy" if codec.lossless_features => {
            bail!("--features lossy contradicts --lossless-features")
        }
        "auto" if !codec.lossless_features && large > sequence::LARGE_MOTION => {
            codec.lossless_features = true;
            println!(
                "large motion (median move up to {large:.1}x the neighbour spacing): time features \
                 coded losslessly in 12 bits (--features lossy for crf {})",
                codec.crf
            );
        }
        _ => {}
    }
    let meta = serde_json::json!({
        "source": format!("{} per-frame files, {} .. {}", files.len(),
            files[0].file_name().unwrap_or_default().to_string_lossy(),
            files[files.len() - 1].file_name().unwrap_or_default().to_string_lossy()),
        "encoder": concat!("dlgs ", env!("CARGO_PKG_VERSION")),
        "settings": codec.changed_settings(),
        "sequence": { "gop_length": seq.gop_length, "key_interval": report.key_interval },
    });
    let cfg = codec.config(meta)?;
    let pb = ProgressBar::new_spinner();
    pb.set_message(format!("coding {} GOPs", model.gops.len()));
    pb.enable_steady_tick(std::time::Duration::from_millis(200));
    let fields = settings.residual_field.is_some() && settings.residual_mode != ResidualMode::Intra;
    let (bytes, written) = if fields {
        pb.finish_and_clear();
        let pf = bar(1, "fitting residual fields");
        let out = sequence::write_with_report(&model, cfg, Vec::new(), &mut |_, done, total| {
            pf.set_length(total as u64);
            pf.set_position(done as u64);
        })?;
        pf.finish_and_clear();
        out
    } else {
        let out = sequence::write(&model, cfg, Vec::new())?;
        pb.finish_and_clear();
        (out, sequence::WriteReport::default())
    };
    std::fs::write(output, &bytes).with_context(|| format!("writing {}", output.display()))?;
    print_report(
        &report,
        &files,
        fit_seconds,
        started.elapsed().as_secs_f64(),
    );
    print_fields(&written);
    println!(
        "{} -> {}: {} bytes ({:.1}% of the frames' {in_bytes} bytes), {:.0} bytes/frame",
        inputs[0].display(),
        output.display(),
        bytes.len(),
        100.0 * bytes.len() as f64 / in_bytes.max(1) as f64,
        bytes.len() as f64 / files.len() as f64
    );
    if seq.check {
        let cams = CameraArgs {
            cameras: None,
            view: None,
            orbit: 8,
            width: None,
            height: None,
            up: "-y".into(),
            distance: 1.6,
        };
        check(output, &files, fps, &cams, seq.check_csv.as_deref())?;
    }
    Ok(())
}

fn print_report(r: &SequenceReport, files: &[PathBuf], fit_s: f64, total_s: f64) {
    let name = |t: usize| {
        files[t]
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .to_string()
    };
    let counts = if r.min_count == r.max_count {
        format!("{} Gaussians", r.min_count)
    } else {
        format!("{}-{} Gaussians", r.min_count, r.max_count)
    };
    println!(
        "{} frames of {counts}: {} tracks' slots, {} static, {} dynamic ({} shown for part of the \
         sequence); read, matched and fitted in {fit_s:.1} s, coded in {:.1} s",
        r.frames,
        r.slots,
        r.n_static,
        r.n_dynamic,
        r.partial,
        total_s - fit_s
    );
    if let Some(w) = r.worst_pair() {
        let n = r.pairs.len() as f64;
        let mean = r.pairs.iter().map(|p| p.confident_share).sum::<f64>() / n;
        let ratio = |p: &sequence::PairReport| p.median_distance / p.spacing.max(1e-12);
        let fastest = r
            .pairs
            .iter()
            .max_by(|a, b| ratio(a).total_cmp(&ratio(b)))
            .expect("pairs");
        println!(
            "correspondence: {:.2}% confident matches on average, worst {:.2}% ({} -> {}); \
             largest move {:.3e}, median move up to {:.1}x the spacing ({} -> {}); {} births, {} \
             deaths",
            100.0 * mean,
            100.0 * w.confident_share,
            name(w.frame - 1),
            name(w.frame),
            r.pairs
                .iter()
                .map(|p| p.max_distance)
                .fold(0.0f32, f32::max),
            ratio(fastest),
            name(fastest.frame - 1),
            name(fastest.frame),
            r.pairs.iter().map(|p| p.births).sum::<usize>(),
            r.pairs.iter().map(|p| p.deaths).sum::<usize>(),
        );
    }
    let pairs_at = |ts: &[usize]| {
        let mut s = ts
            .iter()
            .take(8)
            .map(|&t| format!("{} -> {}", name(t - 1), name(t)))
            .collect::<Vec<_>>()
            .join(", ");
        if ts.len() > 8 {
            s.push_str(", ...");
        }
        s
    };
    if !r.resampled.is_empty() {
        println!(
            "no consistent correspondence at {} frame(s) ({}): the tracks went on carried by the \
             fitted motion (fallback `resample`; those frames' own Gaussians are not shown: \
             --check measures what that costs; --fallback cut codes them exactly, --no-cuts \
             refuses)",
            r.resampled.len(),
            pairs_at(&r.resampled)
        );
    }
    if !r.cuts.is_empty() {
        println!(
            "no consistent correspondence at {} frame(s) ({}): every track ended there and new \
             ones began; coded with {:?} GOPs (--no-cuts refuses instead)",
            r.cuts.len(),
            pairs_at(&r.cuts),
            r.residual_mode
        );
    }
    for (g, f) in r.gops.iter().enumerate() {
        let (worst_u, worst) = f
            .frame_position_rms
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(u, &e)| (u, e))
            .unwrap_or((0, 0.0));
        println!(
            "  GOP {g}: position fit RMS {:.2e} (worst frame {} at {worst:.2e}), shared channels \
             hold {:.4}% of the rotation/scale/colour/opacity offsets{}",
            f.position_rms,
            g * r.gop_length + worst_u,
            100.0 * f.shared_energy_kept,
            if f.scale_offsets { ", scales move" } else { "" }
        );
    }
}

/// Decode the file at every source frame's time and render both from the same cameras.
fn check(
    output: &Path,
    files: &[PathBuf],
    fps: u32,
    cams: &CameraArgs,
    csv: Option<&Path>,
) -> Result<()> {
    let mut dec = Source::open(output)?;
    let first = dlgs::interop::read_splat_file(&files[0])?;
    let cameras = cams.resolve(&first)?;
    let opts = RenderOptions {
        background: [1.0, 1.0, 1.0],
        features: false,
        ..Default::default()
    };
    let pb = bar(files.len(), "checking frames");
    let mut per_frame = Vec::with_capacity(files.len());
    let mut decode_s = 0.0;
    for (t, f) in files.iter().enumerate() {
        let src = dlgs::interop::read_splat_file(f)?;
        let time = t as f64 / fps as f64;
        let mut psnr = 0.0;
        for cam in &cameras {
            let started = std::time::Instant::now();
            let got = dec.at(time, cam.position.to_array(), false)?;
            decode_s += started.elapsed().as_secs_f64();
            let a = render(&src, cam, &opts).map_err(anyhow::Error::msg)?;
            let b = render(&got, cam, &opts).map_err(anyhow::Error::msg)?;
            psnr += metrics::psnr(&a.color, &b.color).min(100.0);
        }
        per_frame.push(psnr / cameras.len() as f64);
        pb.set_position(t as u64 + 1);
    }
    pb.finish_and_clear();
    if let Some(csv) = csv {
        let mut out = String::from("frame,file,psnr_db\n");
        for (t, (p, f)) in per_frame.iter().zip(files).enumerate() {
            let name = f.file_name().unwrap_or_default().to_string_lossy();
            out.push_str(&format!("{t},{name},{p:.3}\n"));
        }
        std::fs::write(csv, out).with_context(|| format!("writing {}", csv.display()))?;
    }
    let mean = per_frame.iter().sum::<f64>() / per_frame.len() as f64;
    let (worst_t, worst) = per_frame
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(t, &p)| (t, p))
        .unwrap_or((0, 0.0));
    println!(
        "check against the {} source frames ({} cameras each, PSNR capped at 100 dB): mean \
         {mean:.2} dB, worst {worst:.2} dB (frame {worst_t}, {}); {:.2} ms per decoded frame",
        files.len(),
        cameras.len(),
        files[worst_t]
            .file_name()
            .unwrap_or_default()
            .to_string_lossy(),
        1e3 * decode_s / (files.len() * cameras.len()) as f64
    );
    Ok(())
}

/// Per GOP with a residual field: how much of the change from the previous GOP the residual field
/// carries (RMS of the position offsets before and after), and the refitted GOP's position fit.
fn print_fields(w: &sequence::WriteReport) {
    for (g, (f, r)) in w.field_gops.iter().zip(w.fields.iter().zip(&w.refits)) {
        let rms = |v: &[f64]| (v[..3].iter().map(|x| x * x).sum::<f64>() / 3.0).sqrt();
        println!(
            "  GOP {}: residual field leaves {:.2e} of the {:.2e} position change (RMS); \
             refitted position RMS {:.2e}",
            g,
            rms(&f.residual_rms),
            rms(&f.target_rms),
            r.position_rms
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_sort_naturally() {
        let mut names = ["f10.ply", "f9.ply", "f100.ply", "f1.ply", "g0.ply"];
        names.sort_by_cached_key(|n| natural_key(n));
        assert_eq!(names, ["f1.ply", "f9.ply", "f10.ply", "f100.ply", "g0.ply"]);
    }
}
