//! PNG plots of an RD sweep with `plotters`: one line per codec setting family (across crf),
//! x = bytes per frame or decode ms per frame, y = PSNR. Text needs a TrueType font: `DLGS_FONT`
//! or DejaVu Sans (Debian: fonts-dejavu-core, installed by scripts/setup.sh).

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;

/// One measured point of a series.
pub struct Point {
    pub x: f64,
    pub psnr: f64,
    pub label: String,
}

const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
];

/// Register a sans-serif font for plot text (once per process).
pub fn register_font() -> Result<PathBuf> {
    static FONT: std::sync::OnceLock<Result<PathBuf, String>> = std::sync::OnceLock::new();
    FONT.get_or_init(|| {
        let candidates: Vec<PathBuf> = std::env::var_os("DLGS_FONT")
            .map(PathBuf::from)
            .into_iter()
            .chain(FONT_PATHS.iter().map(PathBuf::from))
            .collect();
        let path = candidates.into_iter().find(|p| p.exists()).ok_or_else(|| {
            "no TrueType font for plot text: install fonts-dejavu-core or set DLGS_FONT".to_string()
        })?;
        let bytes = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        // plotters keeps registered fonts for the life of the process.
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| format!("{}: not a usable TrueType font", path.display()))?;
        Ok(path)
    })
    .clone()
    .map_err(|e| anyhow!(e))
}

fn padded(lo: f64, hi: f64, log: bool) -> (f64, f64) {
    if log {
        return (lo / 1.25, hi * 1.25);
    }
    let pad = ((hi - lo) * 0.08).max(0.05);
    (lo - pad, hi + pad)
}

/// Draw `series` (name, points ordered along the curve) into a PNG. `log_x`: a log x axis
/// when the values span more than a factor of 8 (fewer ticks than that read badly).
/// `lines`: join each series' points (for curves; not for noisy measurements).
pub fn plot(
    path: &Path,
    title: &str,
    x_label: &str,
    log_x: bool,
    lines: bool,
    series: &[(String, Vec<Point>)],
) -> Result<()> {
    register_font()?;
    let all: Vec<&Point> = series.iter().flat_map(|s| &s.1).collect();
    if all.is_empty() {
        return Ok(());
    }
    let finite = |v: f64| if v.is_finite() { v } else { 99.0 };
    let (x0, x1) = all
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.x), b.max(p.x)));
    let (y0, y1) = all.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
        (a.min(finite(p.psnr)), b.max(finite(p.psnr)))
    });
    let log_x = log_x && x0 > 0.0 && x1 / x0 > 8.0;
    let (x0, x1) = padded(x0.max(1e-9), x1.max(1e-9), log_x);
    let (y0, y1) = padded(y0, y1, false);
    let root = BitMapBackend::new(path, (960, 640)).into_drawing_area();
    let draw = |e: &dyn std::fmt::Display| anyhow!("drawing {}: {e}", path.display());
    root.fill(&WHITE).map_err(|e| draw(&e))?;
    let mut builder = ChartBuilder::on(&root);
    builder
        .caption(title, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(64);
    macro_rules! finish {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc("PSNR (dB)")
                .label_style(("sans-serif", 15))
                .draw()
                .map_err(|e| draw(&e))?;
            for (i, (name, pts)) in series.iter().enumerate() {
                let colour = Palette99::pick(i).to_rgba();
                let xy: Vec<(f64, f64)> = pts.iter().map(|p| (p.x, finite(p.psnr))).collect();
                if lines {
                    chart
                        .draw_series(LineSeries::new(xy.clone(), colour.stroke_width(2)))
                        .map_err(|e| draw(&e))?;
                }
                chart
                    .draw_series(
                        xy.iter()
                            .map(|&(x, y)| Circle::new((x, y), 4, colour.filled())),
                    )
                    .map_err(|e| draw(&e))?
                    .label(name.clone())
                    .legend(move |(x, y)| Circle::new((x + 10, y), 4, colour.filled()));
                chart
                    .draw_series(pts.iter().map(|p| {
                        Text::new(p.label.clone(), (p.x, finite(p.psnr)), ("sans-serif", 13))
                    }))
                    .map_err(|e| draw(&e))?;
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 15))
                .draw()
                .map_err(|e| draw(&e))?;
        }};
    }
    if log_x {
        finish!(builder
            .build_cartesian_2d((x0..x1).log_scale(), y0..y1)
            .map_err(|e| draw(&e))?);
    } else {
        finish!(builder
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| draw(&e))?);
    }
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
