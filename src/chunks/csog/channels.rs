//! The channels of a set in payload order (§6.5.2): what each holds, its bits, its values
//! before quantisation and its name in reports.

use crate::model::{sigmoid, Gaussians};

use super::QuantBits;

/// What a channel holds, in payload order (§6.5.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Position(usize),
    LogScale(usize),
    RotIndex,
    Rotation(usize),
    Opacity,
    Sh(usize),
    LangOpacity,
    Lang(usize),
}

/// Index of `Kind::Rotation(0)` in every set's channel list.
pub(super) const FIRST_ROTATION: usize = 7;

pub(super) fn channels(g: &Gaussians) -> Vec<Kind> {
    let mut k: Vec<Kind> = (0..3).map(Kind::Position).collect();
    k.extend((0..3).map(Kind::LogScale));
    k.push(Kind::RotIndex);
    k.extend((0..3).map(Kind::Rotation));
    k.push(Kind::Opacity);
    k.extend((0..g.sh_stride()).map(Kind::Sh));
    if g.has_language() {
        k.push(Kind::LangOpacity);
        k.extend((0..g.lang_width).map(Kind::Lang));
    }
    k
}

impl Kind {
    pub(super) fn bits(self, b: &QuantBits) -> u8 {
        match self {
            Kind::Position(_) => b.position,
            Kind::LogScale(_) => b.log_scale,
            Kind::RotIndex => 2,
            Kind::Rotation(_) => b.rotation,
            Kind::Opacity | Kind::LangOpacity => b.opacity,
            Kind::Sh(j) if j < 3 => b.sh_dc,
            Kind::Sh(j) if j < 12 => b.sh_rest,
            Kind::Sh(_) => b.sh_high,
            Kind::Lang(_) => b.lang,
        }
    }
}

/// Normalised quaternion, identity for a zero one, sign so the largest |component| is positive;
/// returns (index of the largest, the other three in order).
fn smallest_three(q: [f32; 4]) -> (usize, [f32; 3]) {
    let n = (q.iter().map(|v| v * v).sum::<f32>()).sqrt();
    let q = if n > 0.0 && n.is_finite() {
        q.map(|v| v / n)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    };
    let m = (0..4)
        .max_by(|&a, &b| q[a].abs().total_cmp(&q[b].abs()).then(b.cmp(&a)))
        .expect("four components");
    let s = if q[m] < 0.0 { -1.0 } else { 1.0 };
    let mut rest = [0.0; 3];
    let mut j = 0;
    for (i, v) in q.iter().enumerate() {
        if i != m {
            rest[j] = v * s;
            j += 1;
        }
    }
    (m, rest)
}

/// The channel's values before quantisation.
pub(super) fn values(g: &Gaussians, k: Kind) -> Vec<f32> {
    let n = g.len();
    match k {
        Kind::Position(a) => g.positions.iter().map(|p| p[a]).collect(),
        Kind::LogScale(a) => g.log_scales.iter().map(|p| p[a]).collect(),
        Kind::RotIndex => g
            .rotations
            .iter()
            .map(|&q| smallest_three(q).0 as f32)
            .collect(),
        Kind::Rotation(a) => g
            .rotations
            .iter()
            .map(|&q| smallest_three(q).1[a])
            .collect(),
        Kind::Opacity => g.opacity.iter().map(|&o| sigmoid(o)).collect(),
        Kind::LangOpacity => g.lang_opacity.iter().map(|&o| sigmoid(o)).collect(),
        Kind::Sh(j) => (0..n).map(|i| g.sh[i * g.sh_stride() + j]).collect(),
        Kind::Lang(j) => (0..n).map(|i| g.lang[i * g.lang_width + j]).collect(),
    }
}

impl Kind {
    pub(super) fn name(self) -> String {
        const AXIS: [&str; 3] = ["x", "y", "z"];
        const RGB: [&str; 3] = ["r", "g", "b"];
        match self {
            Kind::Position(a) => format!("position {}", AXIS[a]),
            Kind::LogScale(a) => format!("log_scale {}", AXIS[a]),
            Kind::RotIndex => "rotation index".into(),
            Kind::Rotation(j) => format!("rotation {j}"),
            Kind::Opacity => "opacity".into(),
            // `[coef][rgb]` per Gaussian (coefficient 0 is DC).
            Kind::Sh(j) => format!("sh {} {}", j / 3, RGB[j % 3]),
            Kind::LangOpacity => "language opacity".into(),
            Kind::Lang(j) => format!("language {j}"),
        }
    }

    /// The `--bits` name of the attribute ([`Kind::bits`]'s field).
    pub(super) fn attribute(self) -> &'static str {
        match self {
            Kind::Position(_) => "position",
            Kind::LogScale(_) => "log_scale",
            Kind::RotIndex | Kind::Rotation(_) => "rotation",
            Kind::Opacity | Kind::LangOpacity => "opacity",
            Kind::Sh(j) if j < 3 => "sh_dc",
            Kind::Sh(j) if j < 12 => "sh_rest",
            Kind::Sh(_) => "sh_high",
            Kind::Lang(_) => "lang",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternions_survive_smallest_three() {
        for q in [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0],
            [-0.2, 0.9, -0.3, 0.1],
            [0.5, -0.5, 0.5, -0.5],
            [0.0, 0.0, -3.0, 0.0],
        ] {
            let (m, r) = smallest_three(q);
            assert!(r
                .iter()
                .all(|v| v.abs() <= std::f32::consts::FRAC_1_SQRT_2 + 1e-6));
            let big = (1.0 - r.iter().map(|v| v * v).sum::<f32>()).sqrt();
            let n = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            if n > 0.0 {
                // Same rotation up to sign.
                let mut back = [0.0; 4];
                let mut j = 0;
                for a in 0..4 {
                    back[a] = if a == m {
                        big
                    } else {
                        j += 1;
                        r[j - 1]
                    };
                }
                let dot: f32 = back.iter().zip(q).map(|(a, b)| a * b / n).sum();
                assert!((dot.abs() - 1.0).abs() < 1e-5, "{q:?}");
            }
        }
    }
}
