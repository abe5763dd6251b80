//! Probe of the `AHAC` context fit on a raw (`ANCR`) Scaffold-GS file's first GOP:
//! `cargo run --release -p dlgs-encoder --example ahac_fit_probe -- raw.dlgs [iterations] [hidden] [k | f,s,o] [top levels log2 plane]`
//! (steps `k` times the prior's defaults). Prints prior and fitted bytes, parts and time.

use dlgs::chunks::ancr;
use dlgs::container::ChunkType;
use dlgs::container::FileReader;
use dlgs::Limits;
use dlgs_encoder::scaffold_fit::{fit_anchors, ContextFitSettings};
use dlgs_encoder::scaffold_prior::DEFAULT_PRIOR_STEPS;

fn main() -> dlgs::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = &args[1];
    let arg = |i: usize, d: f64| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let mut r = FileReader::open(std::fs::File::open(path).expect("open"))?;
    let scene = r.scene().clone();
    let c = r
        .gop_chunks(0)?
        .into_iter()
        .find(|c| c.ty == ChunkType::ANCR)
        .expect("a raw GOP 0");
    let p = r.payload(&c)?;
    let anchors = ancr::decode(&p, c.payload_offset(), &scene, &Limits::default())?;
    // Steps: `k` (times the prior's defaults) or `f,s,o`.
    let steps: Vec<f32> = args.get(4).map_or(vec![1.0], |a| {
        a.split(',').map(|v| v.parse().expect("a number")).collect()
    });
    let steps = match steps.as_slice() {
        [f, s, o] => [*f, *s, *o],
        [k] => DEFAULT_PRIOR_STEPS.map(|q| q * k),
        _ => panic!("steps: k or f,s,o"),
    };
    let mut s = ContextFitSettings::new(steps);
    s.iterations = arg(2, 400.0) as usize;
    s.hidden = arg(3, 16.0) as usize;
    // Optional grid: top 3D resolution, 3D levels, log2 table, plane resolution (0: none).
    if args.len() > 5 {
        use dlgs::model::hac_context::GridShape;
        let (top, levels, log2, plane) = (
            arg(5, 24.0),
            arg(6, 4.0) as usize,
            arg(7, 12.0) as u8,
            arg(8, 0.0) as u32,
        );
        let res = (0..levels)
            .map(|l| (6.0 * (top / 6.0).powf(l as f64 / (levels.max(2) - 1) as f64)).round() as u32)
            .collect();
        s.grids = Some((
            GridShape {
                resolutions: res,
                log2_table: log2,
                features: 2,
            },
            GridShape {
                resolutions: if plane > 0 { vec![plane] } else { vec![] },
                log2_table: log2,
                features: 2,
            },
        ));
    }
    let (_, rep) = fit_anchors(&anchors, &s, |_, _| {})?;
    println!(
        "steps {:?}: prior {} B, fitted {} B (kept {}), mantissa {}, {:.1} s",
        s.steps,
        rep.prior_bytes,
        rep.fitted_bytes,
        rep.kept_fit,
        rep.mantissa_bits,
        rep.fit_seconds
    );
    println!("{:?}", rep.sizes);
    let log: Vec<String> = rep
        .bits_log
        .iter()
        .step_by(5)
        .map(|(i, b)| format!("{i}:{b:.0}"))
        .collect();
    println!("bits/anchor: {}", log.join(" "));
    Ok(())
}
