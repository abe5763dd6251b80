//! Write the >= 250k-Gaussian benchmark scene (`bench_scenes::big`: real captures side by side)
//! as an INRIA PLY, so the CLI can be timed on it:
//! `cargo run --release -p dlgs-render --example write_big_scene -- target/big.ply`.

use dlgs_render::bench_scenes::big;

fn main() {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "target/big.ply".into());
    let g = big();
    let bytes = dlgs::interop::ply::write_ply(&g).expect("finite scene");
    std::fs::write(&out, bytes).expect("writable output");
    println!("{out}: {} Gaussians, SH {}", g.len(), g.sh_degree);
}
