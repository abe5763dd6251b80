//! Probe: drop the Gaussians that add least to 24 views of the scene (3 elevations x 8 azimuths,
//! not the benchmark's cameras) and write the rest as PLYs, one per fraction:
//! `cargo run --release -p dlgs-encoder --example prune_probe -- SCENE OUT_PREFIX [F1,F2,..]`.

use dlgs_render::contribution::contributions;
use dlgs_render::{orbit_cameras, OrbitSpec};

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: prune_probe SCENE OUT_PREFIX");
    let prefix = args.next().expect("usage: prune_probe SCENE OUT_PREFIX");
    let g = dlgs::interop::read_splat_file(path.as_ref()).expect("readable scene");
    let mut cams = Vec::new();
    for el in [-25.0, 10.0, 50.0] {
        cams.extend(orbit_cameras(
            &g,
            &OrbitSpec {
                count: 8,
                width: 800,
                height: 600,
                elevation_deg: el,
                ..OrbitSpec::default()
            },
        ));
    }
    let t = std::time::Instant::now();
    let c = contributions(&g, &cams);
    println!(
        "{} Gaussians, contributions in {:.2} s",
        g.len(),
        t.elapsed().as_secs_f64()
    );
    let raw: Vec<u8> = c.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(format!("{prefix}-contrib.f64"), raw).unwrap();
    let mut order: Vec<usize> = (0..g.len()).collect();
    order.sort_by(|&a, &b| c[a].total_cmp(&c[b]).then(a.cmp(&b)));
    // Optional third argument: comma-separated fractions.
    let fracs: Vec<f64> = args
        .next()
        .map_or(vec![0.02, 0.05, 0.1, 0.15, 0.2, 0.3], |s| {
            s.split(',')
                .map(|f| f.parse().expect("a fraction"))
                .collect()
        });
    for frac in fracs {
        let drop = (g.len() as f64 * frac) as usize;
        let mut keep = vec![true; g.len()];
        for &i in &order[..drop] {
            keep[i] = false;
        }
        let mut out = dlgs::Gaussians::new(g.sh_degree, g.lang_width);
        for i in (0..g.len()).filter(|&i| keep[i]) {
            out.push_from(&g, i);
        }
        let thr = c[order[drop]];
        let file = format!("{prefix}-{frac}.ply");
        std::fs::write(&file, dlgs::interop::ply::write_ply(&out).unwrap()).unwrap();
        println!("{frac}: dropped {drop} (weight below {thr:.4} px) -> {file}");
    }
}
