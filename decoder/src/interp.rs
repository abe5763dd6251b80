//! The reference implementation's interpolators (format-spec §6.4), reproduced exactly,
//! including its guards. `sin` and `acos` are the format crate's own (Appendix B), so a frame
//! has the same bits on every platform.

use dlgs::elementary::{acos_f32, acos_lanes, sin_f32, sin_lanes};
use multiversion::multiversion;

use crate::panel::PANEL;

/// `F.normalize(q, eps=1e-12)`: a zero quaternion stays zero.
#[inline]
pub fn normalize4(q: [f32; 4]) -> [f32; 4] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        .sqrt()
        .max(1e-12);
    [q[0] / n, q[1] / n, q[2] / n, q[3] / n]
}

/// Cubic Hermite between `p0` and `p1` with tangents `m0`, `m1` (not scaled by the interval).
#[inline]
pub fn hermite(p0: [f32; 3], m0: [f32; 3], p1: [f32; 3], m1: [f32; 3], d: f32) -> [f32; 3] {
    let (d2, d3) = (d * d, d * d * d);
    let h00 = 2.0 * d3 - 3.0 * d2 + 1.0;
    let h10 = d3 - 2.0 * d2 + d;
    let h01 = -2.0 * d3 + 3.0 * d2;
    let h11 = d3 - d2;
    std::array::from_fn(|a| h00 * p0[a] + h10 * m0[a] + h01 * p1[a] + h11 * m1[a])
}

/// The angle part of the reference's `slerp_interpolate`: `(ω, sin ω)` with the clamped dot and
/// floored angle and sine. It depends only on the two keys, so the decoder computes it once per
/// GOP.
#[inline]
pub fn slerp_angle(q0: [f32; 4], q1: [f32; 4]) -> [f32; 2] {
    let omega = acos_f32(clamped_dot(q0, q1)).max(1e-4);
    [omega, sin_f32(omega).max(1e-4)]
}

/// The keys' dot product, clamped inside `(-1, 1)` as the reference does before `acos`.
#[inline]
fn clamped_dot(q0: [f32; 4], q1: [f32; 4]) -> f32 {
    (q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3]).clamp(-1.0 + 1e-4, 1.0 - 1e-4)
}

/// [`slerp_angle`] of every pair of rows (the same bits), the `acos` and `sin` in SIMD lanes.
pub(crate) fn slerp_angles(q0: &[[f32; 4]], q1: &[[f32; 4]], out: &mut [[f32; 2]]) {
    let mut v: Vec<f64> = q0
        .iter()
        .zip(q1)
        .map(|(&a, &b)| clamped_dot(a, b) as f64)
        .collect();
    acos_lanes(&mut v);
    for (x, o) in v.iter_mut().zip(out.iter_mut()) {
        o[0] = (*x as f32).max(1e-4);
        *x = o[0] as f64;
    }
    sin_lanes(&mut v);
    for (x, o) in v.iter().zip(out.iter_mut()) {
        o[1] = (*x as f32).max(1e-4);
    }
}

/// The blend part of `slerp_interpolate`, given [`slerp_angle`]`(q0, q1)`: weights renormalised
/// to sum 1, no shortest-arc flip, then normalised.
#[inline]
pub fn slerp_blend(q0: [f32; 4], q1: [f32; 4], [omega, s]: [f32; 2], d: f32) -> [f32; 4] {
    let (a0, a1) = slerp_arguments(omega, d);
    slerp_from_sines(q0, q1, s, sin_f32(a0), sin_f32(a1))
}

/// The two angles whose sines [`slerp_blend`] takes: `(1 - d) ω` and `d ω`.
#[inline]
pub(crate) fn slerp_arguments(omega: f32, d: f32) -> (f32, f32) {
    ((1.0 - d) * omega, d * omega)
}

/// [`slerp_blend`] given `sin32` of [`slerp_arguments`] (e.g. from
/// `dlgs::elementary::sin_lanes`, the same bits) and `s = sin ω`.
#[inline]
pub(crate) fn slerp_from_sines(
    q0: [f32; 4],
    q1: [f32; 4],
    s: f32,
    sin0: f32,
    sin1: f32,
) -> [f32; 4] {
    let mut p0 = sin0 / s;
    let mut p1 = sin1 / s;
    let sum = (p0 + p1).max(1e-4);
    p0 /= sum;
    p1 /= sum;
    let r: [f32; 4] = std::array::from_fn(|a| p0 * q0[a] + p1 * q1[a]);
    // Both sides computed and one chosen, so that [`slerp_panel`]'s loop vectorises.
    let n = normalize4(r);
    let tiny = r[0].abs() + r[1].abs() + r[2].abs() + r[3].abs() <= 1e-4;
    std::array::from_fn(|a| if tiny { q0[a] } else { n[a] })
}

/// A panel's quaternions, component by component (`[component][row]`).
pub(crate) type QuatPanel = [[f32; PANEL]; 4];

/// [`slerp_from_sines`] for every row of a panel (the same bits, in SIMD lanes): keys `q0`,
/// `q1`, `s = sin ω` and the two sines per row; rows past the caller's count may hold anything.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx2+fma", "x86_64+avx2+fma", "aarch64+neon"))]
pub(crate) fn slerp_panel(
    q0: &QuatPanel,
    q1: &QuatPanel,
    [s, sin0, sin1]: [&[f32; PANEL]; 3],
    out: &mut QuatPanel,
) {
    for l in 0..PANEL {
        let a = [q0[0][l], q0[1][l], q0[2][l], q0[3][l]];
        let b = [q1[0][l], q1[1][l], q1[2][l], q1[3][l]];
        let r = slerp_from_sines(a, b, s[l], sin0[l], sin1[l]);
        for (c, v) in r.into_iter().enumerate() {
            out[c][l] = v;
        }
    }
}

/// The reference's `slerp_interpolate` on already normalised inputs.
#[inline]
pub fn slerp_reference(q0: [f32; 4], q1: [f32; 4], d: f32) -> [f32; 4] {
    slerp_blend(q0, q1, slerp_angle(q0, q1), d)
}

#[inline]
pub fn lerp(a: f32, b: f32, d: f32) -> f32 {
    a * (1.0 - d) + b * d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hermite_hits_the_keys() {
        let (p0, p1) = ([1.0, 2.0, 3.0], [4.0, 5.0, 6.0]);
        let m = [0.3, -0.2, 9.0];
        assert_eq!(hermite(p0, m, p1, m, 0.0), p0);
        assert_eq!(hermite(p0, m, p1, m, 1.0), p1);
    }

    #[test]
    fn slerp_ends_and_degenerate_inputs() {
        let a = normalize4([1.0, 0.0, 0.0, 0.0]);
        let b = normalize4([0.0, 1.0, 0.0, 0.0]);
        let m = slerp_reference(a, b, 0.5);
        assert!((m[0] - m[1]).abs() < 1e-6 && (m[0] - 0.70710677).abs() < 1e-4);
        let e = slerp_reference(a, b, 0.0);
        assert!((e[0] - 1.0).abs() < 1e-4);
        // Zero quaternions: no NaN, the reference returns q0 (zero), the renderer maps it to
        // the identity.
        let z = slerp_reference([0.0; 4], [0.0; 4], 0.3);
        assert!(z.iter().all(|v| v.is_finite()));
        // Opposite quaternions (no shortest-arc flip): finite.
        let o = slerp_reference(a, [-1.0, 0.0, 0.0, 0.0], 0.5);
        assert!(o.iter().all(|v| v.is_finite()));
    }

    /// The lanes give each pair's [`slerp_angle`] bits.
    #[test]
    fn slerp_angles_give_the_pairs_bits() {
        let mut rng = fastrand::Rng::with_seed(4);
        let q: Vec<[f32; 4]> = (0..2000)
            .map(|i| match i % 9 {
                0 => [0.0; 4],
                1 => [1.0, 0.0, 0.0, 0.0],
                2 => [-1.0, 0.0, 0.0, 0.0],
                _ => normalize4(std::array::from_fn(|_| rng.f32() * 2.0 - 1.0)),
            })
            .collect();
        let (a, b) = q.split_at(1000);
        let mut out = vec![[0f32; 2]; 1000];
        slerp_angles(a, b, &mut out);
        for ((qa, qb), got) in a.iter().zip(b).zip(&out) {
            let want = slerp_angle(*qa, *qb);
            assert_eq!(
                got.map(f32::to_bits),
                want.map(f32::to_bits),
                "{qa:?} {qb:?}"
            );
        }
        // The same quaternion twice (dot clamped below 1), and opposite ones.
        let mut one = [[0f32; 2]; 2];
        slerp_angles(&[a[3], a[1]], &[a[3], a[2]], &mut one);
        assert_eq!(one[0], slerp_angle(a[3], a[3]));
        assert_eq!(one[1], slerp_angle(a[1], a[2]));
    }

    /// The panel's lanes give each row's [`slerp_blend`] bits, degenerate rows included.
    #[test]
    fn slerp_panel_gives_the_rows_bits() {
        let mut rng = fastrand::Rng::with_seed(3);
        let mut quat = |i: usize| -> [f32; 4] {
            match i % 7 {
                0 => [0.0; 4],
                1 => [1.0, 0.0, 0.0, 0.0],
                2 => [-1.0, 0.0, 0.0, 0.0],
                _ => normalize4(std::array::from_fn(|_| rng.f32() * 2.0 - 1.0)),
            }
        };
        let rows: Vec<([f32; 4], [f32; 4], f32)> = (0..40 * PANEL)
            .map(|i| (quat(i), quat(i / 3), (i % 11) as f32 / 10.0))
            .collect();
        for chunk in rows.chunks(PANEL) {
            let d = chunk[0].2;
            let (mut q0, mut q1, mut out) =
                ([[0f32; PANEL]; 4], [[0f32; PANEL]; 4], [[0f32; PANEL]; 4]);
            let (mut s, mut s0, mut s1) = ([0f32; PANEL], [0f32; PANEL], [0f32; PANEL]);
            for (l, &(a, b, _)) in chunk.iter().enumerate() {
                let [omega, sin_omega] = slerp_angle(a, b);
                let (a0, a1) = slerp_arguments(omega, d);
                for c in 0..4 {
                    q0[c][l] = a[c];
                    q1[c][l] = b[c];
                }
                (s[l], s0[l], s1[l]) = (sin_omega, sin_f32(a0), sin_f32(a1));
            }
            slerp_panel(&q0, &q1, [&s, &s0, &s1], &mut out);
            for (l, &(a, b, _)) in chunk.iter().enumerate() {
                let want = slerp_blend(a, b, slerp_angle(a, b), d);
                let got = [out[0][l], out[1][l], out[2][l], out[3][l]];
                assert_eq!(
                    got.map(f32::to_bits),
                    want.map(f32::to_bits),
                    "{a:?} {b:?} {d}"
                );
            }
        }
    }
}
