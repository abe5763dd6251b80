//! `dlgs info` and `dlgs verify`.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use anyhow::{Context, Result};
use dlgs::chunks::csog::{self, CsogSummary};
use dlgs::container::{ChunkType, FileReader, NO_REFERENCE};
use dlgs::Limits;
use serde::Serialize;

#[derive(Serialize)]
struct GopRow {
    gop: u32,
    first_frame: u32,
    frames: u32,
    reference: Option<u32>,
    offset: u64,
    bytes: u64,
    bytes_per_frame: f64,
    chunks: BTreeMap<String, u64>,
}

#[derive(Serialize)]
struct Info {
    file: String,
    file_bytes: u64,
    version: String,
    header: dlgs::SceneHeader,
    duration_seconds: f64,
    bytes_per_frame: f64,
    scene_chunks: BTreeMap<String, u64>,
    chunk_bytes_by_type: BTreeMap<String, u64>,
    index_bytes: u64,
    /// The `META` chunk (informative JSON: encoder, options that differ from the defaults,
    /// source file); a string when it is not valid JSON.
    meta: Option<serde_json::Value>,
    /// How GOP 0 codes its time features (`TFEA` codec, §6.2), when the scene has dynamics.
    time_features: Option<String>,
    gops: Vec<GopRow>,
    /// With `--channels`: each `CSOG` chunk's records (§6.5), GOP by GOP.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    csog: Vec<CsogRow>,
}

#[derive(Serialize)]
struct CsogRow {
    gop: u32,
    #[serde(flatten)]
    summary: CsogSummary,
}

/// `TFEA` codec byte (§6.2) in words.
fn tfea_codec_name(codec: u8) -> String {
    match codec {
        0 => "exact f32 (TFEA codec 0)".into(),
        1 => "12-bit HEVC (TFEA codec 1)".into(),
        2 => "the reference run's own 12-bit HEVC stream (TFEA codec 2)".into(),
        3 => "intra-only 12-bit HEVC, every key decodable alone (TFEA codec 3)".into(),
        4 => "quantised per channel + zstd, no video codec (TFEA codec 4)".into(),
        c => format!("unknown TFEA codec {c}"),
    }
}

fn collect(path: &Path, channels: bool) -> Result<Info> {
    let f = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut r = FileReader::open_with_limits(BufReader::new(f), Limits::default())
        .with_context(|| format!("reading {}", path.display()))?;
    let scene = r.scene().clone();
    let mut by_type: BTreeMap<String, u64> = BTreeMap::new();
    let mut scene_chunks = BTreeMap::new();
    let mut meta = None;
    for c in r.scene_chunks().to_vec() {
        *scene_chunks.entry(c.ty.to_string()).or_insert(0) += c.len;
        *by_type.entry(c.ty.to_string()).or_insert(0) += c.len;
        if c.ty == dlgs::container::ChunkType::META && meta.is_none() {
            let p = r.payload(&c)?;
            meta = Some(serde_json::from_slice(&p).unwrap_or_else(|_| {
                serde_json::Value::String(String::from_utf8_lossy(&p).into_owned())
            }));
        }
    }
    let mut time_features = None;
    let mut gops = Vec::new();
    let mut csog = Vec::new();
    for e in r.index().entries.clone() {
        if time_features.is_none() {
            if let Some(c) = r
                .gop_chunks(e.gop)?
                .into_iter()
                .find(|c| c.ty == dlgs::container::ChunkType::TFEA)
            {
                let p = r.payload(&c)?;
                time_features = p.first().map(|&b| tfea_codec_name(b));
            }
        }
        let mut chunks = BTreeMap::new();
        for c in r.gop_chunks(e.gop)? {
            *chunks.entry(c.ty.to_string()).or_insert(0) += c.len;
            *by_type.entry(c.ty.to_string()).or_insert(0) += c.len;
            if channels && c.ty == ChunkType::CSOG {
                let p = r.payload(&c)?;
                let summary = csog::describe(&p, c.payload_offset(), &scene)
                    .with_context(|| format!("reading the CSOG chunk of GOP {}", e.gop))?;
                csog.push(CsogRow {
                    gop: e.gop,
                    summary,
                });
            }
        }
        gops.push(GopRow {
            gop: e.gop,
            first_frame: e.header.first_frame,
            frames: e.header.frame_count,
            reference: (e.header.reference_gop != NO_REFERENCE).then_some(e.header.reference_gop),
            offset: e.offset,
            bytes: e.length,
            bytes_per_frame: e.length as f64 / e.header.frame_count as f64,
            chunks,
        });
    }
    let (maj, min) = r.version();
    Ok(Info {
        file: path.display().to_string(),
        file_bytes: r.file_len(),
        version: format!("{maj}.{min}"),
        duration_seconds: scene.duration_seconds(),
        bytes_per_frame: r.file_len() as f64 / scene.frame_count as f64,
        header: scene,
        scene_chunks,
        chunk_bytes_by_type: by_type,
        index_bytes: r.index_bytes(),
        meta,
        time_features,
        gops,
        csog,
    })
}

pub fn run_info(path: &Path, json: bool, channels: bool) -> Result<()> {
    let info = collect(path, channels)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(());
    }
    let h = &info.header;
    println!(
        "{}  ({} bytes, .dlgs v{})",
        info.file, info.file_bytes, info.version
    );
    println!(
        "  variant {:?}, residuals {:?}{}, deformation {:?}",
        h.variant,
        h.residual_mode,
        if h.refresh_interval > 0 {
            format!(" (full canonical state every {} GOPs)", h.refresh_interval)
        } else {
            String::new()
        },
        h.deform_model
    );
    println!(
        "  {} frames at {}/{} fps ({:.3} s), {} GOPs of {} frames, key every {} frames",
        h.frame_count,
        h.fps_num,
        h.fps_den,
        info.duration_seconds,
        h.gop_count,
        h.gop_length,
        h.key_interval
    );
    let what = if h.variant == dlgs::container::header::Variant::Scaffold {
        "anchors (10 neural Gaussians each, generated per camera)"
    } else {
        "Gaussians"
    };
    println!(
        "  {} static + {} dynamic {what}, SH degree {}, language {}x{}, {} time channels",
        h.n_static, h.n_dynamic, h.sh_degree, h.lang_levels, h.lang_dims, h.time_channels
    );
    if let Some(t) = &info.time_features {
        println!("  time features: {t}");
    }
    if let Some(m) = &info.meta {
        println!("  META: {m}");
    }
    println!(
        "  bytes per frame: {:.1} ({:.2} KiB)",
        info.bytes_per_frame,
        info.bytes_per_frame / 1024.0
    );
    println!("  payload bytes by chunk type:");
    for (t, b) in &info.chunk_bytes_by_type {
        println!("    {t}  {b:>12}");
    }
    println!("    index+tail {:>8}", info.index_bytes);
    println!("  GOP  first  frames  ref   offset        bytes   bytes/frame  chunks");
    for g in &info.gops {
        let chunks: Vec<String> = g.chunks.iter().map(|(k, v)| format!("{k}:{v}")).collect();
        println!(
            "  {:>3}  {:>5}  {:>6}  {:>3}  {:>8}  {:>11}  {:>12.1}  {}",
            g.gop,
            g.first_frame,
            g.frames,
            g.reference.map_or("-".to_string(), |r| r.to_string()),
            g.offset,
            g.bytes,
            g.bytes_per_frame,
            chunks.join(" ")
        );
    }
    for c in &info.csog {
        print_csog(c, h);
    }
    Ok(())
}

/// A `CSOG` chunk's records, then their bytes by attribute (bits per Gaussian over the set's
/// Gaussians, share of the payload).
fn print_csog(c: &CsogRow, header: &dlgs::SceneHeader) {
    let s = &c.summary;
    println!(
        "  CSOG of GOP {} (layout {}, {} bytes):",
        c.gop, s.layout, s.payload_bytes
    );
    println!(
        "    {:<8} {:>4} {:>9}  {:<17} {:>4}  {:>10} {:>7}  coding",
        "set", "part", "Gaussians", "channel", "bits", "bytes", "bits/G"
    );
    let per_g = |bytes: usize, n: usize| 8.0 * bytes as f64 / n.max(1) as f64;
    for r in &s.records {
        println!(
            "    {:<8} {:>4} {:>9}  {:<17} {:>4}  {:>10} {:>7.2}  {}",
            r.set,
            r.part,
            r.gaussians,
            r.channel,
            r.bits,
            r.bytes,
            per_g(r.bytes, r.gaussians),
            r.coding
        );
    }
    // By set and attribute, in record order.
    let mut groups: Vec<((&str, &str), usize)> = Vec::new();
    for r in &s.records {
        match groups.iter_mut().find(|g| g.0 == (r.set, r.attribute)) {
            Some(g) => g.1 += r.bytes,
            None => groups.push(((r.set, r.attribute), r.bytes)),
        }
    }
    let set_len = |set: &str| match set {
        "static" => header.n_static as usize,
        _ => header.n_dynamic as usize,
    };
    let share = |b: usize| 100.0 * b as f64 / s.payload_bytes.max(1) as f64;
    println!("    by attribute:");
    for ((set, attribute), bytes) in &groups {
        println!(
            "      {set:<8} {attribute:<10} {bytes:>10} B  {:>7.2} bits/G  {:>5.1} %",
            per_g(*bytes, set_len(set)),
            share(*bytes)
        );
    }
    let coded: usize = groups.iter().map(|g| g.1).sum();
    let rest = s.payload_bytes.saturating_sub(coded);
    println!(
        "      record heads, ranges and counts {rest:>6} B  {:>5.1} %",
        share(rest)
    );
}

pub fn run_verify(path: &Path) -> Result<()> {
    let f = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut r = FileReader::open(BufReader::new(f))
        .with_context(|| format!("reading {}", path.display()))?;
    let n = r
        .verify_all()
        .with_context(|| format!("verifying {}", path.display()))?;
    println!(
        "{}: OK ({} GOPs, {n} payload chunks, all CRCs match)",
        path.display(),
        r.scene().gop_count
    );
    Ok(())
}
