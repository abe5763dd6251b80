//! Shared helpers for the integration tests: paths to the real data in `../shared/data`,
//! small real scenes, and an independent reference renderer.

pub mod reference_deform;
pub mod reference_render;
pub mod vectors;

use std::path::PathBuf;

use dlgs::Gaussians;

/// `../shared/data` relative to the workspace root (override with `DLGS_DATA`).
pub fn data_dir() -> PathBuf {
    if let Ok(d) = std::env::var("DLGS_DATA") {
        return PathBuf::from(d);
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data")
}

pub fn data(rel: &str) -> PathBuf {
    data_dir().join(rel)
}

/// Load a real scene from `../shared/data` by relative path.
pub fn load(rel: &str) -> Gaussians {
    let p = data(rel);
    dlgs::interop::read_splat_file(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Real scenes used across tests: (relative path, Gaussian count, SH degree).
pub const REAL_SCENES: &[(&str, usize, u8)] = &[
    ("tiny/metalsplatter_3-points-from-train.ply", 3, 3),
    ("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply", 1971, 3),
    ("ply/supersplat_fruit_drops_minimal_4721_sh3.ply", 4721, 3),
    ("ply/gs3d-fork_lod2_tile_0_6831_sh3.ply", 6831, 3),
    ("ply/gs3d-fork_lod1_tile_0_0.5x_14051_sh3.ply", 14051, 3),
    ("ply/gsplat_DATA_new_22589_sh3.ply", 22589, 3),
    ("ply/v3dg_donut_mipsplatting_45624_sh0.ply", 45624, 0),
    ("splat/marcelpadilla_plant.splat", 113648, 0),
    ("sequence/playcanvas_wave_200f/wave_0001.sog", 4225, 0),
];

/// Give a real scene DLGStream's language channels: a language opacity equal to the colour
/// opacity plus a smooth 9-dim feature derived from position (there is no real language
/// model here; this only exercises the second opacity and the feature image).
pub fn with_synthetic_language(g: &Gaussians) -> Gaussians {
    let mut out = g.clone();
    out.lang_width = 9;
    out.lang_opacity = g.opacity.iter().map(|o| o - 0.5).collect();
    out.lang = g
        .positions
        .iter()
        .flat_map(|p| {
            let s = |k: f32| (p[0] * k).sin() + (p[1] * k * 0.7).cos() * 0.5 + p[2] * 0.1;
            [
                s(1.0),
                s(2.0),
                s(3.0),
                s(0.5),
                s(1.5),
                s(2.5),
                s(0.3),
                s(0.7),
                s(1.1),
            ]
        })
        .collect();
    out
}

/// A real multi-chunk `.dlgs` made from a real scene: `gops` intra GOPs of 2 frames each
/// (positions nudged per GOP so GOPs differ), a META chunk, and unknown ancillary chunks at
/// scene level and inside GOP 0 that readers must skip. Returns (file bytes, GOP contents).
pub fn multi_gop_file(
    g: &Gaussians,
    gops: u32,
    codec: dlgs::chunks::craw::RawCodec,
) -> (Vec<u8>, Vec<dlgs::Canonical>) {
    use dlgs::chunks::craw;
    use dlgs::container::{ChunkType, SceneHeader, Writer, FLAG_MUST_UNDERSTAND};
    let mut scene = SceneHeader::still(g.len() as u32, g.sh_degree);
    if g.has_language() {
        scene.lang_levels = 3;
        scene.lang_dims = 3;
    }
    scene.gop_length = 2;
    scene.key_interval = 1;
    scene.gop_count = gops;
    scene.frame_count = gops * 2;
    let mut w = Writer::new(Vec::new(), scene).unwrap();
    w.scene_chunk(ChunkType::META, 0, br#"{"test":"multi_gop_file"}"#)
        .unwrap();
    w.scene_chunk(ChunkType(*b"XTRA"), 0, b"unknown ancillary, skip me")
        .unwrap();
    let mut canon = Vec::new();
    for k in 0..gops {
        let mut gk = g.clone();
        for p in &mut gk.positions {
            p[0] += 0.01 * k as f32;
        }
        let c = dlgs::Canonical::from_static(gk);
        w.begin_gop().unwrap();
        if k == 0 {
            w.gop_chunk(ChunkType(*b"XTRA"), 0, &[7u8; 33]).unwrap();
        }
        w.gop_chunk(
            ChunkType::CRAW,
            FLAG_MUST_UNDERSTAND,
            &craw::encode(&c, codec, 3).unwrap(),
        )
        .unwrap();
        canon.push(c);
    }
    (w.finish().unwrap(), canon)
}

/// Decode every GOP through the random-access reader.
pub fn decode_all_random(bytes: &[u8], limits: dlgs::Limits) -> dlgs::Result<Vec<dlgs::Canonical>> {
    let mut dec = dlgs_decoder::Decoder::new(std::io::Cursor::new(bytes), limits)?;
    (0..dec.scene().gop_count)
        .map(|g| dec.gop_canonical(g).map(|c| (*c).clone()))
        .collect()
}

/// Decode every GOP's canonical state through the in-order stream decoder (residual GOPs are
/// applied to their reference GOP's state; the index and tail are checked at the end).
pub fn decode_all_stream(bytes: &[u8], limits: dlgs::Limits) -> dlgs::Result<Vec<dlgs::Canonical>> {
    let mut dec = dlgs_decoder::stream::StreamDecoder::with_limits(bytes, limits)?;
    let mut out = Vec::new();
    while let Some(g) = dec.next_gop()? {
        out.push((*g.canonical).clone());
    }
    assert!(dec.finished(), "stream finished without End");
    Ok(out)
}

/// Run `f` on a fresh rayon pool of `threads` threads (determinism tests compare the results).
pub fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool")
        .install(f)
}
