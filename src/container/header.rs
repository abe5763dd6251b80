//! File signature (§2) and the scene header chunk `HEAD` (§4).

use serde::Serialize;

use crate::bytes::{ByteReader, PutLe};
use crate::error::{Error, FormatErrorKind, Result};
use crate::limits::Limits;

/// The 8 magic bytes that open every `.dlgs` file.
pub const MAGIC: [u8; 8] = [0x89, b'D', b'L', b'G', b'S', b'\r', b'\n', 0x1a];
pub const VERSION_MAJOR: u16 = 1;
pub const VERSION_MINOR: u16 = 19;
/// Magic + major + minor.
pub const SIGNATURE_LEN: u64 = 12;
/// Length of a v1.0 `HEAD` payload. Longer payloads are accepted (fields are only appended).
pub const HEAD_LEN_V1: usize = 64;

pub fn encode_signature() -> [u8; 12] {
    let mut s = [0u8; 12];
    s[0..8].copy_from_slice(&MAGIC);
    s[8..10].copy_from_slice(&VERSION_MAJOR.to_le_bytes());
    s[10..12].copy_from_slice(&VERSION_MINOR.to_le_bytes());
    s
}

/// Check the 12-byte signature. Returns (major, minor).
pub fn decode_signature(s: &[u8]) -> Result<(u16, u16)> {
    if s.len() < 8 || s[0..8] != MAGIC {
        return Err(Error::format(FormatErrorKind::BadMagic, 0));
    }
    let mut r = ByteReader::new(&s[8..], 8);
    let major = r.u16("version major")?;
    let minor = r.u16("version minor")?;
    if major != VERSION_MAJOR {
        return Err(Error::format(
            FormatErrorKind::UnsupportedVersion { major, minor },
            8,
        ));
    }
    Ok((major, minor))
}

/// Which primitive family the canonical GOPs hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Variant {
    /// Plain 3D Gaussians (the reference's "fdsd"/SOG variant).
    Gaussians3d = 0,
    /// Scaffold-GS anchors (the reference's HAC variant).
    Scaffold = 1,
}

/// How GOP g >= 1 is reconstructed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum ResidualMode {
    /// Every GOP carries its own canonical Gaussians.
    #[default]
    Intra = 0,
    /// GOP g = GOP g-1 + residual g.
    Sequential = 1,
    /// GOP g = GOP 0 + residual g.
    Parallel = 2,
}

/// How interpolated time features become attribute offsets (format-spec §6.4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum DeformModel {
    /// The reference code: Hermite position with predicted tangents, slerp rotation.
    Reference = 0,
    /// The paper's plain form: lerp of time features, offsets added.
    PaperLerp = 1,
}

/// Everything a reader must know before the first GOP.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SceneHeader {
    pub variant: Variant,
    pub residual_mode: ResidualMode,
    pub deform_model: DeformModel,
    /// SH degree 0..=3 of the colour.
    pub sh_degree: u8,
    /// Language feature levels (0 = no language). DLGStream: 3.
    pub lang_levels: u8,
    /// Dimensions per level. DLGStream: 3.
    pub lang_dims: u8,
    /// Channels of a time feature (0 = no dynamic Gaussians). DLGStream: 16.
    pub time_channels: u8,
    pub fps_num: u32,
    pub fps_den: u32,
    /// Frames per GOP.
    pub gop_length: u32,
    /// Frames between key time features.
    pub key_interval: u32,
    pub gop_count: u32,
    /// Total frames in the stream.
    pub frame_count: u32,
    /// Static primitives per GOP (constant over GOPs).
    pub n_static: u32,
    /// Dynamic primitives per GOP (constant over GOPs).
    pub n_dynamic: u32,
    /// Sequential mode only (since 1.17): every GOP `g` with `g % refresh_interval == 0`
    /// carries its full canonical state (no reference GOP), so a cold seek walks at most
    /// `refresh_interval - 1` residual steps. 0 = no refresh (only GOP 0 is intra).
    pub refresh_interval: u32,
}

impl SceneHeader {
    /// A single static frame: one GOP of one frame, no dynamics, no language.
    pub fn still(n_static: u32, sh_degree: u8) -> Self {
        SceneHeader {
            variant: Variant::Gaussians3d,
            residual_mode: ResidualMode::Intra,
            deform_model: DeformModel::Reference,
            sh_degree,
            lang_levels: 0,
            lang_dims: 0,
            time_channels: 0,
            fps_num: 30,
            fps_den: 1,
            gop_length: 1,
            key_interval: 1,
            gop_count: 1,
            frame_count: 1,
            n_static,
            n_dynamic: 0,
            refresh_interval: 0,
        }
    }

    /// Language feature width (levels x dims).
    pub fn lang_width(&self) -> usize {
        self.lang_levels as usize * self.lang_dims as usize
    }
    /// Key time features per GOP: gop_length / key_interval + 1.
    pub fn keys_per_gop(&self) -> u32 {
        self.gop_length / self.key_interval + 1
    }
    pub fn fps(&self) -> f64 {
        self.fps_num as f64 / self.fps_den as f64
    }
    pub fn duration_seconds(&self) -> f64 {
        self.frame_count as f64 / self.fps()
    }
    /// Frames in GOP `g` (the last GOP may be shorter).
    pub fn frames_in_gop(&self, g: u32) -> u32 {
        let start = g as u64 * self.gop_length as u64;
        (self.frame_count as u64)
            .saturating_sub(start)
            .min(self.gop_length as u64) as u32
    }

    pub fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(HEAD_LEN_V1);
        b.put_u8(self.variant as u8);
        b.put_u8(self.residual_mode as u8);
        b.put_u8(self.sh_degree);
        b.put_u8(self.lang_levels);
        b.put_u8(self.lang_dims);
        b.put_u8(self.time_channels);
        b.put_u8(self.deform_model as u8);
        b.put_u8(0);
        for v in [
            self.fps_num,
            self.fps_den,
            self.gop_length,
            self.key_interval,
            self.gop_count,
            self.frame_count,
            self.n_static,
            self.n_dynamic,
        ] {
            b.put_u32(v);
        }
        b.put_u32(self.refresh_interval);
        b.resize(HEAD_LEN_V1, 0);
        b
    }

    /// Parse a `HEAD` payload whose first byte is at absolute `offset`, and validate every field.
    pub fn decode(p: &[u8], offset: u64, limits: &Limits) -> Result<Self> {
        let mut r = ByteReader::new(p, offset);
        if p.len() < HEAD_LEN_V1 {
            return Err(r.err(FormatErrorKind::Truncated {
                what: "HEAD payload",
                needed: HEAD_LEN_V1 as u64,
                available: p.len() as u64,
            }));
        }
        let bad = |field: &'static str, value: u64, reason: &'static str, at: u64| {
            Error::format(
                FormatErrorKind::InvalidField {
                    field,
                    value,
                    reason,
                },
                at,
            )
        };
        let at = r.offset();
        let variant = match r.u8("variant")? {
            0 => Variant::Gaussians3d,
            1 => Variant::Scaffold,
            v => {
                return Err(bad(
                    "variant",
                    v as u64,
                    "must be 0 (3DGS) or 1 (Scaffold-GS)",
                    at,
                ))
            }
        };
        let at = r.offset();
        let residual_mode = match r.u8("residual_mode")? {
            0 => ResidualMode::Intra,
            1 => ResidualMode::Sequential,
            2 => ResidualMode::Parallel,
            v => return Err(bad("residual_mode", v as u64, "must be 0, 1 or 2", at)),
        };
        let at = r.offset();
        let sh_degree = r.u8("sh_degree")?;
        if sh_degree > 3 {
            return Err(bad("sh_degree", sh_degree as u64, "must be 0..=3", at));
        }
        let at = r.offset();
        let lang_levels = r.u8("lang_levels")?;
        let lang_dims = r.u8("lang_dims")?;
        if lang_levels > 8 || lang_dims > 16 || ((lang_levels == 0) != (lang_dims == 0)) {
            return Err(bad(
                "lang_levels/lang_dims",
                ((lang_levels as u64) << 8) | lang_dims as u64,
                "levels 0..=8, dims 0..=16, both zero or both non-zero",
                at,
            ));
        }
        let at = r.offset();
        let time_channels = r.u8("time_channels")?;
        if time_channels > 64 {
            return Err(bad(
                "time_channels",
                time_channels as u64,
                "must be 0..=64",
                at,
            ));
        }
        let at = r.offset();
        let deform_model = match r.u8("deform_model")? {
            0 => DeformModel::Reference,
            1 => DeformModel::PaperLerp,
            v => return Err(bad("deform_model", v as u64, "must be 0 or 1", at)),
        };
        let _reserved = r.u8("reserved")?;
        let mut next = |name: &'static str| -> Result<(u32, u64)> {
            let at = r.offset();
            Ok((r.u32(name)?, at))
        };
        let (fps_num, a_num) = next("fps_num")?;
        let (fps_den, a_den) = next("fps_den")?;
        let (gop_length, a_gl) = next("gop_length")?;
        let (key_interval, a_ki) = next("key_interval")?;
        let (gop_count, a_gc) = next("gop_count")?;
        let (frame_count, a_fc) = next("frame_count")?;
        let (n_static, a_ns) = next("n_static")?;
        let (n_dynamic, a_nd) = next("n_dynamic")?;
        let (refresh_interval, a_ri) = next("refresh_interval")?;
        if fps_num == 0 {
            return Err(bad("fps_num", 0, "must be > 0", a_num));
        }
        if fps_den == 0 {
            return Err(bad("fps_den", 0, "must be > 0", a_den));
        }
        if gop_length == 0 || gop_length > 65536 {
            return Err(bad(
                "gop_length",
                gop_length as u64,
                "must be 1..=65536",
                a_gl,
            ));
        }
        if key_interval == 0 || key_interval > gop_length || gop_length % key_interval != 0 {
            return Err(bad(
                "key_interval",
                key_interval as u64,
                "must divide gop_length",
                a_ki,
            ));
        }
        if gop_count == 0 {
            return Err(bad("gop_count", 0, "must be > 0", a_gc));
        }
        if gop_count > limits.max_gops {
            return Err(Error::limit(
                "gop_count",
                gop_count as u64,
                limits.max_gops as u64,
                a_gc,
            ));
        }
        let lo = (gop_count as u64 - 1) * gop_length as u64;
        let hi = gop_count as u64 * gop_length as u64;
        if (frame_count as u64) <= lo || (frame_count as u64) > hi {
            return Err(bad(
                "frame_count",
                frame_count as u64,
                "must lie in ((gop_count-1)*gop_length, gop_count*gop_length]",
                a_fc,
            ));
        }
        let total = n_static as u64 + n_dynamic as u64;
        if total > limits.max_gaussians {
            return Err(Error::limit(
                "n_static + n_dynamic",
                total,
                limits.max_gaussians,
                a_ns,
            ));
        }
        if (n_dynamic > 0) != (time_channels > 0) {
            return Err(bad(
                "n_dynamic",
                n_dynamic as u64,
                "dynamic primitives need time_channels > 0 and vice versa",
                a_nd,
            ));
        }
        if refresh_interval == 1 {
            return Err(bad(
                "refresh_interval",
                1,
                "must be 0 (no refresh) or at least 2 (use residual_mode 0 for all-intra)",
                a_ri,
            ));
        }
        if refresh_interval != 0 && residual_mode != ResidualMode::Sequential {
            return Err(bad(
                "refresh_interval",
                refresh_interval as u64,
                "only sequential scenes (residual_mode 1) refresh",
                a_ri,
            ));
        }
        Ok(SceneHeader {
            variant,
            residual_mode,
            deform_model,
            sh_degree,
            lang_levels,
            lang_dims,
            time_channels,
            fps_num,
            fps_den,
            gop_length,
            key_interval,
            gop_count,
            frame_count,
            n_static,
            n_dynamic,
            refresh_interval,
        })
    }
}
