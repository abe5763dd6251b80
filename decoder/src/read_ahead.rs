//! Read-ahead in the random-access decoder: once a caller asks for frames of GOP g as a
//! player does (two requests in g, the second later than the first by at most four frame
//! periods), GOP g + 1 is decoded on a thread of its own while the frames of g are decoded on the caller's, so a player that walks
//! through time does not stall at each GOP boundary. It is the playback pipeline of
//! [`crate::pipeline`] for callers that own a seekable source (the C ABI, Python).
//!
//! Only the next GOP is decoded ahead (one decoded GOP of memory), and only when its
//! reference state is already decoded: the background never walks a residual chain. The
//! payloads are read on the caller's thread (the source is not shared); the decode runs on a
//! one-thread pool, so the other core stays with the frames. A result nobody asks for is
//! dropped when another GOP is scheduled. Every value depends only on the bytes: frames are
//! the same with and without read-ahead.

use std::io::{Read, Seek};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::Arc;

use dlgs::container::gop::NO_REFERENCE;
use dlgs::container::ChunkInfo;
use dlgs::{Error, FormatErrorKind, Result};

use crate::{build, DecodedGop, Decoder, State};

type Decoded = Result<(State, Arc<DecodedGop>)>;

pub(crate) struct ReadAhead {
    enabled: bool,
    /// Built on first use (a decoder that never plays forward starts no thread).
    pool: Option<rayon::ThreadPool>,
    pending: Option<(u32, Receiver<Decoded>)>,
    /// Set when the pending GOP is no longer wanted (another was scheduled, read-ahead was
    /// reset, the decoder dropped): its job stops at its next stage.
    cancel: Arc<AtomicBool>,
    /// The GOP and time of the last frame request.
    last_request: Option<(u32, f64)>,
    /// GOPs taken from the read-ahead thread instead of decoded in turn.
    hits: u64,
}

impl ReadAhead {
    pub(crate) fn new(enabled: bool) -> Self {
        ReadAhead {
            enabled,
            pool: None,
            pending: None,
            cancel: Arc::new(AtomicBool::new(false)),
            last_request: None,
            hits: 0,
        }
    }
}

impl Drop for ReadAhead {
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
    }
}

impl<R: Read + Seek> Decoder<R> {
    /// Decode the next GOP ahead while frames are asked for in time order (default on; see
    /// the module docs of `read_ahead`). Off drops any GOP being decoded ahead.
    pub fn set_read_ahead(&mut self, enabled: bool) {
        self.ahead = ReadAhead::new(enabled);
    }

    /// Whether read-ahead is on.
    pub fn read_ahead(&self) -> bool {
        self.ahead.enabled
    }

    /// How many GOPs were taken ready from the read-ahead thread (since the last
    /// [`Self::set_read_ahead`]): a player can check that playback did not stall on them.
    pub fn read_ahead_hits(&self) -> u64 {
        self.ahead.hits
    }

    /// The GOP decoded ahead, if it is `g` (waiting for it to finish). `None` when nothing
    /// was decoded ahead for `g` or its thread ended without a result: decode it in turn.
    pub(crate) fn take_ahead(&mut self, g: u32) -> Option<Result<Arc<DecodedGop>>> {
        match self.ahead.pending.take() {
            Some((p, rx)) if p == g => {
                let (state, gop) = match rx.recv().ok()? {
                    Ok(v) => v,
                    Err(e) => return Some(Err(e)),
                };
                self.states.insert(g, state);
                self.gops.insert(g, gop.clone());
                self.ahead.hits += 1;
                Some(Ok(gop))
            }
            other => {
                self.ahead.pending = other;
                None
            }
        }
    }

    /// A frame at time `t` of GOP `g` was asked for: start decoding GOP `g + 1` if this is
    /// playback in time order and it is not decoded or under way.
    pub(crate) fn frame_requested(&mut self, g: u32, t: f64) {
        // Playback, not a jump: random seeks that happen to land later in the same GOP do not
        // start a GOP decode that would compete with the next seek.
        let period = 1.0 / self.scene().fps();
        let forward = matches!(self.ahead.last_request,
            Some((lg, lt)) if lg == g && t > lt && t - lt <= 4.0 * period);
        self.ahead.last_request = Some((g, t));
        let next = g + 1;
        if !self.ahead.enabled
            || !forward
            || next >= self.scene().gop_count
            || self.ahead.pending.as_ref().is_some_and(|p| p.0 == next)
            || self.gops.contains(next)
        {
            return;
        }
        // Errors are not reported here: the frame that needs the GOP decodes it in turn and
        // reports them where they belong.
        let _ = self.schedule(next);
    }

    fn schedule(&mut self, g: u32) -> Result<()> {
        let entry = self.reader.gop_entry(g)?;
        let (gop_at, reference) = (entry.offset, entry.header.reference_gop);
        let base = match reference {
            NO_REFERENCE => None,
            r => match self.states.get(r) {
                Some(s) => Some(s),
                None => return Ok(()),
            },
        };
        let infos = self.reader.gop_chunks(g)?;
        let mut payloads = Vec::with_capacity(infos.len());
        for c in &infos {
            payloads.push((*c, self.reader.payload(c)?));
        }
        let scene = self.scene().clone();
        let limits = self.reader.limits().fresh();
        let hevc = self.hevc.clone();
        if self.ahead.pool.is_none() {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .thread_name(|_| "dlgs-read-ahead".into())
                .build()
                .map_err(|e| Error::input(format!("starting the read-ahead thread: {e}")))?;
            self.ahead.pool = Some(pool);
        }
        let (tx, rx) = sync_channel(1);
        self.ahead.cancel.store(true, Ordering::Relaxed);
        self.ahead.cancel = Arc::new(AtomicBool::new(false));
        let cancel = self.ahead.cancel.clone();
        self.ahead.pending = Some((g, rx));
        let pool = self.ahead.pool.as_ref().expect("built above");
        pool.spawn(move || {
            let mut payload = |c: &ChunkInfo| {
                payloads
                    .iter_mut()
                    .find(|(i, _)| i.offset == c.offset)
                    .map(|(_, p)| std::mem::take(p))
                    .ok_or_else(|| Error::format(FormatErrorKind::MissingChunk(c.ty), c.offset))
            };
            // The order of the in-turn decode: payloads, state, then time features. A cancelled
            // job stops between stages and sends nothing (its receiver is gone).
            let stopped = || cancel.load(Ordering::Relaxed);
            if stopped() {
                return;
            }
            let first =
                build::dynamic_payloads(&scene, &infos, gop_at, &mut payload).and_then(|dynamic| {
                    build::state(&scene, &limits, &infos, gop_at, base.as_ref(), payload)
                        .map(|state| (dynamic, state))
                });
            if stopped() {
                return;
            }
            let decoded = first.and_then(|(dynamic, state)| {
                let dynamic = dynamic
                    .map(|p| build::decode_dynamic(&scene, &limits, hevc.as_ref(), &p))
                    .transpose()?;
                let gop = build::assemble(&scene, g, state.clone(), dynamic);
                // A key that fails here fails again in the frame that needs it.
                let _ = gop.prepare_keys(0..usize::MAX);
                Ok((state, Arc::new(gop)))
            });
            let _ = tx.send(decoded);
        });
        Ok(())
    }
}
