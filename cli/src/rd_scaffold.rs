//! `dlgs rd` of a Scaffold-GS file: sweeps the near-lossless anchor steps (`--anchor-step-scale`)
//! by re-coding the file's own HAC-coded anchors (`dlgs_encoder::scaffold_recode`; no HAC run
//! folder needed; raw `ANCR` anchors are coded with the per-channel prior at k times its
//! default steps), and measures each file as `dlgs rd` does for 3DGS: bytes, bytes per frame,
//! decode time per frame (frame f for camera f mod the cameras, culled, GOPs included), colour
//! PSNR / SSIM and, with a language MLP, language PSNR of renders against the file itself.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use dlgs_decoder::scaffold::ScaffoldDecoder;
use dlgs_encoder::scaffold_recode::recode_anchor_steps;
use dlgs_render::{metrics, Camera, Image};

use crate::rd_cmd::{list, renders, sample_times, write_outputs, RdArgs, Row, Setting};
use crate::scene_io::Source;

/// Every frame in order, frame f seen by camera f mod `cams` (culled), with a fresh decoder:
/// mean wall time per frame, GOP decoding included.
fn decode_ms_per_frame(file: &Path, cams: &[Camera]) -> Result<f64> {
    let t0 = Instant::now();
    let f = File::open(file).with_context(|| format!("opening {}", file.display()))?;
    let mut dec = ScaffoldDecoder::new(BufReader::new(f), dlgs::Limits::default())
        .with_context(|| format!("opening {}", file.display()))?;
    let (frames, fps) = (dec.scene().frame_count.max(1), dec.scene().fps());
    for f in 0..frames {
        let cam = &cams[f as usize % cams.len()];
        let in_view = |p: &[[f32; 3]], r: &[f32]| dlgs_render::cull::spheres_in_view(cam, p, r);
        let frame = dec
            .frame_in_view(f as f64 / fps, cam.position.to_array(), false, &in_view)
            .with_context(|| format!("decoding frame {f} of {}", file.display()))?;
        drop(std::hint::black_box(frame));
    }
    Ok(t0.elapsed().as_secs_f64() * 1e3 / frames as f64)
}

/// PSNR of two language feature images with the given peak (`inf` if identical).
pub(crate) fn feature_psnr(a: &[f32], b: &[f32], peak: f64) -> f64 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2))
        .sum::<f64>()
        / a.len().max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (peak * peak / mse).log10()
    }
}

/// The language images' peak: the range of the reference's values (1 if they are constant).
pub(crate) fn feature_peak(images: &[Image]) -> f64 {
    let (lo, hi) = images
        .iter()
        .filter_map(|i| i.features.as_deref())
        .flatten()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let range = f64::from(hi) - f64::from(lo);
    if range > 0.0 {
        range
    } else {
        1.0
    }
}

pub fn run(a: &RdArgs) -> Result<()> {
    let given: Vec<&str> = [
        ("--crf", a.crf.is_some()),
        ("--quality", a.quality.is_some()),
        ("--bits", a.bits.is_some()),
        ("--encode-flags", !a.encode_flags.trim().is_empty()),
    ]
    .into_iter()
    .filter_map(|(f, set)| set.then_some(f))
    .collect();
    if !given.is_empty() {
        bail!(
            "{}: {} is a Scaffold-GS file, whose sweep is --anchor-step-scale (its time features \
             and MLPs are kept as they are)",
            given.join(", "),
            a.model.display()
        );
    }
    let ks: Vec<f32> = list(
        a.anchor_step_scale.as_deref().unwrap_or("1,2,4,8"),
        "anchor-step-scale",
    )?;
    if ks.is_empty() {
        bail!("nothing to sweep: give --anchor-step-scale values");
    }
    if let Some(k) = ks.iter().find(|k| !(k.is_finite() && **k > 0.0)) {
        bail!("--anchor-step-scale: {k} is not a finite number > 0");
    }
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;

    let mut reference = Source::open(&a.model)?;
    let cams = a.cams.resolve(&reference.canonical(0.0)?)?;
    let times = sample_times(&reference, a.times);
    let language = reference.language_shape().is_some();
    let ref_images = renders(&mut reference, &times, &cams, language, a.fast_render)?;
    let peak = feature_peak(&ref_images);

    let bar = indicatif::ProgressBar::new(ks.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} anchor step scales {eta}")
            .expect("valid template"),
    );
    let tmp = a.output.join("rd_current.dlgs");
    let mut rows = Vec::new();
    for k in ks {
        let t0 = Instant::now();
        let f = File::open(&a.model).with_context(|| format!("opening {}", a.model.display()))?;
        let (bytes, _) = recode_anchor_steps(
            BufReader::new(f),
            k,
            crate::hac_ingest_cmd::ZSTD_LEVEL,
            dlgs::Limits::default(),
        )
        .with_context(|| format!("re-coding the anchors of {} at k = {k}", a.model.display()))?;
        let encode_s = t0.elapsed().as_secs_f64();
        std::fs::write(&tmp, &bytes).with_context(|| format!("writing {}", tmp.display()))?;
        let decode_ms_per_frame = decode_ms_per_frame(&tmp, &cams)?;
        let mut test = Source::open(&tmp)?;
        let frames = test.timing().map_or(1, |(_, n)| n.max(1));
        let images = renders(&mut test, &times, &cams, language, a.fast_render)?;
        let (mut psnr, mut ssim, mut lang) = (0.0, 0.0, 0.0);
        for (r, t) in ref_images.iter().zip(&images) {
            psnr += metrics::psnr(&r.color, &t.color);
            ssim += metrics::ssim(&r.color, &t.color, r.width, r.height);
            if let (Some(x), Some(y)) = (&r.features, &t.features) {
                lang += feature_psnr(x, y, peak);
            }
        }
        let n = images.len() as f64;
        rows.push(Row {
            setting: Setting {
                quality: crate::rd_cmd::ANCHOR_STEPS.into(),
                bits: None,
                crf: None,
                anchor_step_scale: Some(k),
            },
            bytes: bytes.len() as u64,
            frames,
            psnr: psnr / n,
            ssim: ssim / n,
            lang_psnr: language.then_some(lang / n),
            decode_ms_per_frame,
            encode_s,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();
    let _ = std::fs::remove_file(&tmp);
    write_outputs(a, &rows, times.len() * cams.len())
}
