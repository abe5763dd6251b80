//! One reference run: its GOP folders, read and decoded exactly as the reference's test-time
//! decoder does (`test_fdsd.py`: `decompress_attr_3`, `measure_decode_latency`,
//! `load_compressed_offset`, `get_*_ori`). The compressed files are what is read: they are what
//! the reference's own player renders (`model.pth` holds the training-side values before
//! compression, so where both exist the compressed files win).

use std::path::{Path, PathBuf};

use dlgs::chunks::tfea::{self, Tiling};
use dlgs::model::dynamic::{DeformMlps, Mlp, MlpRole};
use dlgs::model::TimeFeatures;
use dlgs::{Gaussians, Limits};

use crate::csv::{self, Row};
use crate::latents::{self, LatentResidual};
use crate::ref_gop::{check_sets, mlp_from_state, read, SetTensors};
pub use crate::ref_gop::{FeatureSource, RefGop, RunFile, CHANNELS, KEYS, LANG};
use crate::torch;
use crate::{check_finite, checkpoint, jxl, IngestError};

/// The GOP folders a user names: a `jxl_quant` folder itself, a `gop<g>_<postfix>` folder
/// (its `compression/best/jxl_quant`), or a scene folder holding `gop<g>_*` folders (taken in
/// GOP order).
pub fn resolve(paths: &[PathBuf]) -> Result<Vec<PathBuf>, IngestError> {
    let mut out = Vec::new();
    for p in paths {
        if !p.is_dir() {
            return Err(IngestError::Missing {
                path: p.clone(),
                what: "a reference output folder".into(),
            });
        }
        if has_compressed(p)
            || p.join("model.pth").is_file()
            || p.join(checkpoint::OFFSET_CHECKPOINT).is_file()
        {
            out.push(p.clone());
            continue;
        }
        let best = p.join("compression/best/jxl_quant");
        if best.is_dir() {
            out.push(best);
            continue;
        }
        let mut gops: Vec<(u32, PathBuf)> = std::fs::read_dir(p)
            .map_err(|e| IngestError::Io {
                what: p.display().to_string(),
                source: e,
            })?
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().into_string().ok()?;
                let g = name.strip_prefix("gop")?.split('_').next()?.parse().ok()?;
                let dir = e.path().join("compression/best/jxl_quant");
                dir.is_dir().then_some((g, dir))
            })
            .collect();
        if gops.is_empty() {
            return Err(IngestError::Missing {
                path: p.clone(),
                what: "compression_info.csv, compression/best/jxl_quant or gop<g>_* folders".into(),
            });
        }
        gops.sort();
        out.extend(gops.into_iter().map(|(_, d)| d));
    }
    Ok(out)
}

/// Whether a GOP folder holds the reference's compressed files (else its checkpoints are read).
pub fn has_compressed(dir: &Path) -> bool {
    dir.join("compression_info.csv").is_file()
}

/// Side of a square grid of `n` cells, or an error naming the attribute.
fn square_side(n: usize, what: &str) -> Result<usize, IngestError> {
    let s = (n as f64).sqrt().round() as usize;
    if s * s != n {
        return Err(IngestError::shape(
            what,
            format!("{n} Gaussians is not a square grid (the reference needs side x side)"),
        ));
    }
    Ok(s)
}

/// An attribute image decoded like `decode_with_normalization`: `img * (max - min) + min`,
/// NumPy 1.x arithmetic (the f64 CSV scalars are cast to f32, then one f32 multiply and one
/// f32 add); unnormalised attributes (empty CSV range) are taken as stored.
fn attribute(
    dir: &Path,
    rows: &[Row],
    name: &str,
    channels: usize,
    limits: &Limits,
) -> Result<Vec<f32>, IngestError> {
    let row = csv::find(rows, name).ok_or_else(|| {
        IngestError::format(
            &format!("{}/compression_info.csv", dir.display()),
            format!("no row {name}"),
        )
    })?;
    let path = dir.join(&row.file);
    let what = path.display().to_string();
    let a = jxl::decode(&read(&path, name, limits)?, &what)?;
    if a.data.len() % channels != 0 {
        return Err(IngestError::shape(
            &what,
            format!(
                "{} samples, not a multiple of {channels} channels",
                a.data.len()
            ),
        ));
    }
    // C <= 4: one frame of C channels; C > 4: an animation of side frames of W = C samples.
    let layout_ok = if channels <= 4 {
        a.frames == 1 && a.channels == channels
    } else {
        a.channels == 1 && a.width == channels && a.frames == a.height
    };
    if !layout_ok {
        return Err(IngestError::shape(
            &what,
            format!(
                "{} frame(s) of {}x{}x{}, expected a {channels}-channel grid",
                a.frames, a.height, a.width, a.channels
            ),
        ));
    }
    let mut v = a.data;
    if let Some((lo, hi)) = row.range {
        let (d, m) = ((hi - lo) as f32, lo as f32);
        for x in &mut v {
            *x = *x * d + m;
        }
    }
    check_finite(&what, &v)?;
    Ok(v)
}

fn read_set(
    dir: &Path,
    rows: &[Row],
    suffix: &str,
    limits: &Limits,
) -> Result<SetTensors, IngestError> {
    let name = |a: &str| format!("_{a}{suffix}");
    let rest_row = csv::find(rows, &name("features_rest"));
    let rest_channels = match rest_row {
        // The channel count follows from the image: read it once with its own shape.
        Some(r) => {
            let p = dir.join(&r.file);
            let a = jxl::decode(&read(&p, "SH rest", limits)?, &p.display().to_string())?;
            if a.frames > 1 {
                a.width
            } else {
                a.channels
            }
        }
        None => 0,
    };
    let has_lang = csv::find(rows, &name("language_feature")).is_some();
    let opacity_dim = if has_lang { 2 } else { 1 };
    let set = SetTensors {
        xyz: attribute(dir, rows, &name("xyz"), 3, limits)?,
        dc: attribute(dir, rows, &name("features_dc"), 3, limits)?,
        rest: if rest_channels > 0 {
            attribute(dir, rows, &name("features_rest"), rest_channels, limits)?
        } else {
            vec![]
        },
        scaling: attribute(dir, rows, &name("scaling"), 3, limits)?,
        rotation: attribute(dir, rows, &name("rotation"), 4, limits)?,
        opacity: attribute(dir, rows, &name("opacity"), opacity_dim, limits)?,
        opacity_dim,
        lang: if has_lang {
            Some(attribute(
                dir,
                rows,
                &name("language_feature"),
                LANG,
                limits,
            )?)
        } else {
            None
        },
        rest_channels,
    };
    square_side(set.count(), &format!("{}/{}", dir.display(), name("xyz")))?;
    Ok(set)
}

fn read_features(
    dir: &Path,
    rows: &[Row],
    n: usize,
    limits: &Limits,
) -> Result<(TimeFeatures, FeatureSource), IngestError> {
    let side = square_side(n, &dir.join("_point_feats.mp4").display().to_string())?;
    read_feature_video(dir, "_point_feats", rows, n, side, limits)
}

/// A GOP's time-feature video `{name}.mp4` in `dir` (12-bit HEVC, 7 key pictures of 4 x 4
/// tiles of `side` x `side`) dequantised with the `{name}` row's min/max of
/// `compression_info.csv` as the reference does. The 3DGS variant's tiles are exactly `n`
/// (`_point_feats`); the HAC variant's are `ceil(sqrt(n))` wide, zero-padded
/// (`_temporal_feat`).
pub fn read_feature_video(
    dir: &Path,
    name: &str,
    rows: &[Row],
    n: usize,
    side: usize,
    limits: &Limits,
) -> Result<(TimeFeatures, FeatureSource), IngestError> {
    let path = dir.join(format!("{name}.mp4"));
    let what = path.display().to_string();
    if !path.is_file() {
        return Err(IngestError::Missing {
            path,
            what: "the time-feature video".into(),
        });
    }
    if let Ok(m) = std::fs::metadata(&path) {
        limits.check_alloc("reference run file size", m.len(), 0)?;
    }
    let row = csv::find(rows, name).and_then(|r| r.range).ok_or_else(|| {
        IngestError::format(
            &format!("{}/compression_info.csv", dir.display()),
            format!("no {name} min/max"),
        )
    })?;
    if side * side < n {
        return Err(IngestError::shape(
            &what,
            format!("{side}^2 tiles for {n} rows"),
        ));
    }
    let track =
        dlgs_video::demux_hevc(&path).map_err(|e| IngestError::format(&what, e.to_string()))?;
    if track.width as usize != 4 * side || track.height as usize != 4 * side {
        return Err(IngestError::shape(
            &what,
            format!(
                "{}x{} pictures, expected {}x{} for {n} dynamic rows",
                track.width,
                track.height,
                4 * side,
                4 * side
            ),
        ));
    }
    let refs: Vec<&[u8]> = track.packets.iter().map(|p| p.as_slice()).collect();
    let video = dlgs_video::decode_gray12(&refs, track.width, track.height, KEYS)
        .map_err(|e| IngestError::format(&what, format!("{e} (truncated or damaged video?)")))?;
    let tiling = Tiling {
        n,
        keys: KEYS,
        channels: CHANNELS,
        side,
    };
    let f = tfea::untile_reference(&video.frames, &tiling, row);
    check_finite(&what, &f.data)?;
    Ok((
        f,
        FeatureSource::Video {
            packets: track.packets,
            side,
            range: row,
        },
    ))
}

/// `nn.Sequential(Linear(i, 64, bias=False), ReLU, Linear(64, o, bias=False)[, Tanh])` weights.
fn read_mlp(dir: &Path, file: &str, role: MlpRole, limits: &Limits) -> Result<Mlp, IngestError> {
    let path = dir.join(file);
    let what = path.display().to_string();
    let bytes = read(&path, "a deformation decoder", limits)?;
    let tensors = torch::read_zip_state_dict(std::io::Cursor::new(bytes), &what)?;
    mlp_from_state(tensors.iter().map(|(k, t)| (k.as_str(), t)), role, &what)
}

fn read_mlps(
    dir: &Path,
    language: bool,
    scale_offsets: bool,
    limits: &Limits,
) -> Result<DeformMlps, IngestError> {
    Ok(DeformMlps {
        deform: read_mlp(dir, "mlp_deform.pth", MlpRole::Deform, limits)?,
        cov: read_mlp(dir, "mlp_cov.pth", MlpRole::Cov, limits)?,
        opacity: read_mlp(dir, "mlp_opacity.pth", MlpRole::Opacity, limits)?,
        color: read_mlp(dir, "mlp_color.pth", MlpRole::Color, limits)?,
        lang: if language {
            Some(read_mlp(dir, "mlp_lang.pth", MlpRole::Lang, limits)?)
        } else {
            None
        },
        scale_offsets,
    })
}

/// The files the reference counts per GOP (`test_fdsd.py:test_all`): the mp4, the attribute
/// images (GOP 0) or re-sent positions and latents (GOP >= 1), four MLPs, the CSV; and the
/// files it does not count but a decoder needs (`mlp_lang.pth`).
pub(crate) fn list_files(dir: &Path, first: bool, language: bool) -> Vec<RunFile> {
    let mut names: Vec<(String, bool)> = vec![("_point_feats.mp4".into(), true)];
    if first {
        for a in [
            "_xyz",
            "_scaling",
            "_rotation",
            "_opacity",
            "_features_dc",
            "_features_rest",
        ] {
            names.push((format!("{a}.jxl"), true));
            names.push((format!("{a}_dynamic.jxl"), true));
        }
        if language {
            names.push(("_language_feature.jxl".into(), true));
            names.push(("_language_feature_dynamic.jxl".into(), true));
        }
    } else {
        names.push(("_xyz_offset.jxl".into(), true));
        names.push(("_xyz_dynamic_offset.jxl".into(), true));
        names.push(("offset_compressed.pkl".into(), true));
    }
    for m in ["mlp_deform", "mlp_cov", "mlp_opacity", "mlp_color"] {
        names.push((format!("{m}.pth"), true));
    }
    names.push(("compression_info.csv".into(), true));
    if language {
        names.push(("mlp_lang.pth".into(), false));
    }
    names
        .into_iter()
        .filter_map(|(name, counted)| {
            let bytes = std::fs::metadata(dir.join(&name)).ok()?.len();
            Some(RunFile {
                name,
                bytes,
                counted,
            })
        })
        .collect()
}

fn csv_rows(dir: &Path, limits: &Limits) -> Result<Vec<Row>, IngestError> {
    let path = dir.join("compression_info.csv");
    let what = path.display().to_string();
    let text = String::from_utf8(read(&path, "the attribute ranges", limits)?)
        .map_err(|_| IngestError::format(&what, "not UTF-8"))?;
    csv::parse(&text, &what)
}

/// Read GOP 0 (full canonical state).
pub fn read_first(dir: &Path, limits: &Limits) -> Result<RefGop, IngestError> {
    let rows = csv_rows(dir, limits)?;
    let statics =
        read_set(dir, &rows, "", limits)?.gaussians(&dir.display().to_string(), limits)?;
    let dynamics =
        read_set(dir, &rows, "_dynamic", limits)?.gaussians(&dir.display().to_string(), limits)?;
    check_sets(&statics, &dynamics, &dir.display().to_string())?;
    let language = statics.lang_width > 0;
    let (features, feature_source) = read_features(dir, &rows, dynamics.len(), limits)?;
    Ok(RefGop {
        dir: dir.to_path_buf(),
        mlps: read_mlps(dir, language, false, limits)?,
        files: list_files(dir, true, language),
        statics,
        dynamics,
        features,
        feature_source,
        latents: vec![],
    })
}

/// Attribute group an `offset_compressed.pkl` decoder writes to, and whether it is dynamic.
fn latent_target(name: &str) -> Option<(&str, bool)> {
    let base = name.strip_prefix('_')?.strip_suffix("_offset")?;
    match base.strip_suffix("_dynamic") {
        Some(b) => Some((b, true)),
        None => Some((base, false)),
    }
}

/// `Δ = (round(z) / div) @ scale + shift`, summed in ascending latent order, each product
/// added with one rounding (FMA), the shift added last (as `matmul(...) + shift`).
pub fn latent_delta(r: &LatentResidual, i: usize, out: &mut [f32]) {
    let z = &r.latents[i * r.latent_dim..(i + 1) * r.latent_dim];
    for (j, o) in out.iter_mut().enumerate() {
        let mut acc = 0.0f32;
        for (l, &zl) in z.iter().enumerate() {
            acc = (zl as f32 / r.div[l]).mul_add(r.scale[l * r.feature_dim + j], acc);
        }
        *o = acc + r.shift[j];
    }
}

/// Apply one latent residual to the previous GOP's state (`attr + decoder(latent)`).
pub fn apply_latent(r: &LatentResidual, g: &mut Gaussians) -> Result<(), IngestError> {
    let (attr, _) = latent_target(&r.name)
        .ok_or_else(|| IngestError::format(&r.name, "unknown latent residual"))?;
    let n = g.len();
    if r.count != n {
        return Err(IngestError::shape(
            &r.name,
            format!("{} latents for {n} Gaussians", r.count),
        ));
    }
    let coeffs = g.coeffs();
    let width = match attr {
        "features_dc" => 3,
        "features_rest" => 3 * (coeffs - 1),
        "scaling" => 3,
        "rotation" => 4,
        "opacity" => 1 + usize::from(g.lang_width > 0),
        "language_feature" => g.lang_width,
        _ => return Err(IngestError::format(&r.name, "unknown attribute")),
    };
    if r.feature_dim != width {
        return Err(IngestError::shape(
            &r.name,
            format!(
                "decoder outputs {}, the attribute has {width}",
                r.feature_dim
            ),
        ));
    }
    let mut d = vec![0.0f32; width];
    for i in 0..n {
        latent_delta(r, i, &mut d);
        let stride = 3 * coeffs;
        match attr {
            "features_dc" => g.sh[i * stride..i * stride + 3]
                .iter_mut()
                .zip(&d)
                .for_each(|(a, b)| *a += b),
            "features_rest" => g.sh[i * stride + 3..(i + 1) * stride]
                .iter_mut()
                .zip(&d)
                .for_each(|(a, b)| *a += b),
            "scaling" => g.log_scales[i]
                .iter_mut()
                .zip(&d)
                .for_each(|(a, b)| *a += b),
            "rotation" => g.rotations[i].iter_mut().zip(&d).for_each(|(a, b)| *a += b),
            "opacity" => {
                g.opacity[i] += d[0];
                if width == 2 {
                    g.lang_opacity[i] += d[1];
                }
            }
            _ => g.lang[i * width..(i + 1) * width]
                .iter_mut()
                .zip(&d)
                .for_each(|(a, b)| *a += b),
        }
    }
    Ok(())
}

/// Read GOP g >= 1 on top of the previous GOP's decoded state.
pub fn read_next(dir: &Path, prev: &RefGop, limits: &Limits) -> Result<RefGop, IngestError> {
    let rows = csv_rows(dir, limits)?;
    let pkl = dir.join("offset_compressed.pkl");
    let what = pkl.display().to_string();
    let latents = latents::read(&read(&pkl, "the GOP's latent residuals", limits)?, &what)?;
    let (mut statics, mut dynamics) = (prev.statics.clone(), prev.dynamics.clone());
    for r in &latents {
        let (_, dynamic) = latent_target(&r.name).ok_or_else(|| {
            IngestError::format(&what, format!("unknown latent residual {}", r.name))
        })?;
        apply_latent(r, if dynamic { &mut dynamics } else { &mut statics })?;
    }
    // Positions are re-sent in full.
    for (name, set) in [
        ("_xyz_offset", &mut statics),
        ("_xyz_dynamic_offset", &mut dynamics),
    ] {
        let xyz = attribute(dir, &rows, name, 3, limits)?;
        if xyz.len() != 3 * set.len() {
            return Err(IngestError::shape(
                &format!("{}/{name}", dir.display()),
                format!(
                    "{} positions, the previous GOP has {}",
                    xyz.len() / 3,
                    set.len()
                ),
            ));
        }
        for (p, c) in set.positions.iter_mut().zip(xyz.chunks_exact(3)) {
            *p = [c[0], c[1], c[2]];
        }
    }
    for set in [&statics, &dynamics] {
        check_finite(&dir.display().to_string(), &set.sh)?;
    }
    let language = statics.lang_width > 0;
    let (features, feature_source) = read_features(dir, &rows, dynamics.len(), limits)?;
    Ok(RefGop {
        dir: dir.to_path_buf(),
        mlps: read_mlps(dir, language, true, limits)?,
        files: list_files(dir, false, language),
        statics,
        dynamics,
        features,
        feature_source,
        latents,
    })
}

/// Read a whole run: GOP 0 then each following GOP on top of the previous one.
/// Every file is read within `limits` (file sizes against `max_alloc`, Gaussian counts
/// against `max_gaussians`); each GOP folder's files draw from one fresh budget.
pub fn read_run(
    dirs: &[PathBuf],
    limits: &Limits,
    mut progress: impl FnMut(usize),
) -> Result<Vec<RefGop>, IngestError> {
    let mut gops: Vec<RefGop> = Vec::with_capacity(dirs.len());
    for (g, d) in dirs.iter().enumerate() {
        // The compressed files win where both exist: they are what the reference's own
        // player decodes; the checkpoints hold the values before compression.
        let limits = &limits.fresh();
        let gop = match (gops.last(), has_compressed(d)) {
            (None, true) => read_first(d, limits)?,
            (None, false) => checkpoint::read_first(d, limits)?,
            (Some(prev), true) => read_next(d, prev, limits)?,
            (Some(prev), false) => checkpoint::read_next(d, prev, limits)?,
        };
        gops.push(gop);
        progress(g);
    }
    Ok(gops)
}
