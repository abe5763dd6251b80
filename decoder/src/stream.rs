//! In-order decoding over a plain `Read` (a pipe, a socket, a download in progress): each GOP
//! is decoded as soon as its last chunk has arrived, so playback starts before the file is
//! complete. Residual GOPs need their reference GOP's state: the decoder keeps GOP 0 (the
//! reference of every parallel-mode GOP) and the previous GOP (sequential mode).

use std::io::Read;
use std::sync::Arc;
use std::time::{Duration, Instant};

use dlgs::chunks::laed;
use dlgs::container::gop::{GopHeader, NO_REFERENCE};
use dlgs::container::{ChunkInfo, ChunkType, SceneHeader, StreamEvent, StreamReader};
use dlgs::model::lang_decoder::LangDecoder;
use dlgs::{Error, FormatErrorKind, Limits, Result};

use crate::hevc::SharedKeyPictureDecoder;
use crate::{build, DecodedGop, State};

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
    /// Time spent decoding the last GOP (not waiting for its bytes).
    last_decode: Duration,
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
            last_decode: Duration::ZERO,
            hevc: crate::hevc::default_decoder(),
        };
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
        self.last_decode = t0.elapsed();
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
        self.last_decode
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
        let state = build::state(&scene, &limits, &infos, gop_at, base, &mut payload)?;
        if g == 0 {
            self.first = Some(state.clone());
        }
        self.last = Some((g, state.clone()));
        let hevc = self.hevc.as_ref();
        let gop = build::gop(
            &scene,
            &limits,
            hevc,
            g,
            &infos,
            gop_at,
            state,
            &mut payload,
        )?;
        // A stream is played through: do all key geometry now, while the GOP is decoded,
        // rather than on the first frame of each key interval.
        if let Some(d) = &gop.deformer {
            d.prepare_all_keys(&gop.canonical.dynamics)?;
        }
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
