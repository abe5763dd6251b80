//! Just enough of HEVC's headers (H.265 §7.3) to tell, without decoding, in which order a
//! time-feature stream's pictures come out: the sequence and picture parameter sets' fields
//! that the slice header depends on, and each picture's first slice header up to its picture
//! order count. Nothing here trusts the input: anything unreadable or unexpected is `None`,
//! and the caller then decodes the stream whole, as any decoder would.

use std::collections::HashMap;

/// Escaped slice bytes read for a header: the fields up to `slice_pic_order_cnt_lsb` take at
/// most 158 bits, and 64 escaped bytes hold at least 42 unescaped ones.
const SLICE_HEAD: usize = 64;

/// The output order of a stream of one picture per packet: `display[i]` is the output index
/// of the picture in packet `i` (its picture order count), when every count can be read, they
/// are `0..n` each once, and no count wraps (`MaxPicOrderCntLsb >= 2n`, so each count is its
/// coded LSBs). `None` otherwise.
pub fn display_order(packets: &[Vec<u8>]) -> Option<Vec<usize>> {
    let n = packets.len();
    let mut sps: HashMap<u32, Sps> = HashMap::new();
    let mut pps: HashMap<u32, Pps> = HashMap::new();
    let mut display = Vec::with_capacity(n);
    for p in packets {
        let mut poc = None;
        for nal in nal_units(p) {
            if nal.len() < 2 {
                continue;
            }
            let payload = &nal[2..];
            match (nal[0] >> 1) & 0x3f {
                33 => {
                    let s = parse_sps(&unescape(payload))?;
                    sps.insert(s.id, s);
                }
                34 => {
                    let q = parse_pps(&unescape(payload))?;
                    pps.insert(q.id, q);
                }
                // The first VCL unit of an access unit is its picture's first slice. Its header
                // up to the picture order count is at most about 20 bytes, so only the start of
                // the slice (not the picture's data) is unescaped.
                ty @ 0..=31 if poc.is_none() => {
                    let head = unescape(&payload[..payload.len().min(SLICE_HEAD)]);
                    poc = Some(slice_poc(ty, &head, &sps, &pps)?);
                }
                _ => {}
            }
        }
        display.push(poc? as usize);
    }
    if sps.is_empty() || sps.values().any(|s| (1usize << s.log2_max_poc_lsb) < 2 * n) {
        return None;
    }
    let mut seen = vec![false; n];
    for &d in &display {
        if d >= n || std::mem::replace(&mut seen[d], true) {
            return None;
        }
    }
    Some(display)
}

/// The NAL units of an Annex B byte stream (start codes `00 00 01`, possibly after zeros).
fn nal_units(bytes: &[u8]) -> impl Iterator<Item = &[u8]> {
    let mut starts = Vec::new();
    let mut i = 0;
    while i + 3 <= bytes.len() {
        if bytes[i] == 0 && bytes[i + 1] == 0 && bytes[i + 2] == 1 {
            starts.push(i + 3);
            i += 3;
        } else {
            i += 1;
        }
    }
    let ends: Vec<usize> = starts
        .iter()
        .skip(1)
        .map(|&s| s - 3)
        .chain(std::iter::once(bytes.len()))
        .collect();
    starts
        .into_iter()
        .zip(ends)
        .map(move |(s, e)| &bytes[s..e.max(s)])
}

/// The RBSP of a NAL unit's payload: every emulation prevention byte (`00 00 03`) removed.
fn unescape(payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len());
    let mut zeros = 0;
    for &b in payload {
        if zeros >= 2 && b == 3 {
            zeros = 0;
            continue;
        }
        zeros = if b == 0 { zeros + 1 } else { 0 };
        out.push(b);
    }
    out
}

struct Bits<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Bits<'_> {
    fn new(bytes: &[u8]) -> Bits<'_> {
        Bits { bytes, at: 0 }
    }

    fn u(&mut self, n: usize) -> Option<u32> {
        let mut v = 0u32;
        for _ in 0..n {
            let byte = *self.bytes.get(self.at / 8)?;
            v = (v << 1) | ((byte >> (7 - self.at % 8)) & 1) as u32;
            self.at += 1;
        }
        Some(v)
    }

    fn skip(&mut self, n: usize) -> Option<()> {
        self.at += n;
        (self.at <= self.bytes.len() * 8).then_some(())
    }

    /// Exp-Golomb `ue(v)`, at most 32 bits of value.
    fn ue(&mut self) -> Option<u32> {
        let mut zeros = 0;
        while self.u(1)? == 0 {
            zeros += 1;
            if zeros > 31 {
                return None;
            }
        }
        Some(((1u64 << zeros) - 1 + self.u(zeros)? as u64) as u32)
    }
}

/// The sequence parameter set fields used here.
struct Sps {
    id: u32,
    separate_colour_plane: bool,
    log2_max_poc_lsb: u32,
}

/// The picture parameter set fields a slice header needs before its picture order count.
struct Pps {
    id: u32,
    sps_id: u32,
    output_flag_present: bool,
    extra_slice_header_bits: u32,
}

fn parse_sps(rbsp: &[u8]) -> Option<Sps> {
    let mut b = Bits::new(rbsp);
    b.skip(4)?; // sps_video_parameter_set_id
    let sub_layers = b.u(3)? as usize; // sps_max_sub_layers_minus1
    b.skip(1)?; // sps_temporal_id_nesting_flag
    b.skip(96)?; // profile_tier_level(1, sub_layers): its general part
    let mut present = Vec::with_capacity(sub_layers);
    for _ in 0..sub_layers {
        present.push((b.u(1)?, b.u(1)?)); // sub_layer_{profile,level}_present_flag
    }
    if sub_layers > 0 {
        b.skip(2 * (8 - sub_layers))?; // reserved_zero_2bits
    }
    for (profile, level) in present {
        b.skip(88 * profile as usize + 8 * level as usize)?;
    }
    let id = b.ue()?; // sps_seq_parameter_set_id
    let mut separate_colour_plane = false;
    if b.ue()? == 3 {
        separate_colour_plane = b.u(1)? == 1;
    }
    b.ue()?; // pic_width_in_luma_samples
    b.ue()?; // pic_height_in_luma_samples
    if b.u(1)? == 1 {
        for _ in 0..4 {
            b.ue()?; // conf_win_{left,right,top,bottom}_offset
        }
    }
    b.ue()?; // bit_depth_luma_minus8
    b.ue()?; // bit_depth_chroma_minus8
    let log2_max_poc_lsb = b.ue()?.checked_add(4)?; // log2_max_pic_order_cnt_lsb_minus4
    if log2_max_poc_lsb > 16 {
        return None;
    }
    Some(Sps {
        id,
        separate_colour_plane,
        log2_max_poc_lsb,
    })
}

fn parse_pps(rbsp: &[u8]) -> Option<Pps> {
    let mut b = Bits::new(rbsp);
    let id = b.ue()?;
    let sps_id = b.ue()?;
    // dependent_slice_segments_enabled_flag: a picture's first slice segment carries no
    // dependent_slice_segment_flag (nor a slice_segment_address), so it does not matter here.
    b.skip(1)?;
    Some(Pps {
        id,
        sps_id,
        output_flag_present: b.u(1)? == 1,
        extra_slice_header_bits: b.u(3)?,
    })
}

/// The picture order count LSBs of a picture's first slice segment (NAL type `ty`); 0 for
/// IDR pictures, which carry none.
fn slice_poc(ty: u8, rbsp: &[u8], sps: &HashMap<u32, Sps>, pps: &HashMap<u32, Pps>) -> Option<u32> {
    let mut b = Bits::new(rbsp);
    if b.u(1)? != 1 {
        return None; // first_slice_segment_in_pic_flag: not a picture's first slice
    }
    if (16..=23).contains(&ty) {
        b.skip(1)?; // no_output_of_prior_pics_flag
    }
    let q = pps.get(&b.ue()?)?; // slice_pic_parameter_set_id
    let s = sps.get(&q.sps_id)?;
    b.skip(q.extra_slice_header_bits as usize)?; // slice_reserved_flag[i]
    b.ue()?; // slice_type
    if q.output_flag_present {
        b.skip(1)?; // pic_output_flag
    }
    if s.separate_colour_plane {
        b.skip(2)?; // colour_plane_id
    }
    if ty == 19 || ty == 20 {
        return Some(0); // IDR_W_RADL, IDR_N_LP
    }
    b.u(s.log2_max_poc_lsb as usize) // slice_pic_order_cnt_lsb
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emulation_prevention_bytes_are_removed() {
        assert_eq!(
            unescape(&[0, 0, 3, 1, 0, 0, 3, 0, 3]),
            [0, 0, 1, 0, 0, 0, 3]
        );
    }

    #[test]
    fn nal_units_split_at_start_codes() {
        let s = [0, 0, 0, 1, 0x40, 1, 9, 0, 0, 1, 0x42, 1, 7];
        let units: Vec<&[u8]> = nal_units(&s).collect();
        assert_eq!(units, [&[0x40, 1, 9][..], &[0x42, 1, 7][..]]);
        assert_eq!(nal_units(&[1, 2, 3]).count(), 0);
    }

    /// Truncated or garbage headers are "unknown", never a panic.
    #[test]
    fn unreadable_headers_are_unknown() {
        assert!(display_order(&[]).is_none());
        let garbage = [
            vec![0, 0, 1, 0x42, 1],
            vec![0, 0, 1, 0x42, 1, 0xff],
            [vec![0, 0, 1, 0x42, 1], vec![0; 40]].concat(),
            vec![0, 0, 1, 0x26, 1, 0x80],
            [vec![0, 0, 1, 0x44, 1], vec![0xff; 9]].concat(),
        ];
        for g in garbage {
            assert!(display_order(&[g]).is_none());
        }
    }

    /// An SPS whose `log2_max_pic_order_cnt_lsb_minus4` is the largest `ue(v)` (found by the
    /// `dynamic_payloads` fuzz target: `+ 4` overflowed) is unreadable, not a panic.
    #[test]
    fn the_largest_poc_lsb_field_is_unreadable() {
        let mut bits = String::new();
        bits += "0000" /* vps id */;
        bits += "000" /* sub-layers - 1 */;
        bits += "1" /* nesting */;
        bits += &"0".repeat(96) /* profile_tier_level */;
        bits += "1111" /* sps id, chroma 0, width 0, height 0 */;
        bits += "0" /* no conformance window */;
        bits += "11" /* bit depths */;
        bits += &("0".repeat(31) + &"1".repeat(32)) /* ue = 2^32 - 2 */;
        bits += &"1".repeat(8);
        let pack = |bits: &str| -> Vec<u8> {
            let bits = bits.as_bytes();
            bits.chunks(8)
                .map(|c| {
                    c.iter()
                        .enumerate()
                        .fold(0u8, |b, (i, &bit)| b | (u8::from(bit == b'1') << (7 - i)))
                })
                .collect()
        };
        assert!(parse_sps(&pack(&bits)).is_none());
        let mut ok = bits[..111].to_string();
        ok += "00100" /* ue = 3: 7 bits of LSBs */;
        ok += &"1".repeat(8);
        let bytes = pack(&ok);
        assert_eq!(parse_sps(&bytes).map(|s| s.log2_max_poc_lsb), Some(7));
    }

    /// x265's own streams: the output order read from the slice headers is the order FFmpeg
    /// gives, for every prefix; a fast-start stream's first 2 packets are its first 2 pictures.
    #[cfg(feature = "hevc")]
    #[test]
    fn x265_streams_say_in_which_order_their_pictures_come_out() {
        use dlgs_video::{decode_gray12, encode_gray12, FastStart, Gray12, HevcSettings};
        let (w, h) = (64u32, 64u32);
        let video = Gray12 {
            width: w,
            height: h,
            frames: (0..7)
                .map(|f| {
                    (0..w * h)
                        .map(|i| ((i * 7 + f * 131 + (i / w) * f) % 4096) as u16)
                        .collect()
                })
                .collect(),
        };
        for fast_start in [FastStart::Off, FastStart::EveryGop] {
            let s = HevcSettings {
                preset: "ultrafast".into(),
                fast_start,
                ..Default::default()
            };
            let packets = encode_gray12(&video, &s).unwrap();
            let order = display_order(&packets).expect("readable");
            if fast_start == FastStart::Off {
                assert_ne!(order, (0..7).collect::<Vec<_>>(), "x265 reorders");
            } else {
                assert_eq!(order[..2], [0, 1], "{order:?}");
            }
            // Each prefix decodes to the pictures the order says, in output order.
            let refs: Vec<&[u8]> = packets.iter().map(|p| p.as_slice()).collect();
            let whole = decode_gray12(&refs, w, h, 7).unwrap().frames;
            for m in 1..=7 {
                let mut shown: Vec<usize> = order[..m].to_vec();
                shown.sort();
                let prefix = decode_gray12(&refs[..m], w, h, m).unwrap().frames;
                for (got, &d) in prefix.iter().zip(&shown) {
                    assert!(got == &whole[d], "{fast_start:?}: prefix {m}, picture {d}");
                }
            }
        }
    }
}
