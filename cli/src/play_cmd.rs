//! `dlgs play`: real-time playback over a plain `Read` (the file, stdin, or the file throttled
//! to a network rate) through the library's playback pipeline (`dlgs_decoder::pipeline`): a
//! reader thread decodes GOPs in file order as their bytes arrive, ahead of the player, which
//! decodes each frame at its presentation time and drops the frames it is too late for.
//! Scaffold-GS streams (`play_scaffold`) go through the same pipeline and frame loop, a camera
//! per frame.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use dlgs::container::header::Variant;
use dlgs::model::Gaussians;
use dlgs_decoder::pipeline::{PipelineOptions, PlaybackStream, ReadyGop};
use dlgs_decoder::stream::StreamDecoder;
use dlgs_decoder::{DecodedGop, FrameOptions};

#[derive(clap::Args)]
pub struct PlayArgs {
    /// The .dlgs file, or `-` for stdin.
    pub file: PathBuf,
    /// Presentation rate (default: the file's frame rate).
    #[arg(long)]
    pub fps: Option<f64>,
    /// Deliver the file's bytes at this rate (megabits per second), as a network would.
    #[arg(long)]
    pub bandwidth_mbps: Option<f64>,
    /// Decode every frame as fast as possible (no clock, no drops): the sustained decode rate.
    #[arg(long)]
    pub max_speed: bool,
    /// Also evaluate the language decoders of dynamic Gaussians (Scaffold-GS: the language
    /// MLP of every neural Gaussian).
    #[arg(long)]
    pub language: bool,
    #[arg(long)]
    pub json: bool,
    /// Threads that decode the next GOPs while frames play (GOP 0 uses every core). 1 keeps a
    /// core for the frames on a 2-core machine: docs/benchmarks/play.md has the drops for 1 and 2.
    #[arg(long, default_value_t = 1)]
    pub gop_threads: usize,
    /// Decoded GOPs that may wait for the player (the memory budget: about 45 MB per GOP of
    /// the 273k-Gaussian stream). 2 lets the GOP thread stay busy through a GOP boundary.
    #[arg(long, default_value_t = 2)]
    pub gops_ahead: usize,
    /// Scaffold-GS files (whose Gaussians are generated per camera): frame f is decoded for
    /// camera f mod the cameras given (`--view` for one fixed camera; default: the orbit
    /// `dlgs render` uses). 3DGS files ignore these options.
    #[command(flatten)]
    pub cams: crate::cameras_arg::CameraArgs,
    /// Scaffold-GS files: decode every anchor, not only those whose Gaussians can reach into
    /// the camera's view.
    #[arg(long)]
    pub no_cull: bool,
}

/// The bytes being played: the file, stdin, either throttled.
pub(crate) type Source = Box<dyn Read + Send>;

/// A `Read` that delivers at most `bytes_per_s`, sleeping as a slow link would.
struct Throttled<R> {
    inner: R,
    bytes_per_s: f64,
    start: Instant,
    delivered: u64,
}

impl<R: Read> Read for Throttled<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let cap = buf.len().min(16 * 1024);
        let n = self.inner.read(&mut buf[..cap])?;
        self.delivered += n as u64;
        let due = Duration::from_secs_f64(self.delivered as f64 / self.bytes_per_s);
        if let Some(wait) = due.checked_sub(self.start.elapsed()) {
            std::thread::sleep(wait);
        }
        Ok(n)
    }
}

fn open_source(args: &PlayArgs) -> Result<Source> {
    let raw: Box<dyn Read + Send> = if args.file.as_os_str() == "-" {
        Box::new(std::io::stdin())
    } else {
        Box::new(
            File::open(&args.file).with_context(|| format!("opening {}", args.file.display()))?,
        )
    };
    let buffered = BufReader::with_capacity(1 << 16, raw);
    Ok(match args.bandwidth_mbps {
        Some(m) if m > 0.0 && m.is_finite() => Box::new(Throttled {
            inner: buffered,
            bytes_per_s: m * 1e6 / 8.0,
            start: Instant::now(),
            delivered: 0,
        }),
        Some(m) => bail!("--bandwidth-mbps must be a positive number, got {m}"),
        None => Box::new(buffered),
    })
}

#[derive(Default, serde::Serialize)]
pub(crate) struct PlayReport {
    pub frames: u32,
    pub shown: u32,
    pub dropped: u32,
    pub fps: f64,
    pub time_to_first_frame_ms: f64,
    pub wall_s: f64,
    pub frame_decode_ms_mean: f64,
    pub frame_decode_ms_p95: f64,
    pub frame_decode_ms_max: f64,
    pub gop_decode_ms: Vec<f64>,
    /// Bytes arriving + decoding, per GOP.
    pub gop_ready_ms: Vec<f64>,
    /// Where each GOP's decode went: canonical state, time features and decoders (these two
    /// overlap for GOP 0), key preparation (GOP 0: its first key interval only).
    pub gop_state_ms: Vec<f64>,
    pub gop_features_ms: Vec<f64>,
    pub gop_keys_ms: Vec<f64>,
    /// Time the player waited for a GOP that had not arrived yet.
    pub stall_ms: f64,
    pub sustained_decode_fps: f64,
    /// Frames shown per second of wall time after the first frame (`--max-speed`: the rate
    /// the player keeps up with GOP decodes overlapping frames).
    pub wall_fps: f64,
    /// Scaffold-GS files: Gaussians generated per frame (mean), for the cameras played.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gaussians_mean: Option<f64>,
}

/// The stream's variant, read from its signature and `HEAD`, and the same stream with those
/// bytes put back in front (so that stdin can be played whatever its variant).
fn peek_variant(mut src: Source) -> Result<(Variant, Source)> {
    use dlgs::container::chunk::{decode_header, CHUNK_HEADER_LEN};
    use dlgs::container::header::SIGNATURE_LEN;
    let mut head = vec![0u8; (SIGNATURE_LEN + CHUNK_HEADER_LEN) as usize];
    src.read_exact(&mut head)
        .context("reading the stream header: the stream ended before its HEAD chunk")?;
    let at = SIGNATURE_LEN as usize;
    dlgs::container::header::decode_signature(&head[..at]).context("reading the stream header")?;
    let info = decode_header(head[at..].try_into().expect("24 bytes"), SIGNATURE_LEN)
        .context("reading the stream header")?;
    let limits = dlgs::Limits::default();
    if info.ty != dlgs::container::ChunkType::HEAD || info.len > 1 << 16 {
        bail!("reading the stream header: the first chunk is not a HEAD");
    }
    let start = head.len();
    head.resize(start + info.len as usize + 4, 0);
    src.read_exact(&mut head[start..])
        .context("reading the stream header: the stream ended inside its HEAD chunk")?;
    let scene = dlgs::container::SceneHeader::decode(
        &head[start..start + info.len as usize],
        info.payload_offset(),
        &limits,
    )
    .context("reading the stream header")?;
    Ok((
        scene.variant,
        Box::new(std::io::Cursor::new(head).chain(src)),
    ))
}

/// The pipeline's options from the command line.
pub(crate) fn pipeline_options(args: &PlayArgs) -> PipelineOptions {
    PipelineOptions {
        gop_threads: args.gop_threads.max(1),
        gops_ahead: args.gops_ahead.max(1),
    }
}

pub fn run_play(args: &PlayArgs) -> Result<()> {
    let opened = Instant::now();
    let (variant, src) = peek_variant(open_source(args)?)?;
    if variant == Variant::Scaffold {
        return crate::play_scaffold::run(args, src, opened);
    }
    let dec = StreamDecoder::new(src).context("reading the stream header")?;
    let mut stream = PlaybackStream::spawn(dec, pipeline_options(args))?;
    let scene = stream.scene().clone();
    let fps = args.fps.unwrap_or(scene.fps());
    if !(fps > 0.0 && fps.is_finite()) {
        bail!("--fps must be a positive number, got {fps}");
    }
    let opts = FrameOptions {
        camera_center: [0.0; 3],
        language: args.language,
    };
    let mut buffer = Gaussians::default();
    let index = |g: &DecodedGop| g.index;
    let report = play_loop(
        args,
        &scene,
        fps,
        &mut stream,
        opened,
        index,
        |g, time, _| {
            let frame = DecodedGop::frame(g, time, &opts, std::mem::take(&mut buffer))?;
            buffer = frame.dynamics;
            Ok(())
        },
    )?;
    print_report(&report, args.json)
}

/// Play the frames of `scene` at `fps` as GOPs arrive from `stream`: frame f at its presentation
/// time, `frame(gop, time, f)` decoding it; frames more than a period late are dropped.
pub(crate) fn play_loop<G: Send + Sync + 'static>(
    args: &PlayArgs,
    scene: &dlgs::container::SceneHeader,
    fps: f64,
    stream: &mut PlaybackStream<G>,
    opened: Instant,
    index: fn(&G) -> u32,
    mut frame: impl FnMut(&Arc<G>, dlgs::model::TimePoint, u32) -> Result<()>,
) -> Result<PlayReport> {
    let frames = scene.frame_count;
    let period = 1.0 / fps;
    let mut r = PlayReport {
        frames,
        fps,
        ..Default::default()
    };
    let mut gop: Option<Arc<G>> = None;
    let mut decode_ms: Vec<f64> = Vec::new();
    let mut clock_start: Option<Instant> = None;
    let bar = indicatif::ProgressBar::new(frames as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames {msg}")
            .expect("valid template"),
    );
    for f in 0..frames {
        if let (Some(start), false) = (clock_start, args.max_speed) {
            // More than one period late: this frame's slot has passed, skip it.
            if start.elapsed().as_secs_f64() > (f as f64 + 1.0) * period {
                r.dropped += 1;
                bar.inc(1);
                continue;
            }
        }
        // Frame f is shown at its own time (frame index / file rate).
        let time = scene.locate(f as f64 / scene.fps())?;
        if gop.as_deref().map(index) != Some(time.gop) {
            let wait = Instant::now();
            loop {
                let ready = stream
                    .next_gop()
                    .with_context(|| format!("decoding the GOP of frame {f}"))?
                    .with_context(|| format!("the stream ended before the GOP of frame {f}"))?;
                r.record_gop(&ready);
                let done = index(&ready.gop) >= time.gop;
                gop = Some(ready.gop);
                if done {
                    break;
                }
            }
            if clock_start.is_some() {
                r.stall_ms += wait.elapsed().as_secs_f64() * 1e3;
            }
        }
        let g = gop.as_ref().expect("set above");
        let t0 = Instant::now();
        frame(g, time, f).with_context(|| format!("decoding frame {f}"))?;
        decode_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        r.shown += 1;
        bar.inc(1);
        let start = *clock_start.get_or_insert_with(|| {
            r.time_to_first_frame_ms = opened.elapsed().as_secs_f64() * 1e3;
            Instant::now()
        });
        if !args.max_speed {
            let due = Duration::from_secs_f64((f as f64 + 1.0) * period);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
    }
    bar.finish_and_clear();
    r.wall_s = clock_start.map_or(0.0, |s| s.elapsed().as_secs_f64());
    r.summarise(decode_ms);
    Ok(r)
}

impl PlayReport {
    fn record_gop<G>(&mut self, ready: &ReadyGop<G>) {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        self.gop_decode_ms.push(ms(ready.times.total));
        self.gop_ready_ms.push(ms(ready.ready));
        self.gop_state_ms.push(ms(ready.times.state));
        self.gop_features_ms.push(ms(ready.times.dynamic));
        self.gop_keys_ms.push(ms(ready.times.keys));
    }

    /// Frame decode statistics from the per-frame times.
    pub(crate) fn summarise(&mut self, mut decode_ms: Vec<f64>) {
        if decode_ms.is_empty() {
            return;
        }
        if self.wall_s > 0.0 {
            self.wall_fps = f64::from(self.shown) / self.wall_s;
        }
        let n = decode_ms.len() as f64;
        let frames_ms = decode_ms.iter().sum::<f64>();
        self.frame_decode_ms_mean = frames_ms / n;
        decode_ms.sort_by(f64::total_cmp);
        self.frame_decode_ms_p95 = decode_ms[((n * 0.95) as usize).min(decode_ms.len() - 1)];
        self.frame_decode_ms_max = *decode_ms.last().expect("non-empty");
        // GOP decoding runs on the reader thread, in parallel with frame decoding; the
        // sustained rate counts both, as if they shared one thread.
        let total_ms = frames_ms + self.gop_decode_ms.iter().sum::<f64>();
        self.sustained_decode_fps = n / (total_ms / 1e3);
    }
}

pub(crate) fn print_report(r: &PlayReport, json: bool) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(r)?);
        return Ok(());
    }
    println!(
        "{} frames at {:.2} fps: {} shown, {} dropped, wall {:.2} s",
        r.frames, r.fps, r.shown, r.dropped, r.wall_s
    );
    println!("time to first frame: {:.1} ms", r.time_to_first_frame_ms);
    println!(
        "frame decode: mean {:.2} ms, p95 {:.2} ms, max {:.2} ms",
        r.frame_decode_ms_mean, r.frame_decode_ms_p95, r.frame_decode_ms_max
    );
    let list = |v: &[f64]| {
        v.iter()
            .map(|m| format!("{m:.0}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!(
        "GOP decode (reader thread): {} ms; with bytes arriving: {} ms",
        list(&r.gop_decode_ms),
        list(&r.gop_ready_ms)
    );
    // The 3DGS decoder times its stages; the Scaffold-GS one only the whole GOP.
    if r.gop_state_ms.iter().any(|&m| m > 0.0) {
        println!(
            "  of which canonical state: {} ms; time features + decoders: {} ms; keys: {} ms",
            list(&r.gop_state_ms),
            list(&r.gop_features_ms),
            list(&r.gop_keys_ms)
        );
    }
    println!("player stalled {:.1} ms waiting for GOPs", r.stall_ms);
    if let Some(n) = r.gaussians_mean {
        println!("Scaffold-GS: {n:.0} neural Gaussians per frame (mean)");
    }
    println!(
        "sustained decode rate (frames + GOPs on one thread): {:.1} frames/s; shown per wall second: {:.1}",
        r.sustained_decode_fps, r.wall_fps
    );
    Ok(())
}
