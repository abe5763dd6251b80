//! Where the time of a residual GOP goes: `cargo run --release -p dlgs-decoder --example
//! residual_timing -- FILE.dlgs` times, for every residual GOP, reading and decoding its
//! residual chunk and applying it to the reference state. `-- FILE.dlgs eval` then times the
//! field evaluation alone on GOP 1 (`NtcField::residuals_at` on every static and dynamic
//! position), best of 9 runs, which is steadier on a noisy machine than one apply.

use std::time::Instant;

use dlgs::chunks::{rdlt, rntc};
use dlgs::container::ChunkType;
use dlgs_decoder::Decoder;

fn main() -> dlgs::Result<()> {
    let path = std::env::args()
        .nth(1)
        .expect("usage: residual_timing FILE.dlgs");
    let mut dec = Decoder::open_path(&path)?;
    let scene = dec.scene().clone();
    let limits = dec.reader().limits().clone();
    let base = dec.gop_canonical(0)?;
    if std::env::args().nth(2).as_deref() == Some("eval") {
        return eval_only(&mut dec, &scene, &limits, &base);
    }
    for g in 1..scene.gop_count {
        let chunks = dec.reader().gop_chunks(g)?;
        for c in chunks {
            let t0 = Instant::now();
            let p = dec.reader().payload(&c)?;
            let t1 = Instant::now();
            let (decode_ms, apply_ms) = match c.ty {
                ChunkType::RNTC => {
                    let f = rntc::decode(&p, 0, &scene, &limits)?;
                    let t2 = Instant::now();
                    f.apply(&base)?;
                    (
                        (t2 - t1).as_secs_f64() * 1e3,
                        t2.elapsed().as_secs_f64() * 1e3,
                    )
                }
                ChunkType::RDLT => {
                    let d = rdlt::decode(&p, 0, &scene, &limits)?;
                    let t2 = Instant::now();
                    d.apply(&base);
                    (
                        (t2 - t1).as_secs_f64() * 1e3,
                        t2.elapsed().as_secs_f64() * 1e3,
                    )
                }
                _ => continue,
            };
            println!(
                "GOP {g} {}: {} bytes, read {:.2} ms, decode {decode_ms:.2} ms, apply {apply_ms:.2} ms",
                c.ty,
                p.len(),
                (t1 - t0).as_secs_f64() * 1e3
            );
        }
    }
    Ok(())
}

fn eval_only<R: std::io::Read + std::io::Seek>(
    dec: &mut Decoder<R>,
    scene: &dlgs::SceneHeader,
    limits: &dlgs::Limits,
    base: &dlgs::model::Canonical,
) -> dlgs::Result<()> {
    let c = dec
        .reader()
        .gop_chunks(1)?
        .into_iter()
        .find(|c| c.ty == ChunkType::RNTC)
        .expect("GOP 1 has an RNTC chunk");
    let p = dec.reader().payload(&c)?;
    let f = rntc::decode(&p, 0, scene, limits)?;
    let positions: Vec<[f32; 3]> = base
        .statics
        .positions
        .iter()
        .chain(&base.dynamics.positions)
        .copied()
        .collect();
    let mut best = f64::INFINITY;
    let mut check = 0f64;
    for _ in 0..9 {
        let t = Instant::now();
        let rows = f.residuals_at(&positions);
        best = best.min(t.elapsed().as_secs_f64() * 1e3);
        check = rows.iter().map(|&v| v as f64).sum();
    }
    println!(
        "residuals_at on {} positions, {} threads: best of 9 {best:.2} ms (checksum {check:.6e})",
        positions.len(),
        rayon::current_num_threads()
    );
    Ok(())
}
