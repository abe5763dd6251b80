//! `dlgs encode x.dlgs -o y.dlgs` of a Scaffold-GS file: its anchors re-coded
//! (`dlgs_encoder::scaffold_recode`): HAC-coded anchors (`AHAC`) with `--anchor-step-scale k`
//! times their steps; raw anchors (`ANCR`) HAC-coded at the coarsest steps within
//! `--anchor-budget-db` of the uncoded renders (`anchor_steps`) with a context model fitted to
//! them (`dlgs_encoder::scaffold_fit`), or with the per-channel prior (`--anchor-prior`, fast).
//! Every other chunk is copied.

use std::fs::File;
use std::io::{BufReader, Write};
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use dlgs::container::{ChunkType, FileReader};
use dlgs_encoder::scaffold_fit::ContextFitSettings;
use dlgs_encoder::scaffold_prior::DEFAULT_PRIOR_STEPS;
use dlgs_encoder::scaffold_recode::{recode_anchors, RawAnchorCoding, RecodeOptions};

use crate::anchor_steps::{choose, Judge, Judged};
use crate::codec_args::CodecArgs;
use crate::pending_file::PendingFile;

/// Whether any GOP of the file at `path` holds a chunk of type `ty`.
fn has_chunk(path: &Path, ty: ChunkType) -> Result<bool> {
    let f = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut r = FileReader::open(BufReader::new(f))?;
    for g in 0..r.scene().gop_count {
        if r.gop_chunks(g)?.iter().any(|c| c.ty == ty) {
            return Ok(true);
        }
    }
    Ok(false)
}

pub(crate) fn parse_steps(s: &str) -> Result<[f32; 3]> {
    let v: Vec<f32> = crate::rd_cmd::list(s, "anchor-steps")?;
    match v.as_slice() {
        [f, s, o] if v.iter().all(|q| q.is_finite() && *q > 0.0) => Ok([*f, *s, *o]),
        _ => bail!("--anchor-steps {s}: three finite steps > 0 (feature, log-scaling, offsets)"),
    }
}

fn bar(len: u64, what: &str) -> indicatif::ProgressBar {
    let b = indicatif::ProgressBar::new(len);
    b.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{{bar:40}} {{pos}}/{{len}} {what} {{eta}}"
        ))
        .expect("valid template"),
    );
    b
}

/// What the step search reached: the chosen steps' judgement, candidates judged, seconds.
type Searched = (Judged, usize, f64);

/// The raw anchors' coding the options ask for, with the search's result when it ran.
fn raw_coding(
    input: &Path,
    output: &Path,
    codec: &CodecArgs,
) -> Result<(RecodeOptions, Option<Searched>)> {
    let k = codec.anchor_step_scale;
    let mut searched = None;
    let mut rntc_mantissa = 23;
    let steps = match &codec.anchor_steps {
        Some(s) => parse_steps(s)?,
        None if codec.anchor_prior || k != 1.0 => DEFAULT_PRIOR_STEPS.map(|q| q * k),
        None => {
            let t0 = Instant::now();
            let name = output
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let scratch = output.with_file_name(format!(".{name}.steps.dlgs"));
            let mut judge = Judge::new(input, &scratch)?;
            let b = bar(0, "anchor step candidates judged");
            let rntc = has_chunk(input, ChunkType::RNTC)?;
            let j = choose(&mut judge, codec.anchor_budget_db, rntc, &mut |n| {
                b.set_length(n as u64);
                b.set_position(n as u64);
            })?;
            b.finish_and_clear();
            searched = Some((j, judge.judged.len(), t0.elapsed().as_secs_f64()));
            rntc_mantissa = j.rntc_mantissa;
            j.steps
        }
    };
    let raw = if codec.anchor_prior {
        RawAnchorCoding::Prior(steps)
    } else {
        RawAnchorCoding::Fitted(ContextFitSettings {
            iterations: codec.anchor_fit_iterations,
            ..ContextFitSettings::new(steps)
        })
    };
    let o = RecodeOptions {
        k,
        raw,
        rntc_mantissa,
    };
    Ok((o, searched))
}

pub fn run(input: &Path, output: &Path, codec: &CodecArgs) -> Result<()> {
    let k = codec.anchor_step_scale;
    let (o, searched) = if has_chunk(input, ChunkType::ANCR)? {
        raw_coding(input, output, codec)?
    } else {
        let o = RecodeOptions {
            k,
            raw: RawAnchorCoding::Prior(DEFAULT_PRIOR_STEPS.map(|q| q * k)),
            rntc_mantissa: 23,
        };
        (o, None)
    };
    let f = File::open(input).with_context(|| format!("opening {}", input.display()))?;
    let in_bytes = f.metadata().map(|m| m.len()).unwrap_or(0);
    let b = bar(0, "context fit iterations");
    let t0 = Instant::now();
    let (bytes, report) = recode_anchors(
        BufReader::new(f),
        &o,
        crate::hac_ingest_cmd::ZSTD_LEVEL,
        dlgs::Limits::default(),
        &mut |done, total| {
            b.set_length(total as u64);
            b.set_position(done as u64);
        },
    )
    .with_context(|| format!("re-coding the anchors of {}", input.display()))?;
    b.finish_and_clear();
    let coding_s = t0.elapsed().as_secs_f64();
    let out = PendingFile::create(output)?;
    let mut w = out.writer()?;
    w.write_all(&bytes)
        .with_context(|| format!("writing {}", output.display()))?;
    out.commit_written(w)?;
    println!(
        "{} -> {}: {} bytes ({:.1} % of the input); anchors of {} GOP(s) HAC-coded: {} -> {} bytes",
        input.display(),
        output.display(),
        bytes.len(),
        100.0 * bytes.len() as f64 / in_bytes.max(1) as f64,
        report.ahac_chunks,
        report.ahac_bytes_before,
        report.ahac_bytes_after,
    );
    if report.from_raw > 0 {
        let steps = o.raw.steps();
        match &searched {
            Some((j, n, s)) => println!(
                "raw anchors of {} GOP(s): steps {steps:?} (feature, log-scaling, offsets), the \
                 coarsest within {} dB: colour {:.2} dB{} on the judge renders against the \
                 uncoded anchors ({n} candidates judged in {s:.1} s)",
                report.from_raw,
                codec.anchor_budget_db,
                j.colour_db,
                j.language_db
                    .map_or(String::new(), |l| format!(", language {l:.2} dB")),
            ),
            None => println!("raw anchors of {} GOP(s): steps {steps:?}", report.from_raw),
        }
        if report.fits.is_empty() {
            println!("coded with the per-channel prior (--anchor-prior)");
        }
        for (g, fit) in report.fits.iter().enumerate() {
            println!(
                "raw GOP {g}: context model fitted in {:.1} s ({} iterations): {} bytes with it \
                 against {} with the per-channel prior{} (grids {} B, mlp_grid {} B at {} \
                 mantissa bits, symbols {} B)",
                fit.fit_seconds,
                codec.anchor_fit_iterations,
                fit.fitted_bytes,
                fit.prior_bytes,
                if fit.kept_fit {
                    ""
                } else {
                    ": the prior was kept"
                },
                fit.sizes.grids,
                fit.sizes.mlp,
                fit.mantissa_bits,
                fit.sizes.streams.iter().sum::<usize>(),
            );
        }
        if report.rntc_chunks > 0 {
            println!(
                "anchor residuals (RNTC) of {} GOP(s): MLP weights at {} mantissa bits, {} -> {} \
                 bytes",
                report.rntc_chunks,
                o.rntc_mantissa,
                report.rntc_bytes_before,
                report.rntc_bytes_after
            );
        }
        println!("anchors coded in {coding_s:.1} s");
    }
    Ok(())
}
