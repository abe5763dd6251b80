//! The playback pipeline: a reader thread decodes a stream's GOPs in file order, as their
//! bytes arrive, ahead of the player, which takes them in turn with
//! [`PlaybackStream::next_gop`]. The first GOP is decoded on every core (nothing plays yet)
//! and returned once its first key interval is ready; its other keys and every later GOP are
//! decoded on a pool of their own (`gop_threads`, default 1), so that on a 2-core machine the
//! frames being shown keep a core and never queue behind a GOP's work. Memory is bounded: at
//! most `gops_ahead` decoded GOPs wait for the player, plus the one being decoded.
//!
//! `dlgs play` is this pipeline; the random-access [`crate::Decoder`] has the same read-ahead
//! for players that ask for frames in time order ([`crate::Decoder::set_read_ahead`]).

use std::io::Read;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use dlgs::container::SceneHeader;
use dlgs::{Error, Limits, Result};

use crate::hevc::SharedKeyPictureDecoder;
use crate::stream::{GopTimes, KeyPreparation, StreamDecoder};
use crate::DecodedGop;

/// How a [`PlaybackStream`] decodes ahead.
#[derive(Clone)]
pub struct PipelineOptions {
    /// Threads that decode the GOPs after the first (the first uses every core). 1 keeps a
    /// core for the frames on a 2-core machine.
    pub gop_threads: usize,
    /// Decoded GOPs that may wait for the player (at least 1): the memory budget.
    pub gops_ahead: usize,
    pub limits: Limits,
    /// HEVC time features are decoded with this (default: the built-in FFmpeg decoder, if
    /// the library was built with it).
    pub hevc: Option<SharedKeyPictureDecoder>,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        PipelineOptions {
            gop_threads: 1,
            gops_ahead: 1,
            limits: Limits::default(),
            hevc: None,
        }
    }
}

/// A GOP the reader thread has decoded.
pub struct ReadyGop {
    pub gop: Arc<DecodedGop>,
    /// From the reader asking for the GOP to having it decoded: its bytes arriving plus its
    /// decode.
    pub ready: Duration,
    /// Where the decode time went.
    pub times: GopTimes,
}

type Msg = Result<ReadyGop>;

/// A stream decoded ahead of playback on a thread of its own (see the module docs).
pub struct PlaybackStream {
    scene: SceneHeader,
    rx: Option<Receiver<Msg>>,
    reader: Option<JoinHandle<()>>,
}

impl PlaybackStream {
    /// Start reading `src` and return once its header has been read.
    pub fn spawn<R: Read + Send + 'static>(src: R, opts: PipelineOptions) -> Result<Self> {
        let (tx, rx) = sync_channel::<Msg>(opts.gops_ahead.max(1) - 1);
        let (scene_tx, scene_rx) = sync_channel(1);
        let reader = std::thread::Builder::new()
            .name("dlgs-stream-reader".into())
            .spawn(move || read_ahead(src, opts, scene_tx, tx))
            .map_err(|e| Error::input(format!("starting the stream reader thread: {e}")))?;
        let scene = match scene_rx.recv() {
            Ok(r) => r,
            Err(_) => Err(Error::input(
                "the stream reader thread ended before the header",
            )),
        };
        match scene {
            Ok(scene) => Ok(PlaybackStream {
                scene,
                rx: Some(rx),
                reader: Some(reader),
            }),
            Err(e) => {
                let _ = reader.join();
                Err(e)
            }
        }
    }

    pub fn scene(&self) -> &SceneHeader {
        &self.scene
    }

    /// The next GOP in file order, waiting for the reader if it is not decoded yet; `None`
    /// after the last (the index and tail have then been read and checked).
    pub fn next_gop(&mut self) -> Result<Option<ReadyGop>> {
        let Some(rx) = &self.rx else {
            return Ok(None);
        };
        match rx.recv() {
            Ok(Ok(g)) => Ok(Some(g)),
            Ok(Err(e)) => {
                self.rx = None;
                Err(e)
            }
            // The reader ended after the last GOP.
            Err(_) => {
                self.rx = None;
                Ok(None)
            }
        }
    }
}

impl Drop for PlaybackStream {
    fn drop(&mut self) {
        // The reader stops at its next send; it finishes the GOP it is decoding first.
        self.rx = None;
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
    }
}

/// The reader thread: header, then every GOP, each sent as soon as it is decoded.
fn read_ahead<R: Read + Send>(
    src: R,
    opts: PipelineOptions,
    scene_tx: SyncSender<Result<SceneHeader>>,
    tx: SyncSender<Msg>,
) {
    let mut dec = match StreamDecoder::with_limits(src, opts.limits.clone()) {
        Ok(d) => d,
        Err(e) => {
            let _ = scene_tx.send(Err(e));
            return;
        }
    };
    if let Some(h) = opts.hevc {
        dec.set_key_picture_decoder(h);
    }
    let ahead = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.gop_threads.max(1))
        .thread_name(|i| format!("dlgs-gop-ahead-{i}"))
        .build();
    let ahead = match ahead {
        Ok(p) => p,
        Err(e) => {
            let _ = scene_tx.send(Err(Error::input(format!(
                "starting the GOP decode threads: {e}"
            ))));
            return;
        }
    };
    let _ = scene_tx.send(Ok(dec.scene().clone()));
    // GOP 0 on every core, returned with its first key interval only.
    dec.set_key_preparation(KeyPreparation::FirstInterval);
    let Some(first) = decode_next(&mut dec, &tx, None) else {
        return;
    };
    // Its other keys on the GOP-ahead pool while its first frames play. A key that fails
    // here fails again, with its error, in the frame that needs it.
    ahead.install(|| {
        let _ = first.prepare_keys(0..usize::MAX);
    });
    dec.set_key_preparation(KeyPreparation::All);
    while decode_next(&mut dec, &tx, Some(&ahead)).is_some() {}
}

/// Decode and send the next GOP (on `pool`, or the caller's); `None` when there is none, the
/// player has gone, or decoding failed (the error is sent).
fn decode_next<R: Read + Send>(
    dec: &mut StreamDecoder<R>,
    tx: &SyncSender<Msg>,
    pool: Option<&rayon::ThreadPool>,
) -> Option<Arc<DecodedGop>> {
    let t0 = Instant::now();
    let next = match pool {
        Some(p) => p.install(|| dec.next_gop()),
        None => dec.next_gop(),
    };
    match next {
        Ok(Some(gop)) => {
            let ready = ReadyGop {
                gop: gop.clone(),
                ready: t0.elapsed(),
                times: dec.last_gop_times(),
            };
            tx.send(Ok(ready)).ok().map(|_| gop)
        }
        Ok(None) => None,
        Err(e) => {
            let _ = tx.send(Err(e));
            None
        }
    }
}
