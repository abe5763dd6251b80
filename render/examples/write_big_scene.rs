//! Write a benchmark scene built from the real ones as an INRIA PLY, so the CLI can be timed
//! and compared on it: `bench_scenes::big` (>= 250k Gaussians, the plant twice plus the donut)
//! or, with `--mosaic`, `bench_scenes::mosaic` (every real scene once, no repeats), or, with
//! `--shuffled-copy`, `bench_scenes::big_copy_shuffled` (the same Gaussians as `big`, the second
//! plant in another order):
//! `cargo run --release -p dlgs-render --example write_big_scene -- [--mosaic | --shuffled-copy] target/big.ply`.

use dlgs_testkit::bench_scenes::{big, big_copy_shuffled, mosaic};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let use_mosaic = args.iter().any(|a| a == "--mosaic");
    let out = args
        .iter()
        .find(|a| !a.starts_with("--"))
        .cloned()
        .unwrap_or_else(|| "target/big.ply".into());
    let shuffled = args.iter().any(|a| a == "--shuffled-copy");
    let g = match (use_mosaic, shuffled) {
        (true, true) => {
            eprintln!("--mosaic and --shuffled-copy name two different scenes");
            std::process::exit(2)
        }
        (true, false) => mosaic(),
        (false, true) => big_copy_shuffled(),
        (false, false) => big(),
    };
    let bytes = dlgs::interop::ply::write_ply(&g).expect("finite scene");
    std::fs::write(&out, bytes).expect("writable output");
    println!("{out}: {} Gaussians, SH {}", g.len(), g.sh_degree);
}
