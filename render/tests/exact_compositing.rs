//! The optimised compositor (tile lists trimmed to the ellipse, per-row spans, half-row and
//! AVX-512/AVX2 kernels, finished rows and tiles skipped, chunked gathers) gives the SAME bits
//! as a plain scalar per-pixel loop over every splat whose box covers the pixel, on a real
//! scene, colour and language. So its speed-ups cost nothing: PSNR against this exact rule is
//! infinite. `cargo test --release -p dlgs-render --test exact_compositing`

use dlgs_render::fastexp::exp_neg;
use dlgs_render::project::{project_all, Splat2d, ALPHA_MIN, TILE};
use dlgs_render::raster::{ALPHA_MAX, T_MIN};
use dlgs_render::{orbit_cameras, render, Camera, OrbitSpec, RenderOptions};
use dlgs_testkit::bench_scenes::{plant, with_language};

/// One pixel by the rule of `raster`'s module comment, in the same f32 operations (the dx of a
/// pixel is taken from its tile's origin, as the tile kernel does). `cands` are the splats in
/// (depth, index) order whose box holds the pixel's tile.
fn pixel(
    splats: &[Splat2d],
    cands: &[u32],
    px: u32,
    py: u32,
    lang: Option<(&[f32], usize)>,
) -> ([f32; 3], f32, Vec<f32>) {
    let x0 = px / TILE * TILE;
    let lx = (px - x0) as f32;
    let (mut t, mut tl) = (1.0f32, 1.0f32);
    let mut c = [0.0f32; 3];
    let mut f = vec![0.0f32; lang.map_or(0, |l| l.1)];
    for &k in cands {
        let s = &splats[k as usize];
        let [x_lo, y_lo, x_hi, y_hi] = s.px.map(u32::from);
        if !(x_lo..x_hi).contains(&px) || !(y_lo..y_hi).contains(&py) {
            continue;
        }
        let [ca, cb, cc] = s.conic;
        let dx = lx - (s.mean[0] - x0 as f32);
        let dy = py as f32 - s.mean[1];
        let power = (-0.5 * ca * dx * dx + -cb * dy * dx + -0.5 * cc * dy * dy).min(0.0);
        let g = exp_neg(power);
        let a = (s.opacity * g).min(ALPHA_MAX);
        if a >= ALPHA_MIN {
            let test_t = t * (1.0 - a);
            if test_t < T_MIN {
                break;
            }
            let w = a * t;
            for (ch, sc) in c.iter_mut().zip(s.color) {
                *ch += sc * w;
            }
            t += test_t - t;
        }
        if let Some((all, lw)) = lang {
            let al = (s.lang_opacity * g).min(ALPHA_MAX);
            if al >= ALPHA_MIN {
                let wl = al * tl;
                tl -= wl;
                let feat = &all[s.index as usize * lw..(s.index as usize + 1) * lw];
                for (fc, v) in f.iter_mut().zip(feat) {
                    *fc += v * wl;
                }
            }
        }
    }
    (c, t, f)
}

/// Render `g` and compare every pixel of a few 48x48 windows with [`pixel`], bit for bit.
fn check(g: &dlgs::Gaussians, cam: &Camera, features: bool) {
    let opts = RenderOptions {
        features,
        ..Default::default()
    };
    let img = render(g, cam, &opts).unwrap();
    let splats = project_all(g, cam, features);
    let mut order: Vec<u32> = (0..splats.len() as u32).collect();
    order.sort_by_key(|&k| (splats[k as usize].depth.to_bits(), k));
    let lang = features.then_some((g.lang.as_slice(), g.lang_width));
    let (w, h) = (cam.width, cam.height);
    let mut checked = 0;
    let mut drawn = 0;
    for (wx, wy) in [
        (w / 2 - 24, h / 2 - 24),
        (w / 3, h / 3),
        (2 * w / 3, h / 2),
        (0, 0),
    ] {
        for ty in (wy / TILE)..(wy + 48).div_ceil(TILE).min(h.div_ceil(TILE)) {
            for tx in (wx / TILE)..(wx + 48).div_ceil(TILE).min(w.div_ceil(TILE)) {
                // Every splat whose box reaches the tile, in depth order.
                let cands: Vec<u32> = order
                    .iter()
                    .copied()
                    .filter(|&k| {
                        let t = splats[k as usize].tiles();
                        (t[0] as u32..t[2] as u32).contains(&tx)
                            && (t[1] as u32..t[3] as u32).contains(&ty)
                    })
                    .collect();
                for py in ty * TILE..((ty + 1) * TILE).min(h) {
                    for px in tx * TILE..((tx + 1) * TILE).min(w) {
                        let (c, t, f) = pixel(&splats, &cands, px, py, lang);
                        let p = (py * w + px) as usize;
                        let want: Vec<u32> = c
                            .iter()
                            .zip(opts.background)
                            .map(|(c, b)| (c + t * b).to_bits())
                            .collect();
                        let got: Vec<u32> = img.color[p * 3..p * 3 + 3]
                            .iter()
                            .map(|v| v.to_bits())
                            .collect();
                        assert_eq!(got, want, "colour at ({px}, {py})");
                        assert_eq!(
                            img.transmittance[p].to_bits(),
                            t.to_bits(),
                            "T ({px}, {py})"
                        );
                        if let Some(all) = &img.features {
                            let lw = img.lang_width;
                            let got: Vec<u32> = all[p * lw..(p + 1) * lw]
                                .iter()
                                .map(|v| v.to_bits())
                                .collect();
                            let want: Vec<u32> = f.iter().map(|v| v.to_bits()).collect();
                            assert_eq!(got, want, "features at ({px}, {py})");
                        }
                        checked += 1;
                        drawn += usize::from(t < 1.0);
                    }
                }
            }
        }
    }
    assert!(drawn > checked / 2, "{drawn} of {checked} pixels drawn");
}

fn bench_camera(g: &dlgs::Gaussians) -> Camera {
    orbit_cameras(g, &OrbitSpec::default()).remove(0)
}

#[test]
fn colour_is_bit_identical_to_the_per_pixel_rule_on_the_plant() {
    let g = plant();
    check(&g, &bench_camera(&g), false);
}

#[test]
fn language_is_bit_identical_to_the_per_pixel_rule_on_the_plant() {
    let g = with_language(&plant());
    check(&g, &bench_camera(&g), true);
}
