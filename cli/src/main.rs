//! `dlgs`: encode, inspect, decode and render `.dlgs` streams.

mod ahac_bench_cmd;
mod anchor_steps;
mod cameras_arg;
mod codec_args;
mod codec_config;
mod encode_cmd;
mod export_cmd;
mod hac_ingest_cmd;
mod info;
mod ingest_cmd;
mod pending_file;
mod play_cmd;
mod play_scaffold;
mod query_cmd;
mod rd_cmd;
mod rd_plot;
mod rd_scaffold;
mod residual_args;
mod scaffold_recode_cmd;
mod scene_io;
mod seek_cmd;
mod sequence_cmd;
mod synth_cmd;
mod synth_frames_cmd;

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use dlgs_render::{image_out, metrics, render, Accuracy, RenderOptions};

use cameras_arg::{cameras_to_json, CameraArgs};

#[derive(Parser)]
#[command(
    name = "dlgs",
    version,
    about = "Codec for language-embedded dynamic Gaussian splatting video (.dlgs)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Show a .dlgs file's header, GOP table and bytes per chunk type and per frame.
    Info {
        file: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
        /// Also list each `CSOG` chunk's channel records: bits, codec and bytes per channel
        /// and per attribute (where the bytes of the canonical Gaussians go).
        #[arg(long)]
        channels: bool,
    },
    /// Read every chunk of a .dlgs file and check every CRC and index entry.
    Verify { file: PathBuf },
    /// Time the decode of HAC-coded anchors (`AHAC`, format-spec §6.13): GOP 0 of a reference
    /// HAC run, and a synthetic one of `--anchors` anchors (real positions voxelised from
    /// `--ply`, symbols drawn from the run's context model), on 1 and 2 threads.
    #[command(hide = true)]
    AhacBench {
        /// A reference HAC run (e.g. tests/fixtures/scaffold_run).
        run: PathBuf,
        #[arg(long)]
        ply: Option<PathBuf>,
        #[arg(long, default_value_t = 100_000)]
        anchors: usize,
        /// Decodes per thread count (the median is reported).
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        /// Also fit a context model to each content's anchors at these steps (feature,
        /// log-scaling, offsets), e.g. `0.057,0.18,0.18`, and time its fit and decode.
        #[arg(long, value_name = "F,S,O")]
        fit_steps: Option<String>,
    },
    /// Encode a splat scene (PLY, .splat, SPZ, PlayCanvas SOG) into a single-frame .dlgs
    /// (`--quality high` by default: 41-68 dB against the source on the real scenes;
    /// `--quality lossless` keeps every float), re-encode a .dlgs stream with other settings (lossless canonical by default),
    /// or re-pack a model trained with the DLGStream reference implementation: give its GOP
    /// output folders (each `gop<g>_<postfix>` or its `compression/best/jxl_quant`, in GOP
    /// order) or the scene folder holding them (lossless by default: decodes to the reference
    /// decoder's tensors). A GOP folder without `compression_info.csv` is read from its
    /// checkpoint (`model.pth`, GOP >= 1 `model_offset.pth`); where both exist the compressed
    /// files win. Several splat files, or a folder of them, are a sequence of frames (natural
    /// order of names): matched frame to frame, fitted with key time features and decoders, and
    /// written as a dynamic .dlgs (`--quality high` canonical by default). `-h` lists the
    /// options by group; `--help` explains each.
    Encode {
        #[arg(required = true, num_args = 1..)]
        input: Vec<PathBuf>,
        /// Frame rate of a reference run or a frame sequence (the reference's N3DV videos: 30).
        #[arg(long, default_value_t = 30)]
        fps: u32,
        #[arg(short, long)]
        output: PathBuf,
        /// Change the residual mode when re-encoding a .dlgs (intra, sequential, parallel);
        /// residual GOPs then carry explicit residuals (RDLT, see --residual-error). For a
        /// frame sequence the default is sequential with fitted residual fields (RNTC; see
        /// --explicit-residuals). For a HAC (Scaffold-GS) run the default is sequential when
        /// every GOP after the first has the reference's NTC residual (RNTC); intra writes
        /// full anchors in every GOP.
        #[arg(long)]
        residual_mode: Option<String>,
        #[command(flatten)]
        codec: encode_cmd::CodecArgs,
        #[command(flatten)]
        sequence: sequence_cmd::SequenceArgs,
    },
    /// Seek latency: decode the frame at random times, each from a freshly opened decoder
    /// (cold: nothing cached) and then in one decoder (warm caches), and print the timings.
    Seek {
        file: PathBuf,
        /// Random times to seek to.
        #[arg(long, default_value_t = 20)]
        count: usize,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Decoded GOPs the warm decoder keeps (time features and decoders included): more
        /// makes jumps back into a kept GOP cheap, at the memory of those GOPs.
        #[arg(long, default_value_t = 1)]
        gop_cache: usize,
    },
    /// Render A and B at the last frame of every GOP and the first frame of the next:
    /// PSNR of B against A at both, and the jump across the boundary within each.
    Boundaries {
        a: PathBuf,
        b: PathBuf,
        #[command(flatten)]
        cams: CameraArgs,
    },
    /// Build a SYNTHETIC dynamic model from a real scene (no trained DLGStream model is
    /// available here): a compact subset moves, driven by smooth time features and random
    /// calibrated decoders.
    Synth(synth_cmd::SynthArgs),
    /// Write a hard per-frame sequence from a real scene with SYNTHETIC motion (large rigid or
    /// fast articulated motion, Gaussians that come and go), each frame shuffled, as PLYs.
    SynthFrames(synth_frames_cmd::SynthFramesArgs),
    /// Decode the Gaussians shown at time t into an INRIA PLY (with language extras if present).
    Decode {
        file: PathBuf,
        /// Time in seconds.
        #[arg(long, default_value_t = 0.0)]
        t: f64,
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Render a scene (.dlgs at time t, or PLY / .splat / SPZ / SOG) to PNG.
    Render {
        scene: PathBuf,
        #[command(flatten)]
        cams: CameraArgs,
        /// Time in seconds (for .dlgs).
        #[arg(long, default_value_t = 0.0)]
        t: f64,
        /// Also render the language feature image (written as OUT.features.png and .f32).
        #[arg(long)]
        features: bool,
        /// Background colour r,g,b in [0,1].
        #[arg(long, default_value = "1,1,1")]
        background: String,
        /// Scaffold-GS files: decode every anchor, not only those whose children can reach
        /// into the view (the same image, more time; docs/benchmarks/scaffold.md).
        #[arg(long)]
        no_cull: bool,
        /// Fast compositing (`Accuracy::Fast`): about 15-20 % less render time, pixels within
        /// 60 dB PSNR of the exact renderer (docs/benchmarks/render.md); default exact.
        #[arg(long)]
        fast_render: bool,
        /// Output PNG; with several cameras, `_NN` is inserted before the extension.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Render two scenes from the same cameras and print PSNR / SSIM per view.
    Compare {
        a: PathBuf,
        b: PathBuf,
        #[command(flatten)]
        cams: CameraArgs,
        #[arg(long, default_value_t = 0.0)]
        t: f64,
        #[arg(long, default_value = "1,1,1")]
        background: String,
        /// Write per-view error images (mean |A-B| over RGB, x4 gain) here.
        #[arg(long)]
        error_dir: Option<PathBuf>,
        /// Fast compositing (`Accuracy::Fast`): about 15-20 % less render time, pixels within
        /// 60 dB PSNR of the exact renderer (docs/benchmarks/render.md); default exact.
        #[arg(long)]
        fast_render: bool,
        #[arg(long)]
        json: bool,
    },
    /// Open-vocabulary query: render the language image at time t, decode it with the scene's
    /// language decoder, score it against a text embedding and write mask, heat map and
    /// overlay PNGs (the reference's filtering and thresholds by default).
    Query(query_cmd::QueryArgs),
    /// Decoded frames for other players: INRIA PLY (`--extras`: with the language) or SPZ
    /// (v3, or v2), one time (`--t`) or a sequence (`--frames a..b [--fps F]`); optionally
    /// only the Gaussians a text query selects (--select E.npy, --action keep|delete|highlight).
    Export(export_cmd::ExportArgs),
    /// Build a query test scene from a real scene and its per-Gaussian labels: SYNTHETIC
    /// 9-dim language (one code per category), a constructed language decoder, one text
    /// embedding per category and stand-in negatives (no CLIP model is available here).
    Labels(query_cmd::LabelsArgs),
    /// Play a .dlgs stream in real time from a plain reader (file, `-` for stdin, optionally
    /// throttled to a network rate): GOPs decode as their bytes arrive; reports dropped
    /// frames, time to first frame and the sustained decode rate.
    Play(play_cmd::PlayArgs),
    /// Rate-distortion sweep: encode a model at every crf x quality x bits setting, decode
    /// every frame, render sampled times from the cameras; CSV + PNG plots (bytes/frame vs
    /// PSNR, decode ms/frame vs PSNR). A Scaffold-GS file sweeps its anchor steps instead
    /// (--anchor-step-scale), re-coded from the file itself.
    Rd(rd_cmd::RdArgs),
    /// Write the cameras a scene would be rendered with (orbit or selection) as cameras.json.
    Cameras {
        scene: PathBuf,
        #[command(flatten)]
        cams: CameraArgs,
        #[arg(short, long)]
        output: PathBuf,
    },
}

/// The renderer's accuracy for `--fast-render`.
pub(crate) fn accuracy(fast_render: bool) -> Accuracy {
    if fast_render {
        Accuracy::Fast
    } else {
        Accuracy::Exact
    }
}

fn parse_rgb(s: &str) -> Result<[f32; 3]> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .context("background must be r,g,b")?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        bail!("background must be three finite numbers r,g,b");
    }
    Ok([v[0], v[1], v[2]])
}

fn numbered(path: &std::path::Path, i: usize, n: usize) -> PathBuf {
    if n == 1 {
        return path.to_path_buf();
    }
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("out");
    let ext = path.extension().and_then(|s| s.to_str()).unwrap_or("png");
    path.with_file_name(format!("{stem}_{i:02}.{ext}"))
}

/// `dlgs compare ... | head`: once the reader has gone, printing fails with a broken pipe and
/// `println!` panics. Rust ignores SIGPIPE, which would end a C tool quietly; this does the
/// same (exit status 141 = 128 + SIGPIPE, as a shell reports it) without a backtrace.
fn quiet_on_broken_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let msg = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.contains("failed printing to stdout") && msg.contains("Broken pipe") {
            std::process::exit(141);
        }
        default(info);
    }));
}

fn main() -> Result<()> {
    quiet_on_broken_pipe();
    let cli = Cli::parse();
    match cli.cmd {
        Cmd::Info {
            file,
            json,
            channels,
        } => info::run_info(&file, json, channels),
        Cmd::Verify { file } => info::run_verify(&file),
        Cmd::AhacBench {
            run,
            ply,
            anchors,
            repeat,
            fit_steps,
        } => {
            let steps = fit_steps
                .map(|s| scaffold_recode_cmd::parse_steps(&s))
                .transpose()?;
            ahac_bench_cmd::run_ahac_bench(&run, ply.as_deref(), anchors, repeat, steps)
        }
        Cmd::Encode {
            input,
            fps,
            output,
            residual_mode,
            codec,
            sequence,
        } => {
            let seq_dir = matches!(input.as_slice(), [d] if sequence_cmd::is_sequence_dir(d));
            if seq_dir || (input.len() > 1 && input.iter().all(|p| p.is_file())) {
                sequence_cmd::run_sequence(
                    &input,
                    &output,
                    &codec,
                    fps,
                    residual_mode.as_deref(),
                    &sequence,
                )
            } else if let Some(dirs) = hac_ingest_cmd::hac_gops(&input) {
                hac_ingest_cmd::run_hac_ingest(
                    &dirs,
                    &output,
                    fps,
                    codec.exact_features,
                    codec.quantised_features,
                    residual_mode.as_deref(),
                    codec.raw_anchors,
                    codec.anchor_step_scale,
                )
            } else if input.iter().all(|p| p.is_dir()) {
                ingest_cmd::run_ingest(&input, &output, &codec, fps)
            } else if let [one] = input.as_slice() {
                if scene_io::is_dlgs(one) && scene_io::is_scaffold(one)? {
                    scaffold_recode_cmd::run(one, &output, &codec)
                } else {
                    encode_cmd::run_encode(one, &output, &codec, residual_mode.as_deref())
                }
            } else {
                anyhow::bail!(
                    "several inputs must be all splat frame files (a sequence) or all reference \
                     GOP folders"
                )
            }
        }
        Cmd::Seek {
            file,
            count,
            seed,
            gop_cache,
        } => seek_cmd::run_seek(&file, count, seed, gop_cache),
        Cmd::Boundaries { a, b, cams } => seek_cmd::run_boundaries(&a, &b, &cams),
        Cmd::Synth(args) => synth_cmd::run_synth(&args),
        Cmd::SynthFrames(args) => synth_frames_cmd::run(&args),
        Cmd::Decode { file, t, output } => export_cmd::run_decode(&file, t, &output),
        Cmd::Query(a) => query_cmd::run_query(&a),
        Cmd::Labels(a) => query_cmd::run_labels(&a),
        Cmd::Play(a) => play_cmd::run_play(&a),
        Cmd::Rd(a) => rd_cmd::run_rd(&a),
        Cmd::Export(a) => export_cmd::run_export(&a),
        Cmd::Render {
            scene,
            cams,
            t,
            features,
            background,
            no_cull,
            fast_render,
            output,
        } => {
            let mut src = scene_io::Source::open(&scene)?;
            let cameras = cams.resolve(&src.canonical(t)?)?;
            let opts = RenderOptions {
                background: parse_rgb(&background)?,
                features,
                accuracy: accuracy(fast_render),
            };
            for (i, cam) in cameras.iter().enumerate() {
                let started = std::time::Instant::now();
                let g = src.at_camera(t, cam, features, !no_cull)?;
                let decode_ms = started.elapsed().as_secs_f64() * 1e3;
                let img = render(&g, cam, &opts).map_err(anyhow::Error::msg)?;
                let out = numbered(&output, i, cameras.len());
                image_out::save_rgb_png(&out, &img.color, img.width, img.height)
                    .map_err(anyhow::Error::msg)?;
                if let Some(f) = &img.features {
                    let fpng = out.with_extension("features.png");
                    image_out::save_feature_png(&fpng, f, img.lang_width, 0, img.width, img.height)
                        .map_err(anyhow::Error::msg)?;
                    let raw: Vec<u8> = f.iter().flat_map(|v| v.to_le_bytes()).collect();
                    std::fs::write(out.with_extension("features.f32"), raw)?;
                }
                println!(
                    "{} {}x{}: decoded {} Gaussians in {decode_ms:.1} ms, {} visible, {} tile pairs, rendered in {:.1} ms (project {:.1}, raster {:.1}) -> {}",
                    cam.name,
                    img.width,
                    img.height,
                    g.len(),
                    img.visible,
                    img.pairs,
                    img.timings.project_ms + img.timings.raster_ms,
                    img.timings.project_ms,
                    img.timings.raster_ms,
                    out.display()
                );
            }
            Ok(())
        }
        Cmd::Compare {
            a,
            b,
            cams,
            t,
            background,
            error_dir,
            fast_render,
            json,
        } => {
            let mut sa = scene_io::Source::open(&a)?;
            let mut sb = scene_io::Source::open(&b)?;
            let cameras = cams.resolve(&sa.canonical(t)?)?;
            let opts = RenderOptions {
                background: parse_rgb(&background)?,
                features: false,
                accuracy: accuracy(fast_render),
            };
            if let Some(d) = &error_dir {
                std::fs::create_dir_all(d)?;
            }
            let mut rows = Vec::new();
            for (i, cam) in cameras.iter().enumerate() {
                let ga = sa.at(t, cam.position.to_array(), false)?;
                let gb = sb.at(t, cam.position.to_array(), false)?;
                let ia = render(&ga, cam, &opts).map_err(anyhow::Error::msg)?;
                let ib = render(&gb, cam, &opts).map_err(anyhow::Error::msg)?;
                let p = metrics::psnr(&ia.color, &ib.color);
                let s = metrics::ssim(&ia.color, &ib.color, ia.width, ia.height);
                if let Some(d) = &error_dir {
                    let e = metrics::error_image(&ia.color, &ib.color);
                    image_out::save_gray_png(
                        &d.join(format!("error_{i:02}.png")),
                        &e,
                        ia.width,
                        ia.height,
                        0.0,
                        0.25,
                    )
                    .map_err(anyhow::Error::msg)?;
                }
                if !json {
                    println!("{:<12} PSNR {:>7.2} dB  SSIM {:.5}", cam.name, p, s);
                }
                rows.push((cam.name.clone(), p, s));
            }
            let n = rows.len() as f64;
            let mp = rows.iter().map(|r| r.1).sum::<f64>() / n;
            let ms = rows.iter().map(|r| r.2).sum::<f64>() / n;
            if json {
                let views: Vec<_> = rows
                    .iter()
                    .map(|(name, p, s)| serde_json::json!({"camera": name, "psnr": p, "ssim": s}))
                    .collect();
                println!(
                    "{}",
                    serde_json::to_string_pretty(
                        &serde_json::json!({"views": views, "mean_psnr": mp, "mean_ssim": ms})
                    )?
                );
            } else {
                println!("{:<12} PSNR {:>7.2} dB  SSIM {:.5}", "mean", mp, ms);
            }
            Ok(())
        }
        Cmd::Cameras {
            scene,
            cams,
            output,
        } => {
            let g = scene_io::Source::open(&scene)?.canonical(0.0)?;
            let cameras = cams.resolve(&g)?;
            std::fs::write(&output, cameras_to_json(&cameras))?;
            println!("{} cameras -> {}", cameras.len(), output.display());
            Ok(())
        }
    }
}
