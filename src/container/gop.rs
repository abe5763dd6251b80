//! Per-GOP header `GOPH` (§5.1), the GOP index `GIDX` (§5.2) and the `TAIL` pointer (§5.3).

use serde::Serialize;

use crate::bytes::{ByteReader, PutLe};
use crate::container::header::SceneHeader;
use crate::error::{Error, FormatErrorKind, Result};

/// `reference_gop` value for a GOP that decodes without any other GOP.
pub const NO_REFERENCE: u32 = u32::MAX;
pub const GOPH_LEN: usize = 16;
pub const GIDX_ENTRY_LEN: usize = 32;
pub const TAIL_LEN: usize = 8;

/// The `GOPH` payload: where GOP g sits in time and what it depends on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct GopHeader {
    pub first_frame: u32,
    pub frame_count: u32,
    /// The GOP whose decoded canonical state this GOP's residual applies to, or [`NO_REFERENCE`].
    pub reference_gop: u32,
    pub flags: u32,
}

impl GopHeader {
    pub fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(GOPH_LEN);
        b.put_u32(self.first_frame);
        b.put_u32(self.frame_count);
        b.put_u32(self.reference_gop);
        b.put_u32(self.flags);
        b
    }

    pub fn decode(p: &[u8], offset: u64) -> Result<Self> {
        let mut r = ByteReader::new(p, offset);
        if p.len() < GOPH_LEN {
            return Err(r.err(FormatErrorKind::Truncated {
                what: "GOPH payload",
                needed: GOPH_LEN as u64,
                available: p.len() as u64,
            }));
        }
        Ok(GopHeader {
            first_frame: r.u32("first_frame")?,
            frame_count: r.u32("frame_count")?,
            reference_gop: r.u32("reference_gop")?,
            flags: r.u32("gop flags")?,
        })
    }

    /// The value a GOP g of this scene must hold (§5.1).
    pub fn expected(scene: &SceneHeader, g: u32) -> GopHeader {
        use crate::container::header::ResidualMode::*;
        let reference_gop = match (scene.residual_mode, g) {
            (_, 0) | (Intra, _) => NO_REFERENCE,
            (Sequential, g) if scene.refresh_interval != 0 && g % scene.refresh_interval == 0 => {
                NO_REFERENCE
            }
            (Sequential, g) => g - 1,
            (Parallel, _) => 0,
        };
        GopHeader {
            first_frame: g * scene.gop_length,
            frame_count: scene.frames_in_gop(g),
            reference_gop,
            flags: 0,
        }
    }

    /// Check this GOPH against the scene header; `at` is the payload offset.
    pub fn validate(&self, scene: &SceneHeader, g: u32, at: u64) -> Result<()> {
        let want = GopHeader::expected(scene, g);
        let field = |f: &'static str, v: u32, reason: &'static str| {
            Err(Error::format(
                FormatErrorKind::InvalidField {
                    field: f,
                    value: v as u64,
                    reason,
                },
                at,
            ))
        };
        if self.first_frame != want.first_frame {
            return field("first_frame", self.first_frame, "must be g * gop_length");
        }
        if self.frame_count != want.frame_count {
            return field(
                "frame_count",
                self.frame_count,
                "must match the scene's frame count for this GOP",
            );
        }
        if self.reference_gop != want.reference_gop {
            return field(
                "reference_gop",
                self.reference_gop,
                "must follow the scene's residual mode",
            );
        }
        Ok(())
    }
}

/// One row of the GOP index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct IndexEntry {
    pub gop: u32,
    pub header: GopHeader,
    /// Absolute offset of the GOP's `GOPH` chunk.
    pub offset: u64,
    /// Bytes from that offset to the end of the GOP's last chunk.
    pub length: u64,
}

/// The `GIDX` payload: one entry per GOP, in GOP order.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Default)]
pub struct GopIndex {
    pub entries: Vec<IndexEntry>,
}

impl GopIndex {
    pub fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(4 + self.entries.len() * GIDX_ENTRY_LEN);
        b.put_u32(self.entries.len() as u32);
        for e in &self.entries {
            b.put_u32(e.gop);
            b.put_u32(e.header.first_frame);
            b.put_u32(e.header.frame_count);
            b.put_u32(e.header.reference_gop);
            b.put_u64(e.offset);
            b.put_u64(e.length);
        }
        b
    }

    /// Parse and validate against the scene header and the region where GOPs may lie:
    /// `[gops_start, gops_end)` (the bytes after the scene-level chunks and before `GIDX`).
    pub fn decode(
        p: &[u8],
        offset: u64,
        scene: &SceneHeader,
        gops_start: u64,
        gops_end: u64,
    ) -> Result<Self> {
        let mut r = ByteReader::new(p, offset);
        let at = r.offset();
        let n = r.u32("GIDX entry count")?;
        if n != scene.gop_count {
            return Err(Error::format(
                FormatErrorKind::InvalidField {
                    field: "GIDX entry count",
                    value: n as u64,
                    reason: "must equal gop_count",
                },
                at,
            ));
        }
        let need = n as u64 * GIDX_ENTRY_LEN as u64;
        if need > r.remaining() as u64 {
            return Err(r.err(FormatErrorKind::Truncated {
                what: "GIDX entries",
                needed: need,
                available: r.remaining() as u64,
            }));
        }
        let mut entries = Vec::with_capacity(n as usize);
        let mut expect_offset = gops_start;
        for g in 0..n {
            let at = r.offset();
            let gop = r.u32("GIDX gop")?;
            let header = GopHeader {
                first_frame: r.u32("GIDX first_frame")?,
                frame_count: r.u32("GIDX frame_count")?,
                reference_gop: r.u32("GIDX reference_gop")?,
                flags: 0,
            };
            let off = r.u64("GIDX offset")?;
            let length = r.u64("GIDX length")?;
            if gop != g {
                return Err(Error::format(
                    FormatErrorKind::Index("entries must be in GOP order 0, 1, ..."),
                    at,
                ));
            }
            header.validate(scene, g, at)?;
            if off != expect_offset {
                return Err(Error::format(
                    FormatErrorKind::Index(
                        "GOPs must be contiguous, starting after the scene chunks",
                    ),
                    at,
                ));
            }
            let end = off.checked_add(length).filter(|e| *e <= gops_end);
            let Some(end) = end else {
                return Err(Error::format(
                    FormatErrorKind::Index("GOP range passes the start of GIDX"),
                    at,
                ));
            };
            expect_offset = end;
            entries.push(IndexEntry {
                gop,
                header,
                offset: off,
                length,
            });
        }
        if expect_offset != gops_end {
            return Err(Error::format(
                FormatErrorKind::Index("GOP ranges must end where GIDX starts"),
                offset,
            ));
        }
        Ok(GopIndex { entries })
    }

    /// The GOP that holds frame `f`.
    pub fn gop_of_frame(&self, f: u32) -> Option<&IndexEntry> {
        let i = self
            .entries
            .partition_point(|e| e.header.first_frame + e.header.frame_count <= f);
        self.entries.get(i)
    }
}
