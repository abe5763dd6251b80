//! PlayCanvas SOG version 2, write: the layout [`super::sog`] reads (and splat-transform 2.7.1
//! reads): `meta.json` and lossless WebP textures, one pixel per Gaussian, bundled as a zip
//! (`.sog`) or as files in a directory.
//!
//! What is quantised how (the peers' choices, except where said):
//! - positions: `sign(v) ln(1 + |v|)` per axis, 16 bits over that axis's range (`means_l`,
//!   `means_u`);
//! - rotations: normalised, smallest-three, 8 bits per component (`quats`, alpha 252 + the
//!   dropped component);
//! - log-scales and SH DC: indices into 256-entry codebooks fitted by 1-D k-means (Lloyd,
//!   started from quantiles) over all of the values (`scales`, `sh0`);
//! - opacity: `sigmoid` in 8 bits (`sh0` alpha);
//! - SH above DC: a palette of at most 65,536 entries (16-bit labels). With up to 65,536
//!   Gaussians every Gaussian is its own entry (exact but for the 256-entry coefficient
//!   codebook). Above that, the palette is a median cut of the SH vectors (split on the axis of
//!   largest variance at the median, 65,536 leaves, each the mean of its Gaussians) instead of
//!   splat-transform's k-means, which takes minutes per 50k Gaussians on a CPU.
//!
//! Gaussians keep their order (splat-transform sorts them in Morton order, which makes the
//! textures compress better); language features are dropped (SOG has no place for them).
#![allow(clippy::disallowed_methods)] // a foreign format: see the module doc of `interop`

use std::io::Write;

use image_webp::{ColorType, WebPEncoder};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::model::{sh_coeffs, Gaussians};

/// The most palette entries 16-bit labels address.
const MAX_PALETTE: usize = 65_536;
/// Lloyd iterations of the 256-entry codebooks.
const CODEBOOK_ITERATIONS: usize = 10;

/// The files of an unbundled SOG: `meta.json` first, then the textures it names.
pub fn write_sog_files(g: &Gaussians) -> Result<Vec<(String, Vec<u8>)>> {
    g.check_shapes()?;
    let n = g.len();
    let (w, h) = texture_size(n);
    let pixels = w * h;
    let mut files = Vec::new();
    let mut texture = |name: &str, rgba: Vec<u8>, tw: usize, th: usize| -> Result<String> {
        let file = format!("{name}.webp");
        files.push((file.clone(), encode_webp(&rgba, tw, th, &file)?));
        Ok(file)
    };

    // Means: 16-bit levels of sign(v) ln(1 + |v|) per axis.
    let logv: Vec<[f64; 3]> = g
        .positions
        .par_iter()
        .map(|p| p.map(|v| (v as f64).signum() * (v.abs() as f64).ln_1p()))
        .collect();
    let mut mins = [0f64; 3];
    let mut maxs = [0f64; 3];
    for a in 0..3 {
        let (lo, hi) = logv
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v[a]), hi.max(v[a]))
            });
        (mins[a], maxs[a]) = if n == 0 { (0.0, 0.0) } else { (lo, hi) };
    }
    let mut lo = vec![0u8; 4 * pixels];
    let mut hi = vec![0u8; 4 * pixels];
    for (i, v) in logv.iter().enumerate() {
        for a in 0..3 {
            let range = if maxs[a] - mins[a] == 0.0 {
                1.0
            } else {
                maxs[a] - mins[a]
            };
            let level = ((v[a] - mins[a]) / range * 65535.0)
                .round()
                .clamp(0.0, 65535.0) as u32;
            lo[4 * i + a] = (level & 0xff) as u8;
            hi[4 * i + a] = (level >> 8) as u8;
        }
        lo[4 * i + 3] = 255;
        hi[4 * i + 3] = 255;
    }
    let means_files = vec![texture("means_l", lo, w, h)?, texture("means_u", hi, w, h)?];

    // Quaternions, smallest-three.
    let mut quats = vec![0u8; 4 * pixels];
    quats
        .par_chunks_mut(4)
        .zip(g.rotations.par_iter())
        .for_each(|(px, q)| px.copy_from_slice(&pack_quat(*q)));
    let quats_file = texture("quats", quats, w, h)?;

    // Log-scales through a 256-entry codebook.
    let scale_values: Vec<f32> = g.log_scales.as_flattened().to_vec();
    let scales_book = fit_codebook(&scale_values);
    let mut scales = vec![0u8; 4 * pixels];
    for (i, s) in g.log_scales.iter().enumerate() {
        for a in 0..3 {
            scales[4 * i + a] = nearest(&scales_book, s[a]);
        }
        scales[4 * i + 3] = 255;
    }
    let scales_file = texture("scales", scales, w, h)?;

    // SH DC through a codebook, opacity after the sigmoid in alpha.
    let k = sh_coeffs(g.sh_degree);
    let stride = 3 * k;
    let dc: Vec<f32> = (0..n)
        .flat_map(|i| [0, 1, 2].map(|c| g.sh[i * stride + c]))
        .collect();
    let dc_book = fit_codebook(&dc);
    let mut sh0 = vec![0u8; 4 * pixels];
    for i in 0..n {
        for c in 0..3 {
            sh0[4 * i + c] = nearest(&dc_book, dc[3 * i + c]);
        }
        let a = 1.0 / (1.0 + (-(g.opacity[i] as f64)).exp());
        sh0[4 * i + 3] = (a * 255.0).round().clamp(0.0, 255.0) as u8;
    }
    let sh0_file = texture("sh0", sh0, w, h)?;

    let mut meta = serde_json::json!({
        "version": 2,
        "count": n,
        "means": { "mins": mins, "maxs": maxs, "files": means_files },
        "scales": { "codebook": scales_book, "files": [scales_file] },
        "quats": { "files": [quats_file] },
        "sh0": { "codebook": dc_book, "files": [sh0_file] },
    });
    if g.sh_degree > 0 && n > 0 {
        let rest = k - 1;
        let dim = 3 * rest;
        let vectors: Vec<f32> = (0..n)
            .flat_map(|i| g.sh[i * stride + 3..(i + 1) * stride].iter().copied())
            .collect();
        let (labels, centroids) = palette(&vectors, dim, n.min(MAX_PALETTE));
        let count = centroids.len() / dim;
        let book = fit_codebook(&centroids);
        let (cw, ch) = (64 * rest, count.div_ceil(64));
        let mut ctex = vec![0u8; 4 * cw * ch];
        for e in 0..count {
            for j in 0..rest {
                let px = (e / 64) * cw + (e % 64) * rest + j;
                for c in 0..3 {
                    ctex[4 * px + c] = nearest(&book, centroids[e * dim + 3 * j + c]);
                }
                ctex[4 * px + 3] = 255;
            }
        }
        let mut ltex = vec![0u8; 4 * pixels];
        for (i, &l) in labels.iter().enumerate() {
            ltex[4 * i] = (l & 0xff) as u8;
            ltex[4 * i + 1] = (l >> 8) as u8;
            ltex[4 * i + 3] = 255;
        }
        let files = [
            texture("shN_centroids", ctex, cw, ch)?,
            texture("shN_labels", ltex, w, h)?,
        ];
        meta["shN"] = serde_json::json!({
            "count": count, "bands": g.sh_degree, "codebook": book, "files": files,
        });
    }
    let meta = serde_json::to_vec_pretty(&meta).expect("JSON of numbers and strings");
    files.insert(0, ("meta.json".to_string(), meta));
    Ok(files)
}

/// A bundled `.sog`: the files of [`write_sog_files`] in a zip (`meta.json` deflated, the
/// textures stored: WebP is compressed already).
pub fn write_sog(g: &Gaussians) -> Result<Vec<u8>> {
    let files = write_sog_files(g)?;
    let zerr = |e: zip::result::ZipError| Error::foreign("SOG", format!("writing the zip: {e}"));
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, bytes) in &files {
        let method = if name.ends_with(".json") {
            zip::CompressionMethod::Deflated
        } else {
            zip::CompressionMethod::Stored
        };
        let opts = zip::write::SimpleFileOptions::default().compression_method(method);
        zip.start_file(name.as_str(), opts).map_err(zerr)?;
        zip.write_all(bytes)
            .map_err(|e| Error::foreign("SOG", format!("writing the zip: {e}")))?;
    }
    Ok(zip.finish().map_err(zerr)?.into_inner())
}

/// SOG's texture size: `W = ceil(sqrt(n) / 4) * 4`, `H = ceil(n / W / 4) * 4` (at least 4x4).
pub fn texture_size(n: usize) -> (usize, usize) {
    let w = (((n as f64).sqrt() / 4.0).ceil() as usize * 4).max(4);
    let h = (n.div_ceil(w).div_ceil(4) * 4).max(4);
    (w, h)
}

fn encode_webp(rgba: &[u8], w: usize, h: usize, name: &str) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    WebPEncoder::new(&mut out)
        .encode(rgba, w as u32, h as u32, ColorType::Rgba8)
        .map_err(|e| Error::foreign("SOG", format!("encoding {name}: {e}")))?;
    Ok(out)
}

/// Smallest-three: the largest component (made positive) is dropped and named in alpha.
fn pack_quat(q: [f32; 4]) -> [u8; 4] {
    let q = q.map(f64::from);
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let q = if norm > 0.0 && norm.is_finite() {
        q.map(|v| v / norm)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    };
    let big = (0..4)
        .max_by(|&a, &b| q[a].abs().total_cmp(&q[b].abs()))
        .expect("four components");
    let sign = if q[big] < 0.0 { -1.0 } else { 1.0 };
    let mut px = [0u8; 4];
    let mut slot = 0;
    for (c, v) in q.iter().enumerate() {
        if c != big {
            let b = (v * sign * std::f64::consts::SQRT_2 * 0.5 + 0.5) * 255.0;
            px[slot] = b.round().clamp(0.0, 255.0) as u8;
            slot += 1;
        }
    }
    px[3] = 252 + big as u8;
    px
}

/// A sorted codebook of at most 256 values for `values`: 1-D k-means (Lloyd) from quantiles.
/// On sorted data each cluster is a contiguous run, so an iteration is 256 binary searches.
fn fit_codebook(values: &[f32]) -> Vec<f64> {
    let mut v: Vec<f64> = values
        .iter()
        .filter(|x| x.is_finite())
        .map(|&x| x as f64)
        .collect();
    if v.is_empty() {
        return vec![0.0];
    }
    v.par_sort_unstable_by(f64::total_cmp);
    let m = v.len();
    let mut prefix = Vec::with_capacity(m + 1);
    prefix.push(0.0);
    for x in &v {
        prefix.push(prefix.last().expect("non-empty") + x);
    }
    let k = 256.min(m);
    let mut book: Vec<f64> = (0..k).map(|j| v[(2 * j + 1) * m / (2 * k)]).collect();
    book.dedup();
    for _ in 0..CODEBOOK_ITERATIONS {
        // Cluster j holds the values between the midpoints to its neighbours.
        let mut bounds = vec![0usize];
        for j in 1..book.len() {
            let mid = 0.5 * (book[j - 1] + book[j]);
            bounds.push(v.partition_point(|&x| x < mid));
        }
        bounds.push(m);
        let next: Vec<f64> = (0..book.len())
            .map(|j| {
                let (a, b) = (bounds[j], bounds[j + 1]);
                if b > a {
                    (prefix[b] - prefix[a]) / (b - a) as f64
                } else {
                    book[j]
                }
            })
            .collect();
        if next == book {
            break;
        }
        book = next;
        book.sort_by(f64::total_cmp);
        book.dedup();
    }
    // The values as the reader will see them (f32), still sorted.
    book.iter().map(|&x| x as f32 as f64).collect()
}

/// Index of the codebook entry nearest `x` (`book` sorted).
fn nearest(book: &[f64], x: f32) -> u8 {
    let x = x as f64;
    let i = book.partition_point(|&b| b < x);
    let best = if i == 0 {
        0
    } else if i == book.len() {
        book.len() - 1
    } else if x - book[i - 1] <= book[i] - x {
        i - 1
    } else {
        i
    };
    best as u8
}

/// A palette of at most `entries` rows of `vectors` (`dim` floats each): each row's label and
/// the palette. With as many entries as rows, each row is its own entry; otherwise a median
/// cut into `entries` leaves, each the mean of its rows.
fn palette(vectors: &[f32], dim: usize, entries: usize) -> (Vec<u32>, Vec<f32>) {
    let n = vectors.len() / dim;
    if n <= entries {
        return ((0..n as u32).collect(), vectors.to_vec());
    }
    let mut idx: Vec<u32> = (0..n as u32).collect();
    let mut leaves = Vec::with_capacity(entries);
    median_cut(vectors, dim, &mut idx, entries, &mut leaves);
    let mut labels = vec![0u32; n];
    let mut centroids = Vec::with_capacity(leaves.len() * dim);
    let mut at = 0;
    for (e, len) in leaves.iter().enumerate() {
        let rows = &idx[at..at + len];
        let mut sum = vec![0f64; dim];
        for &r in rows {
            labels[r as usize] = e as u32;
            for (s, v) in sum.iter_mut().zip(&vectors[r as usize * dim..][..dim]) {
                *s += *v as f64;
            }
        }
        centroids.extend(sum.iter().map(|s| (s / rows.len() as f64) as f32));
        at += len;
    }
    (labels, centroids)
}

/// Split `idx` into `leaves` runs (their lengths pushed to `out`, in order) on the axis of
/// largest variance, at the rank that gives each side its share of the leaves.
fn median_cut(v: &[f32], dim: usize, idx: &mut [u32], leaves: usize, out: &mut Vec<usize>) {
    if leaves <= 1 || idx.len() <= 1 {
        out.push(idx.len());
        return;
    }
    let n = idx.len() as f64;
    let axis = (0..dim)
        .map(|d| {
            let (s, s2) = idx.iter().fold((0f64, 0f64), |(s, s2), &r| {
                let x = v[r as usize * dim + d] as f64;
                (s + x, s2 + x * x)
            });
            (d, s2 / n - (s / n) * (s / n))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(d, _)| d);
    let left = leaves / 2;
    let at = (idx.len() * left / leaves).clamp(1, idx.len() - 1);
    idx.select_nth_unstable_by(at, |&a, &b| {
        v[a as usize * dim + axis].total_cmp(&v[b as usize * dim + axis])
    });
    let (l, r) = idx.split_at_mut(at);
    median_cut(v, dim, l, left, out);
    median_cut(v, dim, r, leaves - left, out);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits::Limits;

    fn scene(n: usize, degree: u8, seed: u64) -> Gaussians {
        let mut rng = fastrand::Rng::with_seed(seed);
        let mut g = Gaussians::new(degree, 9);
        let k = sh_coeffs(degree);
        for _ in 0..n {
            g.positions.push([0; 3].map(|_| (rng.f32() - 0.5) * 20.0));
            g.log_scales.push([0; 3].map(|_| -5.0 + 3.0 * rng.f32()));
            g.rotations.push([0; 4].map(|_| rng.f32() - 0.5));
            g.opacity.push((rng.f32() - 0.5) * 8.0);
            g.lang_opacity.push(0.0);
            g.sh.extend((0..3 * k).map(|_| (rng.f32() - 0.5) * 2.0));
            g.lang.extend([0.0; 9]);
        }
        g
    }

    /// `got` is the entry of `book` nearest `x`.
    fn assert_nearest(book: &[f64], x: f32, got: f32) {
        let best = book
            .iter()
            .map(|b| (x as f64 - b).abs())
            .fold(f64::INFINITY, f64::min);
        assert!(book.contains(&(got as f64)), "{got} not in the codebook");
        assert_eq!((x as f64 - got as f64).abs(), best, "{x} -> {got}");
    }

    #[test]
    fn round_trips_through_the_reader_within_the_quantisation() {
        for (n, degree) in [(1000, 3), (777, 0), (1, 1)] {
            let g = scene(n, degree, n as u64);
            let bytes = write_sog(&g).unwrap();
            let back = super::super::sog::read_sog(&bytes, &Limits::default()).unwrap();
            assert_eq!(
                (back.len(), back.sh_degree, back.lang_width),
                (n, degree, 0)
            );
            let files = write_sog_files(&g).unwrap();
            let meta: serde_json::Value = serde_json::from_slice(&files[0].1).unwrap();
            // As the reader takes them: f32 (serde_json's f64 parse may be an ulp off).
            let book = |k: &str| -> Vec<f64> {
                let v: Vec<f64> = serde_json::from_value(meta[k]["codebook"].clone()).unwrap();
                v.iter().map(|&x| x as f32 as f64).collect()
            };
            let (sb, db) = (book("scales"), book("sh0"));
            for i in 0..n {
                for a in 0..3 {
                    // 16 bits over a log-domain range of about 2 ln(11): under 1e-3 here.
                    let (p, q) = (g.positions[i][a], back.positions[i][a]);
                    assert!((p - q).abs() <= 1e-3 * (1.0 + p.abs()), "{p} {q}");
                    assert_nearest(&sb, g.log_scales[i][a], back.log_scales[i][a]);
                    let j = i * back.sh_stride() + a;
                    assert_nearest(&db, g.sh[j], back.sh[j]);
                }
                let q = g.rotations[i];
                let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
                let dot: f32 = (0..4).map(|c| q[c] / norm * back.rotations[i][c]).sum();
                assert!(dot.abs() > 0.995, "{q:?} {:?}", back.rotations[i]);
                let sig = |x: f32| 1.0 / (1.0 + (-x).exp());
                assert!((sig(g.opacity[i]) - sig(back.opacity[i])).abs() <= 0.5 / 255.0 + 1e-6);
            }
            if degree > 0 {
                // Every Gaussian is its own palette entry: only the coefficient codebook is lossy.
                let rb = book("shN");
                let s = g.sh_stride();
                for (x, y) in
                    g.sh.iter()
                        .zip(&back.sh)
                        .enumerate()
                        .filter(|(j, _)| j % s >= 3)
                        .map(|(_, p)| p)
                {
                    assert_nearest(&rb, *x, *y);
                }
            }
        }
    }

    #[test]
    fn median_cut_gives_the_palette_size_and_means() {
        let g = scene(5000, 1, 7);
        let v: Vec<f32> = (0..5000)
            .flat_map(|i| g.sh[i * 12 + 3..i * 12 + 12].iter().copied())
            .collect();
        let (labels, centroids) = palette(&v, 9, 256);
        assert_eq!(centroids.len(), 256 * 9);
        let mut count = [0usize; 256];
        for &l in &labels {
            count[l as usize] += 1;
        }
        // Balanced leaves of 19 or 20 rows, each centroid the mean of its rows.
        assert!(count.iter().all(|&c| c == 19 || c == 20), "{count:?}");
        let mut sum = vec![0f64; 256 * 9];
        for (i, &l) in labels.iter().enumerate() {
            for d in 0..9 {
                sum[l as usize * 9 + d] += v[i * 9 + d] as f64;
            }
        }
        for e in 0..256 {
            for d in 0..9 {
                let mean = sum[e * 9 + d] / count[e] as f64;
                assert!((mean - centroids[e * 9 + d] as f64).abs() < 1e-5);
            }
        }
        // The palette is better than one mean for all.
        let err: f64 = labels
            .iter()
            .enumerate()
            .map(|(i, &l)| {
                (0..9)
                    .map(|d| (v[i * 9 + d] - centroids[l as usize * 9 + d]).powi(2) as f64)
                    .sum::<f64>()
            })
            .sum();
        let total: f64 = v.iter().map(|x| (*x as f64).powi(2)).sum();
        assert!(err < 0.8 * total, "{err} {total}");
    }

    #[test]
    fn texture_sizes_are_splat_transforms() {
        assert_eq!(texture_size(0), (4, 4));
        assert_eq!(texture_size(1000), (32, 32));
        assert_eq!(texture_size(1001), (32, 32));
        assert_eq!(texture_size(100_000), (320, 316));
    }
}
