//! An independent, deliberately simple f64 implementation of the deformation formulas of
//! format-spec §7 (one Gaussian at a time, no GEMM, no per-key caching), to check the
//! decoder's blocked f32 GEMM path against.

use dlgs::model::{DynamicGop, Gaussians, Mlp};

fn mlp(m: &Mlp, x: &[f64]) -> Vec<f64> {
    let mut h = x.to_vec();
    for (li, l) in m.layers.iter().enumerate() {
        let mut o: Vec<f64> = (0..l.outputs)
            .map(|r| {
                (0..l.inputs)
                    .map(|c| l.weights[r * l.inputs + c] as f64 * h[c])
                    .sum()
            })
            .collect();
        if li + 1 < m.layers.len() {
            o.iter_mut().for_each(|v| *v = v.max(0.0));
        }
        h = o;
    }
    if m.role.output_tanh() {
        h.iter_mut().for_each(|v| *v = v.tanh());
    }
    h
}

fn norm(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
    q.map(|v| v / n)
}

/// The dynamic Gaussians of the reference model at key `k`, fraction `d`, seen from `cam`.
pub fn deform_reference(
    canon: &Gaussians,
    gop: &DynamicGop,
    k: usize,
    d: f64,
    cam: [f32; 3],
    language: bool,
) -> Gaussians {
    let f = &gop.features;
    let m = &gop.mlps;
    let mut out = canon.clone();
    for i in 0..canon.len() {
        let fk: Vec<f64> = f.at(i, k).iter().map(|&v| v as f64).collect();
        let fk1: Vec<f64> = f.at(i, k + 1).iter().map(|&v| v as f64).collect();
        let p: [f64; 3] = canon.positions[i].map(|v| v as f64);
        let (ok, ok1) = (mlp(&m.deform, &fk[..12]), mlp(&m.deform, &fk1[..12]));
        let (ck, ck1) = (mlp(&m.cov, &fk[..12]), mlp(&m.cov, &fk1[..12]));
        let (d2, d3) = (d * d, d * d * d);
        let h = [
            2.0 * d3 - 3.0 * d2 + 1.0,
            d3 - 2.0 * d2 + d,
            -2.0 * d3 + 3.0 * d2,
            d3 - d2,
        ];
        for a in 0..3 {
            let pk = p[a] + ok[a];
            let pk1 = p[a] + ok1[a];
            out.positions[i][a] =
                (h[0] * pk + h[1] * ok[3 + a] + h[2] * pk1 + h[3] * ok1[3 + a]) as f32;
        }
        let q: [f64; 4] = canon.rotations[i].map(|v| v as f64);
        let qk = norm(std::array::from_fn(|a| q[a] + ck[3 + a]));
        let qk1 = norm(std::array::from_fn(|a| q[a] + ck1[3 + a]));
        let dot = (0..4)
            .map(|a| qk[a] * qk1[a])
            .sum::<f64>()
            .clamp(-1.0 + 1e-4, 1.0 - 1e-4);
        let w = dot.acos().max(1e-4);
        let s = w.sin().max(1e-4);
        let (mut p0, mut p1) = (((1.0 - d) * w).sin() / s, (d * w).sin() / s);
        let sum = (p0 + p1).max(1e-4);
        p0 /= sum;
        p1 /= sum;
        let r: [f64; 4] = std::array::from_fn(|a| p0 * qk[a] + p1 * qk1[a]);
        let r = if r.iter().map(|v| v.abs()).sum::<f64>() <= 1e-4 {
            qk
        } else {
            norm(r)
        };
        out.rotations[i] = r.map(|v| v as f32);
        if m.scale_offsets {
            for a in 0..3 {
                out.log_scales[i][a] = (canon.log_scales[i][a] as f64 + ck[a]) as f32;
            }
        }
        let lerp = |c: usize| fk[c] * (1.0 - d) + fk1[c] * d;
        let v: [f64; 3] = std::array::from_fn(|a| p[a] - cam[a] as f64);
        let dist = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut x: Vec<f64> = (4..12).map(lerp).collect();
        x.extend(v.map(|c| if dist > 0.0 { c / dist } else { 0.0 }));
        x.push(dist);
        let dop = mlp(&m.opacity, &x);
        out.opacity[i] = (canon.opacity[i] as f64 + dop[0]) as f32;
        let dsh = mlp(&m.color, &x);
        let st = canon.sh_stride();
        for (j, dv) in dsh.iter().enumerate() {
            out.sh[i * st + j] = (canon.sh[i * st + j] as f64 + dv) as f32;
        }
        if canon.has_language() {
            if dop.len() > 1 {
                out.lang_opacity[i] = (canon.lang_opacity[i] as f64 + dop[1]) as f32;
            }
            if language {
                let y: Vec<f64> = (8..16).map(lerp).collect();
                let dl = mlp(m.lang.as_ref().unwrap(), &y);
                let lw = canon.lang_width;
                for (j, dv) in dl.iter().enumerate() {
                    out.lang[i * lw + j] = (canon.lang[i * lw + j] as f64 + dv) as f32;
                }
            }
        }
    }
    out
}
