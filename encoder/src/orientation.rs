//! One ellipsoid, 24 ways to write it: a Gaussian with rotation `R` and axis scales `s` has the
//! same covariance `R diag(s)^2 R^T` as `(R P, P^T s)` for each of the 24 rotations `P` that map
//! the coordinate axes onto themselves (the octahedral group: the axes are permuted, signs do
//! not matter for scales). Picking, per Gaussian, the representative whose rotation is closest
//! to the identity leaves every Gaussian exactly as it renders and shrinks the spread of the
//! stored quaternions: on the real scenes the smallest-three rotation channels lose 2-4 bits per
//! Gaussian of entropy (docs/benchmarks/canonical.md). A sphere (three equal scales)
//! is the same ellipsoid under every rotation and is stored with the identity (gsplat's are a
//! fifth of it, the wave sequence's Gaussians all; docs/benchmarks/canonical-levers.md "Spheres").
//!
//! Only for Gaussians whose rotation and scales nothing else refers to: the static set of a
//! scene without residual GOPs. Deformation decoders and residual fields add offsets to the
//! stored quaternion and log-scales, which would no longer mean the same thing.

use dlgs::model::Gaussians;

const H: f32 = 0.5;
const S: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// The 24 rotations of the octahedral group as quaternions `(w, x, y, z)`, identity first.
pub const OCTAHEDRAL: [[f32; 4]; 24] = [
    [1.0, 0.0, 0.0, 0.0],
    // 180 degrees about an axis.
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
    // +-90 degrees about an axis.
    [S, S, 0.0, 0.0],
    [S, -S, 0.0, 0.0],
    [S, 0.0, S, 0.0],
    [S, 0.0, -S, 0.0],
    [S, 0.0, 0.0, S],
    [S, 0.0, 0.0, -S],
    // 180 degrees about a face diagonal.
    [0.0, S, S, 0.0],
    [0.0, S, -S, 0.0],
    [0.0, S, 0.0, S],
    [0.0, S, 0.0, -S],
    [0.0, 0.0, S, S],
    [0.0, 0.0, S, -S],
    // +-120 degrees about a body diagonal.
    [H, H, H, H],
    [H, H, H, -H],
    [H, H, -H, H],
    [H, H, -H, -H],
    [H, -H, H, H],
    [H, -H, H, -H],
    [H, -H, -H, H],
    [H, -H, -H, -H],
];

/// Hamilton product `a b`, both `(w, x, y, z)`.
pub fn quat_mul(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    let [w1, x1, y1, z1] = a;
    let [w2, x2, y2, z2] = b;
    [
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ]
}

/// Rotation matrix of a unit quaternion, row-major.
pub fn rotation_matrix(q: [f32; 4]) -> [[f32; 3]; 3] {
    let [w, x, y, z] = q;
    [
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
    ]
}

/// For each group element, the old axis that becomes new axis `i` (column i of `P` is
/// +-e_{axis}).
fn axis_maps() -> [[usize; 3]; 24] {
    let mut maps = [[0usize; 3]; 24];
    for (m, p) in maps.iter_mut().zip(OCTAHEDRAL) {
        let r = rotation_matrix(p);
        for (i, slot) in m.iter_mut().enumerate() {
            *slot = (0..3)
                .max_by(|&a, &b| r[a][i].abs().total_cmp(&r[b][i].abs()))
                .expect("three rows");
        }
    }
    maps
}

/// The same Gaussians with each rotation replaced by its representative closest to the
/// identity (largest `|w|` after normalising; the first group element on ties) and the
/// log-scales permuted to match; a sphere (three equal log-scales) takes the identity itself.
/// Zero or non-finite quaternions are left as they are (the codec handles them on its own
/// terms).
pub fn closest_to_identity(g: &Gaussians) -> Gaussians {
    let maps = axis_maps();
    let mut out = g.clone();
    for (q, s) in out.rotations.iter_mut().zip(out.log_scales.iter_mut()) {
        let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
        if !(n > 0.0 && n.is_finite()) {
            continue;
        }
        // A sphere's covariance is `e^(2s) I` whatever its rotation: store none (the identity,
        // which the rotation channels code for nearly nothing).
        if s[0] == s[1] && s[1] == s[2] {
            *q = [1.0, 0.0, 0.0, 0.0];
            continue;
        }
        let u = q.map(|v| v / n);
        let mut best = (0, u[0].abs());
        for (k, p) in OCTAHEDRAL.iter().enumerate().skip(1) {
            let w = quat_mul(u, *p)[0].abs();
            if w > best.1 {
                best = (k, w);
            }
        }
        if best.0 == 0 {
            continue;
        }
        *q = quat_mul(u, OCTAHEDRAL[best.0]);
        let old = *s;
        for (i, &a) in maps[best.0].iter().enumerate() {
            s[i] = old[a];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn covariance(q: [f32; 4], s: [f32; 3]) -> [[f64; 3]; 3] {
        let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
        let r = rotation_matrix(q.map(|v| v / n));
        let mut c = [[0f64; 3]; 3];
        for (i, row) in c.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3)
                    .map(|k| r[i][k] as f64 * r[j][k] as f64 * (2.0 * s[k] as f64).exp())
                    .sum();
            }
        }
        c
    }

    #[test]
    fn the_group_has_24_distinct_axis_maps_and_is_closed() {
        let maps = axis_maps();
        for m in maps {
            let mut seen = [false; 3];
            m.iter().for_each(|&a| seen[a] = true);
            assert!(seen.iter().all(|&v| v), "{m:?} is a permutation");
        }
        for a in OCTAHEDRAL {
            for b in OCTAHEDRAL {
                let c = quat_mul(a, b);
                assert!(
                    OCTAHEDRAL
                        .iter()
                        .any(|p| (0..4).all(|i| (p[i] - c[i]).abs() < 1e-6)
                            || (0..4).all(|i| (p[i] + c[i]).abs() < 1e-6)),
                    "{a:?} {b:?} -> {c:?}"
                );
            }
        }
    }

    #[test]
    fn every_gaussian_keeps_its_covariance_and_rotations_move_towards_identity() {
        let mut g = Gaussians::new(0, 0);
        let mut seed = 3u32;
        let mut rnd = || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            (seed >> 8) as f32 / (1 << 24) as f32 * 2.0 - 1.0
        };
        for _ in 0..2000 {
            g.positions.push([0.0; 3]);
            g.rotations.push([rnd(), rnd(), rnd(), rnd()]);
            g.log_scales
                .push([rnd() * 4.0, rnd() * 4.0 - 2.0, rnd() * 3.0]);
            g.opacity.push(0.0);
            g.sh.extend([0.0; 3]);
        }
        // Degenerate inputs stay as they are.
        g.positions.extend([[0.0; 3]; 2]);
        g.rotations.extend([[0.0; 4], [f32::NAN, 0.0, 0.0, 1.0]]);
        g.log_scales.extend([[1.0, 2.0, 3.0]; 2]);
        g.opacity.extend([0.0; 2]);
        g.sh.extend([0.0; 6]);
        for k in 0..10 {
            g.positions.push([0.0; 3]);
            g.rotations.push([rnd(), rnd(), rnd(), rnd()]);
            g.log_scales.push([k as f32 - 5.0; 3]);
            g.opacity.push(0.0);
            g.sh.extend([0.0; 3]);
        }
        let c = closest_to_identity(&g);
        let mut moved = 0;
        for i in 0..2000 {
            let (a, b) = (
                covariance(g.rotations[i], g.log_scales[i]),
                covariance(c.rotations[i], c.log_scales[i]),
            );
            let scale = a.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
            for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
                assert!(
                    (x - y).abs() <= 1e-5 * scale,
                    "Gaussian {i}: {a:?} vs {b:?}"
                );
            }
            let n = c.rotations[i].iter().map(|v| v * v).sum::<f32>().sqrt();
            // The fundamental region of the group: rotation angle at most ~62.8 degrees.
            assert!(c.rotations[i][0].abs() / n >= 0.85, "{:?}", c.rotations[i]);
            moved += (c.rotations[i] != g.rotations[i]) as usize;
        }
        assert!(moved > 1800, "{moved} of 2000 changed representative");
        // Spheres (all of gsplat's 20.6 % and every Gaussian of the wave sequence) take the
        // identity and keep their covariance.
        for i in 2002..2012 {
            let (a, b) = (
                covariance(g.rotations[i], g.log_scales[i]),
                covariance(c.rotations[i], c.log_scales[i]),
            );
            assert_eq!(c.rotations[i], [1.0, 0.0, 0.0, 0.0]);
            assert_eq!(c.log_scales[i], g.log_scales[i]);
            let scale = a.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
            for (x, y) in a.iter().flatten().zip(b.iter().flatten()) {
                assert!((x - y).abs() <= 1e-5 * scale, "sphere {i}: {a:?} vs {b:?}");
            }
        }
        assert_eq!(c.rotations[2000], [0.0; 4]);
        assert!(c.rotations[2001][0].is_nan());
        assert_eq!(c.log_scales[2001], [1.0, 2.0, 3.0]);
    }
}
