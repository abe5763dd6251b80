//! A splat's colour: the SH at the view direction, or the relevance heat map.

pub(crate) fn heat(u: f32) -> [f32; 3] {
    // Blue -> cyan -> green -> yellow -> red.
    let u = u.clamp(0.0, 1.0) * 4.0;
    let (r, g, b) = match u as u32 {
        0 => (0.0, u, 1.0),
        1 => (0.0, 1.0, 2.0 - u),
        2 => (u - 2.0, 1.0, 0.0),
        _ => (1.0, (4.0 - u).max(0.0), 0.0),
    };
    [r, g, b]
}

// SH basis of dlgs-render (render/src/sh.rs), the CPU renderer's colour.
const C0: f32 = 0.282_094_8;
const C1: f32 = 0.488_602_52;
const C2: [f32; 5] = [1.092_548_4, -1.092_548_4, 0.315_391_57, -1.092_548_4, 0.546_274_2];
const C3: [f32; 7] = [
    -0.590_043_6,
    2.890_611_4,
    -0.457_045_8,
    0.373_176_34,
    -0.457_045_8,
    1.445_305_7,
    -0.590_043_6,
];

pub(crate) fn eval_sh(degree: u8, sh: &[f32], d: [f32; 3]) -> [f32; 3] {
    let [x, y, z] = d;
    let mut basis = [0f32; 16];
    basis[0] = C0;
    if degree >= 1 {
        basis[1] = -C1 * y;
        basis[2] = C1 * z;
        basis[3] = -C1 * x;
    }
    if degree >= 2 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        basis[4] = C2[0] * x * y;
        basis[5] = C2[1] * y * z;
        basis[6] = C2[2] * (2.0 * zz - xx - yy);
        basis[7] = C2[3] * x * z;
        basis[8] = C2[4] * (xx - yy);
        if degree >= 3 {
            basis[9] = C3[0] * y * (3.0 * xx - yy);
            basis[10] = C3[1] * x * y * z;
            basis[11] = C3[2] * y * (4.0 * zz - xx - yy);
            basis[12] = C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
            basis[13] = C3[4] * x * (4.0 * zz - xx - yy);
            basis[14] = C3[5] * z * (xx - yy);
            basis[15] = C3[6] * x * (xx - 3.0 * yy);
        }
    }
    let coeffs = (degree as usize + 1).pow(2);
    let mut out = [0.5f32; 3];
    for (k, bk) in basis.iter().enumerate().take(coeffs) {
        for (c, o) in out.iter_mut().enumerate() {
            *o += bk * sh[k * 3 + c];
        }
    }
    out.map(|v| v.max(0.0))
}
