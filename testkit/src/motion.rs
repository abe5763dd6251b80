//! Hard per-frame sequences from a REAL scene with SYNTHETIC motion: what a fast real capture
//! shows (large rigid motion, fast articulated motion, Gaussians that appear and disappear),
//! each frame shuffled on its own as per-frame files are. Motion is given in units of the
//! scene's neighbour spacing (median nearest-neighbour distance): `speed` is the largest move
//! of any Gaussian between two frames.

use dlgs::model::Gaussians;
use dlgs_encoder::sequence::spacing;

/// Which motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// The whole scene swings about a vertical axis through its centre and sways sideways.
    Rigid,
    /// Three parts along the scene's longest axis, each swinging about a hinge on the part
    /// below with its own phase, like a limb: the first part stays, the others move.
    Articulated,
}

impl std::str::FromStr for Motion {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "rigid" => Ok(Motion::Rigid),
            "articulated" => Ok(Motion::Articulated),
            _ => Err(format!("unknown motion `{s}` (rigid, articulated)")),
        }
    }
}

#[derive(Debug, Clone)]
pub struct MotionSpec {
    pub motion: Motion,
    pub frames: usize,
    /// Largest move of a Gaussian between two frames, in neighbour spacings.
    pub speed: f32,
    /// Frames per swing (period of the motion).
    pub period: f32,
    /// Share of Gaussians that live for only part of the sequence (counts change).
    pub births: f32,
    /// Frames as independent per-frame reconstructions would give them (0: the same Gaussians
    /// moved): every Gaussian's position perturbed by `independent` neighbour spacings (normal,
    /// per axis), its log-scales by 0.2x, pre-sigmoid opacity by 0.5x and SH DC by 0.1x that
    /// (normal), and a share `0.1 x independent` (at most 0.5) of the Gaussians left out, each
    /// frame drawn on its own: no Gaussian of one frame is exactly one of the next.
    pub independent: f32,
    pub seed: u64,
}

/// Per frame: the moved Gaussians (shuffled) and, for tests, `ids[t][j]`, the Gaussian of the
/// source scene that Gaussian `j` of frame `t` is.
pub struct HardSequence {
    pub frames: Vec<Gaussians>,
    pub ids: Vec<Vec<u32>>,
    pub spacing: f32,
}

fn rot_y(theta: f32) -> ([[f32; 3]; 3], [f32; 4]) {
    let (s, c) = theta.sin_cos();
    let (hs, hc) = (0.5 * theta).sin_cos();
    (
        [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        [hc, 0.0, hs, 0.0],
    )
}

fn rot_z(theta: f32) -> ([[f32; 3]; 3], [f32; 4]) {
    let (s, c) = theta.sin_cos();
    let (hs, hc) = (0.5 * theta).sin_cos();
    (
        [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
        [hc, 0.0, 0.0, hs],
    )
}

fn apply(m: &[[f32; 3]; 3], p: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2])
}

/// Hamilton product `a b` (w, x, y, z).
fn qmul(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// A rigid transform: rotation (matrix and quaternion) about `pivot`, then a translation.
#[derive(Clone, Copy)]
struct Rigid {
    m: [[f32; 3]; 3],
    q: [f32; 4],
    pivot: [f32; 3],
    shift: [f32; 3],
}

impl Rigid {
    fn point(&self, p: [f32; 3]) -> [f32; 3] {
        let d = apply(&self.m, std::array::from_fn(|a| p[a] - self.pivot[a]));
        std::array::from_fn(|a| d[a] + self.pivot[a] + self.shift[a])
    }
}

/// The sequence of `scene` moved by `spec`.
pub fn hard_sequence(scene: &Gaussians, spec: &MotionSpec) -> HardSequence {
    let n = scene.len();
    let sp = spacing(&scene.positions);
    let (lo, hi) = scene.bounds().unwrap_or(([0.0; 3], [0.0; 3]));
    let centre: [f32; 3] = std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]));
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap_or(1);
    let radius = (0..3)
        .map(|a| 0.5 * (hi[a] - lo[a]))
        .fold(0.0f32, f32::max)
        .max(1e-6);
    let w = std::f32::consts::TAU / spec.period;
    // Swing amplitude so that the peak speed (amplitude x w x radius) is `speed` spacings.
    let amp = (spec.speed * sp / (w * radius * 1.5)).min(1.2);
    let part_of = |p: &[f32; 3]| -> usize {
        let u = (p[axis] - lo[axis]) / (hi[axis] - lo[axis]).max(1e-9);
        ((u * 3.0) as usize).min(2)
    };
    let hinge = |k: usize| -> [f32; 3] {
        let mut h = centre;
        h[axis] = lo[axis] + (hi[axis] - lo[axis]) * k as f32 / 3.0;
        h
    };
    let transforms = |t: usize| -> Vec<Rigid> {
        let tt = t as f32;
        match spec.motion {
            Motion::Rigid => {
                let (m, q) = rot_y(amp * (w * tt).sin());
                let sway = 0.5 * amp * radius * (0.5 * w * tt).sin();
                vec![Rigid {
                    m,
                    q,
                    pivot: centre,
                    shift: [sway, 0.0, 0.0],
                }]
            }
            Motion::Articulated => {
                // Part 1 swings about hinge 1; part 2 about hinge 2 (carried by part 1).
                let a1 = 0.6 * amp * (w * tt).sin();
                let a2 = amp * (w * tt + 1.3).sin();
                let rot = if axis == 2 { rot_y } else { rot_z };
                let (m1, q1) = rot(a1);
                let (m2, q2) = rot(a2);
                let p1 = Rigid {
                    m: m1,
                    q: q1,
                    pivot: hinge(1),
                    shift: [0.0; 3],
                };
                let h2 = p1.point(hinge(2));
                let p2 = Rigid {
                    m: mat_mul(&m1, &m2),
                    q: qmul(q1, q2),
                    pivot: hinge(2),
                    shift: std::array::from_fn(|a| h2[a] - hinge(2)[a]),
                };
                let id = Rigid {
                    m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                    q: [1.0, 0.0, 0.0, 0.0],
                    pivot: centre,
                    shift: [0.0; 3],
                };
                vec![id, p1, p2]
            }
        }
    };
    let mut rng = fastrand::Rng::with_seed(spec.seed);
    // Lives: a share of the Gaussians is born late or dies early.
    let lives: Vec<(usize, usize)> = (0..n)
        .map(|_| {
            if rng.f32() >= spec.births {
                return (0, spec.frames - 1);
            }
            let a = rng.usize(0..spec.frames);
            let b = rng.usize(0..spec.frames);
            let (a, b) = (a.min(b), a.max(b));
            if rng.bool() {
                (a, spec.frames - 1)
            } else {
                (0, b)
            }
        })
        .collect();
    let mut frames = Vec::with_capacity(spec.frames);
    let mut ids = Vec::with_capacity(spec.frames);
    for t in 0..spec.frames {
        let tr = transforms(t);
        let mut order: Vec<u32> = (0..n as u32)
            .filter(|&i| lives[i as usize].0 <= t && t <= lives[i as usize].1)
            .collect();
        rng.shuffle(&mut order);
        if spec.independent > 0.0 {
            let drop = (0.1 * spec.independent).min(0.5);
            order.retain(|_| rng.f32() >= drop);
        }
        let mut g = Gaussians::new(scene.sh_degree, 0);
        for &i in &order {
            let i = i as usize;
            g.push_from(scene, i);
            let x = &tr[if tr.len() == 1 {
                0
            } else {
                part_of(&scene.positions[i])
            }];
            *g.positions.last_mut().expect("pushed") = x.point(scene.positions[i]);
            *g.rotations.last_mut().expect("pushed") = qmul(x.q, scene.rotations[i]);
            if spec.independent > 0.0 {
                perturb(&mut g, spec.independent, sp, &mut rng);
            }
        }
        frames.push(g);
        ids.push(order);
    }
    HardSequence {
        frames,
        ids,
        spacing: sp,
    }
}

/// A standard normal draw (Box-Muller).
fn normal(rng: &mut fastrand::Rng) -> f32 {
    let u = rng.f32().max(1e-7);
    let v = rng.f32();
    (-2.0 * u.ln()).sqrt() * (std::f32::consts::TAU * v).cos()
}

/// The last Gaussian of `g` as an independent reconstruction might give it (see
/// [`MotionSpec::independent`]).
fn perturb(g: &mut Gaussians, k: f32, spacing: f32, rng: &mut fastrand::Rng) {
    let i = g.len() - 1;
    for a in 0..3 {
        g.positions[i][a] += k * spacing * normal(rng);
        g.log_scales[i][a] += 0.2 * k * normal(rng);
    }
    g.opacity[i] += 0.5 * k * normal(rng);
    let stride = g.sh_stride();
    for c in 0..3 {
        g.sh[i * stride + c] += 0.1 * k * normal(rng);
    }
}

fn mat_mul(a: &[[f32; 3]; 3], b: &[[f32; 3]; 3]) -> [[f32; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

/// The largest move of any Gaussian between two consecutive frames, in spacings.
pub fn peak_speed(seq: &HardSequence) -> f32 {
    let mut peak = 0.0f32;
    for t in 1..seq.frames.len() {
        let at: std::collections::HashMap<u32, usize> = seq.ids[t - 1]
            .iter()
            .enumerate()
            .map(|(j, &i)| (i, j))
            .collect();
        for (j, i) in seq.ids[t].iter().enumerate() {
            if let Some(&k) = at.get(i) {
                let p = seq.frames[t].positions[j];
                let q = seq.frames[t - 1].positions[k];
                let d = (0..3).map(|a| (p[a] - q[a]).powi(2)).sum::<f32>().sqrt();
                peak = peak.max(d);
            }
        }
    }
    peak / seq.spacing.max(1e-12)
}
