//! Low-delay HEVC time features: a one-stream `TFEA` (codecs 1 and 2) whose sequence parameter
//! sets declare `sps_max_num_reorder_pics` 0 has no picture that is output after a picture
//! decoded later, so its first `k` packets decode to its first `k` key pictures. Such a GOP
//! decodes the keys a frame needs (and playback starts) without the rest of the stream.
//!
//! With a decoder that takes packets one at a time ([`KeyPictureStream`], FFmpeg's) each
//! picture is decoded once, in order, as keys are asked for: the first frames wait for 2
//! pictures, and a player's next key interval waits only for its own picture. A plugged-in
//! decoder without one decodes a prefix the first time and the whole stream the second.
//!
//! The encoder writes GOP 0's stream this way by default (`HevcSettings::low_delay`); streams
//! with B-frames (or whose parameter sets cannot be read) decode whole, as before. HEVC decoding
//! is exact, so the prefix's pictures are the samples the whole stream gives.

use std::collections::VecDeque;
use std::sync::{Mutex, OnceLock};

use dlgs::chunks::tfea::{self, Tiling};
use dlgs::container::ChunkType;
use dlgs::{Error, Result};

use crate::build::{check_pictures, key_pictures};
use crate::hevc::{KeyPictureStream, SharedKeyPictureDecoder};
use crate::planar::KeySource;

/// How samples become feature values: codec 1's per-channel ranges, or codec 2's one range.
pub(crate) enum Dequantise {
    Ranges(Vec<(f32, f32)>),
    Reference((f64, f64)),
}

/// The keys of a low-delay one-stream `TFEA`.
pub(crate) struct LowDelayKeys {
    tiling: Tiling,
    dequantise: Dequantise,
    /// One access unit per key picture, in decode (= output) order.
    packets: Vec<Vec<u8>>,
    /// Offset of the `TFEA` payload, for errors.
    at: u64,
    hevc: Option<SharedKeyPictureDecoder>,
    /// Where decoding has got to. Held while a picture is decoded and its slot filled, never
    /// while waiting on other threads' work (so a rayon thread holding it cannot deadlock).
    progress: Mutex<Progress>,
}

#[derive(Default)]
struct Progress {
    /// The decoder fed one packet at a time, once started (dropped after the last picture).
    stream: Option<Box<dyn KeyPictureStream>>,
    /// Packets fed to `stream`, and whether its end has been signalled.
    sent: usize,
    ended: bool,
    /// Pictures released but not yet untiled, and the key index of the next one.
    pending: VecDeque<Vec<u16>>,
    next: usize,
    /// Without a stream decoder: whether a prefix has been decoded (the next decode is whole).
    prefix_done: bool,
    /// The first failure, given again to every later request.
    failed: Option<Error>,
}

impl LowDelayKeys {
    /// Hands `packets` back unless they are a low-delay stream with one packet per key.
    pub fn new(
        tiling: Tiling,
        dequantise: Dequantise,
        packets: Vec<Vec<u8>>,
        at: u64,
        hevc: Option<SharedKeyPictureDecoder>,
    ) -> std::result::Result<Self, Vec<Vec<u8>>> {
        if packets.len() != tiling.keys || !pictures_in_decode_order(&packets) {
            return Err(packets);
        }
        Ok(LowDelayKeys {
            tiling,
            dequantise,
            packets,
            at,
            hevc,
            progress: Mutex::new(Progress::default()),
        })
    }

    /// One key's `(C, N)` block from its picture, on this thread.
    fn untile(&self, picture: &[u16]) -> Vec<f32> {
        let one = Tiling {
            keys: 1,
            ..self.tiling
        };
        match &self.dequantise {
            Dequantise::Ranges(r) => tfea::untile_key(picture, &one, tfea::sample_value(r)),
            Dequantise::Reference(r) => {
                tfea::untile_key(picture, &one, tfea::reference_sample_value(*r))
            }
        }
    }

    fn payload_error(&self, reason: String) -> Error {
        Error::payload(ChunkType::TFEA, reason, self.at)
    }

    /// The next picture in key order from the packet-at-a-time decoder.
    fn next_picture(&self, p: &mut Progress) -> Result<Vec<u16>> {
        let t = &self.tiling;
        while p.pending.is_empty() {
            let stream = p.stream.as_mut().expect("started");
            let released = if p.sent < self.packets.len() {
                p.sent += 1;
                stream.push(&self.packets[p.sent - 1])
            } else if !p.ended {
                p.ended = true;
                stream.finish()
            } else {
                return Err(self.payload_error(format!(
                    "the HEVC decoder gave {} pictures, {} expected",
                    p.next, t.keys
                )));
            }
            .map_err(|e| self.payload_error(e))?;
            check_pictures(&released, t, self.at)?;
            p.pending.extend(released);
        }
        Ok(p.pending.pop_front().expect("a picture"))
    }

    /// Fill `slots` up to key `last` with the packet-at-a-time decoder.
    fn fill_streamed(
        &self,
        p: &mut Progress,
        last: usize,
        slots: &[OnceLock<Vec<f32>>],
    ) -> Result<()> {
        while p.next <= last {
            let picture = self.next_picture(p)?;
            if p.next >= self.tiling.keys {
                return Err(self.payload_error(format!(
                    "the HEVC decoder gave more than {} pictures",
                    self.tiling.keys
                )));
            }
            if slots[p.next].get().is_none() {
                let _ = slots[p.next].set(self.untile(&picture));
            }
            p.next += 1;
        }
        if p.next == self.tiling.keys {
            p.stream = None; // every key is out: free the decoder
        }
        Ok(())
    }

    /// Fill `slots` up to key `last` (at least) by decoding a prefix, or the whole stream.
    fn fill_from_prefix(
        &self,
        p: &mut Progress,
        last: usize,
        slots: &[OnceLock<Vec<f32>>],
    ) -> Result<()> {
        let end = if p.prefix_done {
            self.packets.len()
        } else {
            last + 1
        };
        p.prefix_done = true;
        let refs: Vec<&[u8]> = self.packets[..end].iter().map(|v| v.as_slice()).collect();
        let pictures = key_pictures(self.hevc.as_ref(), &refs, &self.tiling, end, self.at)?;
        for (slot, picture) in slots.iter().zip(&pictures) {
            if slot.get().is_none() {
                let _ = slot.set(self.untile(picture));
            }
        }
        Ok(())
    }
}

impl KeySource for LowDelayKeys {
    /// Key `k` alone (decoding its prefix); [`Self::fill`] is what the features use.
    fn key(&self, k: usize) -> Result<Vec<f32>> {
        let refs: Vec<&[u8]> = self.packets[..=k].iter().map(|v| v.as_slice()).collect();
        let pictures = key_pictures(self.hevc.as_ref(), &refs, &self.tiling, k + 1, self.at)?;
        Ok(self.untile(&pictures[k]))
    }

    fn fill(&self, needed: &[usize], slots: &[OnceLock<Vec<f32>>]) -> Result<()> {
        let Some(&last) = needed.iter().max() else {
            return Ok(());
        };
        // Poisoned only by a panic (a bug) in an earlier fill: carry on from its state.
        let mut p = self.progress.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(e) = &p.failed {
            return Err(e.clone());
        }
        if needed.iter().all(|&k| slots[k].get().is_some()) {
            return Ok(()); // another thread filled them while this one waited
        }
        let t = &self.tiling;
        let hevc = self.hevc.as_ref().ok_or(Error::NoHevcDecoder)?;
        if p.next == 0 && p.stream.is_none() && !p.prefix_done {
            p.stream = hevc.stream(t.width() as u32, t.height() as u32, t.keys);
        }
        let filled = if p.stream.is_some() || p.next > 0 {
            self.fill_streamed(&mut p, last, slots)
        } else {
            self.fill_from_prefix(&mut p, last, slots)
        };
        if let Err(e) = &filled {
            p.failed = Some(e.clone());
            p.stream = None;
        }
        filled
    }
}

/// Whether `packets` hold at least one sequence parameter set and every one of them declares
/// `sps_max_num_reorder_pics` 0 for every sub-layer (H.265 §7.3.2.2): then decode order is
/// output order. Unreadable parameter sets count as "no".
pub fn pictures_in_decode_order(packets: &[Vec<u8>]) -> bool {
    let mut seen = false;
    for nal in packets.iter().flat_map(|p| nal_units(p)) {
        // NAL unit header: forbidden bit, 6-bit type, 6-bit layer id, 3-bit temporal id.
        if nal.len() < 2 || (nal[0] >> 1) & 0x3f != 33 {
            continue;
        }
        match sps_max_reorder(&unescape(&nal[2..])) {
            Some(0) => seen = true,
            _ => return false,
        }
    }
    seen
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

/// The largest `sps_max_num_reorder_pics` a sequence parameter set's RBSP declares.
fn sps_max_reorder(rbsp: &[u8]) -> Option<u32> {
    let mut b = Bits { bytes: rbsp, at: 0 };
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
    b.ue()?; // sps_seq_parameter_set_id
    if b.ue()? == 3 {
        b.skip(1)?; // separate_colour_plane_flag
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
    b.ue()?; // log2_max_pic_order_cnt_lsb_minus4
    let first = if b.u(1)? == 1 { 0 } else { sub_layers };
    let mut reorder = 0;
    for _ in first..=sub_layers {
        b.ue()?; // sps_max_dec_pic_buffering_minus1
        reorder = reorder.max(b.ue()?); // sps_max_num_reorder_pics
        b.ue()?; // sps_max_latency_increase_plus1
    }
    Some(reorder)
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

    /// Truncated or garbage parameter sets are "not low delay", never a panic.
    #[test]
    fn unreadable_parameter_sets_are_not_low_delay() {
        assert!(!pictures_in_decode_order(&[]));
        assert!(!pictures_in_decode_order(&[vec![0, 0, 1, 0x42, 1]]));
        assert!(!pictures_in_decode_order(&[vec![0, 0, 1, 0x42, 1, 0xff]]));
        let zeros = [vec![0, 0, 1, 0x42, 1], vec![0; 40]].concat();
        assert!(!pictures_in_decode_order(&[zeros]));
    }

    /// x265's own streams: B-frames (its default structure) reorder; low-delay and intra-only
    /// streams do not.
    #[cfg(feature = "hevc")]
    #[test]
    fn x265_streams_say_whether_they_reorder() {
        use dlgs_video::{encode_gray12, Gray12, HevcSettings, LowDelay};
        let (w, h) = (64u32, 64u32);
        let frames = (0..7)
            .map(|f| {
                (0..w * h)
                    .map(|i| ((i * 7 + f * 131 + (i / w) * f) % 4096) as u16)
                    .collect()
            })
            .collect();
        let video = Gray12 {
            width: w,
            height: h,
            frames,
        };
        let with = |low_delay, intra_only| HevcSettings {
            preset: "ultrafast".into(),
            low_delay,
            intra_only,
            ..Default::default()
        };
        let b_frames = encode_gray12(&video, &with(LowDelay::Off, false)).unwrap();
        assert!(!pictures_in_decode_order(&b_frames));
        let low = encode_gray12(&video, &with(LowDelay::EveryGop, false)).unwrap();
        assert!(pictures_in_decode_order(&low));
        let intra = encode_gray12(&video, &with(LowDelay::Off, true)).unwrap();
        assert!(pictures_in_decode_order(&intra));
    }
}
