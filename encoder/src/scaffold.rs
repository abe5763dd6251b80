//! Writing Scaffold-GS files (`HEAD.variant = 1`, format-spec §6.9-§6.13): per GOP its raw
//! anchors (`ANCR`) or HAC-coded ones (`AHAC`), view MLPs (`AMLP`) and, with dynamic anchors, their deformation (`ADEF`)
//! and key time features (`TFEA`, exact or 12-bit HEVC). In a sequential scene (since 1.17)
//! GOPs after the first carry an anchor residual (`RNTC`) instead of `ANCR`, and their view
//! MLPs are inherited, or only the language MLP is sent.

use std::io::Write;

use dlgs::chunks::ahac::{AhacSizes, HacAnchors};
use dlgs::chunks::tfea::{self, TfeaBody};
use dlgs::chunks::{adef, amlp, ancr};
use dlgs::chunks::{ahac, rntc};
use dlgs::container::header::{DeformModel, ResidualMode, Variant};
use dlgs::container::{ChunkType, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
use dlgs::model::ntc::NtcField;
use dlgs::model::scaffold::{
    check_scene, AnchorDeformation, ScaffoldCanonical, ScaffoldMlps, TwoLayer, TIME_CHANNELS,
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

/// The view MLPs of a residual GOP (format-spec §6.10, since 1.17).
#[derive(Debug, Clone, Copy)]
pub enum ResidualViewMlps<'a> {
    /// No `AMLP`: the reference GOP's view MLPs.
    Inherit,
    /// A language-only `AMLP`: this language MLP with the reference GOP's other view MLPs.
    LanguageOnly(&'a TwoLayer),
    /// A full `AMLP`.
    Full(&'a ScaffoldMlps),
}

/// Writes a Scaffold-GS file one GOP at a time.
pub struct ScaffoldWriter<W: Write> {
    writer: Writer<W>,
    zstd_level: i32,
    gops: u32,
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
            gops: 0,
        })
    }

    pub fn scene(&self) -> &SceneHeader {
        self.writer.scene()
    }

    /// Append a non-`HEAD` scene-level chunk (e.g. `META`) before the first GOP.
    pub fn scene_chunk(&mut self, ty: ChunkType, payload: &[u8]) -> Result<()> {
        self.writer.scene_chunk(ty, 0, payload)
    }

    /// Append the next GOP as an intra GOP (full anchors); `dynamic` is required iff the scene
    /// has dynamic anchors, with time features of `(n_dynamic, keys, 16)`. In a sequential
    /// scene only GOP 0 is intra.
    pub fn push_gop(
        &mut self,
        canonical: &ScaffoldCanonical,
        mlps: &ScaffoldMlps,
        dynamic: Option<(&AnchorDeformation, &TfeaBody)>,
    ) -> Result<()> {
        let s = self.writer.scene().clone();
        let anchors = ancr::encode(canonical, &s, self.zstd_level)?;
        self.push_intra(ChunkType::ANCR, &anchors, mlps, dynamic)
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
        self.push_intra(ChunkType::AHAC, &payload, mlps, dynamic)?;
        Ok(sizes)
    }

    /// An intra GOP with its anchors chunk (`ANCR` or `AHAC`) already coded.
    fn push_intra(
        &mut self,
        anchors_type: ChunkType,
        anchors: &[u8],
        mlps: &ScaffoldMlps,
        dynamic: Option<(&AnchorDeformation, &TfeaBody)>,
    ) -> Result<()> {
        if self.has_reference() {
            return Err(Error::input(
                "in a sequential Scaffold-GS scene this GOP is a residual GOP (push_residual_gop)",
            ));
        }
        mlps.check().map_err(Error::input)?;
        let s = self.writer.scene().clone();
        let view = amlp::encode(mlps, &s, self.zstd_level)?;
        let dyn_chunks = self.dynamic_chunks(dynamic)?;
        self.write_gop(anchors_type, anchors, Some(&view), dyn_chunks)
    }

    /// Append the next GOP as a residual GOP (sequential scenes, GOP 1 on; format-spec §6.6,
    /// §6.12): `field` is an `RNTC` over anchor groups, applied to the previous GOP's decoded
    /// canonical anchors; `view` says what the GOP's `AMLP` holds.
    pub fn push_residual_gop(
        &mut self,
        field: &NtcField,
        view: ResidualViewMlps,
        dynamic: Option<(&AnchorDeformation, &TfeaBody)>,
    ) -> Result<()> {
        let s = self.writer.scene().clone();
        if !self.has_reference() {
            return Err(Error::input(
                "a residual GOP needs a sequential scene (residual_mode 1) and a previous GOP",
            ));
        }
        let residual = rntc::encode(field, &s, self.zstd_level)?;
        let view = match view {
            ResidualViewMlps::Inherit => None,
            ResidualViewMlps::LanguageOnly(l) => {
                l.check(
                    "mlp_language",
                    dlgs::model::scaffold::VIEW_INPUTS,
                    dlgs::model::scaffold::LANG_DIM * dlgs::model::scaffold::N_OFFSETS,
                    true,
                )
                .map_err(Error::input)?;
                Some(amlp::encode_language_only(l, &s, self.zstd_level)?)
            }
            ResidualViewMlps::Full(m) => {
                m.check().map_err(Error::input)?;
                Some(amlp::encode(m, &s, self.zstd_level)?)
            }
        };
        let dyn_chunks = self.dynamic_chunks(dynamic)?;
        self.write_gop(ChunkType::RNTC, &residual, view.as_deref(), dyn_chunks)
    }

    /// Whether the next GOP has a reference GOP (§5.1: it then must be a residual GOP).
    fn has_reference(&self) -> bool {
        self.gops < self.writer.scene().gop_count
            && dlgs::container::GopHeader::expected(self.writer.scene(), self.gops).reference_gop
                != dlgs::container::NO_REFERENCE
    }

    fn dynamic_chunks(
        &self,
        dynamic: Option<(&AnchorDeformation, &TfeaBody)>,
    ) -> Result<Option<(Vec<u8>, Vec<u8>)>> {
        let s = self.writer.scene();
        Ok(match (s.n_dynamic > 0, dynamic) {
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
        })
    }

    fn write_gop(
        &mut self,
        canonical_ty: ChunkType,
        canonical: &[u8],
        view: Option<&[u8]>,
        dyn_chunks: Option<(Vec<u8>, Vec<u8>)>,
    ) -> Result<()> {
        self.writer.begin_gop()?;
        self.writer
            .gop_chunk(canonical_ty, FLAG_MUST_UNDERSTAND, canonical)?;
        if let Some(v) = view {
            self.writer
                .gop_chunk(ChunkType::AMLP, FLAG_MUST_UNDERSTAND, v)?;
        }
        if let Some((d, f)) = dyn_chunks {
            self.writer
                .gop_chunk(ChunkType::ADEF, FLAG_MUST_UNDERSTAND, &d)?;
            self.writer
                .gop_chunk(ChunkType::TFEA, FLAG_MUST_UNDERSTAND, &f)?;
        }
        self.gops += 1;
        Ok(())
    }

    pub fn finish(self) -> Result<W> {
        self.writer.finish()
    }
}
