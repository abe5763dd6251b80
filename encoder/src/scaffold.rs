//! Writing Scaffold-GS files (`HEAD.variant = 1`, format-spec §6.9-§6.13): per GOP its raw
//! anchors (`ANCR`) or HAC-coded ones (`AHAC`), view MLPs (`AMLP`) and, with dynamic anchors, their deformation (`ADEF`)
//! and key time features (`TFEA`, exact or 12-bit HEVC).

use std::io::Write;

use dlgs::chunks::ahac::{AhacSizes, HacAnchors};
use dlgs::chunks::tfea::{self, TfeaBody};
use dlgs::chunks::{adef, ahac, amlp, ancr};
use dlgs::container::header::{DeformModel, ResidualMode, Variant};
use dlgs::container::{ChunkType, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
use dlgs::model::scaffold::{
    check_scene, AnchorDeformation, ScaffoldCanonical, ScaffoldMlps, TIME_CHANNELS,
};
use dlgs::{Error, Result};

/// The header of a Scaffold-GS scene.
pub fn scaffold_scene(
    n_static: u32,
    n_dynamic: u32,
    language: bool,
    fps: u32,
    gop_length: u32,
    key_interval: u32,
    frame_count: u32,
) -> SceneHeader {
    let mut s = SceneHeader::still(n_static, 0);
    s.variant = Variant::Scaffold;
    s.residual_mode = ResidualMode::Intra;
    s.deform_model = DeformModel::PaperLerp;
    s.n_static = n_static;
    s.n_dynamic = n_dynamic;
    s.time_channels = if n_dynamic > 0 {
        TIME_CHANNELS as u8
    } else {
        0
    };
    (s.lang_levels, s.lang_dims) = if language { (3, 3) } else { (0, 0) };
    s.fps_num = fps;
    s.fps_den = 1;
    s.gop_length = gop_length;
    s.key_interval = key_interval;
    s.frame_count = frame_count;
    s.gop_count = frame_count.div_ceil(gop_length.max(1));
    s
}

/// Writes a Scaffold-GS file one GOP at a time.
pub struct ScaffoldWriter<W: Write> {
    writer: Writer<W>,
    zstd_level: i32,
}

impl<W: Write> ScaffoldWriter<W> {
    pub fn new(out: W, scene: SceneHeader, zstd_level: i32) -> Result<Self> {
        if scene.variant != Variant::Scaffold {
            return Err(Error::input("a Scaffold-GS writer needs HEAD.variant = 1"));
        }
        check_scene(&scene).map_err(Error::input)?;
        Ok(ScaffoldWriter {
            writer: Writer::new(out, scene)?,
            zstd_level,
        })
    }

    pub fn scene(&self) -> &SceneHeader {
        self.writer.scene()
    }

    /// Append a non-`HEAD` scene-level chunk (e.g. `META`) before the first GOP.
    pub fn scene_chunk(&mut self, ty: ChunkType, payload: &[u8]) -> Result<()> {
        self.writer.scene_chunk(ty, 0, payload)
    }

    /// Append the next GOP; `dynamic` is required iff the scene has dynamic anchors, with time
    /// features of `(n_dynamic, keys, 16)`.
    pub fn push_gop(
        &mut self,
        canonical: &ScaffoldCanonical,
        mlps: &ScaffoldMlps,
        dynamic: Option<(&AnchorDeformation, &TfeaBody)>,
    ) -> Result<()> {
        let s = self.writer.scene().clone();
        let anchors = ancr::encode(canonical, &s, self.zstd_level)?;
        self.push(ChunkType::ANCR, &anchors, mlps, dynamic)
    }

    /// As [`Self::push_gop`], with the anchors HAC-coded (`AHAC`, §6.13) in place of `ANCR`.
    /// Returns the sizes of the `AHAC` parts.
    pub fn push_gop_hac(
        &mut self,
        anchors: &HacAnchors,
        mlps: &ScaffoldMlps,
        dynamic: Option<(&AnchorDeformation, &TfeaBody)>,
    ) -> Result<AhacSizes> {
        let s = self.writer.scene().clone();
        let (payload, sizes) = ahac::encode(anchors, &s, self.zstd_level)?;
        self.push(ChunkType::AHAC, &payload, mlps, dynamic)?;
        Ok(sizes)
    }

    fn push(
        &mut self,
        anchors_type: ChunkType,
        anchors: &[u8],
        mlps: &ScaffoldMlps,
        dynamic: Option<(&AnchorDeformation, &TfeaBody)>,
    ) -> Result<()> {
        let s = self.writer.scene().clone();
        mlps.check().map_err(Error::input)?;
        let view = amlp::encode(mlps, &s, self.zstd_level)?;
        let dyn_chunks = match (s.n_dynamic > 0, dynamic) {
            (true, Some((d, f))) => {
                d.mlps.check().map_err(Error::input)?;
                if let TfeaBody::Exact(x) = f {
                    if (x.n, x.keys, x.channels)
                        != (
                            s.n_dynamic as usize,
                            s.keys_per_gop() as usize,
                            TIME_CHANNELS,
                        )
                    {
                        return Err(Error::input(format!(
                            "time features ({}, {}, {}), the scene needs ({}, {}, {TIME_CHANNELS})",
                            x.n,
                            x.keys,
                            x.channels,
                            s.n_dynamic,
                            s.keys_per_gop()
                        )));
                    }
                    dlgs::model::dynamic::check_finite("time features", &x.data)?;
                }
                Some((
                    adef::encode(d, self.zstd_level)?,
                    tfea::encode(f, self.zstd_level)?,
                ))
            }
            (false, None) => None,
            (true, None) => {
                return Err(Error::input(
                    "the scene has dynamic anchors but the GOP has no deformation",
                ))
            }
            (false, Some(_)) => {
                return Err(Error::input(
                    "a deformation for a scene without dynamic anchors",
                ))
            }
        };
        self.writer.begin_gop()?;
        self.writer
            .gop_chunk(anchors_type, FLAG_MUST_UNDERSTAND, anchors)?;
        self.writer
            .gop_chunk(ChunkType::AMLP, FLAG_MUST_UNDERSTAND, &view)?;
        if let Some((d, f)) = dyn_chunks {
            self.writer
                .gop_chunk(ChunkType::ADEF, FLAG_MUST_UNDERSTAND, &d)?;
            self.writer
                .gop_chunk(ChunkType::TFEA, FLAG_MUST_UNDERSTAND, &f)?;
        }
        Ok(())
    }

    pub fn finish(self) -> Result<W> {
        self.writer.finish()
    }
}
