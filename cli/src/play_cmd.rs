//! `dlgs play`: real-time playback over a plain `Read` (the file, stdin, or the file throttled
//! to a network rate). A reader thread decodes GOPs in file order as their bytes arrive and
//! hands them over one GOP ahead; the player decodes each frame at its presentation time and
//! drops the frames it is too late for. Scaffold-GS files (`play_scaffold`) are played by the
//! same reader thread and frame loop, a camera per frame.

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::PathBuf;
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use dlgs::container::header::Variant;
use dlgs::model::Gaussians;
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

/// What the reader thread sends: a decoded GOP, the time from asking for it to having it
/// (bytes arriving + decoding) and the decoding time alone, in ms.
pub(crate) type GopMsg<G> = dlgs::Result<(Arc<G>, f64, f64)>;

/// A decoder of GOPs in file order over a `Read`: the 3DGS `StreamDecoder` and the Scaffold-GS
/// `ScaffoldStreamDecoder`, played by the same reader thread and frame loop.
pub(crate) trait GopStream: Send + 'static {
    type Gop: Send + Sync + 'static;
    fn scene(&self) -> &dlgs::container::SceneHeader;
    fn next_gop(&mut self) -> dlgs::Result<Option<Arc<Self::Gop>>>;
    fn last_decode_time(&self) -> Duration;
}

pub(crate) type Source = Box<dyn Read + Send>;

impl GopStream for StreamDecoder<Source> {
    type Gop = DecodedGop;
    fn scene(&self) -> &dlgs::container::SceneHeader {
        StreamDecoder::scene(self)
    }
    fn next_gop(&mut self) -> dlgs::Result<Option<Arc<DecodedGop>>> {
        StreamDecoder::next_gop(self)
    }
    fn last_decode_time(&self) -> Duration {
        StreamDecoder::last_decode_time(self)
    }
}

/// `src` (from [`open_source`]) handed to a reader thread that decodes GOPs in file order
/// with the decoder `open` makes, one GOP ahead of the player. Returns the scene header, the
/// GOPs' channel and the thread.
#[allow(clippy::type_complexity)]
pub(crate) fn spawn_reader<D: GopStream>(
    args: &PlayArgs,
    src: Source,
    open: fn(Source) -> dlgs::Result<D>,
) -> Result<(
    dlgs::container::SceneHeader,
    Receiver<GopMsg<D::Gop>>,
    std::thread::JoinHandle<()>,
)> {
    let (tx, rx) = sync_channel::<GopMsg<D::Gop>>(1);
    let (scene_tx, scene_rx) = sync_channel(1);
    let background_threads = args.gop_threads.max(1);
    let reader = std::thread::spawn(move || {
        let mut dec = match open(src) {
            Ok(d) => d,
            Err(e) => {
                let _ = scene_tx.send(Err(e));
                return;
            }
        };
        // GOP 0 decodes on every core (nothing plays yet: the first frame waits for it); later
        // GOPs decode ahead on one thread of their own, so that the frames being shown keep
        // the other core and never queue behind a GOP's work in a shared pool.
        let ahead = rayon::ThreadPoolBuilder::new()
            .num_threads(background_threads)
            .thread_name(|i| format!("dlgs-gop-ahead-{i}"))
            .build();
        let ahead = match ahead {
            Ok(p) => p,
            Err(e) => {
                let _ = scene_tx.send(Err(dlgs::Error::input(format!(
                    "starting the GOP decode thread: {e}"
                ))));
                return;
            }
        };
        let _ = scene_tx.send(Ok(dec.scene().clone()));
        let mut first = true;
        loop {
            let t0 = Instant::now();
            let next = if first {
                dec.next_gop()
            } else {
                ahead.install(|| dec.next_gop())
            };
            first = false;
            match next {
                Ok(Some(g)) => {
                    let total = t0.elapsed().as_secs_f64() * 1e3;
                    let decode = dec.last_decode_time().as_secs_f64() * 1e3;
                    if tx.send(Ok((g, total, decode))).is_err() {
                        return;
                    }
                }
                Ok(None) => return,
                Err(e) => {
                    let _ = tx.send(Err(e));
                    return;
                }
            }
        }
    });
    let scene = scene_rx
        .recv()
        .context("the reader thread ended before the header")?
        .context("reading the stream header")?;
    Ok((scene, rx, reader))
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
    /// Time the player waited for a GOP that had not arrived yet.
    pub stall_ms: f64,
    pub sustained_decode_fps: f64,
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

pub fn run_play(args: &PlayArgs) -> Result<()> {
    let opened = Instant::now();
    let (variant, src) = peek_variant(open_source(args)?)?;
    if variant == Variant::Scaffold {
        return crate::play_scaffold::run(args, src, opened);
    }
    let (scene, rx, reader) = spawn_reader(args, src, StreamDecoder::new)?;
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
    let report = play_loop(args, &scene, fps, &rx, opened, index, |g, time, _| {
        let frame = DecodedGop::frame(g, time, &opts, std::mem::take(&mut buffer))?;
        buffer = frame.dynamics;
        Ok(())
    })?;
    drop(rx);
    let _ = reader.join();
    print_report(&report, args.json)
}

/// Play the frames of `scene` at `fps` as GOPs arrive on `rx`: frame f at its presentation
/// time, `frame(gop, time, f)` decoding it; frames more than a period late are dropped.
pub(crate) fn play_loop<G>(
    args: &PlayArgs,
    scene: &dlgs::container::SceneHeader,
    fps: f64,
    rx: &Receiver<GopMsg<G>>,
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
                let (g, arrival_ms, ms) = rx
                    .recv()
                    .context("the stream ended before the GOP of frame")?
                    .with_context(|| format!("decoding the GOP of frame {f}"))?;
                r.gop_decode_ms.push(ms);
                r.gop_ready_ms.push(arrival_ms);
                let done = index(&g) >= time.gop;
                gop = Some(g);
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
    /// Frame decode statistics from the per-frame times.
    pub(crate) fn summarise(&mut self, mut decode_ms: Vec<f64>) {
        if decode_ms.is_empty() {
            return;
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
    println!("player stalled {:.1} ms waiting for GOPs", r.stall_ms);
    if let Some(n) = r.gaussians_mean {
        println!("Scaffold-GS: {n:.0} neural Gaussians per frame (mean)");
    }
    println!(
        "sustained decode rate (frames + GOPs on one thread): {:.1} frames/s",
        r.sustained_decode_fps
    );
    Ok(())
}
