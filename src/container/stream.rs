//! In-order reader over a plain `Read` (§9.2), e.g. a network stream: yields scene chunks, then
//! each GOP's chunks as their bytes arrive. Every structural rule the random-access reader
//! checks is checked here too, and the final `GIDX` must agree with what was seen.

use std::io::Read;

use crate::bytes::ByteReader;
use crate::container::chunk::{
    check_payload_crc, decode_header, ChunkInfo, ChunkType, CHUNK_HEADER_LEN, SCENE_LEVEL,
};
use crate::container::gop::{GopHeader, GopIndex, IndexEntry};
use crate::container::header::{decode_signature, SceneHeader, SIGNATURE_LEN};
use crate::container::rules::{self, GopKind, Section, SectionRules};
use crate::error::{io_err, Error, FormatErrorKind, Result};
use crate::limits::Limits;

/// What the stream produced next.
#[derive(Debug)]
pub enum StreamEvent {
    /// A known scene-level chunk, before the first GOP.
    SceneChunk(ChunkInfo, Vec<u8>),
    /// GOP `g` starts.
    GopStart(u32, GopHeader),
    /// A known payload chunk of the current GOP.
    GopChunk(ChunkInfo, Vec<u8>),
    /// The index at the end; the stream is complete after this.
    End(GopIndex),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Scene,
    InGop(u32),
    AfterIndex,
    Done,
}

pub struct StreamReader<R: Read> {
    inner: R,
    pos: u64,
    limits: Limits,
    scene: SceneHeader,
    state: State,
    seen: Vec<IndexEntry>,
    /// The rules of the section being read (scene chunks, then each GOP's).
    section: SectionRules,
    gidx_offset: u64,
}

impl<R: Read> StreamReader<R> {
    pub fn new(inner: R) -> Result<Self> {
        Self::with_limits(inner, Limits::default())
    }

    pub fn with_limits(inner: R, limits: Limits) -> Result<Self> {
        let mut s = StreamReader {
            inner,
            pos: 0,
            limits,
            scene: SceneHeader::still(0, 0),
            state: State::Scene,
            seen: Vec::new(),
            section: SectionRules::new(Section::Scene),
            gidx_offset: 0,
        };
        let sig = s.read_exact_vec(SIGNATURE_LEN as usize, "signature")?;
        decode_signature(&sig)?;
        let (head, p) = s.read_chunk()?;
        rules::check_head(&head)?;
        s.scene = SceneHeader::decode(&p, head.payload_offset(), &s.limits)?;
        Ok(s)
    }

    pub fn scene(&self) -> &SceneHeader {
        &self.scene
    }
    /// Bytes consumed so far.
    pub fn position(&self) -> u64 {
        self.pos
    }

    fn read_exact_vec(&mut self, n: usize, what: &'static str) -> Result<Vec<u8>> {
        let mut buf = Vec::new();
        // `take` + `read_to_end` grows the buffer only as bytes really arrive.
        let got = self
            .inner
            .by_ref()
            .take(n as u64)
            .read_to_end(&mut buf)
            .map_err(|e| io_err(e, self.pos, what))?;
        if got < n {
            return Err(Error::format(
                FormatErrorKind::Truncated {
                    what,
                    needed: n as u64,
                    available: got as u64,
                },
                self.pos,
            ));
        }
        self.pos += n as u64;
        Ok(buf)
    }

    fn read_header(&mut self) -> Result<ChunkInfo> {
        let at = self.pos;
        let h = self.read_exact_vec(CHUNK_HEADER_LEN as usize, "chunk header")?;
        let info = decode_header(h.as_slice().try_into().expect("24 bytes"), at)?;
        rules::check_len(&info, &self.limits)?;
        Ok(info)
    }

    fn read_payload(&mut self, info: &ChunkInfo) -> Result<Vec<u8>> {
        let p = self.read_exact_vec(info.len as usize, "chunk payload")?;
        let c = self.read_exact_vec(4, "payload CRC")?;
        check_payload_crc(info, &p, u32::from_le_bytes(c.try_into().expect("4 bytes")))?;
        Ok(p)
    }

    fn read_chunk(&mut self) -> Result<(ChunkInfo, Vec<u8>)> {
        let info = self.read_header()?;
        let p = self.read_payload(&info)?;
        Ok((info, p))
    }

    fn close_gop(&mut self, end: u64) {
        if let Some(e) = self.seen.last_mut() {
            if e.length == 0 {
                e.length = end - e.offset;
            }
        }
    }

    /// The next event, or `None` after the stream ended cleanly.
    pub fn next_event(&mut self) -> Result<Option<StreamEvent>> {
        loop {
            match self.state {
                State::Done => return Ok(None),
                State::AfterIndex => {
                    let (c, p) = self.read_chunk()?;
                    if c.ty != ChunkType::TAIL || c.gop != SCENE_LEVEL {
                        return Err(Error::format(
                            FormatErrorKind::Order("GIDX must be followed by TAIL"),
                            c.offset,
                        ));
                    }
                    let off = ByteReader::new(&p, c.payload_offset()).u64("TAIL gidx offset")?;
                    if off != self.gidx_offset {
                        return Err(Error::format(
                            FormatErrorKind::Index("TAIL does not point at GIDX"),
                            c.payload_offset(),
                        ));
                    }
                    let mut extra = [0u8; 1];
                    let n = self
                        .inner
                        .read(&mut extra)
                        .map_err(|e| io_err(e, self.pos, "end of file"))?;
                    if n != 0 {
                        return Err(Error::format(
                            FormatErrorKind::Order("bytes after TAIL"),
                            self.pos,
                        ));
                    }
                    self.state = State::Done;
                    return Ok(None);
                }
                State::Scene | State::InGop(_) => {}
            }
            let c = self.read_header()?;
            let current = match self.state {
                State::InGop(g) => Some(g),
                _ => None,
            };
            let next_gop = current.map_or(0, |g| g + 1);
            match c.ty {
                ChunkType::GOPH => {
                    if c.gop != next_gop || next_gop >= self.scene.gop_count {
                        return Err(Error::format(
                            FormatErrorKind::Order("GOPH out of sequence"),
                            c.offset,
                        ));
                    }
                    let p = self.read_payload(&c)?;
                    let gh = GopHeader::decode(&p, c.payload_offset())?;
                    gh.validate(&self.scene, c.gop, c.payload_offset())?;
                    self.close_gop(c.offset);
                    self.seen.push(IndexEntry {
                        gop: c.gop,
                        header: gh,
                        offset: c.offset,
                        length: 0,
                    });
                    self.state = State::InGop(c.gop);
                    let kind = GopKind::of(&self.scene, &gh);
                    self.section = SectionRules::new(Section::Gop(c.gop, kind));
                    return Ok(Some(StreamEvent::GopStart(c.gop, gh)));
                }
                ChunkType::GIDX => {
                    if c.gop != SCENE_LEVEL || next_gop != self.scene.gop_count {
                        return Err(Error::format(
                            FormatErrorKind::Order("GIDX before the last GOP"),
                            c.offset,
                        ));
                    }
                    let p = self.read_payload(&c)?;
                    self.close_gop(c.offset);
                    let gops_start = self.seen.first().map_or(c.offset, |e| e.offset);
                    let idx = GopIndex::decode(
                        &p,
                        c.payload_offset(),
                        &self.scene,
                        gops_start,
                        c.offset,
                    )?;
                    if idx.entries != self.seen {
                        return Err(Error::format(
                            FormatErrorKind::Index("GIDX disagrees with the GOPs in the stream"),
                            c.payload_offset(),
                        ));
                    }
                    self.gidx_offset = c.offset;
                    self.state = State::AfterIndex;
                    return Ok(Some(StreamEvent::End(idx)));
                }
                _ => {}
            }
            let known = self.section.admit(&c, &self.limits)?;
            let p = self.read_payload(&c)?;
            if !known {
                continue; // unknown ancillary: skipped after its CRC was checked
            }
            return Ok(Some(match current {
                None => StreamEvent::SceneChunk(c, p),
                Some(_) => StreamEvent::GopChunk(c, p),
            }));
        }
    }
}
