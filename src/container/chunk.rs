//! Chunk framing (format-spec §3): a 24-byte header with its own CRC, the payload, and a
//! CRC-32C of the payload.

pub use super::chunk_type::ChunkType;
use crate::bytes::ByteReader;
use crate::error::{Error, FormatErrorKind, Result};

/// Flag bit 0: a reader that does not know this chunk type must stop with an error.
pub const FLAG_MUST_UNDERSTAND: u16 = 1;
/// `gop` field value for chunks that belong to the scene, not to one GOP.
pub const SCENE_LEVEL: u32 = u32::MAX;
/// Size of the fixed chunk header.
pub const CHUNK_HEADER_LEN: u64 = 24;
/// Size of the payload CRC that follows every payload.
pub const CHUNK_TRAILER_LEN: u64 = 4;
/// Bytes a chunk adds around its payload.
pub const CHUNK_OVERHEAD: u64 = CHUNK_HEADER_LEN + CHUNK_TRAILER_LEN;

/// A parsed chunk header plus where it sits in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChunkInfo {
    pub ty: ChunkType,
    pub flags: u16,
    pub gop: u32,
    /// Payload length in bytes.
    pub len: u64,
    /// Absolute offset of the chunk header.
    pub offset: u64,
}

impl ChunkInfo {
    pub fn must_understand(&self) -> bool {
        self.flags & FLAG_MUST_UNDERSTAND != 0
    }
    pub fn payload_offset(&self) -> u64 {
        self.offset + CHUNK_HEADER_LEN
    }
    /// Offset of the byte after this chunk (header + payload + CRC).
    pub fn end(&self) -> u64 {
        self.offset + CHUNK_OVERHEAD + self.len
    }
}

pub fn encode_header(ty: ChunkType, flags: u16, gop: u32, len: u64) -> [u8; 24] {
    let mut h = [0u8; 24];
    h[0..4].copy_from_slice(&ty.0);
    h[4..6].copy_from_slice(&flags.to_le_bytes());
    // bytes 6..8 reserved, zero
    h[8..12].copy_from_slice(&gop.to_le_bytes());
    h[12..20].copy_from_slice(&len.to_le_bytes());
    let crc = crc32c::crc32c(&h[0..20]);
    h[20..24].copy_from_slice(&crc.to_le_bytes());
    h
}

/// Parse and verify a 24-byte chunk header found at absolute `offset`.
pub fn decode_header(h: &[u8; 24], offset: u64) -> Result<ChunkInfo> {
    let mut r = ByteReader::new(h, offset);
    let ty: [u8; 4] = r.take(4, "chunk type")?.try_into().expect("4 bytes");
    let flags = r.u16("chunk flags")?;
    let _reserved = r.u16("chunk reserved")?;
    let gop = r.u32("chunk gop")?;
    let len = r.u64("chunk length")?;
    let stored = r.u32("chunk header crc")?;
    let computed = crc32c::crc32c(&h[0..20]);
    // Under cargo-fuzz, CRCs are not enforced so that mutated inputs reach the parsers behind
    // them; every other check stays on.
    if stored != computed && !cfg!(fuzzing) {
        return Err(Error::format(
            FormatErrorKind::HeaderCrc { stored, computed },
            offset + 20,
        ));
    }
    if !ChunkType::is_valid(ty) {
        return Err(Error::format(FormatErrorKind::InvalidChunkType(ty), offset));
    }
    Ok(ChunkInfo {
        ty: ChunkType(ty),
        flags,
        gop,
        len,
        offset,
    })
}

/// Verify a payload against the CRC stored after it.
pub fn check_payload_crc(info: &ChunkInfo, payload: &[u8], stored: u32) -> Result<()> {
    let computed = crc32c::crc32c(payload);
    if computed != stored && !cfg!(fuzzing) {
        return Err(Error::format(
            FormatErrorKind::PayloadCrc {
                chunk: info.ty,
                stored,
                computed,
            },
            info.payload_offset() + info.len,
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32c_check_value_from_the_spec() {
        assert_eq!(crc32c::crc32c(b"123456789"), 0xE306_9283);
    }

    #[test]
    fn header_round_trip_and_every_single_bit_flip_is_caught() {
        let h = encode_header(ChunkType::CRAW, FLAG_MUST_UNDERSTAND, 7, 123_456);
        let info = decode_header(&h, 40).unwrap();
        assert_eq!(
            (info.ty, info.flags, info.gop, info.len, info.offset),
            (ChunkType::CRAW, 1, 7, 123_456, 40)
        );
        assert_eq!(info.end(), 40 + 28 + 123_456);
        for bit in 0..24 * 8 {
            let mut b = h;
            b[bit / 8] ^= 1 << (bit % 8);
            if !cfg!(fuzzing) {
                assert!(decode_header(&b, 0).is_err(), "flip of bit {bit} accepted");
            }
        }
    }

    #[test]
    fn chunk_type_alphabet() {
        assert!(ChunkType::is_valid(*b"ab 9"));
        assert!(!ChunkType::is_valid(*b"AB\0C"));
        assert!(!ChunkType::is_valid([0xff, b'A', b'B', b'C']));
    }
}
