//! `dlgs-video`: the only crate that talks to FFmpeg. It turns 12-bit gray images into raw HEVC
//! packets (Main 12, 4:0:0, libx265) and back.
//!
//! Linking this crate links FFmpeg and libx265, which are GPL: binaries that include it are
//! GPL-covered (see the README).

mod demux;

use std::sync::Once;

pub use demux::{demux_hevc, HevcTrack};

use ff::format::Pixel;
use ffmpeg_next as ff;

/// What went wrong inside FFmpeg, with FFmpeg's own message.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    #[error("FFmpeg has no {0} codec (install libavcodec with libx265 support)")]
    MissingCodec(&'static str),
    #[error("FFmpeg {stage}: {source}")]
    Ffmpeg {
        stage: &'static str,
        source: ff::Error,
    },
    #[error("{0}")]
    Invalid(String),
}

fn ff_err(stage: &'static str) -> impl Fn(ff::Error) -> VideoError {
    move |source| VideoError::Ffmpeg { stage, source }
}

/// x265 settings for one encode.
#[derive(Debug, Clone, PartialEq)]
pub struct HevcSettings {
    /// Constant rate factor, 0..=51 (the reference uses 6).
    pub crf: u8,
    /// x265 preset name (ultrafast .. placebo).
    pub preset: String,
    /// Mathematically lossless coding of the 12-bit samples (crf is ignored).
    pub lossless: bool,
    /// Every picture an IDR picture with its own VPS/SPS/PPS, one packet each, so any picture
    /// decodes alone (a seek decodes the 2 keys it needs instead of the GOP's 7).
    pub intra_only: bool,
    /// Which GOPs' streams start with their first key interval (see [`FastStart`]).
    pub fast_start: FastStart,
}

/// Streams whose second picture is forced to a P picture, coded right after the first: a GOP's
/// first key interval (keys 0 and 1) then decodes from its first 2 packets, so playback starts
/// after 2 of the GOP's 7 pictures; the rest keep x265's B-frames. The cost, on the real
/// 200-frame sequence, +0.1 % bytes (docs/benchmarks/dynamic.md "Fast start").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FastStart {
    /// x265's own picture types everywhere.
    Off,
    /// The first GOP only, where playback starts (the default).
    #[default]
    FirstGop,
    /// Every GOP.
    EveryGop,
}

impl HevcSettings {
    /// The settings of GOP `g`'s stream: `fast_start` resolved to on (`EveryGop`) or `Off`.
    pub fn for_gop(&self, g: u32) -> HevcSettings {
        let on = match self.fast_start {
            FastStart::Off => false,
            FastStart::FirstGop => g == 0,
            FastStart::EveryGop => true,
        };
        HevcSettings {
            fast_start: if on {
                FastStart::EveryGop
            } else {
                FastStart::Off
            },
            ..self.clone()
        }
    }
}

impl Default for HevcSettings {
    fn default() -> Self {
        HevcSettings {
            crf: 6,
            preset: "medium".into(),
            lossless: false,
            intra_only: false,
            fast_start: FastStart::default(),
        }
    }
}

pub const PRESETS: [&str; 10] = [
    "ultrafast",
    "superfast",
    "veryfast",
    "faster",
    "fast",
    "medium",
    "slow",
    "slower",
    "veryslow",
    "placebo",
];

/// A sequence of equally sized 12-bit gray images (values 0..=4095, row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct Gray12 {
    pub width: u32,
    pub height: u32,
    pub frames: Vec<Vec<u16>>,
}

fn init() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // Registration cannot fail in FFmpeg >= 4; codec chatter is silenced unless asked for.
        let _ = ff::init();
        let level = if std::env::var_os("DLGS_FFMPEG_LOG").is_some() {
            ff::util::log::Level::Info
        } else {
            ff::util::log::Level::Quiet
        };
        ff::util::log::set_level(level);
    });
}

/// Encode `video` as HEVC Main 12 monochrome; returns the packets in decode order, each a
/// self-contained Annex B access unit (the first carries VPS/SPS/PPS). Unless `s.fast_start`
/// is `Off` (resolve it per GOP with [`HevcSettings::for_gop`]), the second picture is a P
/// picture coded second.
pub fn encode_gray12(video: &Gray12, s: &HevcSettings) -> Result<Vec<Vec<u8>>, VideoError> {
    init();
    let (w, h) = (video.width, video.height);
    // HEVC with 4:0:0 needs even sizes only for chroma; x265 still wants multiples of 2.
    if w == 0 || h == 0 || w % 2 != 0 || h % 2 != 0 || w > 16384 || h > 16384 {
        return Err(VideoError::Invalid(format!(
            "image size {w}x{h}: need even sides in 2..=16384"
        )));
    }
    if s.crf > 51 || !PRESETS.contains(&s.preset.as_str()) {
        return Err(VideoError::Invalid(format!(
            "crf {} / preset {:?}: crf must be 0..=51 and preset one of {PRESETS:?}",
            s.crf, s.preset
        )));
    }
    let codec = ff::encoder::find_by_name("libx265").ok_or(VideoError::MissingCodec("libx265"))?;
    let ctx = ff::codec::context::Context::new_with_codec(codec);
    let mut enc = ctx.encoder().video().map_err(ff_err("encoder setup"))?;
    enc.set_width(w);
    enc.set_height(h);
    enc.set_format(Pixel::GRAY12LE);
    enc.set_time_base((1, 30));
    enc.set_frame_rate(Some((30, 1)));
    enc.set_color_range(ff::util::color::Range::JPEG);
    let mut opts = ff::Dictionary::new();
    opts.set("preset", &s.preset);
    let mut params = String::from("log-level=none");
    if s.lossless {
        params.push_str(":lossless=1");
    } else {
        opts.set("crf", &s.crf.to_string());
    }
    if s.intra_only {
        params.push_str(":keyint=1:min-keyint=1:open-gop=0:repeat-headers=1:bframes=0");
    }
    opts.set("x265-params", &params);
    let mut enc = enc.open_with(opts).map_err(ff_err("open libx265"))?;

    let mut packets = Vec::new();
    let mut frame = ff::frame::Video::new(Pixel::GRAY12LE, w, h);
    for (i, img) in video.frames.iter().enumerate() {
        if img.len() != (w * h) as usize {
            return Err(VideoError::Invalid(format!(
                "frame {i} has {} samples, expected {}",
                img.len(),
                w * h
            )));
        }
        let stride = frame.stride(0);
        let data = frame.data_mut(0);
        for (y, row) in img.chunks_exact(w as usize).enumerate() {
            let dst = &mut data[y * stride..y * stride + 2 * w as usize];
            for (d, &v) in dst.chunks_exact_mut(2).zip(row) {
                d.copy_from_slice(&v.min(4095).to_le_bytes());
            }
        }
        frame.set_pts(Some(i as i64));
        // libx265 takes a frame's picture type as a forced slice type.
        let fast = s.fast_start != FastStart::Off && !s.intra_only && i == 1;
        frame.set_kind(if fast {
            ff::picture::Type::P
        } else {
            ff::picture::Type::None
        });
        enc.send_frame(&frame).map_err(ff_err("encode"))?;
        drain_packets(&mut enc, &mut packets)?;
    }
    enc.send_eof().map_err(ff_err("encode flush"))?;
    drain_packets(&mut enc, &mut packets)?;
    if s.intra_only && packets.len() != video.frames.len() {
        return Err(VideoError::Invalid(format!(
            "intra-only coding gave {} packets for {} pictures",
            packets.len(),
            video.frames.len()
        )));
    }
    Ok(packets)
}

fn drain_packets(
    enc: &mut ff::encoder::video::Encoder,
    out: &mut Vec<Vec<u8>>,
) -> Result<(), VideoError> {
    let mut pkt = ff::Packet::empty();
    loop {
        match enc.receive_packet(&mut pkt) {
            Ok(()) => out.push(pkt.data().unwrap_or(&[]).to_vec()),
            Err(ff::Error::Other { errno }) if errno == ff::util::error::EAGAIN => return Ok(()),
            Err(ff::Error::Eof) => return Ok(()),
            Err(e) => return Err(ff_err("encode")(e)),
        }
    }
}

/// Decode packets produced by [`encode_gray12`] (or any HEVC Main 12 4:0:0 stream) into
/// `expect_frames` images of `width` x `height`. Anything else is an error, never a panic.
pub fn decode_gray12(
    packets: &[&[u8]],
    width: u32,
    height: u32,
    expect_frames: usize,
) -> Result<Gray12, VideoError> {
    decode_gray12_on(packets, width, height, expect_frames, 0)
}

/// [`decode_gray12`] with FFmpeg's thread count: 0 = automatic (wavefront threads), 1 = the
/// calling thread only (for a decode that runs beside other work on the other cores).
pub fn decode_gray12_on(
    packets: &[&[u8]],
    width: u32,
    height: u32,
    expect_frames: usize,
    threads: usize,
) -> Result<Gray12, VideoError> {
    let mut dec = Gray12Decoder::with_threads(width, height, expect_frames, threads)?;
    let mut frames = Vec::with_capacity(expect_frames.min(4096));
    for p in packets {
        frames.extend(dec.push(p)?);
    }
    frames.extend(dec.finish()?);
    if frames.len() != expect_frames {
        return Err(VideoError::Invalid(format!(
            "HEVC stream gave {} frames, expected {expect_frames}",
            frames.len()
        )));
    }
    Ok(Gray12 {
        width,
        height,
        frames,
    })
}

/// An HEVC Main 12 4:0:0 decoder fed one packet at a time: each call returns the pictures it
/// released, in output order (a stream with B-frames holds pictures back until the reordering
/// allows them out).
pub struct Gray12Decoder {
    dec: ff::decoder::Video,
    width: u32,
    height: u32,
    max_frames: usize,
    /// Pictures returned so far.
    given: usize,
}

impl Gray12Decoder {
    /// A decoder of pictures of `width` x `height`; more than `max_frames` pictures is an error.
    pub fn new(width: u32, height: u32, max_frames: usize) -> Result<Self, VideoError> {
        Self::with_threads(width, height, max_frames, 0)
    }

    /// [`Self::new`] with FFmpeg's thread count (0 = automatic).
    fn with_threads(
        width: u32,
        height: u32,
        max_frames: usize,
        threads: usize,
    ) -> Result<Self, VideoError> {
        init();
        let codec =
            ff::decoder::find(ff::codec::Id::HEVC).ok_or(VideoError::MissingCodec("HEVC"))?;
        let ctx = ff::codec::context::Context::new_with_codec(codec);
        // Bound what a hostile bitstream can make FFmpeg allocate: pictures much larger than
        // the declared size are refused inside FFmpeg (AVCodecContext.max_pixels). The margin
        // covers the coding-block padding FFmpeg adds before that check.
        let mut opts = ff::Dictionary::new();
        let max_pixels = (width as u64 + 128) * (height as u64 + 128);
        opts.set("max_pixels", &max_pixels.to_string());
        // Wavefront threads (x265 writes WPP streams) unless asked otherwise; HEVC decoding is
        // bit-exact, so the thread count cannot change the features.
        let threads = if threads == 0 {
            "auto".to_string()
        } else {
            threads.to_string()
        };
        opts.set("threads", &threads);
        // Slice (wavefront) threads only: FFmpeg 5.1's HEVC frame threads crashed (SIGSEGV in
        // `avcodec_send_packet`, a race) on damaged streams within a minute of the
        // `dynamic_payloads` fuzz target; with slice threads 2.7 M runs found nothing. x265's
        // streams use wavefront rows, so the decode stays parallel (docs/benchmarks/fuzz.md).
        opts.set("thread_type", "slice");
        let dec = ctx
            .decoder()
            .open_as_with(codec, opts)
            .and_then(|o| o.video())
            .map_err(ff_err("decoder setup"))?;
        Ok(Gray12Decoder {
            dec,
            width,
            height,
            max_frames,
            given: 0,
        })
    }

    /// Decode one packet (empty packets are skipped); the pictures it released.
    pub fn push(&mut self, packet: &[u8]) -> Result<Vec<Vec<u16>>, VideoError> {
        if packet.is_empty() {
            return Ok(Vec::new());
        }
        let pkt = ff::Packet::copy(packet);
        self.dec.send_packet(&pkt).map_err(ff_err("decode"))?;
        self.drain()
    }

    /// End of the stream: the pictures still held.
    pub fn finish(&mut self) -> Result<Vec<Vec<u16>>, VideoError> {
        self.dec.send_eof().map_err(ff_err("decode flush"))?;
        self.drain()
    }

    fn drain(&mut self) -> Result<Vec<Vec<u16>>, VideoError> {
        let mut out = Vec::new();
        let mut frame = ff::frame::Video::empty();
        loop {
            match self.dec.receive_frame(&mut frame) {
                Ok(()) => {
                    if frame.format() != Pixel::GRAY12LE
                        || frame.width() != self.width
                        || frame.height() != self.height
                    {
                        return Err(VideoError::Invalid(format!(
                            "HEVC frame is {:?} {}x{}, expected GRAY12LE {}x{}",
                            frame.format(),
                            frame.width(),
                            frame.height(),
                            self.width,
                            self.height
                        )));
                    }
                    if self.given >= self.max_frames {
                        return Err(VideoError::Invalid(format!(
                            "HEVC stream has more than {} frames",
                            self.max_frames
                        )));
                    }
                    let (w, h) = (self.width as usize, self.height as usize);
                    let stride = frame.stride(0);
                    let data = frame.data(0);
                    let mut img = Vec::with_capacity(w * h);
                    for y in 0..h {
                        let row = &data[y * stride..y * stride + 2 * w];
                        img.extend(
                            row.chunks_exact(2)
                                .map(|b| u16::from_le_bytes([b[0], b[1]]).min(4095)),
                        );
                    }
                    self.given += 1;
                    out.push(img);
                }
                Err(ff::Error::Other { errno }) if errno == ff::util::error::EAGAIN => {
                    return Ok(out)
                }
                Err(ff::Error::Eof) => return Ok(out),
                Err(e) => return Err(ff_err("decode")(e)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32, n: usize) -> Gray12 {
        let frames = (0..n)
            .map(|k| {
                (0..w * h)
                    .map(|i| {
                        let (x, y) = (i % w, i / w);
                        ((x * 13 + y * 7 + k as u32 * 50) % 4096) as u16
                    })
                    .collect()
            })
            .collect();
        Gray12 {
            width: w,
            height: h,
            frames,
        }
    }

    /// Encode losslessly (ultrafast) and decode again.
    fn lossless_round_trip(v: &Gray12) -> Gray12 {
        let s = HevcSettings {
            lossless: true,
            preset: "ultrafast".into(),
            ..Default::default()
        };
        let pk = encode_gray12(v, &s).unwrap();
        let refs: Vec<&[u8]> = pk.iter().map(|p| p.as_slice()).collect();
        decode_gray12(&refs, v.width, v.height, v.frames.len()).unwrap()
    }

    #[test]
    fn lossless_round_trip_is_exact() {
        let v = ramp(64, 48, 7);
        assert_eq!(lossless_round_trip(&v), v);
    }

    #[test]
    fn tile_sizes_the_encoder_produces_decode() {
        // Sides 4 x side for side = 16 (minimum), 46, 185, 283 (80k Gaussians).
        for side in [16u32, 46, 185, 283] {
            let v = ramp(4 * side, 4 * side, 2);
            assert_eq!(lossless_round_trip(&v), v, "side {side}");
        }
    }

    #[test]
    fn lossy_round_trip_is_close() {
        let v = ramp(64, 64, 7);
        let pk = encode_gray12(&v, &HevcSettings::default()).unwrap();
        let refs: Vec<&[u8]> = pk.iter().map(|p| p.as_slice()).collect();
        let d = decode_gray12(&refs, 64, 64, 7).unwrap();
        let max = v
            .frames
            .iter()
            .flatten()
            .zip(d.frames.iter().flatten())
            .map(|(a, b)| (*a as i32 - *b as i32).abs())
            .max()
            .unwrap();
        assert!(max < 400, "max error {max}");
    }

    #[test]
    fn intra_only_pictures_decode_alone_as_in_the_whole_stream() {
        let v = ramp(64, 48, 7);
        let s = HevcSettings {
            intra_only: true,
            ..Default::default()
        };
        let pk = encode_gray12(&v, &s).unwrap();
        assert_eq!(pk.len(), 7, "one packet per picture");
        let refs: Vec<&[u8]> = pk.iter().map(|p| p.as_slice()).collect();
        let all = decode_gray12(&refs, 64, 48, 7).unwrap();
        for (k, p) in pk.iter().enumerate().rev() {
            let one = decode_gray12(&[p.as_slice()], 64, 48, 1).unwrap();
            assert_eq!(one.frames[0], all.frames[k], "picture {k}");
        }
        // Two pictures out of order of the stream, as a seek between keys 4 and 5 needs.
        let pair = decode_gray12(&[pk[4].as_slice(), pk[5].as_slice()], 64, 48, 2).unwrap();
        assert_eq!(pair.frames, all.frames[4..6]);
    }

    #[test]
    fn garbage_is_an_error_not_a_crash() {
        let junk: Vec<u8> = (0..5000u32)
            .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
            .collect();
        assert!(decode_gray12(&[&junk], 64, 64, 7).is_err());
        assert!(decode_gray12(&[], 64, 64, 7).is_err());
    }
}
