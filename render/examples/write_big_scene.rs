//! Write a benchmark scene built from the real ones as an INRIA PLY, so the CLI can be timed
//! and compared on it: `bench_scenes::big` (>= 250k Gaussians, the plant twice plus the donut)
//! or, with `--mosaic`, `bench_scenes::mosaic` (every real scene once, no repeats):
//! `cargo run --release -p dlgs-render --example write_big_scene -- [--mosaic] target/big.ply`.

use dlgs_render::bench_scenes::{big, mosaic};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let use_mosaic = args.iter().any(|a| a == "--mosaic");
    let out = args
        .iter()
        .find(|a| !a.starts_with("--"))
        .cloned()
        .unwrap_or_else(|| "target/big.ply".into());
    let g = if use_mosaic { mosaic() } else { big() };
    let bytes = dlgs::interop::ply::write_ply(&g).expect("finite scene");
    std::fs::write(&out, bytes).expect("writable output");
    println!("{out}: {} Gaussians, SH {}", g.len(), g.sh_degree);
}
