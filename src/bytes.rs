//! A bounds-checked little-endian cursor over a byte slice. Every read that would pass the end
//! returns `Truncated` with the absolute file offset instead of panicking.

use crate::error::{Error, FormatErrorKind, Result};

pub struct ByteReader<'a> {
    data: &'a [u8],
    pos: usize,
    /// Absolute offset of `data[0]` in the file, for error messages.
    base: u64,
}

impl<'a> ByteReader<'a> {
    pub fn new(data: &'a [u8], base: u64) -> Self {
        ByteReader { data, pos: 0, base }
    }
    pub fn offset(&self) -> u64 {
        self.base + self.pos as u64
    }
    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }
    pub fn err(&self, kind: FormatErrorKind) -> Error {
        Error::format(kind, self.offset())
    }
    pub fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8]> {
        if n > self.remaining() {
            return Err(self.err(FormatErrorKind::Truncated {
                what,
                needed: n as u64,
                available: self.remaining() as u64,
            }));
        }
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    pub fn rest(&mut self) -> &'a [u8] {
        let s = &self.data[self.pos..];
        self.pos = self.data.len();
        s
    }
    pub fn u8(&mut self, what: &'static str) -> Result<u8> {
        Ok(self.take(1, what)?[0])
    }
    pub fn u16(&mut self, what: &'static str) -> Result<u16> {
        let b = self.take(2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }
    pub fn u32(&mut self, what: &'static str) -> Result<u32> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes(b.try_into().expect("4 bytes")))
    }
    pub fn u64(&mut self, what: &'static str) -> Result<u64> {
        let b = self.take(8, what)?;
        Ok(u64::from_le_bytes(b.try_into().expect("8 bytes")))
    }
    pub fn f32(&mut self, what: &'static str) -> Result<f32> {
        Ok(f32::from_bits(self.u32(what)?))
    }
    /// A finite f32 (rejects NaN and infinities).
    pub fn finite_f32(&mut self, what: &'static str) -> Result<f32> {
        let at = self.offset();
        let v = self.f32(what)?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(Error::format(
                FormatErrorKind::NonFinite { field: what },
                at,
            ))
        }
    }
    /// An unsigned LEB128 varint of at most 5 bytes whose value fits a u32 (7 bits per byte,
    /// least significant group first, high bit set on every byte but the last).
    pub fn varint_u32(&mut self, what: &'static str) -> Result<u32> {
        let at = self.offset();
        let mut v = 0u64;
        for i in 0..5 {
            let b = self.u8(what)?;
            v |= ((b & 0x7f) as u64) << (7 * i);
            if b & 0x80 == 0 {
                return u32::try_from(v).map_err(|_| {
                    Error::format(
                        FormatErrorKind::InvalidField {
                            field: what,
                            value: v,
                            reason: "varint above u32",
                        },
                        at,
                    )
                });
            }
        }
        Err(Error::format(
            FormatErrorKind::InvalidField {
                field: what,
                value: v,
                reason: "varint longer than 5 bytes",
            },
            at,
        ))
    }
    /// A finite IEEE binary16 value, widened (exactly) to f32.
    pub fn finite_f16(&mut self, what: &'static str) -> Result<f32> {
        let at = self.offset();
        let v = half::f16::from_bits(self.u16(what)?).to_f32();
        if v.is_finite() {
            Ok(v)
        } else {
            Err(Error::format(
                FormatErrorKind::NonFinite { field: what },
                at,
            ))
        }
    }
    /// `n` little-endian f32 values; the length is checked before allocating.
    pub fn f32_vec(&mut self, n: usize, what: &'static str) -> Result<Vec<f32>> {
        let bytes = n.checked_mul(4).ok_or_else(|| {
            self.err(FormatErrorKind::InvalidField {
                field: what,
                value: n as u64,
                reason: "count overflows",
            })
        })?;
        let b = self.take(bytes, what)?;
        Ok(b.chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect())
    }
}

/// Little-endian appends, the writer-side counterpart of [`ByteReader`].
pub trait PutLe {
    fn put_u8(&mut self, v: u8);
    fn put_u16(&mut self, v: u16);
    fn put_u32(&mut self, v: u32);
    fn put_u64(&mut self, v: u64);
    fn put_f32(&mut self, v: f32);
    fn put_f32s(&mut self, v: &[f32]);
    /// Unsigned LEB128, the writer side of [`ByteReader::varint_u32`].
    fn put_varint(&mut self, v: u32);
}

impl PutLe for Vec<u8> {
    fn put_u8(&mut self, v: u8) {
        self.push(v);
    }
    fn put_u16(&mut self, v: u16) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_u32(&mut self, v: u32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_u64(&mut self, v: u64) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_f32(&mut self, v: f32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_f32s(&mut self, v: &[f32]) {
        self.reserve(v.len() * 4);
        for x in v {
            self.extend_from_slice(&x.to_le_bytes());
        }
    }
    fn put_varint(&mut self, mut v: u32) {
        while v >= 0x80 {
            self.push(v as u8 | 0x80);
            v >>= 7;
        }
        self.push(v as u8);
    }
}

/// Compress `data` as one zstd frame at `level` (zstd clamps the level to its range); a
/// failure of the library is reported as `InvalidInput`, the same in every chunk.
pub fn zstd_compress(data: &[u8], level: i32) -> Result<Vec<u8>> {
    zstd::bulk::compress(data, level).map_err(|e| Error::input(format!("zstd level {level}: {e}")))
}

/// Decompress one zstd frame that must yield exactly `len` bytes (never more is allocated);
/// anything else is `Decompress` at `at`. Check `len` against the limits first.
pub fn zstd_exact(data: &[u8], len: u64, at: u64) -> Result<Vec<u8>> {
    let out = zstd::bulk::decompress(data, len as usize)
        .map_err(|e| Error::format(FormatErrorKind::Decompress(e.to_string()), at))?;
    if out.len() as u64 != len {
        return Err(Error::format(
            FormatErrorKind::Decompress(format!(
                "{} bytes decompressed, {len} declared",
                out.len()
            )),
            at,
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varints_round_trip_and_reject_overlong_or_wide_values() {
        for v in [0u32, 1, 127, 128, 300, 16_383, 16_384, u32::MAX] {
            let mut b = Vec::new();
            b.put_varint(v);
            assert_eq!(
                b.len(),
                1 + (32 - v.leading_zeros()).saturating_sub(1) as usize / 7
            );
            let mut r = ByteReader::new(&b, 0);
            assert_eq!(r.varint_u32("v").unwrap(), v);
            assert_eq!(r.remaining(), 0);
        }
        // 2^32 in five bytes, six continuation bytes, and a varint cut short.
        for bad in [&[0x80, 0x80, 0x80, 0x80, 0x10][..], &[0xff; 6], &[0x80]] {
            assert!(ByteReader::new(bad, 0).varint_u32("v").is_err(), "{bad:?}");
        }
    }

    #[test]
    fn f16_values_widen_exactly_and_non_finite_ones_are_errors() {
        let b = [0x00, 0x3c, 0x00, 0x7c]; // 1.0, +inf
        let mut r = ByteReader::new(&b, 0);
        assert_eq!(r.finite_f16("x").unwrap(), 1.0);
        assert!(r.finite_f16("x").is_err());
    }
}
