//! Bytes per attribute of the sorted-grid canonical codec on a real scene, for each preset and
//! sort setting (and with octree positions): `cargo run --release -p dlgs-encoder --example csog_breakdown -- SCENE`.

use std::time::Instant;

use dlgs::chunks::csog::{breakdown, QuantBits};
use dlgs_encoder::grid_sort::{grid_order, neighbour_distance, permute, SortSpec};

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: csog_breakdown SCENE");
    let g = dlgs::interop::read_splat_file(path.as_ref()).expect("readable scene");
    println!("{path}: {} Gaussians, SH {}", g.len(), g.sh_degree);
    // "octree": positions as an octree, the order derived from them (layout 2, the default).
    for (label, sort, octree) in [
        ("octree", None, true),
        ("file order", None, false),
        ("k-d only", Some(SortSpec::NONE), false),
        ("passes 1", Some(SortSpec::FAST), false),
        ("passes 3", Some(SortSpec::REFINED), false),
        ("passes 8", Some(SortSpec { passes: 8 }), false),
    ] {
        let start = Instant::now();
        let order: Vec<u32> = match sort {
            Some(s) => grid_order(&g, s),
            None => (0..g.len() as u32).collect(),
        };
        let t = start.elapsed().as_secs_f64();
        let sorted = permute(&g, &order);
        for (name, bits) in [
            ("high", QuantBits::HIGH),
            ("medium", QuantBits::MEDIUM),
            ("low", QuantBits::LOW),
        ] {
            let b = breakdown(&sorted, &bits, 9, octree);
            let total: usize = b.iter().map(|x| x.1).sum();
            let parts: Vec<String> = b
                .iter()
                .map(|(n, s)| format!("{n} {:.2}", *s as f64 * 8.0 / g.len() as f64))
                .collect();
            println!(
                "{label:10} sort {t:6.2} s  neighbour dist {:.4}  {name:6} {total:8} B = {:6.2} bits/G  [{}]",
                neighbour_distance(&g, &order),
                total as f64 * 8.0 / g.len() as f64,
                parts.join(", ")
            );
        }
    }
}
