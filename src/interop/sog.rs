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

use std::io::Read;
use std::path::Path;

use serde::Deserialize;

use crate::error::{Error, ErrorKind, Result};
use crate::limits::Limits;
use crate::model::{sh_coeffs, Gaussians};

fn err(reason: impl Into<String>) -> Error {
    Error::new(
        ErrorKind::Foreign {
            format: "SOG",
            reason: reason.into(),
        },
        0,
    )
}

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
        .map_err(|e| err(format!("not a readable zip: {e}")))?;
    // The bundle's own files sit at its root; a zip made by hand may hold one folder.
    let meta_name = zip
        .file_names()
        .filter(|n| *n == "meta.json" || n.ends_with("/meta.json"))
        .min_by_key(|n| n.len())
        .map(str::to_string)
        .ok_or_else(|| err("no meta.json in the zip"))?;
    let dir = meta_name.trim_end_matches("meta.json").to_string();
    let mut load = |name: &str| -> Result<Vec<u8>> {
        let full = format!("{dir}{name}");
        let index = zip
            .index_for_name(&full)
            .ok_or_else(|| err(format!("{full}: not in the zip")))?;
        let zerr = |e: zip::result::ZipError| err(format!("{full}: {e}"));
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
            return Err(err(format!("texture name '{name}' leaves the directory")));
        }
        let path = dir.join(name);
        let file = std::fs::File::open(&path)
            .map_err(|e| Error::new(ErrorKind::Io(format!("{}: {e}", path.display())), 0))?;
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
        .map_err(|e| err(format!("{name}: {e}")))?;
    if out.len() as u64 > limits.max_chunk_len {
        return Err(err(format!(
            "{name}: larger than {} bytes",
            limits.max_chunk_len
        )));
    }
    Ok(out)
}

fn parse_meta(bytes: &[u8]) -> Result<Meta> {
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| err(format!("meta.json: {e}")))?;
    match value.get("version").and_then(|v| v.as_u64()) {
        Some(2) => {}
        None => {
            return Err(err(
                "meta.json has no version: SOG version 1 is not read (re-save it with \
                 `npx @playcanvas/splat-transform IN.sog OUT.sog`)",
            ))
        }
        Some(v) => {
            return Err(err(format!(
                "meta.json: SOG version {v} is not read (2 is)"
            )))
        }
    }
    serde_json::from_value(value).map_err(|e| err(format!("meta.json: {e}")))
}

fn decode(
    meta_bytes: &[u8],
    load: &mut dyn FnMut(&str) -> Result<Vec<u8>>,
    limits: &Limits,
) -> Result<Gaussians> {
    let meta = parse_meta(meta_bytes)?;
    if meta.count > limits.max_gaussians {
        return Err(Error::new(
            ErrorKind::LimitExceeded {
                what: "SOG Gaussian count",
                value: meta.count,
                limit: limits.max_gaussians,
            },
            0,
        ));
    }
    let n = meta.count as usize;
    let degree = match &meta.sh_n {
        None => 0,
        Some(s) if (1..=3).contains(&s.bands) => s.bands,
        Some(s) => return Err(err(format!("shN.bands is {}, not 1, 2 or 3", s.bands))),
    };
    let k = sh_coeffs(degree);
    // Output floats: position 3, log-scale 3, rotation 4, opacity 1, SH 3k.
    limits.check_alloc("SOG Gaussians", (n as u64) * (11 + 3 * k as u64) * 4, 0)?;
    for (what, v) in [
        ("means.mins", &meta.means.mins),
        ("means.maxs", &meta.means.maxs),
    ] {
        if v.iter().any(|x| !x.is_finite()) {
            return Err(err(format!("{what} is not finite")));
        }
    }

    let mut r = TextureReader { load, n, limits };
    let mut g = Gaussians::new(degree, 0);
    let lo = r.texture(&meta.means.files, 0, "means")?;
    let hi = r.texture(&meta.means.files, 1, "means")?;
    g.positions = (0..n)
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

    let quats = r.texture(&meta.quats.files, 0, "quats")?;
    g.rotations = (0..n)
        .map(|i| unpack_quat(quats.pixel(i), i, &meta.quats.files[0]))
        .collect::<Result<_>>()?;

    let scales_book = codebook(&meta.scales.codebook, "scales")?;
    let scales = r.texture(&meta.scales.files, 0, "scales")?;
    g.log_scales = (0..n)
        .map(|i| {
            let p = scales.pixel(i);
            let mut s = [0f32; 3];
            for a in 0..3 {
                s[a] = lookup(&scales_book, p[a], "scales", i)?;
            }
            Ok(s)
        })
        .collect::<Result<_>>()?;

    let dc_book = codebook(&meta.sh0.codebook, "sh0")?;
    let sh0 = r.texture(&meta.sh0.files, 0, "sh0")?;
    g.opacity = Vec::with_capacity(n);
    g.sh = vec![0.0; n * k * 3];
    for i in 0..n {
        let p = sh0.pixel(i);
        for c in 0..3 {
            g.sh[i * k * 3 + c] = lookup(&dc_book, p[c], "sh0", i)?;
        }
        g.opacity.push(alpha_to_logit(p[3]));
    }

    if let Some(sh_n) = &meta.sh_n {
        read_sh_rest(&mut g, sh_n, &mut r)?;
    }
    Ok(g)
}

/// Loads the textures `meta.json` names, each checked against the Gaussian count.
struct TextureReader<'a> {
    load: &'a mut dyn FnMut(&str) -> Result<Vec<u8>>,
    n: usize,
    limits: &'a Limits,
}

impl TextureReader<'_> {
    /// Texture `files[slot]`, with a pixel per Gaussian.
    fn texture(&mut self, files: &[String], slot: usize, what: &str) -> Result<Texture> {
        let n = self.n;
        let name = files
            .get(slot)
            .ok_or_else(|| err(format!("{what}.files has no entry {slot}")))?;
        // SOG's own layout pads each side to a multiple of 4; anything far larger is refused
        // so that a tiny file cannot make us decode a huge image.
        let t = self.sized(name, 4 * n as u64 + 65_536)?;
        if t.width * t.height < n {
            return Err(err(format!(
                "{name}: {}x{} pixels for {n} Gaussians",
                t.width, t.height
            )));
        }
        Ok(t)
    }

    /// Texture `name`, refused before decoding if it has more than `max_pixels`.
    fn sized(&mut self, name: &str, max_pixels: u64) -> Result<Texture> {
        let bytes = (self.load)(name)?;
        decode_webp(&bytes, name, max_pixels, self.limits)
    }
}

/// The SH coefficients above DC: each Gaussian's label picks a palette entry.
fn read_sh_rest(g: &mut Gaussians, sh_n: &ShN, r: &mut TextureReader) -> Result<()> {
    let n = g.len();
    let k = g.coeffs();
    let rest = k - 1;
    let book = codebook(&sh_n.codebook, "shN")?;
    // Labels are 16-bit, so a palette has at most 65,536 entries.
    if sh_n.count > 65_536 {
        return Err(err(format!(
            "shN.count is {}, more than 16-bit labels address",
            sh_n.count
        )));
    }
    let centroids_name = sh_n
        .files
        .first()
        .ok_or_else(|| err("shN.files has no centroids texture"))?;
    // 64 entries per row of `rest` pixels each: 16-bit labels address at most 1,024 rows
    // (plus padding), 4 MB of RGBA at SH degree 3.
    let max_pixels = 64 * rest as u64 * (1024 + 4);
    let centroids = r.sized(centroids_name, max_pixels)?;
    if centroids.width != 64 * rest {
        return Err(err(format!(
            "{centroids_name}: width {} where {} bands need {}",
            centroids.width,
            sh_n.bands,
            64 * rest
        )));
    }
    if (centroids.height as u64) * 64 < sh_n.count {
        return Err(err(format!(
            "{centroids_name}: {} rows hold fewer than shN.count = {} entries",
            centroids.height, sh_n.count
        )));
    }
    let labels = r.texture(&sh_n.files, 1, "shN")?;
    for i in 0..n {
        let p = labels.pixel(i);
        let label = p[0] as usize | (p[1] as usize) << 8;
        if label as u64 >= sh_n.count {
            return Err(err(format!(
                "{}: Gaussian {i} has label {label}, past the palette's {} entries",
                sh_n.files[1], sh_n.count
            )));
        }
        let (row, first) = (label / 64, (label % 64) * rest);
        for j in 0..rest {
            let c = centroids.pixel(row * centroids.width + first + j);
            for ch in 0..3 {
                g.sh[i * k * 3 + (j + 1) * 3 + ch] = lookup(&book, c[ch], "shN", i)?;
            }
        }
    }
    Ok(())
}

fn codebook(values: &[f64], what: &str) -> Result<Vec<f32>> {
    if values.is_empty() || values.len() > 256 {
        return Err(err(format!(
            "{what}.codebook has {} entries (1 to 256 expected)",
            values.len()
        )));
    }
    if values.iter().any(|v| !v.is_finite()) {
        return Err(err(format!(
            "{what}.codebook holds a value that is not finite"
        )));
    }
    Ok(values.iter().map(|&v| v as f32).collect())
}

fn lookup(book: &[f32], index: u8, what: &str, gaussian: usize) -> Result<f32> {
    book.get(index as usize).copied().ok_or_else(|| {
        err(format!(
            "{what}: Gaussian {gaussian} indexes entry {index} of a {}-entry codebook",
            book.len()
        ))
    })
}

/// Smallest-three: alpha `252 + i` drops component `i`, which is rebuilt positive.
fn unpack_quat(p: [u8; 4], gaussian: usize, texture: &str) -> Result<[f32; 4]> {
    if p[3] < 252 {
        return Err(err(format!(
            "{texture}: Gaussian {gaussian} has tag {} (252..=255 expected)",
            p[3]
        )));
    }
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
    Ok(q.map(|v| v as f32))
}

/// Opacity byte (after the sigmoid) to the stored logit; `a / 255` is kept within
/// `[1e-6, 1 - 1e-6]` so that 0 and 255 stay finite (about -13.8 and 13.8).
fn alpha_to_logit(a: u8) -> f32 {
    let p = (a as f64 / 255.0).clamp(1e-6, 1.0 - 1e-6);
    (p / (1.0 - p)).ln() as f32
}

/// Decode a lossless WebP to RGBA, its size checked before any pixel is allocated.
fn decode_webp(bytes: &[u8], name: &str, max_pixels: u64, limits: &Limits) -> Result<Texture> {
    let werr = |e: image_webp::DecodingError| err(format!("{name}: {e}"));
    let mut d = image_webp::WebPDecoder::new(std::io::Cursor::new(bytes)).map_err(werr)?;
    if d.is_animated() {
        return Err(err(format!("{name}: an animated WebP, not a texture")));
    }
    if d.is_lossy() {
        return Err(err(format!(
            "{name}: lossy WebP; SOG textures are lossless (their bytes are indices)"
        )));
    }
    let (w, h) = d.dimensions();
    let (width, height) = (w as usize, h as usize);
    let pixels = (width as u64) * (height as u64);
    if pixels > max_pixels {
        return Err(err(format!(
            "{name}: {w}x{h} pixels, more than the {max_pixels} the layout allows"
        )));
    }
    limits.check_alloc("SOG texture", pixels * 4, 0)?;
    d.set_memory_limit(limits.max_alloc.min(usize::MAX as u64) as usize);
    let size = d
        .output_buffer_size()
        .ok_or_else(|| err(format!("{name}: {w}x{h} is too large")))?;
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
