//! In-order decoding of Scaffold-GS files over a plain `Read` (a pipe, a socket, a download in
//! progress): each GOP is decoded as soon as its chunks have arrived, with the same per-GOP
//! decoding as the random-access [`super::ScaffoldDecoder`]. Residual GOPs need their
//! reference GOP's state: GOP 0's and the previous GOP's are kept.

use std::io::Read;
use std::sync::Arc;
use std::time::Duration;

use crate::clock::Instant;

use dlgs::container::gop::{GopHeader, NO_REFERENCE};
use dlgs::container::header::Variant;
use dlgs::container::{ChunkInfo, ChunkType, SceneHeader, StreamEvent, StreamReader};
use dlgs::{Error, FormatErrorKind, Limits, Result};

use super::gop_decode::{decode_dynamic, decode_state, GopChunks, GopState};
use super::ScaffoldGop;
use crate::hevc::{self, SharedKeyPictureDecoder};

/// Decodes the GOPs of a Scaffold-GS stream in file order from a `Read`.
pub struct ScaffoldStreamDecoder<R: Read> {
    stream: StreamReader<R>,
    limits: Limits,
    /// The next GOP's start (index, header, stream offset), read but not yet decoded.
    next: Option<(u32, GopHeader, u64)>,
    /// Reference states: GOP 0's and the most recent GOP's.
    first: Option<Arc<GopState>>,
    last: Option<(u32, Arc<GopState>)>,
    last_decode: Duration,
    hevc: Option<SharedKeyPictureDecoder>,
}

impl<R: Read> ScaffoldStreamDecoder<R> {
    /// Read the scene header and scene-level chunks (up to the first GOP).
    pub fn new(src: R, limits: Limits) -> Result<Self> {
        let stream = StreamReader::with_limits(src, limits.clone())?;
        if stream.scene().variant != Variant::Scaffold {
            return Err(Error::request(
                "not a Scaffold-GS stream (HEAD.variant is 0): decode it with \
                 dlgs_decoder::stream::StreamDecoder",
            ));
        }
        dlgs::model::scaffold::check_scene(stream.scene())
            .map_err(|r| Error::payload(ChunkType::HEAD, r, 0))?;
        let mut d = ScaffoldStreamDecoder {
            stream,
            limits,
            next: None,
            first: None,
            last: None,
            last_decode: Duration::ZERO,
            hevc: hevc::default_decoder(),
        };
        d.next = d.read_gop_chunks(None)?.1;
        Ok(d)
    }

    pub fn scene(&self) -> &SceneHeader {
        self.stream.scene()
    }

    /// Decode HEVC time features of the GOPs still to come with `decoder`.
    pub fn set_key_picture_decoder(&mut self, decoder: SharedKeyPictureDecoder) {
        self.hevc = Some(decoder);
    }

    /// How long decoding the last GOP took, without the time its bytes took to arrive.
    pub fn last_decode_time(&self) -> Duration {
        self.last_decode
    }

    /// Read events up to the next `GOPH` (returned) or the end of the stream (`None`); the
    /// chunks of the GOP being read (`in_gop`) are collected, scene chunks before GOP 0 skipped.
    #[allow(clippy::type_complexity)]
    fn read_gop_chunks(
        &mut self,
        in_gop: Option<u32>,
    ) -> Result<(Vec<(ChunkInfo, Vec<u8>)>, Option<(u32, GopHeader, u64)>)> {
        let mut chunks = Vec::new();
        loop {
            let at = self.stream.position();
            match self.stream.next_event()? {
                Some(StreamEvent::SceneChunk(..)) if in_gop.is_none() => {}
                Some(StreamEvent::GopChunk(c, p)) if in_gop.is_some() => chunks.push((c, p)),
                Some(StreamEvent::GopStart(g, h)) => return Ok((chunks, Some((g, h, at)))),
                Some(StreamEvent::End(_)) | None => return Ok((chunks, None)),
                Some(StreamEvent::SceneChunk(c, _)) | Some(StreamEvent::GopChunk(c, _)) => {
                    return Err(Error::format(
                        FormatErrorKind::Order("a chunk outside its section"),
                        c.offset,
                    ))
                }
            }
        }
    }

    /// The next GOP, decoded once all its chunks have arrived; `None` after the last.
    pub fn next_gop(&mut self) -> Result<Option<Arc<ScaffoldGop>>> {
        let Some((g, header, at)) = self.next.take() else {
            return Ok(None);
        };
        let (collected, next) = self.read_gop_chunks(Some(g))?;
        let t0 = Instant::now();
        let reference = match header.reference_gop {
            NO_REFERENCE => None,
            0 if self.first.is_some() => self.first.clone(),
            r => match &self.last {
                Some((lg, s)) if *lg == r => Some(s.clone()),
                _ => {
                    return Err(Error::format(
                        FormatErrorKind::Index(
                            "a streamed GOP may only reference GOP 0 or the GOP before it",
                        ),
                        at,
                    ))
                }
            },
        };
        let scene = self.scene().clone();
        let limits = self.limits.fresh();
        let infos: Vec<ChunkInfo> = collected.iter().map(|(c, _)| *c).collect();
        let mut read = |c: &ChunkInfo| -> Result<Vec<u8>> {
            Ok(collected
                .iter()
                .find(|(k, _)| k.offset == c.offset)
                .map(|(_, p)| p.clone())
                .expect("a chunk of this GOP"))
        };
        let mut chunks = GopChunks {
            chunks: &infos,
            at,
            read: &mut read,
        };
        let state = Arc::new(decode_state(
            &scene,
            &limits,
            &mut chunks,
            reference.as_deref(),
        )?);
        let dynamic = decode_dynamic(&scene, &limits, self.hevc.as_ref(), &mut chunks)?;
        let gop = Arc::new(ScaffoldGop::new(
            g,
            state.canonical.clone(),
            state.mlps.clone(),
            dynamic,
        ));
        if g == 0 {
            self.first = Some(state.clone());
        }
        self.last = Some((g, state));
        self.next = next;
        self.last_decode = t0.elapsed();
        Ok(Some(gop))
    }
}

/// The playback pipeline drives this decoder as it drives the 3DGS one (only the whole GOP's
/// decode is timed).
impl<R: Read + Send + 'static> crate::pipeline::GopSource for ScaffoldStreamDecoder<R> {
    type Gop = ScaffoldGop;
    fn scene(&self) -> &SceneHeader {
        ScaffoldStreamDecoder::scene(self)
    }
    fn next_gop(&mut self) -> Result<Option<Arc<ScaffoldGop>>> {
        ScaffoldStreamDecoder::next_gop(self)
    }
    fn last_gop_times(&self) -> crate::stream::GopTimes {
        crate::stream::GopTimes {
            total: self.last_decode_time(),
            ..Default::default()
        }
    }
}
