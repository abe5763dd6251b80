//! Image quality metrics on linear [0,1] RGB buffers (row-major, 3 floats per pixel).

/// PSNR in dB with peak 1.0; `f64::INFINITY` for identical images.
pub fn psnr(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "PSNR of images of different sizes");
    let mse: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| {
            let d = x.clamp(0.0, 1.0) as f64 - y.clamp(0.0, 1.0) as f64;
            d * d
        })
        .sum::<f64>()
        / a.len().max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (1.0 / mse).log10()
    }
}

/// PSNR in dB of `b` against the reference `a` for values of any range (language features):
/// no clamping, the peak is `a`'s range (max - min); `f64::INFINITY` for identical buffers.
pub fn psnr_range(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "PSNR of buffers of different sizes");
    let (lo, hi) = a.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &v| {
        (lo.min(v as f64), hi.max(v as f64))
    });
    let mse: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum::<f64>()
        / a.len().max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * ((hi - lo).max(f64::MIN_POSITIVE).powi(2) / mse).log10()
    }
}

fn gaussian_window() -> [f64; 11] {
    let mut w = [0f64; 11];
    for (i, v) in w.iter_mut().enumerate() {
        let x = i as f64 - 5.0;
        *v = (-x * x / (2.0 * 1.5 * 1.5)).exp();
    }
    let s: f64 = w.iter().sum();
    w.map(|v| v / s)
}

/// Separable 11-tap filter with zero padding ("same" size), as the 3DGS `ssim` does.
fn blur(img: &[f64], w: usize, h: usize, k: &[f64; 11]) -> Vec<f64> {
    let mut tmp = vec![0f64; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (j, kv) in k.iter().enumerate() {
                let xx = x as isize + j as isize - 5;
                if xx >= 0 && (xx as usize) < w {
                    s += kv * img[y * w + xx as usize];
                }
            }
            tmp[y * w + x] = s;
        }
    }
    let mut out = vec![0f64; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = 0.0;
            for (j, kv) in k.iter().enumerate() {
                let yy = y as isize + j as isize - 5;
                if yy >= 0 && (yy as usize) < h {
                    s += kv * tmp[yy as usize * w + x];
                }
            }
            out[y * w + x] = s;
        }
    }
    out
}

/// Mean SSIM over the three channels: 11x11 Gaussian window, sigma 1.5, C1 = 0.01^2,
/// C2 = 0.03^2, zero-padded borders (the convention of the 3DGS evaluation code).
pub fn ssim(a: &[f32], b: &[f32], width: u32, height: u32) -> f64 {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(a.len(), w * h * 3);
    assert_eq!(b.len(), w * h * 3);
    let k = gaussian_window();
    let (c1, c2) = (0.01f64 * 0.01, 0.03f64 * 0.03);
    let mut total = 0.0;
    for ch in 0..3 {
        let x: Vec<f64> = (0..w * h)
            .map(|i| a[i * 3 + ch].clamp(0.0, 1.0) as f64)
            .collect();
        let y: Vec<f64> = (0..w * h)
            .map(|i| b[i * 3 + ch].clamp(0.0, 1.0) as f64)
            .collect();
        let mx = blur(&x, w, h, &k);
        let my = blur(&y, w, h, &k);
        let xx = blur(&x.iter().map(|v| v * v).collect::<Vec<_>>(), w, h, &k);
        let yy = blur(&y.iter().map(|v| v * v).collect::<Vec<_>>(), w, h, &k);
        let xy = blur(
            &x.iter().zip(&y).map(|(p, q)| p * q).collect::<Vec<_>>(),
            w,
            h,
            &k,
        );
        let mut s = 0.0;
        for i in 0..w * h {
            let (vx, vy, cxy) = (
                xx[i] - mx[i] * mx[i],
                yy[i] - my[i] * my[i],
                xy[i] - mx[i] * my[i],
            );
            s += ((2.0 * mx[i] * my[i] + c1) * (2.0 * cxy + c2))
                / ((mx[i] * mx[i] + my[i] * my[i] + c1) * (vx + vy + c2));
        }
        total += s / (w * h) as f64;
    }
    total / 3.0
}

/// Per-pixel mean absolute error over RGB, in [0, 1].
pub fn error_image(a: &[f32], b: &[f32]) -> Vec<f32> {
    a.chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| {
            (0..3)
                .map(|c| (p[c].clamp(0.0, 1.0) - q[c].clamp(0.0, 1.0)).abs())
                .sum::<f32>()
                / 3.0
        })
        .collect()
}
