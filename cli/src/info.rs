//! `dlgs info` and `dlgs verify`.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use anyhow::{Context, Result};
use dlgs::container::{FileReader, NO_REFERENCE};
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
    gops: Vec<GopRow>,
}

fn collect(path: &Path) -> Result<Info> {
    let f = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut r = FileReader::open_with_limits(BufReader::new(f), Limits::default())
        .with_context(|| format!("reading {}", path.display()))?;
    let scene = r.scene().clone();
    let mut by_type: BTreeMap<String, u64> = BTreeMap::new();
    let mut scene_chunks = BTreeMap::new();
    for c in r.scene_chunks() {
        *scene_chunks.entry(c.ty.to_string()).or_insert(0) += c.len;
        *by_type.entry(c.ty.to_string()).or_insert(0) += c.len;
    }
    let mut gops = Vec::new();
    for e in r.index().entries.clone() {
        let mut chunks = BTreeMap::new();
        for c in r.gop_chunks(e.gop)? {
            *chunks.entry(c.ty.to_string()).or_insert(0) += c.len;
            *by_type.entry(c.ty.to_string()).or_insert(0) += c.len;
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
        gops,
    })
}

pub fn run_info(path: &Path, json: bool) -> Result<()> {
    let info = collect(path)?;
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
        "  variant {:?}, residuals {:?}, deformation {:?}",
        h.variant, h.residual_mode, h.deform_model
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
    println!(
        "  {} static + {} dynamic Gaussians, SH degree {}, language {}x{}, {} time channels",
        h.n_static, h.n_dynamic, h.sh_degree, h.lang_levels, h.lang_dims, h.time_channels
    );
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
    Ok(())
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
