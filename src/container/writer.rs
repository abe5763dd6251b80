//! Streaming writer: signature, `HEAD`, scene chunks, GOPs in order, then `GIDX` and `TAIL`.

use std::io::Write;

use crate::bytes::PutLe;
use crate::container::chunk::{encode_header, ChunkType, FLAG_MUST_UNDERSTAND, SCENE_LEVEL};
use crate::container::gop::{GopHeader, GopIndex, IndexEntry};
use crate::container::header::{encode_signature, ResidualMode, SceneHeader};
use crate::error::{io_err, Error, Result};

pub struct Writer<W: Write> {
    out: W,
    pos: u64,
    scene: SceneHeader,
    index: GopIndex,
    /// The GOP being written, if any.
    open_gop: Option<IndexEntry>,
}

impl<W: Write> Writer<W> {
    /// Write the signature and `HEAD`.
    pub fn new(out: W, scene: SceneHeader) -> Result<Self> {
        let r = scene.refresh_interval;
        if r == 1 || (r != 0 && scene.residual_mode != ResidualMode::Sequential) {
            return Err(Error::input(format!(
                "refresh_interval {r}: 0, or at least 2 in a sequential scene (format-spec §4.1)"
            )));
        }
        let mut w = Writer {
            out,
            pos: 0,
            scene,
            index: GopIndex::default(),
            open_gop: None,
        };
        w.raw(&encode_signature())?;
        let head = w.scene.encode();
        w.chunk(ChunkType::HEAD, FLAG_MUST_UNDERSTAND, SCENE_LEVEL, &head)?;
        Ok(w)
    }

    pub fn scene(&self) -> &SceneHeader {
        &self.scene
    }
    pub fn position(&self) -> u64 {
        self.pos
    }

    fn raw(&mut self, b: &[u8]) -> Result<()> {
        self.out
            .write_all(b)
            .map_err(|e| io_err(e, self.pos, "write"))?;
        self.pos += b.len() as u64;
        Ok(())
    }

    fn chunk(&mut self, ty: ChunkType, flags: u16, gop: u32, payload: &[u8]) -> Result<()> {
        self.raw(&encode_header(ty, flags, gop, payload.len() as u64))?;
        self.raw(payload)?;
        self.raw(&crc32c::crc32c(payload).to_le_bytes())
    }

    fn misuse(&self, what: &str) -> Error {
        Error::request(what.to_string())
    }

    /// A scene-level chunk (e.g. `META`); only before the first GOP.
    pub fn scene_chunk(&mut self, ty: ChunkType, flags: u16, payload: &[u8]) -> Result<()> {
        if !self.index.entries.is_empty() || self.open_gop.is_some() {
            return Err(self.misuse("scene-level chunks must precede the first GOP"));
        }
        self.chunk(ty, flags, SCENE_LEVEL, payload)
    }

    /// Start the next GOP; writes its `GOPH`.
    pub fn begin_gop(&mut self) -> Result<u32> {
        self.end_gop();
        let g = self.index.entries.len() as u32;
        if g >= self.scene.gop_count {
            return Err(self.misuse("more GOPs than the header's gop_count"));
        }
        let header = GopHeader::expected(&self.scene, g);
        let offset = self.pos;
        self.chunk(ChunkType::GOPH, FLAG_MUST_UNDERSTAND, g, &header.encode())?;
        self.open_gop = Some(IndexEntry {
            gop: g,
            header,
            offset,
            length: 0,
        });
        Ok(g)
    }

    /// A payload chunk of the current GOP.
    pub fn gop_chunk(&mut self, ty: ChunkType, flags: u16, payload: &[u8]) -> Result<()> {
        let Some(g) = self.open_gop.map(|e| e.gop) else {
            return Err(self.misuse("gop_chunk called outside a GOP"));
        };
        self.chunk(ty, flags, g, payload)
    }

    fn end_gop(&mut self) {
        if let Some(mut e) = self.open_gop.take() {
            e.length = self.pos - e.offset;
            self.index.entries.push(e);
        }
    }

    /// Write `GIDX` and `TAIL`; returns the sink.
    pub fn finish(mut self) -> Result<W> {
        self.end_gop();
        if self.index.entries.len() as u32 != self.scene.gop_count {
            return Err(self.misuse("fewer GOPs written than the header's gop_count"));
        }
        let gidx_offset = self.pos;
        let idx = self.index.encode();
        self.chunk(ChunkType::GIDX, FLAG_MUST_UNDERSTAND, SCENE_LEVEL, &idx)?;
        let mut tail = Vec::with_capacity(8);
        tail.put_u64(gidx_offset);
        self.chunk(ChunkType::TAIL, 0, SCENE_LEVEL, &tail)?;
        self.out.flush().map_err(|e| io_err(e, self.pos, "flush"))?;
        Ok(self.out)
    }
}
