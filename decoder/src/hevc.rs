//! The seam between deformation and the HEVC decoder of the time features (`TFEA` codecs 1-3).
//!
//! Time features are 12-bit monochrome HEVC pictures (format-spec §6.2). The decoder does not
//! care who decodes them: with the default cargo feature `hevc` it is FFmpeg (crate
//! `dlgs-video`, GPL because of libx265 in Debian's FFmpeg build); without it, nothing links
//! FFmpeg and a player plugs in its own decoder (an LGPL FFmpeg, a hardware decoder, ...) with
//! [`crate::Decoder::set_key_picture_decoder`]. Files with exact time features (`TFEA` codec 0)
//! and still files need no HEVC decoder at all.

use std::sync::Arc;

pub use crate::hevc_headers::display_order;

/// Decodes HEVC Main 12 4:0:0 access units into 12-bit gray pictures.
///
/// HEVC decoding is exactly specified, so every conforming decoder gives the same samples and
/// the decoded frames keep their bits whatever implementation is plugged in.
pub trait KeyPictureDecoder: Send + Sync {
    /// Decode `packets` (one access unit each, in decode order: the `TFEA` packets of one
    /// stream, or one intra packet) into exactly `expect` pictures of `width` x `height`
    /// samples (values 0..=4095, row-major, in output order).
    fn decode(
        &self,
        packets: &[&[u8]],
        width: u32,
        height: u32,
        expect: usize,
    ) -> Result<Vec<Vec<u16>>, String>;

    /// [`Self::decode`] for a decode that runs beside other work using the other cores (a
    /// GOP's first keys beside its canonical state): FFmpeg then decodes on the calling thread
    /// only, which leaves the cores to that work (on the 273k playback stream the first frame
    /// comes about 50 ms sooner). Default: [`Self::decode`].
    fn decode_beside(
        &self,
        packets: &[&[u8]],
        width: u32,
        height: u32,
        expect: usize,
    ) -> Result<Vec<Vec<u16>>, String> {
        self.decode(packets, width, height, expect)
    }

    /// A decoder that takes one stream's packets one at a time ([`KeyPictureStream`]), when
    /// this implementation has one: one-stream features then decode key by key, each picture
    /// once. Default: none (such streams decode from prefixes with [`Self::decode`]).
    fn stream(
        &self,
        _width: u32,
        _height: u32,
        _expect: usize,
    ) -> Option<Box<dyn KeyPictureStream>> {
        None
    }
}

/// One stream's decoder, fed packets in decode order.
pub trait KeyPictureStream: Send {
    /// Decode the next packet; the pictures it released, in output order.
    fn push(&mut self, packet: &[u8]) -> Result<Vec<Vec<u16>>, String>;
    /// The end of the stream: the pictures still held.
    fn finish(&mut self) -> Result<Vec<Vec<u16>>, String>;
}

/// The shared handle the decoder keeps.
pub type SharedKeyPictureDecoder = Arc<dyn KeyPictureDecoder>;

/// FFmpeg's HEVC decoder through `dlgs-video` (feature `hevc`, on by default; GPL).
#[cfg(feature = "hevc")]
#[derive(Debug, Clone, Copy, Default)]
pub struct Ffmpeg;

#[cfg(feature = "hevc")]
impl KeyPictureDecoder for Ffmpeg {
    fn decode(
        &self,
        packets: &[&[u8]],
        width: u32,
        height: u32,
        expect: usize,
    ) -> Result<Vec<Vec<u16>>, String> {
        dlgs_video::decode_gray12(packets, width, height, expect)
            .map(|v| v.frames)
            .map_err(|e| e.to_string())
    }

    fn decode_beside(
        &self,
        packets: &[&[u8]],
        width: u32,
        height: u32,
        expect: usize,
    ) -> Result<Vec<Vec<u16>>, String> {
        dlgs_video::decode_gray12_on(packets, width, height, expect, 1)
            .map(|v| v.frames)
            .map_err(|e| e.to_string())
    }

    fn stream(&self, width: u32, height: u32, expect: usize) -> Option<Box<dyn KeyPictureStream>> {
        // A decoder FFmpeg cannot set up now fails again, with its message, in `decode`.
        dlgs_video::Gray12Decoder::new(width, height, expect)
            .ok()
            .map(|d| Box::new(FfmpegStream(d)) as Box<dyn KeyPictureStream>)
    }
}

#[cfg(feature = "hevc")]
struct FfmpegStream(dlgs_video::Gray12Decoder);

#[cfg(feature = "hevc")]
impl KeyPictureStream for FfmpegStream {
    fn push(&mut self, packet: &[u8]) -> Result<Vec<Vec<u16>>, String> {
        self.0.push(packet).map_err(|e| e.to_string())
    }
    fn finish(&mut self) -> Result<Vec<Vec<u16>>, String> {
        self.0.finish().map_err(|e| e.to_string())
    }
}

/// The decoder a new [`crate::Decoder`] starts with: FFmpeg with the `hevc` feature, none
/// without it.
pub fn default_decoder() -> Option<SharedKeyPictureDecoder> {
    #[cfg(feature = "hevc")]
    return Some(Arc::new(Ffmpeg));
    #[cfg(not(feature = "hevc"))]
    None
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    #[allow(unused_imports)] // which of these a test uses depends on the `hevc` feature
    use dlgs::{Error, FormatErrorKind, Limits};

    use crate::{Decoder, FrameOptions};

    fn open(name: &str) -> Decoder<Cursor<Vec<u8>>> {
        let path = format!(
            "{}/../format-spec/vectors/valid/{name}.dlgs",
            env!("CARGO_MANIFEST_DIR")
        );
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
        Decoder::new(Cursor::new(bytes), Limits::default()).unwrap()
    }

    const OPTS: FrameOptions = FrameOptions {
        camera_center: [0.3, -0.2, -2.5],
        language: true,
    };

    /// With or without the `hevc` feature: exact time features and still files decode.
    #[test]
    fn exact_feature_and_still_files_decode_with_or_without_hevc() {
        let mut d = open("lod3-dynamic");
        let (a, b) = (
            d.frame_at(0.5, &OPTS).unwrap(),
            d.frame_at(2.0, &OPTS).unwrap(),
        );
        assert_eq!(a.dynamics.len(), 128);
        assert_ne!(a.dynamics.positions, b.dynamics.positions, "frames move");
        let mut s = open("lod3-csog-compact");
        assert_eq!(s.frame_at(0.0, &OPTS).unwrap().merged().len(), 1971);
    }

    /// A plugged-in decoder that gives too few pictures, pictures of the wrong size or samples
    /// above 12 bits makes the frame a `Payload` error of the `TFEA` chunk, not a panic.
    #[test]
    fn a_misbehaving_plugged_in_decoder_is_a_payload_error() {
        use std::sync::Arc;

        use super::KeyPictureDecoder;

        /// (pictures less than asked, samples less than the picture, sample value)
        struct Wrong(usize, usize, u16);
        impl KeyPictureDecoder for Wrong {
            fn decode(
                &self,
                _: &[&[u8]],
                w: u32,
                h: u32,
                n: usize,
            ) -> Result<Vec<Vec<u16>>, String> {
                let side = (w * h) as usize - self.1;
                Ok(vec![vec![self.2; side]; n - self.0])
            }
        }
        for wrong in [Wrong(1, 0, 0), Wrong(0, 1, 0), Wrong(0, 0, 5000)] {
            let mut d = open("lod3-dynamic-intra");
            d.set_key_picture_decoder(Arc::new(wrong));
            let e = d.frame_at(0.5, &OPTS).err().expect("refused");
            assert!(
                matches!(e.format_kind(), Some(FormatErrorKind::Payload { .. })),
                "{e}"
            );
        }
    }

    /// Without the feature, HEVC time features are a typed error naming what is missing.
    #[cfg(not(feature = "hevc"))]
    #[test]
    fn hevc_features_without_a_decoder_are_a_typed_error() {
        let mut d = open("lod3-dynamic-intra");
        let e = d.frame_at(0.5, &OPTS).err().expect("no HEVC decoder");
        assert_eq!(e, Error::NoHevcDecoder, "{e}");
        assert!(e.offset().is_none(), "the TFEA payload's offset");
    }

    /// A plugged-in decoder is the one used, and gives the same frames as FFmpeg.
    #[cfg(feature = "hevc")]
    #[test]
    fn a_plugged_in_decoder_is_used() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        use std::sync::Arc;

        use super::{Ffmpeg, KeyPictureDecoder};

        struct Counting(AtomicUsize);
        impl KeyPictureDecoder for Counting {
            fn decode(
                &self,
                p: &[&[u8]],
                w: u32,
                h: u32,
                n: usize,
            ) -> Result<Vec<Vec<u16>>, String> {
                self.0.fetch_add(1, Ordering::SeqCst);
                Ffmpeg.decode(p, w, h, n)
            }
        }
        let want = open("lod3-dynamic-intra").frame_at(1.2345, &OPTS).unwrap();
        let counting = Arc::new(Counting(AtomicUsize::new(0)));
        let mut d = open("lod3-dynamic-intra");
        d.set_key_picture_decoder(counting.clone());
        let got = d.frame_at(1.2345, &OPTS).unwrap();
        assert_eq!(got.dynamics.positions, want.dynamics.positions);
        let _ = Error::NoHevcDecoder; // the kind a build without the feature reports
    }
}
