//! Lossless coder candidates for the quantised attribute grids (issue 5): writes every channel
//! of a real scene's sorted, quantised grid (as `dlgs encode --quality Q` builds it: never-drawn
//! Gaussians left out, orientation canonicalised, k-d layout) to `OUT_DIR/chNN.u16` (u16 LE, row-major, `width` wide) with
//! `OUT_DIR/manifest.json`, and records the bytes of each of our grid codecs on it, so that
//! `experiments/canonical/grid_candidates.py` can set PNG, lossless WebP and JPEG XL beside them.
//! `cargo run --release -p dlgs-encoder --example grid_candidates -- SCENE OUT_DIR [QUALITY]`

use std::path::PathBuf;

use dlgs::chunks::csog::grid_codecs as grid_coder;
use dlgs::chunks::csog::{grid_width, quantise_set, QuantBits};
use dlgs_encoder::grid_sort::{grid_order, permute, SortSpec};
use dlgs_encoder::invisible::drop_never_drawn;
use dlgs_encoder::orientation::closest_to_identity;

/// Channel names in payload order (§6.5.2) for a scene with `sh_stride` SH coefficients.
fn names(sh_stride: usize) -> Vec<String> {
    let mut n: Vec<String> = [
        "x",
        "y",
        "z",
        "ls0",
        "ls1",
        "ls2",
        "rot_index",
        "r0",
        "r1",
        "r2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    n.push("opacity".into());
    n.extend((0..sh_stride).map(|j| format!("sh{j}")));
    n
}

fn main() {
    let mut args = std::env::args().skip(1);
    let usage = "usage: grid_candidates SCENE OUT_DIR [QUALITY]";
    let scene = PathBuf::from(args.next().expect(usage));
    let out = PathBuf::from(args.next().expect(usage));
    let quality = args.next().unwrap_or_else(|| "high".into());
    let bits = QuantBits::preset(&quality).expect("quality high, medium or low");
    let g = dlgs::interop::read_splat_file(&scene).expect("readable scene");
    let (g, _) = drop_never_drawn(&g);
    let g = closest_to_identity(&g);
    let g = permute(&g, &grid_order(&g, SortSpec::NONE));
    let w = grid_width(g.len()).max(1);
    let set = quantise_set(&g, &bits);
    let names = names(g.sh_stride());
    std::fs::create_dir_all(&out).expect("output directory");
    let mut rows = Vec::new();
    for (j, (b, _, _, q)) in set.channels.iter().enumerate() {
        let mut cells = q.clone();
        cells.resize(w * w, 0);
        let file = format!("ch{j:02}.u16");
        let raw: Vec<u8> = cells.iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(out.join(&file), raw).expect("grid file");
        let prev = j
            .checked_sub(1)
            .map(|p| (set.channels[p].3.as_slice(), set.channels[p].0));
        let prev2 = j
            .checked_sub(2)
            .map(|p| (set.channels[p].3.as_slice(), set.channels[p].0));
        let (codec, best) =
            grid_coder::encode_best(q, prev, prev2, w, *b, 19, Some(grid_coder::MIXED_MARGIN));
        let (_, tabled) = grid_coder::encode_best_tabled(q, prev, w, *b, 19);
        let sizes = serde_json::json!({
            "name": names.get(j).cloned().unwrap_or_else(|| format!("ch{j}")),
            "file": file,
            "bits": b,
            "best_codec": codec as u8,
            "codec5_mode": (codec == grid_coder::GridCodec::Adaptive).then(|| [best[0], best[1]]),
            "best": best.len(),
            "tabled": tabled.len(),
            "histogram": grid_coder::encode_histogram(q, 19).map(|d| d.len()),
            "zstd19": grid_coder::encode_zstd(q, *b, 19).len(),
        });
        rows.push(sizes);
    }
    let manifest = serde_json::json!({
        "scene": scene.file_name().map(|s| s.to_string_lossy().into_owned()),
        "quality": quality,
        "n": g.len(),
        "width": w,
        "channels": rows,
    });
    std::fs::write(
        out.join("manifest.json"),
        serde_json::to_string_pretty(&manifest).expect("json"),
    )
    .expect("manifest");
    println!(
        "{}: {} channels, {} Gaussians, grid {w}x{w}",
        scene.display(),
        set.channels.len(),
        g.len()
    );
}
