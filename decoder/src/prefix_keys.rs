//! One-stream HEVC time features (`TFEA` codecs 1 and 2) decoded as far as the keys asked for:
//! the slice headers say in which order the pictures come out ([`display_order`]), so a
//! request for some keys decodes only the packets up to the last of their pictures. A GOP's
//! first key interval is its first 2 packets when the encoder forced its second picture to P
//! (`HevcSettings::fast_start`, the default for GOP 0): playback starts after 2 pictures of 7.
//!
//! The first request decodes that prefix alone; later ones go on with a decoder fed one packet
//! at a time ([`KeyPictureStream`], FFmpeg's), from the first packet (the prefix is decoded
//! twice, the rest once), filling each key as its picture comes out, so a player's next key
//! interval waits only for its own picture. A plugged-in decoder without one decodes the
//! whole stream on the second request. Streams whose headers cannot be read decode whole, as
//! before. HEVC decoding is exact, so a prefix's pictures are the samples the whole stream
//! gives.

use std::collections::VecDeque;
use std::sync::{Mutex, OnceLock};

use dlgs::chunks::tfea::{self, Tiling};
use dlgs::container::ChunkType;
use dlgs::{Error, Result};

use crate::build::{check_pictures, key_pictures};
use crate::hevc::{KeyPictureStream, SharedKeyPictureDecoder};
use crate::hevc_headers::display_order;
use crate::planar::KeySource;

/// How samples become feature values: codec 1's per-channel ranges, or codec 2's one range.
pub(crate) enum Dequantise {
    Ranges(Vec<(f32, f32)>),
    Reference((f64, f64)),
}

impl Dequantise {
    /// One key's `(C, N)` block from its picture, on the calling thread.
    pub fn untile_key(&self, picture: &[u16], tiling: &Tiling) -> Vec<f32> {
        let one = Tiling { keys: 1, ..*tiling };
        match self {
            Dequantise::Ranges(r) => tfea::untile_key(picture, &one, tfea::sample_value(r)),
            Dequantise::Reference(r) => {
                tfea::untile_key(picture, &one, tfea::reference_sample_value(*r))
            }
        }
    }
}

/// The keys of a one-stream `TFEA` whose output order is known.
pub(crate) struct PrefixKeys {
    tiling: Tiling,
    dequantise: Dequantise,
    /// One access unit per key picture, in decode order.
    packets: Vec<Vec<u8>>,
    /// `position[k]`: the packet of key `k`'s picture.
    position: Vec<usize>,
    /// Offset of the `TFEA` payload, for errors.
    at: u64,
    hevc: Option<SharedKeyPictureDecoder>,
    /// Where decoding has got to. Held while a picture is decoded and its slot filled, never
    /// while waiting on other threads' work (so a rayon thread holding it cannot deadlock).
    progress: Mutex<Progress>,
}

#[derive(Default)]
struct Progress {
    /// A prefix has been decoded on its own (the next request streams, or decodes whole).
    prefix_done: bool,
    /// The decoder fed one packet at a time, once started (dropped after the last picture).
    stream: Option<Box<dyn KeyPictureStream>>,
    streaming: bool,
    /// Packets fed to `stream`, and whether its end has been signalled.
    sent: usize,
    ended: bool,
    /// Pictures released but not yet untiled, and the key of the next one (output order).
    pending: VecDeque<Vec<u16>>,
    next: usize,
    /// The first failure, given again to every later request.
    failed: Option<Error>,
}

impl PrefixKeys {
    /// Hands `packets` back unless there is one per key and their output order can be read.
    pub fn new(
        tiling: Tiling,
        dequantise: Dequantise,
        packets: Vec<Vec<u8>>,
        at: u64,
        hevc: Option<SharedKeyPictureDecoder>,
    ) -> std::result::Result<Self, Vec<Vec<u8>>> {
        let Some(display) = (packets.len() == tiling.keys)
            .then(|| display_order(&packets))
            .flatten()
        else {
            return Err(packets);
        };
        let mut position = vec![0; display.len()];
        for (i, &d) in display.iter().enumerate() {
            position[d] = i;
        }
        Ok(PrefixKeys {
            tiling,
            dequantise,
            packets,
            position,
            at,
            hevc,
            progress: Mutex::new(Progress::default()),
        })
    }

    fn untile(&self, picture: &[u16]) -> Vec<f32> {
        self.dequantise.untile_key(picture, &self.tiling)
    }

    fn payload_error(&self, reason: String) -> Error {
        Error::payload(ChunkType::TFEA, reason, self.at)
    }

    /// Decode the first `m` packets on their own (any decoder): the pictures they hold, in
    /// output order, fill their keys' slots. A prefix of at most half the stream is decoded on
    /// one thread: it is a first request, which runs beside the GOP's state decode (a longer one
    /// gains more from FFmpeg's threads than the state loses to them: cold seeks on the 273k
    /// parallel-mode file, docs/benchmarks/residuals-seek.md).
    fn fill_from_prefix(&self, m: usize, slots: &[OnceLock<Vec<f32>>]) -> Result<()> {
        let refs: Vec<&[u8]> = self.packets[..m].iter().map(|v| v.as_slice()).collect();
        let beside = 2 * m <= self.packets.len();
        let pictures = key_pictures(self.hevc.as_ref(), &refs, &self.tiling, m, self.at, beside)?;
        // The prefix's pictures come out in key order.
        let keys = (0..self.tiling.keys).filter(|&k| self.position[k] < m);
        for (k, picture) in keys.zip(&pictures) {
            if slots[k].get().is_none() {
                let _ = slots[k].set(self.untile(picture));
            }
        }
        Ok(())
    }

    /// The next picture in output order from the packet-at-a-time decoder.
    fn next_picture(&self, p: &mut Progress) -> Result<Vec<u16>> {
        let t = &self.tiling;
        while p.pending.is_empty() {
            let stream = p.stream.as_mut().expect("streaming");
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

    /// Stream pictures (in output order, each key's slot filled unless it already is) until
    /// every key of `needed` is filled.
    fn fill_streamed(
        &self,
        p: &mut Progress,
        needed: &[usize],
        slots: &[OnceLock<Vec<f32>>],
    ) -> Result<()> {
        while needed.iter().any(|&k| slots[k].get().is_none()) {
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

    fn fill_locked(
        &self,
        p: &mut Progress,
        needed: &[usize],
        slots: &[OnceLock<Vec<f32>>],
    ) -> Result<()> {
        let t = &self.tiling;
        let m = 1 + needed.iter().map(|&k| self.position[k]).max().unwrap_or(0);
        if !p.streaming {
            // The first request, when it needs fewer than all packets: that prefix alone (even
            // for a stream in output order: a prefix decoded on its own leaves the cores to the
            // state decode beside it).
            if !p.prefix_done && m < self.packets.len() {
                p.prefix_done = true;
                return self.fill_from_prefix(m, slots);
            }
            let hevc = self.hevc.as_ref().ok_or(Error::NoHevcDecoder)?;
            p.stream = hevc.stream(t.width() as u32, t.height() as u32, t.keys);
            if p.stream.is_none() {
                // No packet-at-a-time decoder: a prefix the first time, then the whole stream.
                let m = if p.prefix_done { self.packets.len() } else { m };
                p.prefix_done = true;
                return self.fill_from_prefix(m, slots);
            }
            p.streaming = true;
        }
        self.fill_streamed(p, needed, slots)
    }
}

impl KeySource for PrefixKeys {
    /// Key `k` alone (decoding the prefix up to its picture); the features use [`Self::fill`].
    fn key(&self, k: usize) -> Result<Vec<f32>> {
        let m = self.position[k] + 1;
        let refs: Vec<&[u8]> = self.packets[..m].iter().map(|v| v.as_slice()).collect();
        let pictures = key_pictures(self.hevc.as_ref(), &refs, &self.tiling, m, self.at, true)?;
        let rank = (0..self.tiling.keys)
            .filter(|&j| j < k && self.position[j] < m)
            .count();
        Ok(self.untile(&pictures[rank]))
    }

    fn fill(&self, needed: &[usize], slots: &[OnceLock<Vec<f32>>]) -> Result<()> {
        // Poisoned only by a panic (a bug) in an earlier fill: carry on from its state.
        let mut p = self.progress.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(e) = &p.failed {
            return Err(e.clone());
        }
        if needed.iter().all(|&k| slots[k].get().is_some()) {
            return Ok(()); // another thread filled them while this one waited
        }
        let filled = self.fill_locked(&mut p, needed, slots);
        if let Err(e) = &filled {
            p.failed = Some(e.clone());
            p.stream = None;
        }
        filled
    }
}
