//! In-order decoding over a plain `Read` (a pipe, a socket, a download in progress): each GOP
//! is decoded as soon as its last chunk has arrived, so playback starts before the file is
//! complete. Residual GOPs need their reference GOP's state: the decoder keeps GOP 0 (the
//! reference of every parallel-mode GOP) and the previous GOP (sequential mode).

use std::io::Read;
use std::sync::Arc;
use std::time::Duration;

use crate::clock::Instant;

use dlgs::chunks::laed;
use dlgs::container::gop::{GopHeader, NO_REFERENCE};
use dlgs::container::{ChunkInfo, ChunkType, SceneHeader, StreamEvent, StreamReader};
use dlgs::model::lang_decoder::LangDecoder;
use dlgs::{Error, FormatErrorKind, Limits, Result};

use crate::hevc::SharedKeyPictureDecoder;
use crate::{build, DecodedGop, State};

/// Which time-feature keys [`StreamDecoder::next_gop`] prepares (decoded, geometry computed)
/// before it returns a GOP.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum KeyPreparation {
    /// Every key: a stream is played through, so the key work is done while the GOP is
    /// decoded ahead rather than on the first frame of each key interval (the default).
    #[default]
    All,
    /// Only the first key interval (keys 0 and 1): the GOP is returned sooner and its first
    /// frames can be shown; the caller prepares the rest with [`DecodedGop::prepare_keys`]
    /// (or each frame computes the keys it needs). Players use it for the first GOP.
    FirstInterval,
}

/// Where the time of the last [`StreamDecoder::next_gop`] went (not counting the wait for its
/// bytes). `state` and `dynamic` overlap when the calling pool has more than one thread.
#[derive(Clone, Copy, Debug, Default)]
pub struct GopTimes {
    /// Canonical chunk decoded, or residual applied to the reference state.
    pub state: Duration,
    /// Time features (HEVC included) and decoders.
    pub dynamic: Duration,
    /// Key preparation ([`KeyPreparation`]).
    pub keys: Duration,
    /// The whole decode.
    pub total: Duration,
}

/// Decodes GOPs in file order from a `Read`.
pub struct StreamDecoder<R: Read> {
    stream: StreamReader<R>,
    limits: Limits,
    scene_chunks: Vec<(ChunkInfo, Vec<u8>)>,
    /// The GOP whose chunks are being collected: index, header, stream offset of its start.
    open: Option<(u32, GopHeader, u64)>,
    chunks: Vec<(ChunkInfo, Vec<u8>)>,
    /// Decoded states kept as references: GOP 0 and the most recent GOP.
    first: Option<State>,
    last: Option<(u32, State)>,
    ended: bool,
    /// Where the time of the last GOP's decode went (not waiting for its bytes).
    last_times: GopTimes,
    key_preparation: KeyPreparation,
    /// Decodes HEVC time features (see [`crate::hevc`]).
    hevc: Option<SharedKeyPictureDecoder>,
}

impl<R: Read> StreamDecoder<R> {
    /// Read the scene header and scene-level chunks (up to the first GOP).
    pub fn new(src: R) -> Result<Self> {
        Self::with_limits(src, Limits::default())
    }

    pub fn with_limits(src: R, limits: Limits) -> Result<Self> {
        let mut d = StreamDecoder {
            stream: StreamReader::with_limits(src, limits.clone())?,
            limits,
            scene_chunks: Vec::new(),
            open: None,
            chunks: Vec::new(),
            first: None,
            last: None,
            ended: false,
            last_times: GopTimes::default(),
            key_preparation: KeyPreparation::All,
            hevc: crate::hevc::default_decoder(),
        };
        if d.scene().variant == dlgs::container::header::Variant::Scaffold {
            return Err(Error::request(
                "a Scaffold-GS stream: its frames depend on the camera; decode it with \
                 dlgs_decoder::scaffold::ScaffoldStreamDecoder",
            ));
        }
        d.read_until_next_gop(false)?;
        Ok(d)
    }

    pub fn scene(&self) -> &SceneHeader {
        self.stream.scene()
    }

    /// Decode HEVC time features of the GOPs still to come with `decoder` (see
    /// [`crate::Decoder::set_key_picture_decoder`]).
    pub fn set_key_picture_decoder(&mut self, decoder: SharedKeyPictureDecoder) {
        self.hevc = Some(decoder);
    }

    /// Which keys [`Self::next_gop`] prepares before returning a GOP (default: all).
    pub fn set_key_preparation(&mut self, keys: KeyPreparation) {
        self.key_preparation = keys;
    }

    /// Bytes read from the source so far.
    pub fn position(&self) -> u64 {
        self.stream.position()
    }

    /// The scene's language decoder (`LAED`), if the stream carries one.
    pub fn lang_decoder(&self) -> Result<Option<LangDecoder>> {
        let Some((c, p)) = self
            .scene_chunks
            .iter()
            .find(|(c, _)| c.ty == ChunkType::LAED)
        else {
            return Ok(None);
        };
        laed::decode(p, c.payload_offset(), self.scene(), &self.limits.fresh()).map(Some)
    }

    /// The next GOP in file order, decoded; `None` after the last GOP (the index and tail
    /// have then been read and checked).
    pub fn next_gop(&mut self) -> Result<Option<Arc<DecodedGop>>> {
        let Some((g, header, gop_at)) = self.open.take() else {
            return Ok(None);
        };
        self.chunks.clear();
        self.read_until_next_gop(true)?;
        let t0 = Instant::now();
        let gop = self.decode_collected(g, &header, gop_at)?;
        self.last_times.total = t0.elapsed();
        Ok(Some(gop))
    }

    /// Read events up to the next GOP start (remembered in `open`) or the end of the stream:
    /// scene-level chunks before the first GOP (`in_gop` false), the GOP's chunks inside one.
    fn read_until_next_gop(&mut self, in_gop: bool) -> Result<()> {
        loop {
            let at = self.stream.position();
            match self.stream.next_event()? {
                Some(StreamEvent::SceneChunk(c, p)) if !in_gop => self.scene_chunks.push((c, p)),
                Some(StreamEvent::GopChunk(c, p)) if in_gop => self.chunks.push((c, p)),
                Some(StreamEvent::GopStart(g, h)) => {
                    self.open = Some((g, h, at));
                    return Ok(());
                }
                Some(StreamEvent::End(_)) | None => return self.finish(),
                Some(StreamEvent::SceneChunk(c, _)) => {
                    return Err(Error::format(
                        FormatErrorKind::Order("a scene-level chunk after the first GOP"),
                        c.offset,
                    ))
                }
                Some(StreamEvent::GopChunk(c, _)) => {
                    return Err(Error::format(
                        FormatErrorKind::Order("a GOP chunk before any GOPH"),
                        c.offset,
                    ))
                }
            }
        }
    }

    /// How long decoding the last GOP took, without the time its bytes took to arrive.
    pub fn last_decode_time(&self) -> Duration {
        self.last_times.total
    }

    /// Where the time of the last GOP's decode went.
    pub fn last_gop_times(&self) -> GopTimes {
        self.last_times
    }

    fn decode_collected(
        &mut self,
        g: u32,
        header: &GopHeader,
        gop_at: u64,
    ) -> Result<Arc<DecodedGop>> {
        let scene = self.scene().clone();
        let infos: Vec<ChunkInfo> = self.chunks.iter().map(|(c, _)| *c).collect();
        let base = match header.reference_gop {
            NO_REFERENCE => None,
            0 if self.first.is_some() => self.first.as_ref(),
            r => match &self.last {
                Some((lg, s)) if *lg == r => Some(s),
                _ => {
                    return Err(Error::format(
                        FormatErrorKind::Index(
                            "a streamed GOP may only reference GOP 0 or the GOP before it",
                        ),
                        gop_at,
                    ))
                }
            },
        };
        // Each payload is read once (the canonical or residual chunk, then TFEA and MLPW):
        // hand it over instead of copying it.
        let chunks = &mut self.chunks;
        let mut payload = |c: &ChunkInfo| {
            chunks
                .iter_mut()
                .find(|(i, _)| i.offset == c.offset)
                .map(|(_, p)| std::mem::take(p))
                .ok_or_else(|| Error::format(FormatErrorKind::MissingChunk(c.ty), c.offset))
        };
        // One budget for everything this GOP's chunks allocate.
        let limits = self.limits.fresh();
        let hevc = self.hevc.clone();
        let dynamic_payloads = build::dynamic_payloads(&scene, &infos, gop_at, &mut payload)?;
        let keys = match self.key_preparation {
            KeyPreparation::All => 0..usize::MAX,
            KeyPreparation::FirstInterval => 0..2,
        };
        // The keys to prepare are decoded here, beside the state (intra-only features, and
        // one-stream features whose headers can be read, decode only those; others whole).
        let decode_dynamic = || {
            let t0 = Instant::now();
            let d = dynamic_payloads
                .as_ref()
                .map(|p| {
                    let parts = build::decode_dynamic(&scene, &limits, hevc.as_ref(), p)?;
                    parts.0.ensure_keys(keys.clone())?;
                    Ok(parts)
                })
                .transpose();
            (d, t0.elapsed())
        };
        let decode_state = |payload| {
            let t0 = Instant::now();
            let s = build::state(&scene, &limits, &infos, gop_at, base, payload);
            (s, t0.elapsed())
        };
        // The time features (HEVC) need nothing of the canonical state: with a second thread
        // to spare they decode beside it (as the random-access decoder does); on a one-thread
        // pool (a player's GOP-ahead thread) they run in turn, leaving the other core to the
        // frames. Errors are reported state first either way; no value depends on the order.
        let ((state, state_time), (dynamic, dynamic_time)) = if rayon::current_num_threads() > 1 {
            std::thread::scope(|s| {
                let worker = s.spawn(decode_dynamic);
                let state = decode_state(&mut payload);
                let dynamic = worker
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
                (state, dynamic)
            })
        } else {
            let state = decode_state(&mut payload);
            (state, decode_dynamic())
        };
        let state = state?;
        let dynamic = dynamic?;
        if g == 0 {
            self.first = Some(state.clone());
        }
        self.last = Some((g, state.clone()));
        let gop = build::assemble(&scene, g, state, dynamic);
        let t0 = Instant::now();
        gop.prepare_keys(keys)?;
        self.last_times = GopTimes {
            state: state_time,
            dynamic: dynamic_time,
            keys: t0.elapsed(),
            total: Duration::ZERO,
        };
        Ok(Arc::new(gop))
    }

    /// After the index: read and check the tail (and that nothing follows it).
    fn finish(&mut self) -> Result<()> {
        while self.stream.next_event()?.is_some() {}
        self.ended = true;
        Ok(())
    }

    /// Whether the whole stream (index and tail included) has been read.
    pub fn finished(&self) -> bool {
        self.ended && self.open.is_none()
    }
}
