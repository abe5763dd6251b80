//! Random-access reader over `Read + Seek` (§9.1): reads the signature, `HEAD`, the scene-level
//! chunk headers, then `TAIL` -> `GIDX`, and afterwards any GOP's chunks on demand.

use std::io::{Read, Seek, SeekFrom};

use crate::bytes::ByteReader;
use crate::container::chunk::{
    check_payload_crc, decode_header, ChunkInfo, ChunkType, CHUNK_HEADER_LEN, CHUNK_OVERHEAD,
    SCENE_LEVEL,
};
use crate::container::gop::{GopHeader, GopIndex, IndexEntry, TAIL_LEN};
use crate::container::header::{decode_signature, SceneHeader, SIGNATURE_LEN};
use crate::container::rules::{self, GopKind, Section, SectionRules};
use crate::error::{io_err, Error, FormatErrorKind, Result};
use crate::limits::Limits;

pub struct FileReader<R: Read + Seek> {
    inner: R,
    file_len: u64,
    limits: Limits,
    scene: SceneHeader,
    version: (u16, u16),
    scene_chunks: Vec<ChunkInfo>,
    index: GopIndex,
    gidx: ChunkInfo,
}

impl<R: Read + Seek> FileReader<R> {
    pub fn open(inner: R) -> Result<Self> {
        Self::open_with_limits(inner, Limits::default())
    }

    pub fn open_with_limits(mut inner: R, limits: Limits) -> Result<Self> {
        let file_len = inner
            .seek(SeekFrom::End(0))
            .map_err(|e| io_err(e, 0, "seek"))?;
        let sig = read_at(
            &mut inner,
            0,
            SIGNATURE_LEN.min(file_len) as usize,
            "signature",
        )?;
        if sig.len() < SIGNATURE_LEN as usize {
            // A short file is only "truncated" if what is there is a magic prefix.
            decode_signature(&sig)?;
            return Err(Error::format(
                FormatErrorKind::Truncated {
                    what: "signature",
                    needed: SIGNATURE_LEN,
                    available: file_len,
                },
                0,
            ));
        }
        let version = decode_signature(&sig)?;
        let mut this = FileReader {
            inner,
            file_len,
            limits,
            scene: SceneHeader::still(0, 0),
            version,
            scene_chunks: Vec::new(),
            index: GopIndex::default(),
            gidx: ChunkInfo {
                ty: ChunkType::GIDX,
                flags: 0,
                gop: 0,
                len: 0,
                offset: 0,
            },
        };
        // HEAD
        let head = this.header_at(SIGNATURE_LEN, file_len)?;
        rules::check_head(&head)?;
        let p = this.payload(&head)?;
        this.scene = SceneHeader::decode(&p, head.payload_offset(), &this.limits)?;

        // TAIL -> GIDX
        let tail_size = CHUNK_OVERHEAD + TAIL_LEN as u64;
        if file_len < head.end() + tail_size {
            return Err(Error::format(
                FormatErrorKind::Truncated {
                    what: "TAIL chunk",
                    needed: head.end() + tail_size,
                    available: file_len,
                },
                file_len,
            ));
        }
        // Anything but a valid TAIL in the last 36 bytes means the file was cut short or never
        // finished: say so rather than report whatever bytes happen to sit there.
        let missing_tail = Error::format(
            FormatErrorKind::MissingChunk(ChunkType::TAIL),
            file_len - tail_size,
        );
        let tail = this
            .header_at(file_len - tail_size, file_len)
            .map_err(|_| missing_tail.clone())?;
        if tail.ty != ChunkType::TAIL || tail.len != TAIL_LEN as u64 || tail.gop != SCENE_LEVEL {
            return Err(missing_tail);
        }
        let tp = this.payload(&tail).map_err(|_| missing_tail.clone())?;
        let gidx_offset = ByteReader::new(&tp, tail.payload_offset()).u64("TAIL gidx offset")?;
        if gidx_offset < head.end() || gidx_offset >= tail.offset {
            return Err(Error::format(
                FormatErrorKind::Index("TAIL points outside the file body"),
                tail.payload_offset(),
            ));
        }
        let gidx = this.header_at(gidx_offset, tail.offset)?;
        if gidx.ty != ChunkType::GIDX || gidx.gop != SCENE_LEVEL {
            return Err(Error::format(
                FormatErrorKind::MissingChunk(ChunkType::GIDX),
                gidx.offset,
            ));
        }
        if gidx.end() != tail.offset {
            return Err(Error::format(
                FormatErrorKind::Order("GIDX must be followed directly by TAIL"),
                gidx.end(),
            ));
        }

        // Scene-level chunks up to the first GOPH.
        let mut at = head.end();
        let mut scene_rules = SectionRules::new(Section::Scene);
        loop {
            let c = this.header_at(at, gidx.offset)?;
            if c.ty == ChunkType::GOPH {
                break;
            }
            if scene_rules.admit(&c, &this.limits)? {
                this.scene_chunks.push(c);
            }
            at = c.end();
        }
        let gp = this.payload(&gidx)?;
        this.index = GopIndex::decode(&gp, gidx.payload_offset(), &this.scene, at, gidx.offset)?;
        this.gidx = gidx;
        Ok(this)
    }

    pub fn scene(&self) -> &SceneHeader {
        &self.scene
    }
    pub fn version(&self) -> (u16, u16) {
        self.version
    }
    pub fn index(&self) -> &GopIndex {
        &self.index
    }
    pub fn file_len(&self) -> u64 {
        self.file_len
    }
    pub fn limits(&self) -> &Limits {
        &self.limits
    }
    /// Known scene-level chunks (unknown ancillary ones are skipped).
    pub fn scene_chunks(&self) -> &[ChunkInfo] {
        &self.scene_chunks
    }
    /// Size of the `GIDX` + `TAIL` trailer.
    pub fn index_bytes(&self) -> u64 {
        self.file_len - self.gidx.offset
    }

    /// Parse the chunk header at `offset`; the whole chunk must end at or before `region_end`.
    fn header_at(&mut self, offset: u64, region_end: u64) -> Result<ChunkInfo> {
        if offset + CHUNK_HEADER_LEN > region_end {
            return Err(Error::format(
                FormatErrorKind::Truncated {
                    what: "chunk header",
                    needed: CHUNK_HEADER_LEN,
                    available: region_end.saturating_sub(offset),
                },
                offset,
            ));
        }
        let h = read_at(
            &mut self.inner,
            offset,
            CHUNK_HEADER_LEN as usize,
            "chunk header",
        )?;
        let info = decode_header(h.as_slice().try_into().expect("24 bytes"), offset)?;
        rules::check_len(&info, &self.limits)?;
        let avail = region_end - offset - CHUNK_HEADER_LEN;
        if info.len.checked_add(4).is_none_or(|n| n > avail) {
            return Err(Error::format(
                FormatErrorKind::Truncated {
                    what: "chunk payload",
                    needed: info.len + 4,
                    available: avail,
                },
                offset + 12,
            ));
        }
        Ok(info)
    }

    /// Read and CRC-check a chunk's payload.
    pub fn payload(&mut self, info: &ChunkInfo) -> Result<Vec<u8>> {
        let mut buf = read_at(
            &mut self.inner,
            info.payload_offset(),
            info.len as usize + 4,
            "chunk payload",
        )?;
        let stored = u32::from_le_bytes(buf[info.len as usize..].try_into().expect("4 bytes"));
        buf.truncate(info.len as usize);
        check_payload_crc(info, &buf, stored)?;
        Ok(buf)
    }

    /// The index entry of GOP `g`.
    pub fn gop_entry(&self, g: u32) -> Result<IndexEntry> {
        self.index.entries.get(g as usize).copied().ok_or_else(|| {
            Error::request(format!(
                "GOP {g} requested, file has {}",
                self.scene.gop_count
            ))
        })
    }

    /// The known payload chunks of GOP `g` (its `GOPH` is checked and not returned), checked
    /// against §3.3's GOP rules (types, counts, order). Reads only chunk headers; payloads are
    /// read with [`FileReader::payload`].
    pub fn gop_chunks(&mut self, g: u32) -> Result<Vec<ChunkInfo>> {
        let e = self.gop_entry(g)?;
        let end = e.offset + e.length;
        let goph = self.header_at(e.offset, end)?;
        if goph.ty != ChunkType::GOPH || goph.gop != g {
            return Err(Error::format(
                FormatErrorKind::Index("GIDX entry does not point at this GOP's GOPH"),
                e.offset,
            ));
        }
        let gh = GopHeader::decode(&self.payload(&goph)?, goph.payload_offset())?;
        gh.validate(&self.scene, g, goph.payload_offset())?;
        let mut out = Vec::new();
        let mut at = goph.end();
        let mut rules = SectionRules::new(Section::Gop(g, GopKind::of(&self.scene, &gh)));
        while at < end {
            let c = self.header_at(at, end)?;
            if rules.admit(&c, &self.limits)? {
                out.push(c);
            }
            at = c.end();
        }
        Ok(out)
    }

    /// Read every chunk of every GOP and check every CRC. Returns the number of chunks read.
    pub fn verify_all(&mut self) -> Result<usize> {
        let mut n = 0;
        for c in self.scene_chunks.clone() {
            self.payload(&c)?;
            n += 1;
        }
        for g in 0..self.scene.gop_count {
            for c in self.gop_chunks(g)? {
                self.payload(&c)?;
                n += 1;
            }
        }
        Ok(n)
    }
}

/// Read exactly `n` bytes at `offset`. Callers have checked `offset + n <= file_len`.
fn read_at<R: Read + Seek>(
    r: &mut R,
    offset: u64,
    n: usize,
    what: &'static str,
) -> Result<Vec<u8>> {
    r.seek(SeekFrom::Start(offset))
        .map_err(|e| io_err(e, offset, what))?;
    let mut buf = Vec::new();
    let got = r
        .by_ref()
        .take(n as u64)
        .read_to_end(&mut buf)
        .map_err(|e| io_err(e, offset, what))?;
    if got < n {
        return Err(Error::format(
            FormatErrorKind::Truncated {
                what,
                needed: n as u64,
                available: got as u64,
            },
            offset,
        ));
    }
    Ok(buf)
}
