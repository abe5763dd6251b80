//! The HEVC track of an MP4 file (the reference's `_point_feats.mp4`), as the Annex B packets
//! `TFEA` stores: FFmpeg's demuxer splits the samples, and the `hvcC` parameter sets and
//! length-prefixed NAL units are rewritten with start codes. The samples are the file's own
//! bytes: nothing is re-encoded.

use std::path::Path;

use ff::media::Type;
use ffmpeg_next as ff;

use crate::{ff_err, init, VideoError};

/// One video track: picture size and its packets as Annex B access units, in file order.
#[derive(Debug, Clone, PartialEq)]
pub struct HevcTrack {
    pub width: u32,
    pub height: u32,
    pub packets: Vec<Vec<u8>>,
}

const START: [u8; 4] = [0, 0, 0, 1];

/// Read the HEVC video track of `path`.
pub fn demux_hevc(path: &Path) -> Result<HevcTrack, VideoError> {
    init();
    let mut ictx = ff::format::input(&path).map_err(ff_err("open container"))?;
    let stream = ictx
        .streams()
        .best(Type::Video)
        .ok_or_else(|| VideoError::Invalid("no video track".into()))?;
    let index = stream.index();
    let par = stream.parameters();
    if par.id() != ff::codec::Id::HEVC {
        return Err(VideoError::Invalid(format!(
            "video track is {:?}, expected HEVC",
            par.id()
        )));
    }
    let extradata = extradata(&par);
    let dec = ff::codec::context::Context::from_parameters(par)
        .and_then(|c| c.decoder().video())
        .map_err(ff_err("track parameters"))?;
    let (width, height) = (dec.width(), dec.height());
    let (length_size, param_sets) = parameter_sets(&extradata)?;
    let mut packets = Vec::new();
    for (s, pkt) in ictx.packets() {
        if s.index() != index {
            continue;
        }
        let Some(data) = pkt.data() else { continue };
        let mut out = Vec::with_capacity(data.len() + 64);
        if packets.is_empty() {
            out.extend_from_slice(&param_sets);
        }
        match length_size {
            Some(n) => to_annex_b(data, n, &mut out)?,
            None => out.extend_from_slice(data),
        }
        packets.push(out);
    }
    if packets.is_empty() {
        return Err(VideoError::Invalid("the video track has no packets".into()));
    }
    Ok(HevcTrack {
        width,
        height,
        packets,
    })
}

/// The codec parameters' extradata (the `hvcC` box body for MP4).
#[allow(unsafe_code)]
fn extradata(par: &ff::codec::Parameters) -> Vec<u8> {
    // SAFETY: FFI boundary. `par` borrows the stream's live AVCodecParameters; FFmpeg guarantees
    // `extradata` points to `extradata_size` readable bytes (or is null with size 0). The bytes
    // are copied before `par`'s borrow ends.
    unsafe {
        let p = par.as_ptr();
        let (data, size) = ((*p).extradata, (*p).extradata_size);
        if data.is_null() || size <= 0 {
            Vec::new()
        } else {
            std::slice::from_raw_parts(data, size as usize).to_vec()
        }
    }
}

/// From `hvcC`: the NAL length size and the VPS/SPS/PPS (and SEI) units with start codes.
/// Extradata that is already Annex B (or absent) gives `None`: packets pass unchanged.
fn parameter_sets(x: &[u8]) -> Result<(Option<usize>, Vec<u8>), VideoError> {
    if x.is_empty() || x.starts_with(&START) || x.starts_with(&START[1..]) {
        return Ok((None, x.to_vec()));
    }
    let bad = |r: &str| VideoError::Invalid(format!("hvcC: {r}"));
    if x.len() < 23 || x[0] != 1 {
        return Err(bad("not an HEVC decoder configuration record"));
    }
    let length_size = (x[21] & 3) as usize + 1;
    let arrays = x[22] as usize;
    let mut at = 23;
    let mut out = Vec::new();
    for _ in 0..arrays {
        let count = x
            .get(at + 1..at + 3)
            .ok_or_else(|| bad("truncated array"))?;
        let count = u16::from_be_bytes([count[0], count[1]]) as usize;
        at += 3;
        for _ in 0..count {
            let len = x
                .get(at..at + 2)
                .ok_or_else(|| bad("truncated NAL length"))?;
            let len = u16::from_be_bytes([len[0], len[1]]) as usize;
            at += 2;
            let nal = x
                .get(at..at + len)
                .ok_or_else(|| bad("truncated NAL unit"))?;
            out.extend_from_slice(&START);
            out.extend_from_slice(nal);
            at += len;
        }
    }
    Ok((Some(length_size), out))
}

/// Length-prefixed NAL units (ISO/IEC 14496-15) to start-code-prefixed ones.
fn to_annex_b(mut data: &[u8], length_size: usize, out: &mut Vec<u8>) -> Result<(), VideoError> {
    while !data.is_empty() {
        if data.len() < length_size {
            return Err(VideoError::Invalid(
                "truncated NAL length in a sample".into(),
            ));
        }
        let len = data[..length_size]
            .iter()
            .fold(0usize, |a, &b| (a << 8) | b as usize);
        data = &data[length_size..];
        if len > data.len() {
            return Err(VideoError::Invalid(format!(
                "NAL unit of {len} bytes in a sample with {} left (file truncated?)",
                data.len()
            )));
        }
        out.extend_from_slice(&START);
        out.extend_from_slice(&data[..len]);
        data = &data[len..];
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn length_prefixed_to_start_codes() {
        let mut out = Vec::new();
        to_annex_b(&[0, 0, 0, 2, 0x40, 0x01, 0, 0, 0, 1, 0x26], 4, &mut out).unwrap();
        assert_eq!(out, [0, 0, 0, 1, 0x40, 0x01, 0, 0, 0, 1, 0x26]);
        assert!(to_annex_b(&[0, 0, 0, 9, 1], 4, &mut Vec::new()).is_err());
        assert!(to_annex_b(&[0, 0], 4, &mut Vec::new()).is_err());
    }

    #[test]
    fn hvcc_truncations_are_errors() {
        let mut rec = vec![1u8; 23];
        rec[21] = 3;
        rec[22] = 1;
        rec.extend_from_slice(&[32, 0, 1, 0, 3, 0x40, 1, 2]);
        let (n, ps) = parameter_sets(&rec).unwrap();
        assert_eq!(n, Some(4));
        assert_eq!(ps, [0, 0, 0, 1, 0x40, 1, 2]);
        for cut in 1..rec.len() {
            let _ = parameter_sets(&rec[..cut]); // never panics
        }
        assert!(parameter_sets(&rec[..rec.len() - 1]).is_err());
    }
}
