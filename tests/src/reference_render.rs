//! A deliberately simple reference renderer, written separately from `dlgs-render`: f64,
//! one pixel at a time, every Gaussian tested at every pixel (no tiles, no bounding boxes,
//! no fast exp). It implements the same forward model (EWA projection with 0.3 px dilation,
//! 1.3x FOV clamp of the Jacobian, near plane 0.2, SH + 0.5 clamped at 0, alpha =
//! min(0.99, o exp(power)), skip alpha < 1/255, stop before T drops below 1e-4, white or given
//! background, language with its own opacity and transmittance, truncated where colour stops).

use dlgs::Gaussians;
use dlgs_render::Camera;

struct Prim {
    depth: f64,
    index: usize,
    mean: [f64; 2],
    conic: [f64; 3],
    o: f64,
    ol: f64,
    rgb: [f64; 3],
}

fn sh_rgb(deg: u8, sh: &[f32], d: [f64; 3]) -> [f64; 3] {
    let [x, y, z] = d;
    let c1 = 0.4886025119029199;
    let c2 = [
        1.0925484305920792,
        -1.0925484305920792,
        0.31539156525252005,
        -1.0925484305920792,
        0.5462742152960396,
    ];
    let c3 = [
        -0.5900435899266435,
        2.890611442640554,
        -0.4570457994644658,
        0.3731763325901154,
        -0.4570457994644658,
        1.445305721320277,
        -0.5900435899266435,
    ];
    let mut b = vec![0.28209479177387814];
    if deg >= 1 {
        b.extend([-c1 * y, c1 * z, -c1 * x]);
    }
    if deg >= 2 {
        b.extend([
            c2[0] * x * y,
            c2[1] * y * z,
            c2[2] * (2.0 * z * z - x * x - y * y),
            c2[3] * x * z,
            c2[4] * (x * x - y * y),
        ]);
    }
    if deg >= 3 {
        b.extend([
            c3[0] * y * (3.0 * x * x - y * y),
            c3[1] * x * y * z,
            c3[2] * y * (4.0 * z * z - x * x - y * y),
            c3[3] * z * (2.0 * z * z - 3.0 * x * x - 3.0 * y * y),
            c3[4] * x * (4.0 * z * z - x * x - y * y),
            c3[5] * z * (x * x - y * y),
            c3[6] * x * (x * x - 3.0 * y * y),
        ]);
    }
    let mut out = [0.5; 3];
    for (k, bk) in b.iter().enumerate() {
        for c in 0..3 {
            out[c] += bk * sh[k * 3 + c] as f64;
        }
    }
    out.map(|v: f64| v.max(0.0))
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

fn transpose(a: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = a[j][i];
        }
    }
    m
}

fn prims(g: &Gaussians, cam: &Camera, lang: bool) -> Vec<Prim> {
    // World-to-camera rotation as rows.
    let w2c: [[f64; 3]; 3] =
        std::array::from_fn(|r| std::array::from_fn(|c| cam.rotation.col(c)[r] as f64));
    let pos = cam.position.to_array().map(|v| v as f64);
    let (fx, fy) = (cam.fx as f64, cam.fy as f64);
    let (tanx, tany) = (cam.width as f64 * 0.5 / fx, cam.height as f64 * 0.5 / fy);
    let mut out = Vec::new();
    for i in 0..g.len() {
        let p = g.positions[i].map(|v| v as f64);
        let d = [p[0] - pos[0], p[1] - pos[1], p[2] - pos[2]];
        let t: [f64; 3] = std::array::from_fn(|r| (0..3).map(|c| w2c[r][c] * d[c]).sum());
        if !(t[2] > 0.2) {
            continue;
        }
        let q = g.rotations[i].map(|v| v as f64);
        let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let [w, x, y, z] = if n > 0.0 { q.map(|v| v / n) } else { [0.0; 4] };
        let r = [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ];
        let s = g.log_scales[i].map(|v| (v as f64).exp());
        let rs: [[f64; 3]; 3] = std::array::from_fn(|a| std::array::from_fn(|b| r[a][b] * s[b]));
        let sigma = mat_mul(&rs, &transpose(&rs));
        let tx = (t[0] / t[2]).clamp(-1.3 * tanx, 1.3 * tanx) * t[2];
        let ty = (t[1] / t[2]).clamp(-1.3 * tany, 1.3 * tany) * t[2];
        let j = [
            [fx / t[2], 0.0, -fx * tx / (t[2] * t[2])],
            [0.0, fy / t[2], -fy * ty / (t[2] * t[2])],
            [0.0, 0.0, 0.0],
        ];
        let tm = mat_mul(&j, &w2c);
        let cov = mat_mul(&mat_mul(&tm, &sigma), &transpose(&tm));
        let (a, b, c) = (cov[0][0] + 0.3, cov[0][1], cov[1][1] + 0.3);
        let det = a * c - b * b;
        if !(det > 0.0) {
            continue;
        }
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let dir = if len > 0.0 {
            d.map(|v| v / len)
        } else {
            [0.0; 3]
        };
        let sig = |v: f32| 1.0 / (1.0 + (-(v as f64)).exp());
        out.push(Prim {
            depth: t[2],
            index: i,
            mean: [
                fx * t[0] / t[2] + cam.cx as f64 - 0.5,
                fy * t[1] / t[2] + cam.cy as f64 - 0.5,
            ],
            conic: [c / det, -b / det, a / det],
            o: sig(g.opacity[i]),
            ol: if lang { sig(g.lang_opacity[i]) } else { 0.0 },
            rgb: sh_rgb(g.sh_degree, g.sh_of(i), dir),
        });
    }
    // Same order as the renderer: depth (as f32, which it sorts by), then index.
    out.sort_by(|p, q| {
        (p.depth as f32)
            .total_cmp(&(q.depth as f32))
            .then(p.index.cmp(&q.index))
    });
    out
}

/// Render RGB (and language features when `lang`) in f64; returns (rgb, features).
pub fn render_reference(
    g: &Gaussians,
    cam: &Camera,
    background: [f64; 3],
    lang: bool,
) -> (Vec<f64>, Vec<f64>) {
    let ps = prims(g, cam, lang);
    let lw = g.lang_width;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let mut rgb = vec![0.0; w * h * 3];
    let mut feat = vec![0.0; if lang { w * h * lw } else { 0 }];
    for py in 0..h {
        for px in 0..w {
            let (mut t, mut tl) = (1.0f64, 1.0f64);
            let mut c = [0.0f64; 3];
            let mut f = vec![0.0f64; lw];
            for p in &ps {
                let dx = px as f64 - p.mean[0];
                let dy = py as f64 - p.mean[1];
                let power =
                    -0.5 * (p.conic[0] * dx * dx + p.conic[2] * dy * dy) - p.conic[1] * dx * dy;
                let gval = power.min(0.0).exp();
                let a = (p.o * gval).min(0.99);
                if a >= 1.0 / 255.0 {
                    let nt = t * (1.0 - a);
                    if nt < 1e-4 {
                        break;
                    }
                    for k in 0..3 {
                        c[k] += p.rgb[k] * a * t;
                    }
                    t = nt;
                }
                if lang {
                    let al = (p.ol * gval).min(0.99);
                    if al >= 1.0 / 255.0 {
                        for (k, fk) in f.iter_mut().enumerate() {
                            *fk += g.lang[p.index * lw + k] as f64 * al * tl;
                        }
                        tl *= 1.0 - al;
                    }
                }
            }
            let o = (py * w + px) * 3;
            for k in 0..3 {
                rgb[o + k] = c[k] + t * background[k];
            }
            if lang {
                feat[(py * w + px) * lw..(py * w + px + 1) * lw].copy_from_slice(&f);
            }
        }
    }
    (rgb, feat)
}
