//! Decoder of the reference implementation's HAC (Scaffold-GS) bitstreams: a GOP folder
//! (`compression/best/`) with `bitstreams/` (`anchor.npy`, `patched_infos.npy`, `hash.b`,
//! `feat|scaling|offsets_{s}_0.b`; or for a later GOP `ntc_2D.b`, `ntc_3D.b`) and
//! `png_quant/mlps.pth`, decoded to the anchor tensors the reference's decoder produces
//! (../shared/reference §1.3-1.4, §3, §6.2; conventions in
//! `tests/fixtures/scaffold_run/README.md`). The time features (the mp4) are read elsewhere.
//!
//! [`npy`] reads the NumPy files, [`bitstream`] the `.b` layout and binary grids, [`grid`]
//! looks up binary hash grids, [`context`] is the context model, [`gaussian`] decodes the
//! Gaussian-coded attributes (with a search when a chunk does not re-encode, `repair.rs`),
//! [`ntc`] evaluates the NTC residual.
//!
//! Exactness, measured on `tests/fixtures/scaffold_run` (`tests/tests/hac_ingest.rs`): the
//! anchors, the hash-grid bits, the context model's means and scales (sequential float32 FMA
//! like torch's MKL sgemm here) and the NTC bits are bit-exact. What is not: torch's CPU
//! float32 `tanh` and `erfc` are MKL's `vsTanh`/`vsErfc` (faithful, not correctly rounded;
//! checked by calling them), so Q can be one ulp off for some anchors, and CDF entries can
//! round to another integer, which desynchronises the range decoder for the rest of its
//! chunk. Each chunk is therefore re-encoded to check it, and a failing chunk is searched for
//! the other roundings ([`DecodeReport`] lists the chunks repaired and unverified). The NTC
//! residual differs by up to 2e-7 (torch's sigmoid uses SLEEF's `expf`).

pub mod bitstream;
pub mod context;
pub mod gaussian;
pub mod grid;
pub mod npy;
pub mod ntc;
mod repair;
pub mod synthetic;
mod to_ahac;

use std::path::Path;

use dlgs::model::scaffold::{Anchors, FEAT_DIM, N_OFFSETS};
use rayon::prelude::*;

use crate::hac_mlps::{read_hac_mlps, HacMlps};
use crate::IngestError;

use context::{Attr, AttrContext, ContextGrids, CONTEXT_OUT, GRID_WIDTH};
use npy::PatchedInfos;

/// Bounds on what one GOP folder may declare.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HacLimits {
    pub max_anchors: usize,
    /// Extra decodes per chunk that does not re-encode to its bytes, trying the other
    /// roundings of torch's tanh/erfc (see [`gaussian::decode_gaussian`]); 0 = none.
    pub repair_trials: usize,
}

impl Default for HacLimits {
    fn default() -> Self {
        HacLimits {
            max_anchors: 1 << 24,
            repair_trials: 2048,
        }
    }
}

/// GOP 1's NTC residual (from its bits and `ntc_mlp`).
#[derive(Debug, Clone, PartialEq)]
pub struct NtcResidual {
    pub plane_bits: Vec<bool>,
    pub gate_bits: Vec<bool>,
    /// `FEAT_DIM` per anchor.
    pub d_feat: Vec<f32>,
    /// `N_OFFSETS * 3` per anchor.
    pub d_offsets: Vec<f32>,
}

/// The entropy decode's own check: each chunk's symbols re-encoded with the CDFs used must
/// give the chunk's bytes. A chunk that does not is decoded with CDFs that differ from the
/// encoder's (float32 `erfc`/`tanh` rounded otherwise than torch's MKL), so its values from
/// the first differing symbol on are wrong.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct DecodeReport {
    pub chunks: usize,
    pub verified_chunks: usize,
    /// `(file name, chunk index)` of each chunk that did not verify.
    pub unverified: Vec<(String, usize)>,
    /// `(file name, chunk index)` of each chunk that verified only after the repair search
    /// (counted in `verified_chunks`; consistent with its bytes but not proven right).
    pub repaired: Vec<(String, usize)>,
    /// Anchors whose Q took the other tanh rounding to verify a chunk.
    pub q_switched: usize,
}

/// One decoded GOP.
#[derive(Debug, Clone, PartialEq)]
pub struct HacGop {
    /// Static anchors first, then dynamic ones; positions dequantised. For a GOP with an NTC
    /// residual: the previous GOP's anchors with features and offsets plus the residual.
    pub anchors: Anchors,
    pub n_static: usize,
    /// `anchor.npy` (GOP 0; a later GOP keeps the previous GOP's).
    pub quantized: Vec<[u16; 3]>,
    pub bound_min: [f32; 3],
    pub bound_max: [f32; 3],
    /// The decoded `hash.b` (GOP 0).
    pub hash_bits: Vec<bool>,
    /// The context model's outputs per attribute (feat, scaling, offsets) (GOP 0).
    pub context: Option<[AttrContext; 3]>,
    /// The coded integers `round(x / Q)` per attribute (feat, scaling, offsets), anchor-major
    /// (GOP 0; empty for a later GOP).
    pub symbols: [Vec<i32>; 3],
    /// Anchors per coded batch (`patched_infos.npy`; GOP 0).
    pub batch: usize,
    /// How the Gaussian-coded files decoded (GOP 0).
    pub report: DecodeReport,
    pub mlps: HacMlps,
    pub ntc: Option<NtcResidual>,
}

/// `â = q · interval + min`, `interval = (max − min) · (1/65535) + 1e-6`, float32.
pub fn dequantize(q: &[[u16; 3]], bound_min: [f32; 3], bound_max: [f32; 3]) -> Vec<[f32; 3]> {
    let interval: [f32; 3] = std::array::from_fn(|d| {
        (bound_max[d] - bound_min[d]) * (1.0f64 / 65535.0) as f32 + 1e-6f32
    });
    q.iter()
        .map(|v| std::array::from_fn(|d| v[d] as f32 * interval[d] + bound_min[d]))
        .collect()
}

/// Anchors per parallel block of the context model (fixed: results do not depend on it).
const BLOCK: usize = 64;

/// The context model at every anchor (per attribute, anchor-major).
pub fn context_all(
    grids: &ContextGrids,
    mlp_grid: &dlgs::model::scaffold::TwoLayer,
    anchors: &[[f32; 3]],
    bound_min: [f32; 3],
    bound_max: [f32; 3],
) -> [AttrContext; 3] {
    let parts: Vec<[AttrContext; 3]> = anchors
        .par_chunks(BLOCK)
        .map(|c| context::context(grids, mlp_grid, c, bound_min, bound_max))
        .collect();
    let mut out: [AttrContext; 3] = Default::default();
    for p in parts {
        for (o, q) in out.iter_mut().zip(p) {
            o.mean.extend(q.mean);
            o.scale.extend(q.scale);
            o.q.extend(q.q);
            o.q_alt.extend(q.q_alt);
        }
    }
    out
}

fn missing(path: &Path, what: &str) -> IngestError {
    IngestError::Missing {
        path: path.to_path_buf(),
        what: what.to_string(),
    }
}

/// Decode one GOP folder (`.../compression/best`). GOP 0 (with `anchor.npy`) needs no
/// `previous`; a GOP with `ntc_2D.b` needs the previous GOP's decode.
pub fn read_gop(
    dir: &Path,
    previous: Option<&HacGop>,
    limits: HacLimits,
) -> Result<HacGop, IngestError> {
    let bs = dir.join("bitstreams");
    let mlps_path = dir.join("png_quant").join("mlps.pth");
    if !mlps_path.is_file() {
        return Err(missing(&mlps_path, "the GOP's MLPs"));
    }
    let mlps = read_hac_mlps(&mlps_path)?;
    if bs.join("anchor.npy").is_file() {
        read_base(&bs, mlps, limits)
    } else if bs.join("ntc_2D.b").is_file() {
        let prev = previous.ok_or_else(|| {
            IngestError::format(
                &bs.display().to_string(),
                "an NTC GOP needs the previous GOP's decode",
            )
        })?;
        read_ntc(&bs, prev, mlps)
    } else {
        Err(missing(
            &bs.join("anchor.npy"),
            "neither anchor.npy nor ntc_2D.b",
        ))
    }
}

fn read_base(bs: &Path, mlps: HacMlps, limits: HacLimits) -> Result<HacGop, IngestError> {
    let infos: PatchedInfos = npy::read_patched_infos(&bs.join("patched_infos.npy"))?;
    let apath = bs.join("anchor.npy");
    let what_a = apath.display().to_string();
    let quantized = npy::read_anchor_npy(&apath)?;
    let n = quantized.len();
    if n != infos.n_anchor || n > limits.max_anchors {
        return Err(IngestError::shape(
            &what_a,
            format!(
                "{n} anchors (patched_infos: {}; limit {})",
                infos.n_anchor, limits.max_anchors
            ),
        ));
    }
    let (bmin, bmax) = (infos.x_bound_min, infos.x_bound_max);
    if (0..3).any(|d| bmax[d].partial_cmp(&bmin[d]) != Some(std::cmp::Ordering::Greater)) {
        return Err(IngestError::format(
            &bs.join("patched_infos.npy").display().to_string(),
            format!("bounds {bmin:?}..{bmax:?} are empty"),
        ));
    }
    let mlp_grid = mlps
        .grid
        .as_ref()
        .ok_or_else(|| IngestError::format("mlps.pth", "GOP 0 has no mlp_grid"))?;
    mlp_grid
        .check("mlp_grid", GRID_WIDTH, CONTEXT_OUT, true)
        .map_err(|r| IngestError::format("mlps.pth", r))?;
    let hpath = bs.join("hash.b");
    let hash_bits = bitstream::read_binary(&hpath, context::hash_bits())?;
    let grids = ContextGrids::from_bits(&hash_bits)
        .ok_or_else(|| IngestError::shape(&hpath.display().to_string(), "bit count"))?;
    let positions = dequantize(&quantized, bmin, bmax);
    let ctx = context_all(&grids, mlp_grid, &positions, bmin, bmax);

    // One job per (batch, attribute) file; each file's symbols are independent.
    let batches = n.div_ceil(infos.batch);
    let jobs: Vec<(usize, Attr)> = (0..batches)
        .flat_map(|s| Attr::ALL.into_iter().map(move |a| (s, a)))
        .collect();
    let decoded: Vec<gaussian::GaussianDecode> = jobs
        .par_iter()
        .map(|&(s, attr)| {
            let a0 = s * infos.batch;
            let a1 = (a0 + infos.batch).min(n);
            let c = attr.channels();
            let ac = &ctx[attr as usize];
            let path = bs.join(format!("{}_{s}_0.b", attr.name()));
            let bytes = bitstream::read(&path)?;
            gaussian::decode_gaussian(
                &bytes,
                c,
                &ac.mean[a0 * c..a1 * c],
                &ac.scale[a0 * c..a1 * c],
                &ac.q[a0..a1],
                &ac.q_alt[a0..a1],
                limits.repair_trials,
                &path.display().to_string(),
            )
        })
        .collect::<Result<_, _>>()?;
    let mut anchors = Anchors {
        positions,
        ..Default::default()
    };
    let mut report = DecodeReport::default();
    let mut symbols: [Vec<i32>; 3] = Default::default();
    for (&(s, attr), d) in jobs.iter().zip(decoded) {
        symbols[attr as usize].extend_from_slice(&d.symbols);
        report.chunks += d.chunks;
        let file = format!("{}_{s}_0.b", attr.name());
        report
            .unverified
            .extend(d.unverified.iter().map(|&k| (file.clone(), k)));
        report
            .repaired
            .extend(d.repaired.iter().map(|&k| (file.clone(), k)));
        report.verified_chunks += d.verified_chunks;
        report.q_switched += d.q_switched;
        let v = d.values;
        match attr {
            Attr::Feat => anchors.features.extend(v),
            Attr::Scaling => anchors.log_scalings.extend(v),
            Attr::Offsets => anchors.offsets.extend(v),
        }
    }
    anchors
        .check_shapes()
        .map_err(|r| IngestError::shape(&bs.display().to_string(), r))?;
    Ok(HacGop {
        anchors,
        n_static: infos.n_static,
        quantized,
        bound_min: bmin,
        bound_max: bmax,
        hash_bits,
        context: Some(ctx),
        symbols,
        batch: infos.batch,
        report,
        mlps,
        ntc: None,
    })
}

fn read_ntc(bs: &Path, prev: &HacGop, mlps: HacMlps) -> Result<HacGop, IngestError> {
    let mlp = mlps
        .ntc
        .as_ref()
        .ok_or_else(|| IngestError::format("mlps.pth", "an NTC GOP has no ntc_mlp"))?;
    mlp.check("ntc_mlp", ntc::NTC_IN, ntc::NTC_OUT, true)
        .map_err(|r| IngestError::format("mlps.pth", r))?;
    let p2 = bs.join("ntc_2D.b");
    let p3 = bs.join("ntc_3D.b");
    let plane_bits = bitstream::read_binary(&p2, ntc::plane_bits())?;
    let gate_bits = bitstream::read_binary(&p3, ntc::gate_bits())?;
    let grids = ntc::NtcGrids::from_bits(&plane_bits, &gate_bits)
        .ok_or_else(|| IngestError::shape(&bs.display().to_string(), "NTC bit counts"))?;
    let a = &prev.anchors;
    let positions = &a.positions;
    let parts: Vec<(Vec<f32>, Vec<f32>)> = positions
        .par_chunks(BLOCK)
        .map(|c| ntc::residuals(&grids, mlp, c, prev.bound_min, prev.bound_max))
        .collect();
    let mut d_feat = Vec::with_capacity(positions.len() * FEAT_DIM);
    let mut d_offsets = Vec::with_capacity(positions.len() * 3 * N_OFFSETS);
    for (f, o) in parts {
        d_feat.extend(f);
        d_offsets.extend(o);
    }
    let mut anchors = a.clone();
    anchors
        .features
        .iter_mut()
        .zip(&d_feat)
        .for_each(|(v, d)| *v += d);
    anchors
        .offsets
        .iter_mut()
        .zip(&d_offsets)
        .for_each(|(v, d)| *v += d);
    Ok(HacGop {
        anchors,
        n_static: prev.n_static,
        quantized: prev.quantized.clone(),
        bound_min: prev.bound_min,
        bound_max: prev.bound_max,
        hash_bits: Vec::new(),
        context: None,
        symbols: Default::default(),
        batch: prev.batch,
        report: DecodeReport::default(),
        mlps,
        ntc: Some(NtcResidual {
            plane_bits,
            gate_bits,
            d_feat,
            d_offsets,
        }),
    })
}
