//! Which Gaussian of one frame is which of the next, under large motion and changing counts.
//!
//! Per-frame splat files are sorted independently and real motion moves Gaussians by many times
//! their spacing between two frames, so position alone cannot say which is which. Gaussians are
//! matched in a joint space of **predicted position** and **what motion does not change**
//! (log-scales, opacity, DC colour), coarse to fine:
//!
//! 1. each Gaussian of frame `a` is predicted into frame `b` (its track's velocity, if any);
//! 2. every Gaussian of `b` takes its nearest neighbour in the joint space, where position is
//!    measured against a wide search radius and the attributes against their noise;
//! 3. a smooth displacement field is estimated from those matches (per Gaussian, the median
//!    displacement of its 16 spatial neighbours in `a`), which corrects the prediction; the
//!    radius and the attribute noise shrink to what the agreeing matches show; repeat;
//! 4. the final match is mutual nearest neighbours within a gate (or near the prediction with
//!    attributes within four times the gate), then the left-overs paired by position near the
//!    prediction with attributes within the same bound. What stays unmatched is a death (in `a`) or a birth (in
//!    `b`). A match is *confident* when it is mutual, within the gate, and its nearest
//!    neighbour is at most half as far as the second nearest (squared joint distance ratio
//!    0.25).

use dlgs::model::Gaussians;

use super::kdtree::KdTree;

/// Dimensions of the attribute signature: log-scales 3, opacity 1, DC colour 3.
const SIG: usize = 7;
/// Joint space: position 3 + signature.
const JOINT: usize = 3 + SIG;
/// Least attribute noise assumed (log-scale, pre-sigmoid opacity, SH DC): the changes a
/// per-frame file's own quantisation gives (SOG's 8-bit levels, codebooks fitted per frame).
const NOISE_FLOOR: [f32; SIG] = [0.05, 0.05, 0.05, 0.1, 0.03, 0.03, 0.03];
/// Spatial neighbours that vote on a Gaussian's displacement.
const VOTERS: usize = 16;
/// Coarse-to-fine rounds before the final match.
const ROUNDS: usize = 4;
/// Squared joint distance (in units of the final radius and attribute noise) beyond which two
/// Gaussians are not the same one.
pub const GATE: f32 = 4.0;

/// How frame `b` continues frame `a`.
#[derive(Debug, Clone, PartialEq)]
pub struct JointMatch {
    /// `prev_of[j]`: the Gaussian of `a` that Gaussian `j` of `b` continues (`None`: a birth).
    pub prev_of: Vec<Option<u32>>,
    /// Matches that are mutual, within the gate and with a clear margin.
    pub confident: usize,
    /// Matched pairs (the rest of `b` are births, the rest of `a` deaths).
    pub matched: usize,
    /// Largest distance between matched positions.
    pub max_distance: f32,
    /// Median displacement between matched positions.
    pub median_distance: f32,
    /// Median distance between neighbouring Gaussians of `a`.
    pub spacing: f32,
    /// Each Gaussian of `a` carried into `b`'s time by the fitted displacement field (its
    /// prediction corrected by its neighbours' matches): the motion that remains where no
    /// consistent correspondence exists (the resampling fallback of `tracks`).
    pub field: Vec<[f32; 3]>,
}

impl JointMatch {
    /// Confident matches among the matched pairs, 0..=1.
    pub fn confident_share(&self) -> f64 {
        self.confident as f64 / self.matched.max(1) as f64
    }
    pub fn births(&self) -> usize {
        self.prev_of.len() - self.matched
    }
}

fn signature(g: &Gaussians, i: usize) -> [f32; SIG] {
    let s = g.log_scales[i];
    let c = &g.sh[i * g.sh_stride()..];
    [
        s[0],
        s[1],
        s[2],
        g.opacity[i].clamp(-12.0, 12.0),
        c[0],
        c[1],
        c[2],
    ]
}

fn median(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let m = v.len() / 2;
    *v.select_nth_unstable_by(m, f32::total_cmp).1
}

fn quantile(v: &mut [f32], q: f64) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let m = ((v.len() - 1) as f64 * q) as usize;
    *v.select_nth_unstable_by(m, f32::total_cmp).1
}

/// Median distance from a Gaussian to its nearest neighbour (every 8th Gaussian sampled).
pub fn spacing(p: &[[f32; 3]]) -> f32 {
    if p.len() < 2 {
        return 0.0;
    }
    let tree = KdTree::new(p);
    let mut d: Vec<f32> = p
        .iter()
        .step_by(8)
        .map(|q| tree.nearest(q, 2).get(1).map_or(0.0, |n| n.1.sqrt()))
        .collect();
    median(&mut d)
}

fn extent(p: &[[f32; 3]]) -> f32 {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for q in p {
        for a in 0..3 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    (0..3).map(|a| hi[a] - lo[a]).fold(0.0f32, f32::max)
}

/// Squared attribute distance in units of the attribute noise.
fn sig_d2(a: &[f32; SIG], b: &[f32; SIG], sigma: &[f32; SIG]) -> f32 {
    (0..SIG).map(|k| ((a[k] - b[k]) / sigma[k]).powi(2)).sum()
}

fn joint(p: &[f32; 3], s: &[f32; SIG], r: f32, sigma: &[f32; SIG]) -> [f32; JOINT] {
    let mut out = [0.0; JOINT];
    for a in 0..3 {
        out[a] = p[a] / r;
    }
    for k in 0..SIG {
        out[3 + k] = s[k] / sigma[k];
    }
    out
}

/// Match frame `b` onto frame `a`, whose Gaussians are predicted at `predicted` in `b`'s time.
///
/// Two starts are tried: **position-led** (a radius of one spacing around the prediction, the
/// attributes only breaking ties: motion within the spacing, attributes that change) and, when
/// that does not match nearly everything confidently, **attribute-led** (a radius of a third of
/// the scene: motion of many spacings, attributes that persist). The start with more confident
/// matches wins.
pub fn match_joint(a: &Gaussians, predicted: &[[f32; 3]], b: &Gaussians) -> JointMatch {
    let enough = |m: &JointMatch| m.confident as f64 >= 0.98 * a.len().min(b.len()) as f64;
    // Motion well within the spacing: nearest positions say it all.
    let mut best = match_from(a, &a.positions, b, Start::Plain);
    if enough(&best) {
        return best;
    }
    // With the velocity, without it (a track's velocity can mislead where motion turns or
    // jitters), then attribute-led.
    let tries: [(&[[f32; 3]], Start); 3] = [
        (predicted, Start::PositionLed),
        (&a.positions, Start::PositionLed),
        (predicted, Start::AttributeLed),
    ];
    for (p, start) in tries {
        let m = match_from(a, p, b, start);
        if m.confident > best.confident {
            best = m;
        }
        if enough(&best) {
            break;
        }
    }
    best
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Start {
    /// Positions as they are, attributes ignored, no rounds.
    Plain,
    PositionLed,
    AttributeLed,
}

/// Both frames as the left-over pairing sees them.
struct Sides<'a> {
    /// Frame `a`'s Gaussians predicted into `b`'s time.
    pred: &'a [[f32; 3]],
    b: &'a [[f32; 3]],
    sig_a: &'a [[f32; SIG]],
    sig_b: &'a [[f32; SIG]],
    sigma: &'a [f32; SIG],
}

impl Sides<'_> {
    /// Pair the unmatched Gaussians of `b` with the untaken ones of `a` among each one's `k`
    /// nearest predictions within `reach` and attributes within `sig_gate` (squared, in noise
    /// units), nearest pairs first (ties by index). Returns the pairs made.
    fn pair_leftovers(
        &self,
        prev_of: &mut [Option<u32>],
        taken: &mut [bool],
        k: usize,
        reach: f32,
        sig_gate: f32,
    ) -> usize {
        let left_a: Vec<u32> = (0..taken.len() as u32)
            .filter(|&i| !taken[i as usize])
            .collect();
        let left_pos: Vec<[f32; 3]> = left_a.iter().map(|&i| self.pred[i as usize]).collect();
        let tree = KdTree::new(&left_pos);
        let mut pairs: Vec<(f32, u32, u32)> = Vec::new();
        for j in (0..self.b.len()).filter(|&j| prev_of[j].is_none()) {
            for (n, d) in tree.nearest(&self.b[j], k) {
                let i = left_a[n as usize];
                if d <= reach * reach
                    && sig_d2(&self.sig_a[i as usize], &self.sig_b[j], self.sigma) <= sig_gate
                {
                    pairs.push((d, j as u32, i));
                }
            }
        }
        pairs.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
        let mut made = 0;
        for (_, j, i) in pairs {
            if prev_of[j as usize].is_none() && !taken[i as usize] {
                prev_of[j as usize] = Some(i);
                taken[i as usize] = true;
                made += 1;
            }
        }
        made
    }
}

/// Each point's `k` nearest points of `p` (itself among them): the voters of [`smoothed`].
pub(super) fn neighbours(p: &[[f32; 3]], k: usize) -> Vec<Vec<u32>> {
    let tree = KdTree::new(p);
    p.iter()
        .map(|q| tree.nearest(q, k).into_iter().map(|n| n.0).collect())
        .collect()
}

/// `moved` (each point of `p` carried somewhere) with each point's displacement replaced by the
/// median of its voters' (per axis).
pub(super) fn smoothed(p: &[[f32; 3]], moved: &[[f32; 3]], voters: &[Vec<u32>]) -> Vec<[f32; 3]> {
    (0..p.len())
        .map(|i| {
            let mut v: [Vec<f32>; 3] = Default::default();
            for &n in &voters[i] {
                for ax in 0..3 {
                    v[ax].push(moved[n as usize][ax] - p[n as usize][ax]);
                }
            }
            std::array::from_fn(|ax| p[i][ax] + median(&mut v[ax]))
        })
        .collect()
}

fn match_from(a: &Gaussians, predicted: &[[f32; 3]], b: &Gaussians, start: Start) -> JointMatch {
    let (na, nb) = (a.len(), b.len());
    let spacing = spacing(&a.positions);
    if na == 0 || nb == 0 {
        return JointMatch {
            prev_of: vec![None; nb],
            confident: 0,
            matched: 0,
            max_distance: 0.0,
            median_distance: 0.0,
            spacing,
            field: a.positions.clone(),
        };
    }
    let sig_a: Vec<[f32; SIG]> = (0..na).map(|i| signature(a, i)).collect();
    let sig_b: Vec<[f32; SIG]> = (0..nb).map(|j| signature(b, j)).collect();
    // Attribute spreads (robust), the unit of the first round's attribute noise.
    let spread: [f32; SIG] = std::array::from_fn(|k| {
        let mut v: Vec<f32> = sig_a.iter().map(|s| s[k]).collect();
        let m = median(&mut v);
        let mut dev: Vec<f32> = v.iter().map(|x| (x - m).abs()).collect();
        (1.4826 * median(&mut dev)).max(1e-3)
    });
    let ext = extent(&a.positions).max(extent(&b.positions)).max(1e-6);
    let floor = spacing.max(1e-6 * ext);
    // Spatial neighbours in `a` that vote on each other's displacement.
    let voters = neighbours(&a.positions, VOTERS);
    // The prediction smoothed like the displacements below: one wrong velocity (a wrong match
    // of the pair before) must not carry a Gaussian away from its neighbours.
    let mut pred: Vec<[f32; 3]> = if start == Start::Plain {
        predicted.to_vec()
    } else {
        smoothed(&a.positions, predicted, &voters)
    };
    let (mut r, mut sigma): (f32, [f32; SIG]) = match start {
        Start::Plain => (floor, [1e6; SIG]),
        Start::PositionLed => (floor, std::array::from_fn(|k| 10.0 * spread[k])),
        Start::AttributeLed => (
            (0.35 * ext).max(4.0 * floor),
            std::array::from_fn(|k| 0.05 * spread[k]),
        ),
    };
    let nearest = |pred: &[[f32; 3]], r: f32, sigma: &[f32; SIG]| {
        let pts: Vec<[f32; JOINT]> = (0..na)
            .map(|i| joint(&pred[i], &sig_a[i], r, sigma))
            .collect();
        let tree = KdTree::new(&pts);
        let from_b: Vec<Vec<(u32, f32)>> = (0..nb)
            .map(|j| tree.nearest(&joint(&b.positions[j], &sig_b[j], r, sigma), 4))
            .collect();
        let pts_b: Vec<[f32; JOINT]> = (0..nb)
            .map(|j| joint(&b.positions[j], &sig_b[j], r, sigma))
            .collect();
        let tree_b = KdTree::new(&pts_b);
        let from_a: Vec<u32> = (0..na).map(|i| tree_b.nearest(&pts[i], 1)[0].0).collect();
        (from_b, from_a)
    };
    let rounds = if start == Start::Plain { 0 } else { ROUNDS };
    for _ in 0..rounds {
        let (from_b, from_a) = nearest(&pred, r, &sigma);
        // Mutual pairs give the displacements that vote.
        let mut disp: Vec<Option<[f32; 3]>> = vec![None; na];
        for (j, c) in from_b.iter().enumerate() {
            let i = c[0].0 as usize;
            if from_a[i] == j as u32 {
                disp[i] = Some(std::array::from_fn(|ax| {
                    b.positions[j][ax] - a.positions[i][ax]
                }));
            }
        }
        let mut next = pred.clone();
        for i in 0..na {
            let mut v: [Vec<f32>; 3] = Default::default();
            for &n in &voters[i] {
                if let Some(d) = disp[n as usize] {
                    for ax in 0..3 {
                        v[ax].push(d[ax]);
                    }
                }
            }
            if v[0].len() >= 3 {
                next[i] = std::array::from_fn(|ax| a.positions[i][ax] + median(&mut v[ax]));
            }
        }
        pred = next;
        // Shrink the radius and the attribute noise to what the agreeing pairs show.
        let mut res = Vec::new();
        let mut sres: [Vec<f32>; SIG] = Default::default();
        for (j, c) in from_b.iter().enumerate() {
            let i = c[0].0 as usize;
            if from_a[i] == j as u32 {
                let d: f32 = (0..3)
                    .map(|ax| (b.positions[j][ax] - pred[i][ax]).powi(2))
                    .sum::<f32>()
                    .sqrt();
                res.push(d);
                for k in 0..SIG {
                    sres[k].push((sig_b[j][k] - sig_a[i][k]).abs());
                }
            }
        }
        if res.is_empty() {
            break;
        }
        // Twice the 90th percentile: quantised attributes often do not change at all, so a
        // median would leave no room for those that move by a level.
        r = (2.0 * quantile(&mut res, 0.9)).max(0.25 * floor);
        sigma = std::array::from_fn(|k| {
            (2.0 * quantile(&mut sres[k], 0.9))
                .max(0.02 * spread[k])
                .max(NOISE_FLOOR[k])
        });
    }
    // Final: mutual nearest neighbours within the gate, then left-overs by distance.
    let (from_b, from_a) = nearest(&pred, r, &sigma);
    let mut prev_of = vec![None; nb];
    let mut taken = vec![false; na];
    let (mut matched, mut confident) = (0, 0);
    let reach = (3.0 * r).max(if start == Start::Plain { 4.0 } else { 1.0 } * floor);
    for (j, c) in from_b.iter().enumerate() {
        let (i, d1) = c[0];
        let moved: f32 = (0..3)
            .map(|ax| (b.positions[j][ax] - pred[i as usize][ax]).powi(2))
            .sum();
        // Mutual nearest neighbours: the same Gaussian if the joint distance is within the gate
        // or (attributes that changed) the position is within reach of the prediction.
        let close =
            moved <= reach * reach && sig_d2(&sig_a[i as usize], &sig_b[j], &sigma) <= 4.0 * GATE;
        if from_a[i as usize] == j as u32 && (d1 <= GATE || close) {
            prev_of[j] = Some(i);
            taken[i as usize] = true;
            matched += 1;
            let d2 = c.get(1).map_or(f32::INFINITY, |x| x.1);
            if d1 <= 0.25 * d2 {
                confident += 1;
            }
        }
    }
    // Left-overs: by position alone (attributes may change where motion does not), near the
    // prediction: within three radii or one spacing.
    let sides = Sides {
        pred: &pred,
        b: &b.positions,
        sig_a: &sig_a,
        sig_b: &sig_b,
        sigma: &sigma,
    };
    matched += sides.pair_leftovers(&mut prev_of, &mut taken, 4, reach, 4.0 * GATE);
    // Where the displacement field is not smooth (the seam between two parts that move apart),
    // the prediction misses: a wider reach, with attributes held to the gate itself.
    if start != Start::Plain {
        let wide = (10.0 * r).max(4.0 * floor);
        matched += sides.pair_leftovers(&mut prev_of, &mut taken, 8, wide, GATE);
    }
    let mut dists: Vec<f32> = prev_of
        .iter()
        .enumerate()
        .filter_map(|(j, p)| {
            p.map(|i| {
                (0..3)
                    .map(|ax| (b.positions[j][ax] - a.positions[i as usize][ax]).powi(2))
                    .sum::<f32>()
                    .sqrt()
            })
        })
        .collect();
    let max_distance = dists.iter().copied().fold(0.0f32, f32::max);
    JointMatch {
        prev_of,
        confident,
        matched,
        max_distance,
        median_distance: median(&mut dists),
        spacing,
        field: pred,
    }
}
