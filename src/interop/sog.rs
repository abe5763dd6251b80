//! PlayCanvas SOG version 2, read: a zip (`.sog`) or a directory (`meta.json`) of lossless WebP
//! textures, one pixel per Gaussian in every texture (Gaussian `i` is pixel `i` in row-major order).
//!
//! What each texture holds (facts from splat-transform 2.7.1's reader and writer):
//! - `means_l`, `means_u`: low and high bytes of a 16-bit level per axis (RGB) over
//!   `[means.mins, means.maxs]` of `v' = sign(v) ln(1 + |v|)`; a zero range counts as 1.
//! - `quats`: smallest-three; alpha `252 + i` names the dropped (largest, positive) component
//!   `i` of (w, x, y, z); RGB carry the other three as `(b / 255 * 2 - 1) / sqrt(2)`.
//! - `scales`: RGB index `scales.codebook` (log-scales).
//! - `sh0`: RGB index `sh0.codebook` (SH DC); alpha is the opacity after the sigmoid, `a / 255`.
//! - `shN_centroids`, `shN_labels` (SH degree `shN.bands`): the 16-bit label (R + 256 G) picks a
//!   palette entry of `15`, `8` or `3` coefficients laid out 64 entries per row; each RGB byte
//!   indexes `shN.codebook`.
//!
//! Everything is computed in f64 then rounded to f32, as the reference reader does, so the
//! floats equal those of `splat-transform FILE.sog FILE.ply`. A file that breaks the layout
//! (a label past the palette, a quaternion tag outside 252..=255, a texture smaller than the
//! count) is an error naming the texture and the Gaussian, where splat-transform substitutes
//! zeros or the identity. SOG version 1 (no `version` in `meta.json`) is not read.
#![allow(clippy::disallowed_methods)] // a foreign format: see the module doc of `interop`

use std::io::Read;
use std::path::Path;

use rayon::prelude::*;
use serde::Deserialize;

use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::{sh_coeffs, Gaussians};

#[derive(Deserialize)]
struct Meta {
    count: u64,
    means: Means,
    scales: Codebooked,
    quats: Files,
    sh0: Codebooked,
    #[serde(rename = "shN")]
    sh_n: Option<ShN>,
}

#[derive(Deserialize)]
struct Means {
    mins: [f64; 3],
    maxs: [f64; 3],
    files: Vec<String>,
}

#[derive(Deserialize)]
struct Codebooked {
    codebook: Vec<f64>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct Files {
    files: Vec<String>,
}

#[derive(Deserialize)]
struct ShN {
    count: u64,
    bands: u8,
    codebook: Vec<f64>,
    files: Vec<String>,
}

/// A decoded texture, 4 bytes (RGBA) per pixel.
struct Texture {
    rgba: Vec<u8>,
    width: usize,
    height: usize,
}

impl Texture {
    fn pixel(&self, i: usize) -> [u8; 4] {
        self.rgba[4 * i..4 * i + 4].try_into().expect("4 bytes")
    }
}

/// Read a bundled `.sog` file (a zip holding `meta.json` and the textures it names).
pub fn read_sog(data: &[u8], limits: &Limits) -> Result<Gaussians> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(data))
        .map_err(|e| Error::foreign("SOG", format!("not a readable zip: {e}")))?;
    // The bundle's own files sit at its root; a zip made by hand may hold one folder.
    let meta_name = zip
        .file_names()
        .filter(|n| *n == "meta.json" || n.ends_with("/meta.json"))
        .min_by_key(|n| n.len())
        .map(str::to_string)
        .ok_or_else(|| Error::foreign("SOG", "no meta.json in the zip"))?;
    let dir = meta_name
        .strip_suffix("meta.json")
        .unwrap_or("")
        .to_string();
    let mut load = |name: &str| -> Result<Vec<u8>> {
        let full = format!("{dir}{name}");
        let index = zip
            .index_for_name(&full)
            .ok_or_else(|| Error::foreign("SOG", format!("{full}: not in the zip")))?;
        let zerr = |e: zip::result::ZipError| Error::foreign("SOG", format!("{full}: {e}"));
        // Fuzzing builds skip the CRC of stored entries (as they skip the container's CRCs), so
        // that mutated textures reach the WebP decoder.
        if cfg!(fuzzing)
            && zip.by_index_raw(index).map_err(zerr)?.compression()
                == zip::CompressionMethod::Stored
        {
            return read_bounded(zip.by_index_raw(index).map_err(zerr)?, &full, limits);
        }
        read_bounded(zip.by_index(index).map_err(zerr)?, &full, limits)
    };
    let meta = load("meta.json")?;
    decode(&meta, &mut load, limits)
}

/// Read an unbundled SOG: `meta_json` and the textures beside it.
pub fn read_sog_dir(meta_json: &Path, limits: &Limits) -> Result<Gaussians> {
    let dir = meta_json.parent().unwrap_or(Path::new("."));
    let mut load = |name: &str| -> Result<Vec<u8>> {
        // Names are plain file names; anything that climbs out of the directory is refused.
        if name.contains("..") || Path::new(name).is_absolute() {
            return Err(Error::foreign(
                "SOG",
                format!("texture name '{name}' leaves the directory"),
            ));
        }
        let path = dir.join(name);
        let file = std::fs::File::open(&path)
            .map_err(|e| Error::io(format!("reading {}", path.display()), e, 0))?;
        read_bounded(file, name, limits)
    };
    let meta = load(
        meta_json
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("meta.json"),
    )?;
    decode(&meta, &mut load, limits)
}

fn read_bounded(r: impl Read, name: &str, limits: &Limits) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    r.take(limits.max_chunk_len.saturating_add(1))
        .read_to_end(&mut out)
        .map_err(|e| Error::foreign("SOG", format!("{name}: {e}")))?;
    if out.len() as u64 > limits.max_chunk_len {
        return Err(Error::foreign(
            "SOG",
            format!("{name}: larger than {} bytes", limits.max_chunk_len),
        ));
    }
    Ok(out)
}

fn parse_meta(bytes: &[u8]) -> Result<Meta> {
    let value: serde_json::Value = serde_json::from_slice(bytes)
        .map_err(|e| Error::foreign("SOG", format!("meta.json: {e}")))?;
    if !value.is_object() {
        return Err(Error::foreign("SOG", "meta.json is not a JSON object"));
    }
    match value.get("version") {
        None => {
            return Err(Error::foreign(
                "SOG",
                "meta.json has no version: SOG version 1 is not read (re-save it with \
                 `npx @playcanvas/splat-transform IN.sog OUT.sog`)",
            ))
        }
        Some(v) if v.as_u64() == Some(2) => {}
        Some(v) => {
            return Err(Error::foreign(
                "SOG",
                format!("meta.json: SOG version {v} is not read (2 is)"),
            ))
        }
    }
    serde_json::from_value(value).map_err(|e| Error::foreign("SOG", format!("meta.json: {e}")))
}

fn decode(
    meta_bytes: &[u8],
    load: &mut dyn FnMut(&str) -> Result<Vec<u8>>,
    limits: &Limits,
) -> Result<Gaussians> {
    let meta = parse_meta(meta_bytes)?;
    if meta.count > limits.max_gaussians {
        return Err(Error::limit(
            "SOG Gaussian count",
            meta.count,
            limits.max_gaussians,
            0,
        ));
    }
    let n = meta.count as usize;
    let degree = match &meta.sh_n {
        None => 0,
        Some(s) if (1..=3).contains(&s.bands) => s.bands,
        Some(s) => {
            return Err(Error::foreign(
                "SOG",
                format!("shN.bands is {}, not 1, 2 or 3", s.bands),
            ))
        }
    };
    let k = sh_coeffs(degree);
    // Output floats: position 3, log-scale 3, rotation 4, opacity 1, SH 3k.
    limits.check_alloc("SOG Gaussians", (n as u64) * (11 + 3 * k as u64) * 4, 0)?;
    for (what, v) in [
        ("means.mins", &meta.means.mins),
        ("means.maxs", &meta.means.maxs),
    ] {
        // Positions are `sign(v) (e^|v| - 1)`: past |v| ~ 88.7 that overflows f32.
        if let Some(x) = v
            .iter()
            .find(|x| !((x.abs().exp() - 1.0) as f32).is_finite())
        {
            return Err(Error::foreign(
                "SOG",
                format!("{what} holds {x:e}, which decodes to a position past f32's range"),
            ));
        }
    }

    let t = fetch_textures(&meta, load, n, limits)?;
    // Every byte that could break the layout is checked first, in Gaussian order (so the error
    // names the first bad Gaussian on any thread count); the conversions below then run in
    // parallel, each Gaussian on its own.
    if let Some(i) = (0..n).find(|&i| t.quats.pixel(i)[3] < 252) {
        return Err(Error::foreign(
            "SOG",
            format!(
                "{}: Gaussian {i} has tag {} (252..=255 expected)",
                meta.quats.files[0],
                t.quats.pixel(i)[3]
            ),
        ));
    }
    let scales_book = codebook(&meta.scales.codebook, "scales")?;
    check_indices(&t.scales, n, scales_book.len(), "scales")?;
    let dc_book = codebook(&meta.sh0.codebook, "sh0")?;
    check_indices(&t.sh0, n, dc_book.len(), "sh0")?;

    let mut g = Gaussians::new(degree, 0);
    let (lo, hi) = (&t.means_lo, &t.means_hi);
    g.positions = (0..n)
        .into_par_iter()
        .map(|i| {
            let (l, h) = (lo.pixel(i), hi.pixel(i));
            std::array::from_fn(|a| {
                let level = l[a] as f64 + 256.0 * h[a] as f64;
                let (min, max) = (meta.means.mins[a], meta.means.maxs[a]);
                let range = if max - min == 0.0 { 1.0 } else { max - min };
                let v = min + range * (level / 65535.0);
                // Inverse of sign(x) ln(1 + |x|).
                (v.signum() * (v.abs().exp() - 1.0)) as f32
            })
        })
        .collect();
    g.rotations = (0..n)
        .into_par_iter()
        .map(|i| unpack_quat(t.quats.pixel(i)))
        .collect();
    g.log_scales = (0..n)
        .into_par_iter()
        .map(|i| {
            let p = t.scales.pixel(i);
            [0, 1, 2].map(|a| scales_book[p[a] as usize])
        })
        .collect();
    g.opacity = (0..n)
        .into_par_iter()
        .map(|i| alpha_to_logit(t.sh0.pixel(i)[3]))
        .collect();
    g.sh = vec![0.0; n * k * 3];
    g.sh.par_chunks_mut(k * 3).enumerate().for_each(|(i, sh)| {
        let p = t.sh0.pixel(i);
        for c in 0..3 {
            sh[c] = dc_book[p[c] as usize];
        }
    });

    if let (Some(sh_n), Some((centroids, labels))) = (&meta.sh_n, &t.sh_rest) {
        read_sh_rest(&mut g, sh_n, centroids, labels)?;
    }
    Ok(g)
}

/// The textures a file's `meta.json` names.
struct Textures {
    means_lo: Texture,
    means_hi: Texture,
    quats: Texture,
    scales: Texture,
    sh0: Texture,
    /// `shN`'s centroids and labels.
    sh_rest: Option<(Texture, Texture)>,
}

/// Fetch every texture, then decode them in parallel (each is independent, and each decodes
/// to the same pixels on any thread count); the first failing one in `meta.json`'s order is
/// the error reported. Each texture is refused before decoding if it has more pixels than the
/// layout allows, so that a tiny file cannot make us decode a huge image.
fn fetch_textures(
    meta: &Meta,
    load: &mut dyn FnMut(&str) -> Result<Vec<u8>>,
    n: usize,
    limits: &Limits,
) -> Result<Textures> {
    let name = |files: &[String], slot: usize, what: &str| -> Result<String> {
        files
            .get(slot)
            .cloned()
            .ok_or_else(|| Error::foreign("SOG", format!("{what}.files has no entry {slot}")))
    };
    // SOG's own layout pads each side of a per-Gaussian texture to a multiple of 4.
    let per_gaussian = 4 * n as u64 + 65_536;
    let mut jobs = vec![
        (name(&meta.means.files, 0, "means")?, per_gaussian),
        (name(&meta.means.files, 1, "means")?, per_gaussian),
        (name(&meta.quats.files, 0, "quats")?, per_gaussian),
        (name(&meta.scales.files, 0, "scales")?, per_gaussian),
        (name(&meta.sh0.files, 0, "sh0")?, per_gaussian),
    ];
    if let Some(sh_n) = &meta.sh_n {
        // 64 entries per row of `rest` pixels each: 16-bit labels address at most 1,024 rows
        // (plus padding), 4 MB of RGBA at SH degree 3.
        let rest = sh_coeffs(sh_n.bands) as u64 - 1; // bands: 1-3, checked by `decode`
        jobs.push((name(&sh_n.files, 0, "shN")?, 64 * rest * (1024 + 4)));
        jobs.push((name(&sh_n.files, 1, "shN")?, per_gaussian));
    }
    let bytes = jobs
        .iter()
        .map(|(name, _)| load(name))
        .collect::<Result<Vec<_>>>()?;
    let decoded: Vec<Result<Texture>> = jobs
        .par_iter()
        .zip(bytes.par_iter())
        .map(|((name, max_pixels), b)| decode_webp(b, name, *max_pixels, limits))
        .collect();
    let mut textures = Vec::with_capacity(decoded.len());
    for (i, t) in decoded.into_iter().enumerate() {
        let t = t?;
        // Every texture but the centroids (slot 5) has a pixel per Gaussian.
        if i != 5 && t.width * t.height < n {
            return Err(Error::foreign(
                "SOG",
                format!(
                    "{}: {}x{} pixels for {n} Gaussians",
                    jobs[i].0, t.width, t.height
                ),
            ));
        }
        textures.push(t);
    }
    let mut it = textures.into_iter();
    let mut next = || it.next().expect("one texture per job");
    let (means_lo, means_hi, quats, scales, sh0) = (next(), next(), next(), next(), next());
    let sh_rest = meta.sh_n.as_ref().map(|_| (next(), next()));
    Ok(Textures {
        means_lo,
        means_hi,
        quats,
        scales,
        sh0,
        sh_rest,
    })
}

/// The SH coefficients above DC: each Gaussian's label picks a palette entry.
fn read_sh_rest(
    g: &mut Gaussians,
    sh_n: &ShN,
    centroids: &Texture,
    labels: &Texture,
) -> Result<()> {
    let n = g.len();
    let k = g.coeffs();
    let rest = k - 1;
    let book = codebook(&sh_n.codebook, "shN")?;
    // Labels are 16-bit, so a palette has at most 65,536 entries.
    if sh_n.count > 65_536 {
        return Err(Error::foreign(
            "SOG",
            format!(
                "shN.count is {}, more than 16-bit labels address",
                sh_n.count
            ),
        ));
    }
    let centroids_name = &sh_n.files[0];
    if centroids.width != 64 * rest {
        return Err(Error::foreign(
            "SOG",
            format!(
                "{centroids_name}: width {} where {} bands need {}",
                centroids.width,
                sh_n.bands,
                64 * rest
            ),
        ));
    }
    if (centroids.height as u64) * 64 < sh_n.count {
        return Err(Error::foreign(
            "SOG",
            format!(
                "{centroids_name}: {} rows hold fewer than shN.count = {} entries",
                centroids.height, sh_n.count
            ),
        ));
    }
    let label_of = |i: usize| {
        let p = labels.pixel(i);
        p[0] as usize | (p[1] as usize) << 8
    };
    if let Some(i) = (0..n).find(|&i| label_of(i) as u64 >= sh_n.count) {
        return Err(Error::foreign(
            "SOG",
            format!(
                "{}: Gaussian {i} has label {}, past the palette's {} entries",
                sh_n.files[1],
                label_of(i),
                sh_n.count
            ),
        ));
    }
    let pixel_of = |entry: usize, j: usize| {
        centroids.pixel((entry / 64) * centroids.width + (entry % 64) * rest + j)
    };
    for entry in 0..sh_n.count as usize {
        for j in 0..rest {
            if let Some(&b) = pixel_of(entry, j)[..3]
                .iter()
                .find(|&&b| b as usize >= book.len())
            {
                return Err(Error::foreign(
                    "SOG",
                    format!(
                        "{centroids_name}: palette entry {entry} indexes entry {b} of a {}-entry \
                     codebook",
                        book.len()
                    ),
                ));
            }
        }
    }
    g.sh.par_chunks_mut(k * 3).enumerate().for_each(|(i, sh)| {
        let label = label_of(i);
        for j in 0..rest {
            let c = pixel_of(label, j);
            for ch in 0..3 {
                sh[(j + 1) * 3 + ch] = book[c[ch] as usize];
            }
        }
    });
    Ok(())
}

fn codebook(values: &[f64], what: &str) -> Result<Vec<f32>> {
    if values.is_empty() || values.len() > 256 {
        return Err(Error::foreign(
            "SOG",
            format!(
                "{what}.codebook has {} entries (1 to 256 expected)",
                values.len()
            ),
        ));
    }
    if let Some(v) = values.iter().find(|v| !(**v as f32).is_finite()) {
        return Err(Error::foreign(
            "SOG",
            format!("{what}.codebook holds {v:e}, past f32's range"),
        ));
    }
    Ok(values.iter().map(|&v| v as f32).collect())
}

/// `Foreign` at the first Gaussian whose RGB bytes of `texture` index past a codebook of
/// `len` entries (only a codebook under 256 entries can be indexed past).
fn check_indices(texture: &Texture, n: usize, len: usize, what: &str) -> Result<()> {
    match (0..n).find_map(|i| {
        let p = texture.pixel(i);
        p[..3].iter().find(|&&b| b as usize >= len).map(|&b| (i, b))
    }) {
        Some((i, b)) => Err(Error::foreign(
            "SOG",
            format!("{what}: Gaussian {i} indexes entry {b} of a {len}-entry codebook"),
        )),
        None => Ok(()),
    }
}

/// Smallest-three: alpha `252 + i` (checked by the caller) drops component `i`, which is
/// rebuilt positive.
fn unpack_quat(p: [u8; 4]) -> [f32; 4] {
    let dropped = (p[3] - 252) as usize;
    let mut q = [0f64; 4];
    let mut rgb = p[..3].iter();
    for (c, slot) in q.iter_mut().enumerate() {
        if c != dropped {
            let b = *rgb.next().expect("three stored components");
            *slot = (b as f64 / 255.0 * 2.0 - 1.0) / std::f64::consts::SQRT_2;
        }
    }
    let rest: f64 = q.iter().map(|v| v * v).sum();
    q[dropped] = (1.0 - rest).max(0.0).sqrt();
    q.map(|v| v as f32)
}

/// Opacity byte (after the sigmoid) to the stored logit; `a / 255` is kept within
/// `[1e-6, 1 - 1e-6]` so that 0 and 255 stay finite (about -13.8 and 13.8).
fn alpha_to_logit(a: u8) -> f32 {
    let p = (a as f64 / 255.0).clamp(1e-6, 1.0 - 1e-6);
    (p / (1.0 - p)).ln() as f32
}

/// Decode a lossless WebP to RGBA, its size checked before any pixel is allocated.
fn decode_webp(bytes: &[u8], name: &str, max_pixels: u64, limits: &Limits) -> Result<Texture> {
    let werr = |e: image_webp::DecodingError| Error::foreign("SOG", format!("{name}: {e}"));
    let mut d = image_webp::WebPDecoder::new(std::io::Cursor::new(bytes)).map_err(werr)?;
    if d.is_animated() {
        return Err(Error::foreign(
            "SOG",
            format!("{name}: an animated WebP, not a texture"),
        ));
    }
    if d.is_lossy() {
        return Err(Error::foreign(
            "SOG",
            format!("{name}: lossy WebP; SOG textures are lossless (their bytes are indices)"),
        ));
    }
    let (w, h) = d.dimensions();
    let (width, height) = (w as usize, h as usize);
    let pixels = (width as u64) * (height as u64);
    if pixels > max_pixels {
        return Err(Error::foreign(
            "SOG",
            format!("{name}: {w}x{h} pixels, more than the {max_pixels} the layout allows"),
        ));
    }
    limits.check_alloc("SOG texture", pixels * 4, 0)?;
    d.set_memory_limit(limits.max_alloc.min(usize::MAX as u64) as usize);
    let size = d
        .output_buffer_size()
        .ok_or_else(|| Error::foreign("SOG", format!("{name}: {w}x{h} is too large")))?;
    let mut buf = vec![0u8; size];
    d.read_image(&mut buf).map_err(werr)?;
    let rgba = if d.has_alpha() {
        buf
    } else {
        // An opaque texture decodes to RGB; its alpha is 255 everywhere.
        buf.chunks_exact(3)
            .flat_map(|c| [c[0], c[1], c[2], 255])
            .collect()
    };
    Ok(Texture {
        rgba,
        width,
        height,
    })
}
