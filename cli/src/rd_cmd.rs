//! `dlgs rd`: rate-distortion sweep. Encodes a model at every setting (crf x canonical
//! quality x bits), decodes every frame in order (decode time per frame), renders sampled
//! times from the cameras, and writes PSNR / SSIM against the model itself to a CSV plus two
//! PNG plots (bytes per frame vs PSNR, decode ms per frame vs PSNR). Scaffold-GS files sweep
//! their anchor steps instead (`rd_scaffold`), into the same table, CSV and plots.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Parser;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_render::{metrics, render, Camera, RenderOptions};

use crate::cameras_arg::CameraArgs;
use crate::encode_cmd::{encode_file, CodecArgs};
use crate::rd_plot::{self, Point};
use crate::scene_io::{is_dlgs, is_scaffold, Source};

#[derive(clap::Args)]
pub struct RdArgs {
    /// The reference model: a .dlgs (ideally lossless, e.g. from `dlgs synth`) or a splat
    /// scene; PSNR is measured against it. A Scaffold-GS .dlgs (e.g. from `dlgs encode
    /// HAC_RUN`) is re-coded from the file itself at each --anchor-step-scale.
    pub model: PathBuf,
    /// x265 crf values to sweep (time features; ignored for still scenes) [default:
    /// 6,10,14,18,24].
    #[arg(long)]
    pub crf: Option<String>,
    /// Canonical quality presets to sweep (lossless, high, medium, low) [default: high].
    #[arg(long)]
    pub quality: Option<String>,
    /// Canonical bit settings to sweep, `;`-separated, each as `dlgs encode --bits`
    /// (e.g. `position=16;position=14,sh_rest=5`); crossed with --quality.
    #[arg(long)]
    pub bits: Option<String>,
    /// Extra `dlgs encode` flags for every setting, e.g. "--preset fast --mlp-f16".
    #[arg(long, allow_hyphen_values = true, default_value = "")]
    pub encode_flags: String,
    /// Scaffold-GS files only: anchor step scales to sweep (`dlgs encode HAC_RUN
    /// --anchor-step-scale`), relative to the file's steps; the file's HAC-coded anchors
    /// (`AHAC`) are decoded and re-coded at each, every other chunk kept [default: 1,2,4,8].
    #[arg(long)]
    pub anchor_step_scale: Option<String>,
    /// Times rendered per setting, evenly spread over the model (GOP starts included).
    #[arg(long, default_value_t = 4)]
    pub times: usize,
    #[command(flatten)]
    pub cams: CameraArgs,
    /// Output directory: rd.csv, rd_bytes_psnr.png, rd_decode_psnr.png.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Only redraw the plots from OUTPUT/rd.csv (no encoding).
    #[arg(long)]
    pub plot_only: bool,
    /// Render reference and decoded frames with the fast compositor (`Accuracy::Fast`, within
    /// 60 dB PSNR of the exact renderer); default exact.
    #[arg(long)]
    pub fast_render: bool,
}

#[derive(Parser)]
struct EncodeFlags {
    #[command(flatten)]
    codec: CodecArgs,
}

/// One point of the sweep.
pub(crate) struct Setting {
    pub quality: String,
    pub bits: Option<String>,
    pub crf: Option<u8>,
    /// Scaffold-GS: the anchor step scale (then `quality` is [`ANCHOR_STEPS`]).
    pub anchor_step_scale: Option<f32>,
}

/// The `quality` column of Scaffold-GS rows (the family of the anchor step sweep).
pub(crate) const ANCHOR_STEPS: &str = "anchor-steps";

impl Setting {
    fn family(&self) -> String {
        match &self.bits {
            Some(b) => format!("{} {b}", self.quality),
            None => self.quality.clone(),
        }
    }
    /// The setting as the table shows it.
    fn name(&self) -> String {
        match self.anchor_step_scale {
            Some(k) => format!("anchor-step-scale {k}"),
            None => self.family(),
        }
    }
    /// The point's label in the plots.
    fn label(&self) -> String {
        match (self.crf, self.anchor_step_scale) {
            (Some(c), _) => format!(" crf {c}"),
            (None, Some(k)) => format!(" k={k}"),
            (None, None) => String::new(),
        }
    }
    fn codec(&self, extra: &str) -> Result<CodecArgs> {
        let mut argv: Vec<String> = vec!["encode".into(), "--quality".into(), self.quality.clone()];
        if let Some(b) = &self.bits {
            argv.extend(["--bits".into(), b.clone()]);
        }
        if let Some(c) = self.crf {
            argv.extend(["--crf".into(), c.to_string()]);
        }
        argv.extend(extra.split_whitespace().map(String::from));
        Ok(EncodeFlags::try_parse_from(&argv)
            .with_context(|| format!("encode flags {}", argv[1..].join(" ")))?
            .codec)
    }
}

pub(crate) struct Row {
    pub setting: Setting,
    pub bytes: u64,
    pub frames: u32,
    pub psnr: f64,
    pub ssim: f64,
    /// PSNR of the language feature images (files with language; Scaffold-GS sweeps only).
    pub lang_psnr: Option<f64>,
    pub decode_ms_per_frame: f64,
    pub encode_s: f64,
}

pub(crate) fn list<T: std::str::FromStr>(s: &str, what: &str) -> Result<Vec<T>> {
    s.split(',')
        .filter(|x| !x.trim().is_empty())
        .map(|x| {
            x.trim()
                .parse::<T>()
                .map_err(|_| anyhow::anyhow!("--{what}: cannot read {x:?}"))
        })
        .collect()
}

/// Sampled times: evenly spread, starting at 0.
pub(crate) fn sample_times(src: &Source, n: usize) -> Vec<f64> {
    match src.timing() {
        None => vec![0.0],
        Some((fps, frames)) => {
            let n = n.clamp(1, frames as usize);
            (0..n)
                .map(|i| (i as u64 * frames as u64 / n as u64) as f64 / fps)
                .collect()
        }
    }
}

/// Decode every frame in order with a fresh decoder: mean wall time per frame, GOP decoding
/// (HEVC, residuals) included.
fn decode_ms_per_frame(file: &Path) -> Result<f64> {
    let t0 = Instant::now();
    let mut dec =
        Decoder::open_path(file).with_context(|| format!("opening {}", file.display()))?;
    let frames = dec.scene().frame_count.max(1);
    let fps = dec.scene().fps();
    let opts = FrameOptions {
        camera_center: [0.0; 3],
        language: false,
    };
    let mut reuse = dlgs::Gaussians::default();
    for f in 0..frames {
        reuse = dec.frame_at_reusing(f as f64 / fps, &opts, reuse)?.dynamics;
    }
    Ok(t0.elapsed().as_secs_f64() * 1e3 / frames as f64)
}

/// Colour renders (with `language`, the language feature images too) of `src` at every
/// (time, camera). Scaffold-GS files decode only the anchors in view: the same image.
pub(crate) fn renders(
    src: &mut Source,
    times: &[f64],
    cams: &[Camera],
    language: bool,
    fast_render: bool,
) -> Result<Vec<dlgs_render::Image>> {
    let opts = RenderOptions {
        features: language,
        accuracy: crate::accuracy(fast_render),
        ..RenderOptions::default()
    };
    let mut out = Vec::new();
    for &t in times {
        for cam in cams {
            let g = src.at_camera(t, cam, language, true)?;
            out.push(render(&g, cam, &opts).map_err(anyhow::Error::msg)?);
        }
    }
    Ok(out)
}

/// Rows of an `rd.csv` written by [`write_outputs`].
fn read_csv(path: &Path) -> Result<Vec<Row>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let bad = || anyhow::anyhow!("{}:{}: not a dlgs rd row", path.display(), i + 1);
        // The bits column is quoted and may hold commas.
        let (head, rest) = line.split_once(",\"").ok_or_else(bad)?;
        let (bits, tail) = rest.split_once("\",").ok_or_else(bad)?;
        // Since the Scaffold-GS sweep: two more columns (anchor step scale, language PSNR).
        let f: Vec<&str> = tail.split(',').collect();
        if f.len() != 8 && f.len() != 10 {
            return Err(bad());
        }
        let num = |k: usize| f[k].parse::<f64>().map_err(|_| bad());
        let opt = |k: usize| f.get(k).and_then(|v| v.parse::<f64>().ok());
        rows.push(Row {
            setting: Setting {
                quality: head.to_string(),
                bits: (!bits.is_empty()).then(|| bits.to_string()),
                crf: f[0].parse().ok(),
                anchor_step_scale: opt(8).map(|k| k as f32),
            },
            bytes: num(1)? as u64,
            frames: num(2)? as u32,
            psnr: num(4)?,
            ssim: num(5)?,
            lang_psnr: opt(9),
            decode_ms_per_frame: num(6)?,
            encode_s: num(7)?,
        });
    }
    Ok(rows)
}

pub fn run_rd(a: &RdArgs) -> Result<()> {
    if a.plot_only {
        let rows = read_csv(&a.output.join("rd.csv"))?;
        return plots(a, &rows);
    }
    let dynamic = is_dlgs(&a.model);
    if dynamic && is_scaffold(&a.model)? {
        return crate::rd_scaffold::run(a);
    }
    if a.anchor_step_scale.is_some() {
        bail!(
            "--anchor-step-scale sweeps the anchors of Scaffold-GS files; {} is not one",
            a.model.display()
        );
    }
    let crfs: Vec<Option<u8>> = if dynamic {
        list::<u8>(a.crf.as_deref().unwrap_or("6,10,14,18,24"), "crf")?
            .into_iter()
            .map(Some)
            .collect()
    } else {
        vec![None]
    };
    let qualities: Vec<String> = list(a.quality.as_deref().unwrap_or("high"), "quality")?;
    let bits: Vec<Option<String>> = match &a.bits {
        Some(b) => b.split(';').map(|s| Some(s.trim().to_string())).collect(),
        None => vec![None],
    };
    let mut settings = Vec::new();
    for q in &qualities {
        for b in &bits {
            for &crf in &crfs {
                settings.push(Setting {
                    quality: q.clone(),
                    bits: b.clone(),
                    crf,
                    anchor_step_scale: None,
                });
            }
        }
    }
    if settings.is_empty() {
        bail!("nothing to sweep: give --crf and --quality values");
    }
    // Check every setting's flags before the long work starts.
    for s in &settings {
        s.codec(&a.encode_flags)?;
    }
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;

    let mut reference = Source::open(&a.model)?;
    let cams = a.cams.resolve(&reference.canonical(0.0)?)?;
    let times = sample_times(&reference, a.times);
    let ref_images = renders(&mut reference, &times, &cams, false, a.fast_render)?;

    let bar = indicatif::ProgressBar::new(settings.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} settings {msg} {eta}")
            .expect("valid template"),
    );
    let tmp = a.output.join("rd_current.dlgs");
    let mut rows = Vec::new();
    for s in settings {
        bar.set_message(format!("{} crf {:?}", s.family(), s.crf));
        let t0 = Instant::now();
        let frames = encode_file(&a.model, &tmp, &s.codec(&a.encode_flags)?, None, false)?;
        let encode_s = t0.elapsed().as_secs_f64();
        let bytes = std::fs::metadata(&tmp)?.len();
        let decode_ms_per_frame = decode_ms_per_frame(&tmp)?;
        let mut test = Source::open(&tmp)?;
        let images = renders(&mut test, &times, &cams, false, a.fast_render)?;
        let (mut psnr, mut ssim) = (0.0, 0.0);
        for (r, t) in ref_images.iter().zip(&images) {
            psnr += metrics::psnr(&r.color, &t.color);
            ssim += metrics::ssim(&r.color, &t.color, r.width, r.height);
        }
        let n = images.len() as f64;
        rows.push(Row {
            setting: s,
            bytes,
            frames,
            psnr: psnr / n,
            ssim: ssim / n,
            lang_psnr: None,
            decode_ms_per_frame,
            encode_s,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    let _ = std::fs::remove_file(&tmp);
    write_outputs(a, &rows, times.len() * cams.len())
}

pub(crate) fn write_outputs(a: &RdArgs, rows: &[Row], views: usize) -> Result<()> {
    let mut csv = String::from(
        "quality,bits,crf,bytes,frames,bytes_per_frame,psnr_db,ssim,decode_ms_per_frame,encode_s,\
         anchor_step_scale,lang_psnr_db\n",
    );
    let lang = rows.iter().any(|r| r.lang_psnr.is_some());
    println!(
        "{:<24} {:>4} {:>11} {:>13} {:>9} {:>8} {:>10} {:>9}{}",
        "setting",
        "crf",
        "bytes",
        "bytes/frame",
        "PSNR dB",
        "SSIM",
        "decode ms",
        "encode s",
        if lang { "  lang dB" } else { "" }
    );
    for r in rows {
        let s = &r.setting;
        let crf = s.crf.map_or(String::new(), |c| c.to_string());
        let bpf = r.bytes as f64 / r.frames as f64;
        let k = s.anchor_step_scale.map_or(String::new(), |k| k.to_string());
        let lang_db = r.lang_psnr.map_or(String::new(), |p| format!("{p:.3}"));
        csv += &format!(
            "{},\"{}\",{},{},{},{:.1},{:.3},{:.5},{:.3},{:.2},{k},{lang_db}\n",
            s.quality,
            s.bits.as_deref().unwrap_or(""),
            crf,
            r.bytes,
            r.frames,
            bpf,
            r.psnr,
            r.ssim,
            r.decode_ms_per_frame,
            r.encode_s
        );
        println!(
            "{:<24} {:>4} {:>11} {:>13.1} {:>9.2} {:>8.5} {:>10.3} {:>9.2}{}",
            s.name(),
            crf,
            r.bytes,
            bpf,
            r.psnr,
            r.ssim,
            r.decode_ms_per_frame,
            r.encode_s,
            r.lang_psnr.map_or(String::new(), |p| format!(" {p:>8.2}"))
        );
    }
    let csv_path = a.output.join("rd.csv");
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    println!(
        "PSNR/SSIM: mean over {views} renders (times x cameras) against {}",
        a.model.display()
    );
    if lang {
        println!(
            "language PSNR: peak = the range of the reference's language feature values, \
             mean over the same renders"
        );
    }
    println!("-> {}", csv_path.display());
    plots(a, rows)
}

fn plots(a: &RdArgs, rows: &[Row]) -> Result<()> {
    let mut families: Vec<(String, Vec<&Row>)> = Vec::new();
    for r in rows {
        let f = r.setting.family();
        match families.iter_mut().find(|(n, _)| *n == f) {
            Some((_, v)) => v.push(r),
            None => families.push((f, vec![r])),
        }
    }
    let label = |r: &Row| r.setting.label();
    let series = |x: &dyn Fn(&Row) -> f64| -> Vec<(String, Vec<Point>)> {
        families
            .iter()
            .map(|(name, rs)| {
                let pts = rs
                    .iter()
                    .map(|r| Point {
                        x: x(r),
                        psnr: r.psnr,
                        label: label(r),
                    })
                    .collect();
                (name.clone(), pts)
            })
            .collect()
    };
    let name = a
        .model
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let plots = [
        (
            "rd_bytes_psnr.png",
            format!("{name}: rate vs quality"),
            "KB per frame",
            true,
            true,
            series(&|r| r.bytes as f64 / r.frames as f64 / 1e3),
        ),
        (
            "rd_decode_psnr.png",
            format!("{name}: decode time vs quality"),
            "decode ms per frame (all frames in order, 1 process)",
            false,
            false,
            series(&|r| r.decode_ms_per_frame),
        ),
    ];
    for (file, title, xl, log, lines, s) in plots {
        let p = a.output.join(file);
        match rd_plot::plot(&p, &title, xl, log, lines, &s) {
            Ok(()) => println!("-> {}", p.display()),
            Err(e) => eprintln!("warning: no plot {}: {e:#}", p.display()),
        }
    }
    Ok(())
}
