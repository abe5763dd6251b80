//! `dlgs query`, `dlgs labels` and the 3D selection of `dlgs export`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use dlgs::model::lang_decoder::LangDecoder;
use dlgs::Gaussians;
use dlgs_query::{
    decoder_io, embeddings, images, query_levels, read_embeddings, select_gaussians, Embeddings,
    MaskParams, Precision, RelevanceField,
};
use dlgs_render::{render, RenderOptions};
use dlgs_testkit::labels::{read_point_annotations, LabelCodebook};

use crate::cameras_arg::CameraArgs;
use crate::scene_io::Source;

/// Where the decoder and negatives of a query come from.
#[derive(Args, Debug, Clone)]
pub struct QuerySource {
    /// Positive text embedding(s): .npy (D,) or (K, D), or JSON; one query per row.
    #[arg(long)]
    pub text_embedding: PathBuf,
    /// Negative embeddings (default: the ones stored in the file's language decoder).
    #[arg(long)]
    pub negatives: Option<PathBuf>,
    /// Language decoder (safetensors) for files without one (PLY scenes, or to override).
    #[arg(long)]
    pub lang_decoder: Option<PathBuf>,
    /// Softmax temperature of the relevance score.
    #[arg(long, default_value_t = dlgs_query::relevance::TEMPERATURE)]
    pub temperature: f32,
    /// Decode every distinct feature through the decoder instead of interpolating a table
    /// of decoded grid points (slower; see docs/benchmarks/queries.md for the difference).
    #[arg(long)]
    pub exact: bool,
    /// Table points per axis when not --exact.
    #[arg(long, default_value_t = dlgs_query::relevance::DEFAULT_TABLE)]
    pub table: usize,
    /// Use this language level (1-based) instead of choosing the best-scoring one.
    #[arg(long)]
    pub level: Option<usize>,
}

impl QuerySource {
    fn precision(&self) -> Precision {
        if self.exact {
            Precision::Exact
        } else {
            Precision::Table(self.table)
        }
    }
    fn level(&self, levels: usize) -> Result<Option<usize>> {
        match self.level {
            None => Ok(None),
            Some(l) if l >= 1 && l <= levels => Ok(Some(l - 1)),
            Some(l) => bail!("--level {l}: the scene has levels 1..={levels}"),
        }
    }
    /// Decoder, positives and negatives.
    fn load(&self, src: &mut Source) -> Result<(LangDecoder, Embeddings, Embeddings)> {
        let dec = match &self.lang_decoder {
            Some(p) => decoder_io::load_lang_decoder(p)?,
            None => src.lang_decoder()?.context(
                "the scene has no language decoder: encode it with --lang-decoder, or pass \
                 --lang-decoder here (see docs/queries.md)",
            )?,
        };
        let positives = read_embeddings(&self.text_embedding)?;
        let negatives = match &self.negatives {
            Some(p) => read_embeddings(p)?,
            None if !dec.negatives.is_empty() => {
                Embeddings::from_named(&dec.negatives).map_err(anyhow::Error::msg)?
            }
            None => bail!(
                "no negatives: the file's language decoder stores none, pass --negatives N.npy \
                 (the reference uses CLIP's \"object\", \"things\", \"stuff\", \"texture\")"
            ),
        };
        Ok((dec, positives, negatives))
    }
}

fn lang_shape(src: &Source, g: &Gaussians) -> Result<(usize, usize)> {
    match src.language_shape() {
        Some(s) => Ok(s),
        None if g.lang_width.is_multiple_of(3) && g.lang_width > 0 => Ok((g.lang_width / 3, 3)),
        None => bail!("the scene has no language features"),
    }
}

#[derive(Args, Debug, Clone)]
pub struct QueryArgs {
    /// .dlgs file (or a PLY with language features and --lang-decoder).
    pub file: PathBuf,
    /// Time in seconds.
    #[arg(long, default_value_t = 0.0)]
    pub t: f64,
    #[command(flatten)]
    pub cams: CameraArgs,
    #[command(flatten)]
    pub source: QuerySource,
    /// Mask threshold on the normalised relevance.
    #[arg(long, default_value_t = 0.4)]
    pub threshold: f32,
    /// Mean filter size applied to the relevance before normalising.
    #[arg(long, default_value_t = 29)]
    pub mean_kernel: usize,
    /// Smoothing filter size applied to the thresholded mask.
    #[arg(long, default_value_t = 7)]
    pub smooth_kernel: usize,
    /// Empty mask when the chosen level's score (mean relevance inside the mask) is below
    /// this: the text does not beat the negatives anywhere (0 = the reference, which then
    /// stretches noise to a mask).
    #[arg(long, default_value_t = 0.5)]
    pub min_score: f32,
    /// Output prefix: PREFIX.mask.png, PREFIX.heat.png, PREFIX.overlay.png (with several
    /// cameras or embeddings, _<camera>_<name> is appended).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Also time a colour-only render, to report what the query adds.
    #[arg(long)]
    pub timing: bool,
    #[arg(long)]
    pub json: bool,
}

fn out_path(prefix: &Path, tag: &str, kind: &str) -> PathBuf {
    let mut s = prefix.as_os_str().to_owned();
    s.push(tag);
    s.push(format!(".{kind}.png"));
    PathBuf::from(s)
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

pub fn run_query(a: &QueryArgs) -> Result<()> {
    let mut src = Source::open(&a.file)?;
    let (dec, positives, negatives) = a.source.load(&mut src)?;
    let mut field = RelevanceField::new(&dec, &positives, &negatives, a.source.precision())?;
    field.temperature = a.source.temperature;
    let canonical = src.canonical(a.t)?;
    let cameras = a.cams.resolve(&canonical)?;
    let (levels, dims) = lang_shape(&src, &canonical)?;
    let params = MaskParams {
        mean_kernel: a.mean_kernel,
        threshold: a.threshold,
        smooth_kernel: a.smooth_kernel,
        level: a.source.level(levels)?,
        min_score: a.min_score,
    };
    if let Some(parent) = a.output.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)?;
    }
    let mut report = Vec::new();
    for (ci, cam) in cameras.iter().enumerate() {
        let t0 = Instant::now();
        // Scaffold-GS files: the neural Gaussians of this camera with their language, only
        // the anchors in view (the same image as every anchor).
        let g = src.at_camera(a.t, cam, true, true)?;
        let decode_ms = ms(t0);
        if !g.has_language() {
            bail!("{} has no language features", a.file.display());
        }
        let colour_only_ms = if a.timing {
            let t = Instant::now();
            render(&g, cam, &RenderOptions::default()).map_err(anyhow::Error::msg)?;
            Some(ms(t))
        } else {
            None
        };
        let t1 = Instant::now();
        let img = render(
            &g,
            cam,
            &RenderOptions {
                features: true,
                ..RenderOptions::default()
            },
        )
        .map_err(anyhow::Error::msg)?;
        let render_ms = ms(t1);
        let features = img.features.as_ref().context("no language image")?;
        let (w, h) = (img.width as usize, img.height as usize);
        let t2 = Instant::now();
        let answers = query_levels(features, w, h, levels, dims, &field, &params);
        let query_ms = ms(t2);
        for (qi, ans) in answers.iter().enumerate() {
            let mut tag = String::new();
            if cameras.len() > 1 {
                tag.push_str(&format!("_{ci:02}"));
            }
            if answers.len() > 1 {
                tag.push_str(&format!("_{}", positives.names[qi]));
            }
            let lvl = &ans.levels[ans.level];
            images::save_mask(&out_path(&a.output, &tag, "mask"), &ans.mask, w, h)?;
            images::save_heatmap(&out_path(&a.output, &tag, "heat"), &lvl.normalised, w, h)?;
            images::save_overlay(
                &out_path(&a.output, &tag, "overlay"),
                &img.color,
                &ans.mask,
                w,
                h,
            )?;
            let selected = ans.mask.iter().filter(|&&m| m).count();
            let scores: Vec<f32> = ans.levels.iter().map(|l| l.score).collect();
            if !a.json {
                println!(
                    "{} '{}': level {} (scores {:?}), {selected} of {} pixels ({:.1}%) -> {}",
                    cam.name,
                    positives.names[qi],
                    ans.level + 1,
                    scores
                        .iter()
                        .map(|s| (s * 1000.0).round() / 1000.0)
                        .collect::<Vec<_>>(),
                    w * h,
                    100.0 * selected as f64 / (w * h) as f64,
                    out_path(&a.output, &tag, "mask").display()
                );
            }
            report.push(serde_json::json!({
                "camera": cam.name, "embedding": positives.names[qi], "level": ans.level + 1,
                "scores": scores, "selected_pixels": selected, "pixels": w * h,
            }));
        }
        let timing = serde_json::json!({
            "camera": cam.name, "width": w, "height": h, "decode_ms": decode_ms,
            "render_colour_and_language_ms": render_ms, "relevance_and_mask_ms": query_ms,
            "render_colour_only_ms": colour_only_ms,
        });
        if !a.json {
            let extra = colour_only_ms.map_or(String::new(), |c| {
                format!(
                    "; colour-only render {c:.1} ms, so the query adds {:.1} ms",
                    render_ms + query_ms - c
                )
            });
            println!(
                "  {w}x{h}: frame decode {decode_ms:.1} ms, render colour+language {render_ms:.1} ms, relevance+mask {query_ms:.1} ms ({}){extra}",
                match a.source.precision() {
                    Precision::Exact => "exact".to_string(),
                    Precision::Table(n) => format!("table {n}^3"),
                }
            );
        }
        report.push(timing);
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    Ok(())
}

/// 3D selection options of `dlgs export`.
#[derive(Args, Debug, Clone)]
pub struct SelectArgs {
    /// Select Gaussians relevant to this text embedding (first row).
    #[arg(long)]
    pub select: Option<PathBuf>,
    #[arg(long)]
    pub negatives: Option<PathBuf>,
    #[arg(long)]
    pub lang_decoder: Option<PathBuf>,
    /// Threshold on the per-Gaussian relevance.
    #[arg(long, default_value_t = dlgs_query::select::DEFAULT_THRESHOLD)]
    pub select_threshold: f32,
    /// Language level (1-based); default: the best-scoring one.
    #[arg(long)]
    pub level: Option<usize>,
    /// `keep` only the selection, `delete` it, or `highlight` it (tinted red).
    #[arg(long, default_value = "keep")]
    pub action: String,
    #[arg(long)]
    pub exact: bool,
}

/// A `--select` query loaded once (decoder, embeddings, language shape) and applied to any
/// number of frames; the relevance field built from it keeps its decoded table across frames.
pub struct Selection {
    args: SelectArgs,
    dec: LangDecoder,
    positives: Embeddings,
    negatives: Embeddings,
    precision: Precision,
    levels: usize,
    dims: usize,
    level: Option<usize>,
}

impl Selection {
    /// `None` without `--select`. `t`: a time of the scene (PLY scenes' language shape).
    pub fn load(a: &SelectArgs, src: &mut Source, t: f64) -> Result<Option<Self>> {
        let Some(sel) = &a.select else {
            return Ok(None);
        };
        let qs = QuerySource {
            text_embedding: sel.clone(),
            negatives: a.negatives.clone(),
            lang_decoder: a.lang_decoder.clone(),
            temperature: dlgs_query::relevance::TEMPERATURE,
            exact: a.exact,
            table: dlgs_query::relevance::DEFAULT_TABLE,
            level: a.level,
        };
        let (dec, positives, negatives) = qs.load(src)?;
        let (levels, dims) = match src.language_shape() {
            Some(shape) => shape,
            None => {
                let sample = src.canonical(t)?;
                lang_shape(src, &sample)?
            }
        };
        Ok(Some(Selection {
            args: a.clone(),
            dec,
            positives,
            negatives,
            precision: qs.precision(),
            levels,
            dims,
            level: qs.level(levels)?,
        }))
    }

    pub fn field(&self) -> Result<RelevanceField<'_>> {
        Ok(RelevanceField::new(
            &self.dec,
            &self.positives,
            &self.negatives,
            self.precision,
        )?)
    }

    /// Keep, delete or highlight the selected Gaussians of `g`.
    pub fn apply(&self, field: &RelevanceField, g: Gaussians) -> Result<Gaussians> {
        let a = &self.args;
        let t = Instant::now();
        let s = select_gaussians(
            &g,
            self.levels,
            self.dims,
            field,
            0,
            a.select_threshold,
            self.level,
        )?;
        eprintln!(
            "selected {} of {} Gaussians for '{}' at level {} ({:.1} ms)",
            s.count(),
            g.len(),
            self.positives.names[0],
            s.level + 1,
            ms(t)
        );
        let mut out = Gaussians::new(g.sh_degree, g.lang_width);
        match a.action.as_str() {
            "keep" | "delete" => {
                let keep = a.action == "keep";
                for i in 0..g.len() {
                    if s.selected[i] == keep {
                        out.push_from(&g, i);
                    }
                }
            }
            "highlight" => {
                out = g.clone();
                let c = dlgs::model::sh_coeffs(g.sh_degree);
                for i in (0..g.len()).filter(|&i| s.selected[i]) {
                    // SH DC of pure red, view-independent.
                    let sh = &mut out.sh[i * 3 * c..(i + 1) * 3 * c];
                    sh.fill(0.0);
                    sh[0] = (1.0 - 0.5) / 0.282_094_8;
                    sh[1] = -0.5 / 0.282_094_8;
                    sh[2] = -0.5 / 0.282_094_8;
                }
            }
            v => bail!("--action {v}: expected keep, delete or highlight"),
        }
        Ok(out)
    }
}

#[derive(Args, Debug, Clone)]
pub struct LabelsArgs {
    /// Real scene (PLY) the labels belong to.
    pub scene: PathBuf,
    /// SuperSplat annotation JSON with one label per Gaussian.
    #[arg(long)]
    pub annotations: PathBuf,
    /// Output directory.
    #[arg(short, long)]
    pub output: PathBuf,
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
}

/// `dlgs labels`: a query test scene from real per-Gaussian labels.
pub fn run_labels(a: &LabelsArgs) -> Result<()> {
    let g = dlgs::interop::read_splat_file(&a.scene)
        .with_context(|| format!("reading {}", a.scene.display()))?;
    let text = std::fs::read_to_string(&a.annotations)
        .with_context(|| format!("reading {}", a.annotations.display()))?;
    let labels = read_point_annotations(&text)?;
    // Codes placed so that categories touching in 3D blend without decoding to a third one.
    let book = LabelCodebook::for_scene(&g, &labels, a.seed)?;
    let lg = book.apply(&g, &labels)?;
    std::fs::create_dir_all(&a.output)?;
    let scene_out = a.output.join("scene.ply");
    std::fs::write(&scene_out, dlgs::interop::ply::write_ply(&lg)?)?;
    decoder_io::save_lang_decoder(&a.output.join("lang_decoder.safetensors"), &book.decoder)?;
    embeddings::write_npy(&a.output.join("negatives.npy"), &book.negatives())?;
    let mut counts = [0usize; dlgs_testkit::labels::MAX_CATEGORIES];
    for &l in &labels {
        counts[l as usize] += 1;
    }
    for (l, &n) in counts.iter().enumerate() {
        embeddings::write_npy(
            &a.output.join(format!("category_{l}.npy")),
            &book.category_embedding(l as u16),
        )?;
        println!("category {l}: {n} Gaussians -> category_{l}.npy");
    }
    embeddings::write_npy(
        &a.output.join("any_category.npy"),
        &book.labelled_embedding(),
    )?;
    println!(
        "{} Gaussians with SYNTHETIC 9-dim language from the labels -> {}\n\
         constructed language decoder (3->16->32->64->128->256->512) -> lang_decoder.safetensors, \
         stand-in negatives -> negatives.npy\n\
         next: dlgs encode {} -o scene.dlgs --lang-decoder {} --negatives {}",
        lg.len(),
        scene_out.display(),
        scene_out.display(),
        a.output.join("lang_decoder.safetensors").display(),
        a.output.join("negatives.npy").display()
    );
    Ok(())
}
