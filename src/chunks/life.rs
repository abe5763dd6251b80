//! `LIFE`: the frames at which each dynamic Gaussian of a GOP is shown (format-spec §6.14,
//! since 1.18). Entries as index gaps, first and last frames, in one zstd frame.

use crate::bytes::{zstd_exact, ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, Result};
use crate::model::lifetimes::{Life, Lifetimes};
use crate::Limits;

/// Bytes of one entry before compression: u32 index gap, u16 first, u16 last.
const ENTRY_BYTES: u64 = 8;

/// Serialise a GOP's entries (indices strictly increasing, each below `n_dynamic`).
pub fn encode(l: &Lifetimes, n_dynamic: u32, zstd_level: i32) -> Result<Vec<u8>> {
    let mut raw = Vec::with_capacity(l.entries.len() * ENTRY_BYTES as usize);
    let mut next = 0u32;
    for e in &l.entries {
        if e.index < next || e.index >= n_dynamic {
            return Err(Error::input(format!(
                "LIFE entry for dynamic Gaussian {} out of order or beyond the {n_dynamic} dynamic \
                 Gaussians",
                e.index
            )));
        }
        raw.put_u32(e.index - next);
        raw.put_u16(e.first);
        raw.put_u16(e.last);
        next = e.index + 1;
    }
    let mut b = Vec::new();
    b.put_u32(l.entries.len() as u32);
    b.extend_from_slice(&crate::bytes::zstd_compress(&raw, zstd_level)?);
    Ok(b)
}

/// Parse a `LIFE` payload at absolute `offset` (§6.14).
pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<Lifetimes> {
    let mut r = ByteReader::new(p, offset);
    let count = r.u32("LIFE count")?;
    if count > scene.n_dynamic {
        return Err(Error::payload(
            ChunkType::LIFE,
            format!("{count} entries for {} dynamic Gaussians", scene.n_dynamic),
            offset,
        ));
    }
    let raw_len = u64::from(count) * ENTRY_BYTES;
    limits.check_alloc("LIFE entries", raw_len, offset)?;
    let body_at = r.offset();
    let raw = zstd_exact(r.rest(), raw_len, body_at)?;
    let mut entries = Vec::with_capacity(count as usize);
    let mut next = 0u64;
    for (j, e) in raw.chunks_exact(ENTRY_BYTES as usize).enumerate() {
        let gap = u32::from_le_bytes([e[0], e[1], e[2], e[3]]);
        let index = next + u64::from(gap);
        if index >= u64::from(scene.n_dynamic) {
            return Err(Error::payload(
                ChunkType::LIFE,
                format!(
                    "entry {j} names dynamic Gaussian {index} of {}",
                    scene.n_dynamic
                ),
                body_at,
            ));
        }
        entries.push(Life {
            index: index as u32,
            first: u16::from_le_bytes([e[4], e[5]]),
            last: u16::from_le_bytes([e[6], e[7]]),
        });
        next = index + 1;
    }
    Ok(Lifetimes { entries })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(n: u32) -> SceneHeader {
        let mut s = SceneHeader::still(0, 0);
        s.n_dynamic = n;
        s
    }

    #[test]
    fn round_trip_and_every_bad_field_is_a_typed_error() {
        let l = Lifetimes {
            entries: vec![
                Life {
                    index: 0,
                    first: 3,
                    last: 59,
                },
                Life {
                    index: 7,
                    first: u16::MAX,
                    last: 0,
                },
            ],
        };
        let p = encode(&l, 8, 3).unwrap();
        assert_eq!(decode(&p, 100, &scene(8), &Limits::default()).unwrap(), l);
        // Beyond the dynamic set, out of order.
        assert!(encode(&l, 7, 3).is_err());
        let mut rev = l.clone();
        rev.entries.reverse();
        assert!(encode(&rev, 8, 3).is_err());
        let e = decode(&p, 100, &scene(7), &Limits::default()).unwrap_err();
        assert!(e.to_string().contains("LIFE"), "{e}");
        // More entries than dynamic Gaussians; a count the body does not hold; truncation.
        let mut big = p.clone();
        big[0] = 9;
        assert!(decode(&big, 0, &scene(8), &Limits::default()).is_err());
        let mut short = p.clone();
        short[0] = 1;
        assert!(decode(&short, 0, &scene(8), &Limits::default()).is_err());
        assert!(decode(&p[..3], 0, &scene(8), &Limits::default()).is_err());
        let tight = Limits {
            max_alloc: 8,
            ..Limits::default()
        };
        assert!(decode(&p, 0, &scene(8), &tight).is_err());
        assert_eq!(
            decode(
                &encode(&Lifetimes::default(), 8, 3).unwrap(),
                0,
                &scene(8),
                &Limits::default()
            )
            .unwrap(),
            Lifetimes::default()
        );
    }
}
