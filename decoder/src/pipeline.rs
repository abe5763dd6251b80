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
use std::time::Duration;

use crate::clock::Instant;

use dlgs::container::SceneHeader;
use dlgs::{Error, Result};

use crate::stream::{GopTimes, KeyPreparation, StreamDecoder};
use crate::DecodedGop;

/// A decoder of GOPs in file order that [`PlaybackStream`] drives on its reader thread: the
/// 3DGS [`StreamDecoder`] and the Scaffold-GS stream decoder.
pub trait GopSource: Send + 'static {
    type Gop: Send + Sync + 'static;
    fn scene(&self) -> &SceneHeader;
    /// The next GOP, decoded; `None` after the last.
    fn next_gop(&mut self) -> Result<Option<Arc<Self::Gop>>>;
    /// Where the last GOP's decode time went (`total` at least).
    fn last_gop_times(&self) -> GopTimes;
    /// Whether the next GOP should be returned as soon as its first frames can be shown
    /// (what is left then done by [`Self::finish_gop`]). Default: nothing to hurry.
    fn hurry(&mut self, _first_frames_only: bool) {}
    /// Finish what a hurried GOP left undone (default: nothing).
    fn finish_gop(_gop: &Self::Gop) {}
}

impl<R: Read + Send + 'static> GopSource for StreamDecoder<R> {
    type Gop = DecodedGop;
    fn scene(&self) -> &SceneHeader {
        StreamDecoder::scene(self)
    }
    fn next_gop(&mut self) -> Result<Option<Arc<DecodedGop>>> {
        StreamDecoder::next_gop(self)
    }
    fn last_gop_times(&self) -> GopTimes {
        StreamDecoder::last_gop_times(self)
    }
    /// Hurried: only the first key interval's keys (see [`KeyPreparation`]).
    fn hurry(&mut self, first_frames_only: bool) {
        self.set_key_preparation(if first_frames_only {
            KeyPreparation::FirstInterval
        } else {
            KeyPreparation::All
        });
    }
    fn finish_gop(gop: &DecodedGop) {
        // Interval by interval, so that a frame waiting for a key gets it as soon as it is
        // decoded (one-stream features decode picture by picture, `prefix_keys.rs`). A key that fails here fails again,
        // with its error, in the frame that needs it.
        let keys = gop.deformer.as_ref().map_or(0, |d| d.key_count());
        for k in 0..keys.saturating_sub(1) {
            if gop.prepare_keys(k..k + 2).is_err() {
                return;
            }
        }
    }
}

/// How a [`PlaybackStream`] decodes ahead.
#[derive(Clone, Copy, Debug)]
pub struct PipelineOptions {
    /// Threads that decode the GOPs after the first (the first uses every core). 1 keeps a
    /// core for the frames on a 2-core machine.
    pub gop_threads: usize,
    /// Decoded GOPs that may wait for the player (at least 1): the memory budget.
    pub gops_ahead: usize,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        PipelineOptions {
            gop_threads: 1,
            gops_ahead: 2,
        }
    }
}

/// A GOP the reader thread has decoded.
pub struct ReadyGop<G = DecodedGop> {
    pub gop: Arc<G>,
    /// From the reader asking for the GOP to having it decoded: its bytes arriving plus its
    /// decode.
    pub ready: Duration,
    /// Where the decode time went.
    pub times: GopTimes,
}

/// A stream decoded ahead of playback on a thread of its own (see the module docs).
pub struct PlaybackStream<G: Send + Sync + 'static = DecodedGop> {
    scene: SceneHeader,
    rx: Option<Receiver<Result<ReadyGop<G>>>>,
    reader: Option<JoinHandle<()>>,
}

impl PlaybackStream<DecodedGop> {
    /// Read a 3DGS stream's header from `src` and start decoding its GOPs ahead (the default
    /// limits and HEVC decoder; [`Self::spawn`] takes a decoder set up otherwise).
    pub fn open<R: Read + Send + 'static>(src: R, opts: PipelineOptions) -> Result<Self> {
        Self::spawn(StreamDecoder::new(src)?, opts)
    }
}

impl<G: Send + Sync + 'static> PlaybackStream<G> {
    /// Start decoding the GOPs of `source` (its header already read) on a reader thread.
    pub fn spawn<S: GopSource<Gop = G>>(source: S, opts: PipelineOptions) -> Result<Self> {
        let scene = source.scene().clone();
        let (tx, rx) = sync_channel(opts.gops_ahead.max(1) - 1);
        let ahead = rayon::ThreadPoolBuilder::new()
            .num_threads(opts.gop_threads.max(1))
            .thread_name(|i| format!("dlgs-gop-ahead-{i}"))
            .build()
            .map_err(|e| Error::input(format!("starting the GOP decode threads: {e}")))?;
        let reader = std::thread::Builder::new()
            .name("dlgs-stream-reader".into())
            .spawn(move || read_ahead(source, ahead, tx))
            .map_err(|e| Error::input(format!("starting the stream reader thread: {e}")))?;
        Ok(PlaybackStream {
            scene,
            rx: Some(rx),
            reader: Some(reader),
        })
    }

    pub fn scene(&self) -> &SceneHeader {
        &self.scene
    }

    /// The next GOP in file order, waiting for the reader if it is not decoded yet; `None`
    /// after the last (the index and tail have then been read and checked).
    pub fn next_gop(&mut self) -> Result<Option<ReadyGop<G>>> {
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

impl<G: Send + Sync + 'static> Drop for PlaybackStream<G> {
    fn drop(&mut self) {
        // The reader stops at its next send; it finishes the GOP it is decoding first.
        self.rx = None;
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
    }
}

/// The reader thread: every GOP, each sent as soon as it is decoded.
fn read_ahead<S: GopSource>(
    mut source: S,
    ahead: rayon::ThreadPool,
    tx: SyncSender<Result<ReadyGop<S::Gop>>>,
) {
    // GOP 0 on every core, returned as soon as its first frames can be shown.
    source.hurry(true);
    let Some(first) = decode_next(&mut source, &tx, None) else {
        return;
    };
    // The rest of it on the GOP-ahead pool while its first frames play.
    ahead.install(|| S::finish_gop(&first));
    source.hurry(false);
    while decode_next(&mut source, &tx, Some(&ahead)).is_some() {}
}

/// Decode and send the next GOP (on `pool`, or the caller's); `None` when there is none, the
/// player has gone, or decoding failed (the error is sent).
fn decode_next<S: GopSource>(
    source: &mut S,
    tx: &SyncSender<Result<ReadyGop<S::Gop>>>,
    pool: Option<&rayon::ThreadPool>,
) -> Option<Arc<S::Gop>> {
    let t0 = Instant::now();
    let next = match pool {
        Some(p) => p.install(|| source.next_gop()),
        None => source.next_gop(),
    };
    match next {
        Ok(Some(gop)) => {
            let ready = ReadyGop {
                gop: gop.clone(),
                ready: t0.elapsed(),
                times: source.last_gop_times(),
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
