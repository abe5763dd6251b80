//! Median wall time to decode GOP 0 (canonical Gaussians) of a `.dlgs` file, from bytes in
//! memory: `cargo run --release -p dlgs-decoder --example decode_timing -- FILE [RUNS]`.
//! A PlayCanvas `.sog` file is timed through dlgs's SOG reader instead (one thread: its WebP
//! textures decode one after another), for the comparison with SOG's own reader.

use std::io::Cursor;
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: decode_timing FILE [RUNS]");
    let runs: usize = args
        .next()
        .map_or(7, |r| r.parse().expect("RUNS is a number"));
    let bytes = std::fs::read(&path).expect("readable file");
    let mut times: Vec<f64> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            if path.ends_with(".sog") {
                let g = dlgs::interop::sog::read_sog(&bytes, &dlgs::Limits::default())
                    .expect("valid SOG file");
                std::hint::black_box(g.len());
                return start.elapsed().as_secs_f64() * 1e3;
            }
            let mut dec =
                dlgs_decoder::Decoder::new(Cursor::new(bytes.as_slice()), dlgs::Limits::default())
                    .expect("valid file");
            let c = dec.gop_canonical(0).expect("decodable GOP 0");
            std::hint::black_box(c.len());
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let what = if path.ends_with(".sog") {
        "read with dlgs's SOG reader"
    } else {
        "decode GOP 0"
    };
    println!(
        "{path}: {what} median {:.1} ms over {runs} runs",
        times[runs / 2]
    );
}
