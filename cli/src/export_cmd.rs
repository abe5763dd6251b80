//! `dlgs export` / `dlgs decode`: decoded frames as files other players read: INRIA PLY (plain,
//! or with the DLGStream extras), Niantic SPZ (v3 by default) or PlayCanvas SOG (a bundled
//! `.sog`), one frame or a sequence.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use dlgs::interop::spz_write::{write_spz, SpzVersion};
use dlgs::Gaussians;
use dlgs_query::RelevanceField;

use crate::query_cmd::{SelectArgs, Selection};
use crate::scene_io::Source;

#[derive(Args, Debug)]
pub struct ExportArgs {
    pub file: PathBuf,
    /// Time in seconds of a single frame.
    #[arg(long, default_value_t = 0.0, conflicts_with = "frames")]
    pub t: f64,
    /// A frame sequence: `a..b` (b excluded) or `a..=b`, in the file's frame numbers; OUTPUT
    /// is then a directory that receives `frame_NNNNN.<ext>`.
    #[arg(long)]
    pub frames: Option<String>,
    /// Resample the sequence at this rate (frames between the file's frames are interpolated).
    #[arg(long, requires = "frames")]
    pub fps: Option<f64>,
    /// `ply` (INRIA 3DGS layout), `spz` or `sog` (PlayCanvas SOG v2, bundled `.sog`).
    #[arg(long, default_value = "ply")]
    pub format: String,
    /// SPZ version to write: 3 (smallest-three rotations, current players) or 2 (older players).
    #[arg(long, default_value_t = 3)]
    pub spz_version: u8,
    /// PLY only: also write the DLGStream extras (language opacity and the 9-dim language
    /// feature as `lang_opacity`, `lang_0..`); plain INRIA PLY otherwise.
    #[arg(long)]
    pub extras: bool,
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub select: SelectArgs,
}

enum Format {
    Ply { extras: bool },
    Spz(SpzVersion),
    Sog,
}

impl Format {
    fn parse(a: &ExportArgs) -> Result<Self> {
        Ok(match a.format.as_str() {
            "ply" => Format::Ply { extras: a.extras },
            "spz" => {
                if a.extras {
                    bail!("--extras is for PLY: SPZ has no place for language features");
                }
                Format::Spz(match a.spz_version {
                    3 => SpzVersion::V3,
                    2 => SpzVersion::V2,
                    v => bail!("--spz-version {v}: 2 or 3"),
                })
            }
            "sog" => {
                if a.extras {
                    bail!("--extras is for PLY: SOG has no place for language features");
                }
                Format::Sog
            }
            f => bail!("--format {f}: ply, spz or sog"),
        })
    }
    fn ext(&self) -> &'static str {
        match self {
            Format::Ply { .. } => "ply",
            Format::Spz(_) => "spz",
            Format::Sog => "sog",
        }
    }
    fn encode(&self, g: &Gaussians) -> Result<Vec<u8>> {
        Ok(match self {
            Format::Ply { extras: true } => dlgs::interop::ply::write_ply(g)?,
            Format::Ply { extras: false } => dlgs::interop::ply::write_ply(&g.without_language())?,
            Format::Spz(v) => write_spz(g, *v)?,
            Format::Sog => dlgs::interop::sog_write::write_sog(&g.without_language())?,
        })
    }
}

/// Parse `a..b` / `a..=b` into the frames it names.
fn parse_frames(s: &str, frame_count: u32) -> Result<(u32, u32)> {
    let (a, b, inclusive) = if let Some((a, b)) = s.split_once("..=") {
        (a, b, true)
    } else if let Some((a, b)) = s.split_once("..") {
        (a, b, false)
    } else {
        bail!("--frames {s}: expected a..b or a..=b");
    };
    let a: u32 = a.trim().parse().with_context(|| format!("--frames {s}"))?;
    let b: u32 = b.trim().parse().with_context(|| format!("--frames {s}"))?;
    let end = if inclusive { b.saturating_add(1) } else { b };
    if a >= end || end > frame_count {
        bail!("--frames {s}: the file has frames 0..{frame_count}");
    }
    Ok((a, end))
}

/// Decodes the frames of one export: view-dependent decoders see the default orbit's first
/// camera (placed around the canonical Gaussians of the GOP shown, recomputed only when the
/// GOP changes), the language is evaluated, and a `--select` query is applied when given.
struct Frames<'s> {
    src: Source,
    /// (GOP, viewpoint, scene has language) of the last frame.
    view: Option<(Option<u32>, [f32; 3], bool)>,
    select: Option<(&'s Selection, RelevanceField<'s>)>,
}

impl Frames<'_> {
    fn at(&mut self, t: f64) -> Result<Gaussians> {
        let gop = self.src.gop_at(t);
        let (eye, language) = match self.view {
            Some((g, eye, language)) if g == gop => (eye, language),
            _ => {
                let canon = self.src.canonical(t)?;
                let eye = dlgs_render::orbit_cameras(&canon, &Default::default())
                    .first()
                    .map_or([0.0; 3], |c| c.position.to_array());
                self.view = Some((gop, eye, canon.has_language()));
                (eye, canon.has_language())
            }
        };
        let g = self.src.at(t, eye, language)?;
        match &self.select {
            Some((s, field)) => s.apply(field, g),
            None => Ok(g),
        }
    }
}

fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

fn export_one(frames: &mut Frames, t: f64, format: &Format, output: &Path) -> Result<()> {
    let g = frames.at(t)?;
    write(output, &format.encode(&g)?)?;
    println!("{} Gaussians at t = {t} s -> {}", g.len(), output.display());
    if let (Source::Scaffold(..), Some((_, eye, _))) = (&frames.src, frames.view) {
        println!(
            "  Scaffold-GS: the neural Gaussians generated for a camera at ({:.4}, {:.4}, {:.4}) \
             (orbit camera 0 of `dlgs render`), every anchor decoded",
            eye[0], eye[1], eye[2]
        );
    }
    Ok(())
}

/// `dlgs decode`: the Gaussians at `t` as a PLY with every attribute the file has.
pub fn run_decode(file: &Path, t: f64, output: &Path) -> Result<()> {
    let mut frames = Frames {
        src: Source::open(file)?,
        view: None,
        select: None,
    };
    export_one(&mut frames, t, &Format::Ply { extras: true }, output)
}

pub fn run_export(a: &ExportArgs) -> Result<()> {
    let format = Format::parse(a)?;
    let mut src = Source::open(&a.file)?;
    let selection = Selection::load(&a.select, &mut src, a.t)?;
    let select = match &selection {
        Some(s) => Some((s, s.field()?)),
        None => None,
    };
    let timing = src.timing();
    let mut frames = Frames {
        src,
        view: None,
        select,
    };
    let Some(range) = &a.frames else {
        return export_one(&mut frames, a.t, &format, &a.output);
    };
    let (file_fps, frame_count) = timing.context("--frames needs a .dlgs stream")?;
    let (first, end) = parse_frames(range, frame_count)?;
    let (t0, t1) = (first as f64 / file_fps, end as f64 / file_fps);
    let times: Vec<f64> = match a.fps {
        None => (first..end).map(|f| f as f64 / file_fps).collect(),
        Some(r) if r > 0.0 && r.is_finite() => {
            let n = ((t1 - t0) * r - 1e-9).ceil().max(1.0) as usize;
            (0..n).map(|i| t0 + i as f64 / r).collect()
        }
        Some(r) => bail!("--fps must be a positive number, got {r}"),
    };
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let bar = indicatif::ProgressBar::new(times.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames {eta}")
            .expect("valid template"),
    );
    let mut bytes = 0usize;
    for (i, &t) in times.iter().enumerate() {
        let g = frames.at(t)?;
        let data = format.encode(&g)?;
        bytes += data.len();
        write(
            &a.output.join(format!("frame_{i:05}.{}", format.ext())),
            &data,
        )?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    println!(
        "{} frames (t = {t0:.4} .. {:.4} s) -> {}/frame_NNNNN.{}, {:.1} KB per frame",
        times.len(),
        times.last().copied().unwrap_or(t0),
        a.output.display(),
        format.ext(),
        bytes as f64 / times.len() as f64 / 1e3
    );
    Ok(())
}
