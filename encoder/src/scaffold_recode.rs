//! Re-coding a Scaffold-GS file's HAC-coded anchors (`AHAC`, format-spec §6.13) with larger
//! steps, from the `.dlgs` alone: every `AHAC` chunk is decoded to its integers and context
//! model, requantised (`HacAnchors::requantized`, steps `k` times the file's) and coded again;
//! every other chunk is copied byte for byte. Residual GOPs (`RNTC`) then apply to the
//! requantised anchors, exactly as in a file written from the HAC run with
//! `--anchor-step-scale k` (the same `AHAC` bytes when the file was written with k = 1).
//! Raw anchors (`ANCR`) have no context model: they are HAC-coded either with a context model
//! fitted to them ([`crate::scaffold_fit`], [`RawAnchorCoding::Fitted`]) or with the
//! per-channel prior of [`crate::scaffold_prior`] ([`RawAnchorCoding::Prior`], fast).

use std::io::{Read, Seek};

use dlgs::chunks::{ahac, ancr, rntc};
use dlgs::container::header::Variant;
use dlgs::container::{ChunkType, FileReader, Writer};
use dlgs::{Error, Limits, Result};

use crate::mantissa::round_mantissa;
use crate::scaffold_fit::{fit_anchors, ContextFitReport, ContextFitSettings};
use crate::scaffold_prior::{prior_anchors, DEFAULT_PRIOR_STEPS};

/// What [`recode_anchors`] changes.
#[derive(Debug, Clone, PartialEq)]
pub struct RecodeOptions {
    /// `AHAC` steps times this (1: the same symbols).
    pub k: f32,
    /// How raw (`ANCR`) anchors are coded.
    pub raw: RawAnchorCoding,
    /// Mantissa bits kept in the weights of every anchor residual's (`RNTC`) MLP (23: all, the
    /// chunks are copied as they are).
    pub rntc_mantissa: u32,
}

/// How raw (`ANCR`) anchors are HAC-coded.
#[derive(Debug, Clone, PartialEq)]
pub enum RawAnchorCoding {
    /// Left raw (`ANCR` copied).
    Keep,
    /// The per-channel prior at these steps (feature, log-scaling, offsets): fast.
    Prior([f32; 3]),
    /// A context model fitted to each GOP's anchors (its steps are the settings').
    Fitted(ContextFitSettings),
}

impl RawAnchorCoding {
    /// The steps raw anchors are quantised with (0: kept raw).
    pub fn steps(&self) -> [f32; 3] {
        match self {
            RawAnchorCoding::Keep => [0.0; 3],
            RawAnchorCoding::Prior(s) => *s,
            RawAnchorCoding::Fitted(f) => f.steps,
        }
    }
}

/// What [`recode_anchor_steps`] changed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecodeReport {
    /// `AHAC` chunks re-coded (one per intra GOP).
    pub ahac_chunks: usize,
    /// Of those, raw `ANCR` chunks coded with the prior model.
    pub from_raw: usize,
    /// Their payload bytes before and after.
    pub ahac_bytes_before: u64,
    pub ahac_bytes_after: u64,
    /// Per raw GOP coded with a fitted model: what the fit reached.
    pub fits: Vec<ContextFitReport>,
    /// `RNTC` chunks whose MLP weights were rounded, and their payload bytes before and after.
    pub rntc_chunks: usize,
    pub rntc_bytes_before: u64,
    pub rntc_bytes_after: u64,
}

/// `META` with `settings.anchor_step_scale` multiplied by `k` (the steps are now `k` times
/// the file's); anything that is not a JSON object is kept as it is.
fn scaled_meta(payload: &[u8], k: f32) -> Vec<u8> {
    let Ok(serde_json::Value::Object(mut meta)) = serde_json::from_slice(payload) else {
        return payload.to_vec();
    };
    let settings = meta
        .entry("settings")
        .or_insert_with(|| serde_json::json!({}));
    if let Some(s) = settings.as_object_mut() {
        let old = s
            .get("anchor_step_scale")
            .and_then(|v| v.as_f64())
            .unwrap_or(1.0);
        s.insert(
            "anchor_step_scale".into(),
            serde_json::json!(old * f64::from(k)),
        );
    }
    serde_json::to_vec(&meta).unwrap_or_else(|_| payload.to_vec())
}

/// The Scaffold-GS file read from `src` with every `AHAC` chunk's steps `k` times larger
/// (`k = 1`: the same anchors, re-coded), and every raw `ANCR` chunk HAC-coded with the
/// prior model at `k` times its default steps. Fails on a file of the 3DGS variant. Scene-level
/// chunks the reader does not know are not copied.
pub fn recode_anchor_steps<R: Read + Seek>(
    src: R,
    k: f32,
    zstd_level: i32,
    limits: Limits,
) -> Result<(Vec<u8>, RecodeReport)> {
    let o = RecodeOptions {
        k,
        raw: RawAnchorCoding::Prior(DEFAULT_PRIOR_STEPS.map(|q| q * k)),
        rntc_mantissa: 23,
    };
    recode_anchors(src, &o, zstd_level, limits, &mut |_, _| {})
}

/// [`recode_anchor_steps`] with raw anchors coded and residual MLPs rounded as `o` says.
/// `progress(done, total)` reports the fits' iterations of each raw GOP.
pub fn recode_anchors<R: Read + Seek>(
    src: R,
    o: &RecodeOptions,
    zstd_level: i32,
    limits: Limits,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Vec<u8>, RecodeReport)> {
    let (k, raw) = (o.k, &o.raw);
    if !(k.is_finite() && k > 0.0) {
        return Err(Error::input(format!(
            "anchor step scale {k}: a finite number > 0"
        )));
    }
    let mut r = FileReader::open_with_limits(src, limits.clone())?;
    let scene = r.scene().clone();
    if scene.variant != Variant::Scaffold {
        return Err(Error::input(
            "re-coding anchor steps needs a Scaffold-GS file (HEAD.variant 1); this one is 3DGS",
        ));
    }
    let mut w = Writer::new(Vec::new(), scene.clone())?;
    for c in r.scene_chunks().to_vec() {
        let p = r.payload(&c)?;
        let p = if c.ty == ChunkType::META {
            scaled_meta(&p, k)
        } else {
            p
        };
        w.scene_chunk(c.ty, c.flags, &p)?;
    }
    let mut report = RecodeReport::default();
    for g in 0..scene.gop_count {
        w.begin_gop()?;
        for c in r.gop_chunks(g)? {
            let p = r.payload(&c)?;
            let hac = match c.ty {
                ChunkType::AHAC => {
                    let (h, _) = ahac::decode_full(&p, c.payload_offset(), &scene, &limits)?;
                    h.requantized(k)?
                }
                ChunkType::ANCR if *raw != RawAnchorCoding::Keep => {
                    let anchors = ancr::decode(&p, c.payload_offset(), &scene, &limits)?;
                    report.from_raw += 1;
                    if let RawAnchorCoding::Fitted(settings) = raw {
                        let (hac, fit) = fit_anchors(&anchors, settings, &mut *progress)?;
                        report.fits.push(fit);
                        hac
                    } else {
                        prior_anchors(&anchors, raw.steps())?
                    }
                }
                ChunkType::RNTC if o.rntc_mantissa < 23 => {
                    let mut f = rntc::decode(&p, c.payload_offset(), &scene, &limits)?;
                    let m = &mut f.mlp;
                    for v in [&mut m.w1, &mut m.b1, &mut m.w2, &mut m.b2] {
                        v.iter_mut()
                            .for_each(|x| *x = round_mantissa(*x, o.rntc_mantissa));
                    }
                    let q = rntc::encode(&f, &scene, zstd_level)?;
                    report.rntc_chunks += 1;
                    report.rntc_bytes_before += p.len() as u64;
                    report.rntc_bytes_after += q.len() as u64;
                    w.gop_chunk(c.ty, c.flags, &q)?;
                    continue;
                }
                _ => {
                    w.gop_chunk(c.ty, c.flags, &p)?;
                    continue;
                }
            };
            let (coded, _) = ahac::encode(&hac, &scene, zstd_level)?;
            report.ahac_chunks += 1;
            report.ahac_bytes_before += p.len() as u64;
            report.ahac_bytes_after += coded.len() as u64;
            w.gop_chunk(ChunkType::AHAC, c.flags, &coded)?;
        }
    }
    Ok((w.finish()?, report))
}
