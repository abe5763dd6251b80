//! Real motion: a sequence of per-frame splat scenes (one file per frame) encoded as a dynamic
//! `.dlgs` by fitting DLGStream's deformation field to it.
//!
//! 1. `correspondence`: consecutive frames are matched one to one (they may be sorted
//!    independently), so every Gaussian becomes a track through the sequence;
//! 2. the tracks are split into static and dynamic Gaussians by how much they change within
//!    any GOP ([`is_dynamic`]);
//! 3. `fit`: per GOP, the canonical state is the GOP's middle frame and the key time
//!    features and decoders are fitted to every frame of the GOP;
//! 4. the result is a model like any other: [`write`] codes it with the stream encoder
//!    (canonical coding, HEVC time features, residuals between GOPs). With residual fields
//!    (`ntc_fit`), GOPs after the first carry no canonical Gaussians: a binary voxel field
//!    fitted to the change from the decoder's previous state, and time features refitted to
//!    what that field gives.

mod fit;
mod joint_match;
mod kdtree;
mod linalg;
mod ntc_fit;
mod tracks;

use dlgs::container::header::ResidualMode;
use dlgs::container::SceneHeader;
use dlgs::model::{Canonical, DynamicGop, Gaussians, Lifetimes};
use dlgs::{Error, Result};

pub use fit::GopFit;
pub use joint_match::{match_joint, spacing, JointMatch};
pub use ntc_fit::{NtcFitReport, NtcFitSettings};
pub use tracks::Fallback;

/// How a sequence is cut and fitted.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceSettings {
    pub fps_num: u32,
    pub fps_den: u32,
    /// Frames per GOP.
    pub gop_length: u32,
    /// Frames between key time features (divides `gop_length`).
    pub key_interval: u32,
    /// Where the motion is large (a median move of more than one neighbour spacing between
    /// some two frames), this key interval instead of `key_interval` (it must divide
    /// `gop_length`): on the hard sequences keys every 5 frames gave 50.6 dB against 39.8 with
    /// 10, for 34 % more bytes (docs/benchmarks/sequences.md). `None`: always `key_interval`.
    pub large_motion_key_interval: Option<u32>,
    /// A pair of consecutive frames whose matched Gaussians match confidently less often than
    /// this share (see [`match_joint`]), or that match less than half their Gaussians, has no
    /// consistent correspondence: new tracks begin there (`allow_cuts`) or the sequence is
    /// refused.
    pub min_confident: f64,
    /// Where two frames cannot be matched, fall back (`fallback`, reported per pair) instead
    /// of refusing the sequence.
    pub allow_cuts: bool,
    /// What the fallback does: by default the tracks go on carried by the fitted motion within
    /// a GOP and begin anew at the next GOP's first frame. A sequence with cuts is coded with
    /// intra GOPs whatever `residual_mode` says (a residual cannot jump from one Gaussian to
    /// another; intra GOPs let new tracks take the slots of ended ones).
    pub fallback: Fallback,
    /// How GOPs after the first carry their canonical state.
    pub residual_mode: ResidualMode,
    /// Sequential mode: every K-th GOP carries its full canonical state so that a cold seek
    /// walks at most K-1 residuals (format-spec §4.1, since 1.17); 0 = only GOP 0.
    pub refresh_interval: u32,
    /// With a residual mode other than intra: residuals as fitted binary voxel fields
    /// (`RNTC`) with these settings; `None` sends explicit residuals (`RDLT`). The default,
    /// sequential fields, measured best on the wave sequence: 2,345 bytes/frame at 50.05 dB
    /// mean against intra GOPs' 2,379 at 49.05 (docs/benchmarks/sequences.md).
    pub residual_field: Option<NtcFitSettings>,
}

impl Default for SequenceSettings {
    fn default() -> Self {
        SequenceSettings {
            fps_num: 30,
            fps_den: 1,
            gop_length: 60,
            key_interval: 10,
            large_motion_key_interval: Some(5),
            min_confident: 0.9,
            allow_cuts: true,
            fallback: Fallback::Resample,
            residual_mode: ResidualMode::Sequential,
            refresh_interval: 0,
            residual_field: Some(NtcFitSettings::default()),
        }
    }
}

/// Median move between two frames, in neighbour spacings, above which a sequence's motion is
/// large (see [`SequenceSettings::large_motion_key_interval`]).
pub const LARGE_MOTION: f32 = 1.0;

/// One pair of consecutive frames as matched.
#[derive(Debug, Clone, PartialEq)]
pub struct PairReport {
    /// The later frame of the pair (0-based).
    pub frame: usize,
    /// Confident matches among the matched pairs.
    pub confident_share: f64,
    /// Matched pairs among the smaller frame's Gaussians.
    pub mutual_share: f64,
    pub max_distance: f32,
    pub median_distance: f32,
    /// Median nearest-neighbour distance in the earlier frame.
    pub spacing: f32,
    /// Gaussians of the later frame that begin a track, and of the earlier that end one.
    pub births: usize,
    pub deaths: usize,
    /// No consistent correspondence: every track ended here (the fallback).
    pub cut: bool,
    /// No consistent correspondence: the tracks went on carried by the fitted motion and this
    /// frame's own Gaussians are not shown (the resampling fallback).
    pub resampled: bool,
}

/// What building the model found, for the user.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SequenceReport {
    pub frames: usize,
    /// Largest median move between two frames, in neighbour spacings.
    pub motion: f32,
    /// The key interval used (see [`SequenceSettings::large_motion_key_interval`]).
    pub key_interval: u32,
    pub gop_length: usize,
    /// Gaussians of the first frame.
    pub gaussians: usize,
    /// Fewest and most Gaussians of a frame.
    pub min_count: usize,
    pub max_count: usize,
    /// Dynamic and static Gaussians of the file (tracks share slots, see `tracks`).
    pub slots: usize,
    /// Slots shown for only part of the sequence.
    pub partial: usize,
    /// Frames where new tracks began because no consistent match existed.
    pub cuts: Vec<usize>,
    /// Frames shown as the tracks carried by the fitted motion because no consistent match
    /// existed (see [`Fallback::Resample`]).
    pub resampled: Vec<usize>,
    /// The residual mode the file takes: `SequenceSettings::residual_mode`, or intra where the
    /// sequence has cuts.
    pub residual_mode: ResidualMode,
    pub n_static: usize,
    pub n_dynamic: usize,
    pub pairs: Vec<PairReport>,
    pub gops: Vec<GopFit>,
}

impl SequenceReport {
    /// The least confident pair of frames.
    pub fn worst_pair(&self) -> Option<&PairReport> {
        self.pairs
            .iter()
            .min_by(|a, b| a.confident_share.total_cmp(&b.confident_share))
    }
}

/// A fitted sequence: the scene header and, per GOP, its canonical state and deformation field.
#[derive(Debug, Clone)]
pub struct SequenceModel {
    pub scene: SceneHeader,
    pub gops: Vec<(Canonical, DynamicGop)>,
    /// With residual fields: what [`write`] needs to fit them and refit the GOPs after the
    /// first against the decoder's state.
    refit: Option<Refit>,
}

#[derive(Debug, Clone)]
struct Refit {
    /// Per GOP, its frames (and the next GOP's first) with one row per slot.
    filled: Vec<Vec<Gaussians>>,
    dyn_ids: Vec<usize>,
    settings: NtcFitSettings,
}

/// What [`write`] measured of the residual fields it fitted, per GOP after the first.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WriteReport {
    /// The GOPs that carry a residual field (not GOP 0, not refresh GOPs), in order.
    pub field_gops: Vec<usize>,
    pub fields: Vec<NtcFitReport>,
    /// The refitted GOPs' fits (replacing those of [`SequenceReport::gops`] from GOP 1 on).
    pub refits: Vec<GopFit>,
}

/// Progress of [`build`]: (stage, done, total).
pub type Progress<'a> = &'a mut dyn FnMut(&str, usize, usize);

/// Whether a track changes visibly within a GOP: its position by more than a tenth of its
/// size (largest axis) or 1e-5 of the scene, its colour by more than 1/255 in any channel
/// (SH DC), its rotation by more than ~0.2°, its log-scale or opacity by more than 0.01.
pub fn is_dynamic(frames: &[&Gaussians], i: usize, scene_size: f32) -> bool {
    let f0 = frames[0];
    let size = f0.log_scales[i]
        .iter()
        .fold(f32::NEG_INFINITY, |a, &b| a.max(b))
        .exp();
    let tol = (0.1 * size).max(1e-5 * scene_size);
    let stride = f0.sh_stride();
    let q0 = f0.rotations[i];
    let n0 = q0.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
    frames[1..].iter().any(|f| {
        let p = f.positions[i];
        let moved = (0..3)
            .map(|a| (p[a] - f0.positions[i][a]).powi(2))
            .sum::<f32>()
            .sqrt();
        let q = f.rotations[i];
        let n = q.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
        let dot = (0..4).map(|c| q[c] * q0[c]).sum::<f32>().abs() / (n * n0);
        moved > tol
            || (0..3).any(|c| {
                (f.sh[i * stride + c] - f0.sh[i * stride + c]).abs() * 0.282_095 > 1.0 / 255.0
            })
            || dot < 0.999_998
            || (0..3).any(|a| (f.log_scales[i][a] - f0.log_scales[i][a]).abs() > 0.01)
            || (f.opacity[i] - f0.opacity[i]).abs() > 0.01
    })
}

/// Build the model of a sequence of frames (any Gaussian counts, any sort order).
pub fn build(
    mut frames: Vec<Gaussians>,
    s: &SequenceSettings,
    progress: Progress,
) -> Result<(SequenceModel, SequenceReport)> {
    if frames.len() < 2 {
        return Err(Error::input(format!(
            "a sequence needs at least 2 frames, got {}",
            frames.len()
        )));
    }
    if s.key_interval == 0 || s.gop_length == 0 || !s.gop_length.is_multiple_of(s.key_interval) {
        return Err(Error::input(format!(
            "the key interval ({}) must divide the GOP length ({})",
            s.key_interval, s.gop_length
        )));
    }
    for (t, f) in frames.iter().enumerate() {
        f.check_shapes()
            .and_then(|_| f.check_finite())
            .map_err(|e| Error::input(format!("frame {t}: {e}")))?;
        if f.sh_degree != frames[0].sh_degree {
            return Err(Error::input(format!(
                "frame {t} has SH degree {}, frame 0 has {}",
                f.sh_degree, frames[0].sh_degree
            )));
        }
        if f.lang_width != 0 {
            return Err(Error::input(format!(
                "frame {t} carries language features; sequences are fitted without language"
            )));
        }
    }
    let total = frames.len();
    let l = s.gop_length as usize;
    let ts = tracks::TrackSettings {
        min_confident: s.min_confident,
        allow_cuts: s.allow_cuts,
        fallback: s.fallback,
        gop_length: l,
    };
    let min_count = frames.iter().map(Gaussians::len).min().unwrap_or(0);
    let max_count = frames.iter().map(Gaussians::len).max().unwrap_or(0);
    let (mut tracks, pairs) = tracks::track(&mut frames, &ts, &mut |done, total| {
        progress("matching frames", done, total)
    })?;
    let residual_mode = if tracks.cuts.is_empty() {
        s.residual_mode
    } else {
        ResidualMode::Intra
    };
    if residual_mode == ResidualMode::Intra {
        tracks.pack(l);
    }
    let mut report = SequenceReport {
        frames: total,
        gop_length: l,
        gaussians: frames[0].len(),
        min_count,
        max_count,
        slots: tracks.slots,
        cuts: tracks.cuts.clone(),
        resampled: tracks.resampled.clone(),
        residual_mode,
        pairs,
        ..Default::default()
    };
    report.motion = report
        .pairs
        .iter()
        .map(|p| p.median_distance / p.spacing.max(1e-12))
        .fold(0.0f32, f32::max);
    let key_interval = match s.large_motion_key_interval {
        Some(k) if report.motion > LARGE_MOTION && k > 0 && s.gop_length.is_multiple_of(k) => k,
        _ => s.key_interval,
    };
    report.key_interval = key_interval;
    let s = &SequenceSettings {
        key_interval,
        residual_mode,
        ..s.clone()
    };
    let gop_count = total.div_ceil(l);
    // Per GOP: its frames and the next GOP's first (the last key's anchor), one row per slot.
    let filled: Vec<Vec<Gaussians>> = (0..gop_count)
        .map(|g| {
            let start = g * l;
            let end = ((g + 1) * l).min(total - 1);
            let fr = tracks::fill(
                &frames,
                &tracks,
                start,
                l.min(total - start),
                end,
                s.key_interval as usize,
            );
            progress("filling tracks", g + 1, gop_count);
            fr
        })
        .collect();
    drop(frames);
    let gop_frames = |g: usize| -> Vec<&Gaussians> { filled[g].iter().collect() };
    let scene_size = filled[0][0]
        .bounds()
        .map(|(lo, hi)| (0..3).map(|a| hi[a] - lo[a]).fold(0.0f32, f32::max))
        .unwrap_or(0.0);
    let n = tracks.slots;
    let partial: Vec<bool> = (0..n)
        .map(|i| (0..total).any(|t| !tracks.alive(t, i)))
        .collect();
    report.partial = partial.iter().filter(|&&p| p).count();
    let dynamic: Vec<bool> = (0..n)
        .map(|i| partial[i] || (0..gop_count).any(|g| is_dynamic(&gop_frames(g), i, scene_size)))
        .collect();
    let mut dyn_ids: Vec<usize> = (0..n).filter(|&i| dynamic[i]).collect();
    // Dynamic Gaussians are stored in the order the time-feature tiles show them (row by row,
    // `side` wide, §6.2): a k-d layout of frame 0's positions on that grid makes neighbouring
    // pixels neighbouring Gaussians, smooth pictures that HEVC codes far better.
    let side = dlgs::chunks::tfea::Tiling::for_count(
        dyn_ids.len(),
        (s.gop_length / s.key_interval + 1) as usize,
        fit::CHANNELS,
    )
    .side;
    let mut first = Gaussians::new(filled[0][0].sh_degree, 0);
    for &i in &dyn_ids {
        first.push_from(&filled[0][0], i);
    }
    let order = crate::grid_sort::grid_order_with_width(&first, crate::SortSpec::NONE, side);
    dyn_ids = order.iter().map(|&o| dyn_ids[o as usize]).collect();
    let static_ids: Vec<usize> = (0..n).filter(|&i| !dynamic[i]).collect();
    report.n_static = static_ids.len();
    report.n_dynamic = dyn_ids.len();
    let sh_degree = filled[0][0].sh_degree;
    let scene = SceneHeader {
        residual_mode: s.residual_mode,
        deform_model: fit::DEFORM_MODEL,
        time_channels: if dyn_ids.is_empty() {
            0
        } else {
            fit::CHANNELS as u8
        },
        fps_num: s.fps_num,
        fps_den: s.fps_den,
        gop_length: s.gop_length,
        key_interval: s.key_interval,
        gop_count: gop_count as u32,
        frame_count: total as u32,
        n_static: static_ids.len() as u32,
        n_dynamic: dyn_ids.len() as u32,
        refresh_interval: s.refresh_interval,
        ..SceneHeader::still(static_ids.len() as u32, sh_degree)
    };
    let mut gops = Vec::with_capacity(gop_count);
    for g in 0..gop_count {
        let fr = gop_frames(g);
        let mut statics = Gaussians::new(sh_degree, 0);
        let canonical = fr[fit::canonical_frame(fr.len(), l)];
        for &i in &static_ids {
            statics.push_from(canonical, i);
        }
        let (dynamics, mut field, fit) = fit::fit_gop(&fr, &dyn_ids, l, s.key_interval as usize);
        let frames_here = l.min(total - g * l);
        let ranges: Vec<(u16, u16)> = dyn_ids
            .iter()
            .map(|&i| tracks.local_life(i, g * l, frames_here))
            .collect();
        field.life = Lifetimes::from_ranges(&ranges, frames_here as u16);
        gops.push((Canonical { statics, dynamics }, field));
        report.gops.push(fit);
        progress("fitting GOPs", g + 1, gop_count);
    }
    let refit = match (&s.residual_field, s.residual_mode) {
        (Some(f), m) if m != ResidualMode::Intra && !dyn_ids.is_empty() => Some(Refit {
            filled,
            dyn_ids,
            settings: f.clone(),
        }),
        _ => None,
    };
    Ok((SequenceModel { scene, gops, refit }, report))
}

/// Code a fitted sequence with the stream encoder.
pub fn write<W: std::io::Write>(
    model: &SequenceModel,
    cfg: crate::EncoderConfig,
    out: W,
) -> Result<W> {
    write_with_report(model, cfg, out, &mut |_, _, _| {}).map(|(w, _)| w)
}

/// As [`write`], saying what the residual fields' fits found; `progress` follows them.
pub fn write_with_report<W: std::io::Write>(
    model: &SequenceModel,
    cfg: crate::EncoderConfig,
    out: W,
    progress: Progress,
) -> Result<(W, WriteReport)> {
    let mut enc = crate::StreamEncoder::new(out, model.scene.clone(), cfg)?;
    let dynamic = model.scene.n_dynamic > 0;
    let mut report = WriteReport::default();
    let l = model.scene.gop_length as usize;
    for (g, (canonical, field)) in model.gops.iter().enumerate() {
        // GOP 0 and refresh GOPs (no reference GOP) carry their own canonical state.
        let refit = model
            .refit
            .as_ref()
            .filter(|_| enc.reference_state().is_some());
        let Some(r) = refit else {
            enc.push(
                crate::GopCanonical::State(canonical),
                dynamic.then_some(field),
            )?;
            continue;
        };
        let base = enc
            .reference_state()
            .expect("a residual scene keeps its reference state")
            .clone();
        let targets = ntc_fit::offset_rows(&base.dynamics, &canonical.dynamics, r.settings.groups);
        let total = r.settings.iterations * (model.gops.len() - 1);
        let done = (g - 1) * r.settings.iterations;
        let (ntc, fit_report) = ntc_fit::fit(
            &base.dynamics.positions,
            &targets,
            &r.settings,
            model.scene.sh_degree,
            |i, _| progress("fitting residual fields", done + i, total),
        );
        let state = ntc.apply(&base)?;
        let frames: Vec<&Gaussians> = r.filled[g].iter().collect();
        let (mut refitted, gop_fit) = fit::fit_gop_to(
            &frames,
            &r.dyn_ids,
            &state.dynamics,
            l,
            model.scene.key_interval as usize,
        );
        refitted.life = field.life.clone();
        enc.push(crate::GopCanonical::Ntc(&ntc), Some(&refitted))?;
        report.field_gops.push(g);
        report.fields.push(fit_report);
        report.refits.push(gop_fit);
    }
    Ok((enc.finish()?, report))
}
