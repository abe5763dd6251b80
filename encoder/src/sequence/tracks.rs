//! Tracks through a sequence whose Gaussians move far and come and go. Every Gaussian of every
//! frame belongs to one *track* (a run of consecutive frames); tracks live in *slots*, the
//! dynamic Gaussians of the file. A slot holds one track, or (with intra GOPs) a later track
//! after its earlier one died in an earlier GOP, so within one GOP a slot shows at most one
//! run of frames: what `LIFE` (format-spec §6.14) can say.
//!
//! Where two frames have no consistent correspondence (independent per-frame reconstructions,
//! say), the [`Fallback`] decides: by default the tracks go on as their Gaussians carried by
//! the displacement field the matcher fitted (a resampled set moved by fitted motion) until the
//! next GOP, whose first frame begins new tracks from its own Gaussians.

use dlgs::model::Gaussians;
use dlgs::{Error, Result};

use super::joint_match::{match_joint, neighbours, smoothed, JointMatch};
use super::PairReport;

/// No Gaussian: the slot's track is not alive at this frame.
pub const NONE: u32 = u32::MAX;

/// How frames were matched into tracks.
#[derive(Debug, Clone, Default)]
pub struct Tracks {
    /// `rows[t][s]`: the Gaussian of frame `t` that slot `s` shows, or [`NONE`].
    pub rows: Vec<Vec<u32>>,
    /// Slots in all.
    pub slots: usize,
    /// Frames where no consistent match with the previous frame existed and every track
    /// ended there, new ones beginning (the fallback at a GOP's first frame, or everywhere
    /// with [`Fallback::Cut`]).
    pub cuts: Vec<usize>,
    /// Frames where no consistent match with the previous frame existed and the tracks went
    /// on carried by the fitted displacement field ([`Fallback::Resample`]).
    pub resampled: Vec<usize>,
}

/// What tracking does where two frames have no consistent correspondence.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Fallback {
    /// Within a GOP, every track goes on as its Gaussian of the frame before, carried by the
    /// displacement field fitted between the two frames (the frame's own Gaussians are not
    /// shown: a resampled set with fitted motion); at a GOP's first frame, a cut. One set of
    /// Gaussians per GOP instead of one per frame.
    #[default]
    Resample,
    /// Every track ends and the frame's Gaussians begin new ones: as many Gaussians as coding
    /// every frame on its own.
    Cut,
}

/// What matching may do.
#[derive(Debug, Clone, Copy)]
pub struct TrackSettings {
    pub min_confident: f64,
    /// Fall back (see `fallback`) where frames cannot be matched (else refuse the sequence).
    pub allow_cuts: bool,
    pub fallback: Fallback,
    pub gop_length: usize,
}

impl Tracks {
    /// Whether slot `s` shows a Gaussian at frame `t`.
    pub fn alive(&self, t: usize, s: usize) -> bool {
        self.rows[t].get(s).is_some_and(|&r| r != NONE)
    }

    /// The frames of GOP `g` (`frames` wide) at which slot `s` is shown, local to the GOP:
    /// `(first, last)`, or `(u16::MAX, 0)` when never.
    pub fn local_life(&self, s: usize, start: usize, frames: usize) -> (u16, u16) {
        let alive: Vec<usize> = (start..start + frames)
            .filter(|&t| self.alive(t, s))
            .collect();
        match (alive.first(), alive.last()) {
            (Some(&a), Some(&b)) => ((a - start) as u16, (b - start) as u16),
            _ => (u16::MAX, 0),
        }
    }
}

/// Match every frame onto the one before and cut the sequence into tracks, one slot per
/// track (see [`Tracks::pack`]). [`Fallback::Resample`] appends the carried Gaussians to
/// their frames.
pub fn track(
    frames: &mut [Gaussians],
    s: &TrackSettings,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Tracks, Vec<PairReport>)> {
    let total = frames.len();
    let mut tr = Tracks {
        rows: Vec::with_capacity(total),
        slots: frames[0].len(),
        cuts: Vec::new(),
        resampled: Vec::new(),
    };
    tr.rows.push((0..frames[0].len() as u32).collect());
    let mut pairs = Vec::with_capacity(total.saturating_sub(1));
    progress(1, total);
    for t in 1..total {
        let prev = &tr.rows[t - 1];
        let alive: Vec<usize> = (0..tr.slots).filter(|&s| prev[s] != NONE).collect();
        let mut a = Gaussians::new(frames[t - 1].sh_degree, 0);
        let mut pred = Vec::with_capacity(alive.len());
        for &s in &alive {
            let p = frames[t - 1].positions[prev[s] as usize];
            a.push_from(&frames[t - 1], prev[s] as usize);
            // Constant velocity where the track was alive two frames back.
            let before = (t >= 2)
                .then(|| tr.rows[t - 2][s])
                .filter(|&r| r != NONE)
                .map(|r| frames[t - 2].positions[r as usize]);
            pred.push(match before {
                Some(q) => std::array::from_fn(|ax| 2.0 * p[ax] - q[ax]),
                None => p,
            });
        }
        let b = &frames[t];
        let m = match_joint(&a, &pred, b);
        let nb = b.len();
        let consistent = m.confident_share() >= s.min_confident
            && m.matched as f64 >= 0.5 * a.len().min(b.len()) as f64;
        let resample = !consistent
            && s.allow_cuts
            && s.fallback == Fallback::Resample
            && !t.is_multiple_of(s.gop_length)
            && !a.is_empty();
        let report = pair_report(t, &m, a.len(), nb, consistent, resample);
        if !consistent && !s.allow_cuts {
            return Err(Error::input(format!(
                "frames {} and {t}: only {:.1}% of the matched Gaussians match confidently (at \
                 least {:.1}% asked), {} of {} matched: no consistent correspondence (allow new \
                 tracks where frames cannot be matched, or lower the floor knowing matches may be \
                 wrong)",
                t - 1,
                100.0 * m.confident_share(),
                100.0 * s.min_confident,
                m.matched,
                nb
            )));
        }
        let mut row = vec![NONE; tr.slots];
        let mut births = Vec::new();
        if consistent {
            for (j, p) in m.prev_of.iter().enumerate() {
                match p {
                    Some(i) => row[alive[*i as usize]] = j as u32,
                    None => births.push(j),
                }
            }
        } else if resample {
            // The tracks go on where the fitted field carries them; this frame's own
            // Gaussians are not shown.
            tr.resampled.push(t);
            let base = frames[t].len();
            let mut carried = smooth_field(&a.positions, &m.field);
            // Where a Gaussian's own match lands near where the field carries it, the matched
            // position: the set stays on this frame's surface instead of drifting with the
            // field's errors, which add up frame after frame.
            let reach = (2.0 * m.spacing).powi(2);
            for (j, p) in m.prev_of.iter().enumerate() {
                if let Some(k) = p {
                    let k = *k as usize;
                    let q = frames[t].positions[j];
                    let d: f32 = (0..3).map(|ax| (q[ax] - carried[k][ax]).powi(2)).sum();
                    if d <= reach {
                        carried[k] = q;
                    }
                }
            }
            for (k, &slot) in alive.iter().enumerate() {
                row[slot] = (base + k) as u32;
                frames[t].push_from(&a, k);
                *frames[t].positions.last_mut().expect("just pushed") = carried[k];
            }
        } else {
            tr.cuts.push(t);
            births.extend(0..frames[t].len());
        }
        for j in births {
            tr.slots += 1;
            row.push(NONE);
            for r in &mut tr.rows {
                r.push(NONE);
            }
            row[tr.slots - 1] = j as u32;
        }
        tr.rows.push(row);
        pairs.push(report);
        progress(t + 1, total);
    }
    Ok((tr, pairs))
}

/// Neighbours over which the resampling fallback averages the fitted displacements.
const FIELD_NEIGHBOURS: usize = 32;

/// `field` (each point of `p` carried by the matcher's displacement field) with every
/// displacement replaced by the median of its [`FIELD_NEIGHBOURS`] nearest points': the
/// matcher's field is a median of 16 noisy matches per point, and carried frame after frame
/// its point-to-point noise would scatter neighbouring Gaussians (a median over a symmetric
/// neighbourhood keeps a field that is locally affine, rotations of parts included).
fn smooth_field(p: &[[f32; 3]], field: &[[f32; 3]]) -> Vec<[f32; 3]> {
    smoothed(p, field, &neighbours(p, FIELD_NEIGHBOURS))
}

fn pair_report(
    t: usize,
    m: &JointMatch,
    na: usize,
    nb: usize,
    consistent: bool,
    resampled: bool,
) -> PairReport {
    let cut = !consistent && !resampled;
    PairReport {
        frame: t,
        confident_share: m.confident_share(),
        mutual_share: m.matched as f64 / na.min(nb).max(1) as f64,
        max_distance: m.max_distance,
        median_distance: m.median_distance,
        spacing: m.spacing,
        births: if consistent {
            m.births()
        } else if cut {
            nb
        } else {
            0
        },
        deaths: if consistent {
            na - m.matched
        } else if cut {
            na
        } else {
            0
        },
        cut,
        resampled,
    }
}

impl Tracks {
    /// With intra GOPs, let a later track take the slot of one that ended in an earlier GOP
    /// (not at the frame just before its GOP: that frame's GOP ends on the next frame's
    /// state), the lowest free slot first, tracks in order of birth. A residual between GOPs
    /// cannot jump from one Gaussian to another, so only intra GOPs may share slots.
    pub fn pack(&mut self, gop_length: usize) {
        let total = self.rows.len();
        let life: Vec<(usize, usize)> = (0..self.slots)
            .map(|s| {
                let first = (0..total).find(|&t| self.alive(t, s)).unwrap_or(0);
                let last = (0..total).rev().find(|&t| self.alive(t, s)).unwrap_or(0);
                (first, last)
            })
            .collect();
        let mut order: Vec<usize> = (0..self.slots).collect();
        order.sort_by_key(|&s| (life[s].0, s));
        // Per new slot: the last frame of the track it holds.
        let mut held: Vec<usize> = Vec::new();
        let mut to = vec![0usize; self.slots];
        for s in order {
            let (first, last) = life[s];
            let gop_start = first - first % gop_length;
            let free = held.iter().position(|&l| l < gop_start && l + 1 < first);
            to[s] = match free {
                Some(x) => x,
                None => {
                    held.push(0);
                    held.len() - 1
                }
            };
            held[to[s]] = last;
        }
        for row in &mut self.rows {
            let mut packed = vec![NONE; held.len()];
            for (s, &r) in row.iter().enumerate() {
                if r != NONE {
                    packed[to[s]] = r;
                }
            }
            *row = packed;
        }
        self.slots = held.len();
    }
}

/// The frames `start ..= end` with one row per slot: where the slot's track of this GOP
/// (`gop` = `start .. start + gop_frames`) is not alive, its nearest alive state, the position
/// carried on at the track's velocity for at most `carry` frames. A slot with no track alive in
/// the GOP holds its nearest state in time.
pub fn fill(
    frames: &[Gaussians],
    tr: &Tracks,
    start: usize,
    gop_frames: usize,
    end: usize,
    carry: usize,
) -> Vec<Gaussians> {
    let sh = frames[0].sh_degree;
    let mut out: Vec<Gaussians> = (start..=end).map(|_| Gaussians::new(sh, 0)).collect();
    for s in 0..tr.slots {
        // The run of this GOP (or the nearest frame alive at all).
        let own: Vec<usize> = (start..start + gop_frames)
            .filter(|&t| tr.alive(t, s))
            .collect();
        let (first, last) = match (own.first(), own.last()) {
            (Some(&a), Some(&b)) => (a, b),
            _ => {
                let t = nearest_alive(tr, s, start);
                (t, t)
            }
        };
        // The run may go on to the anchor frame past the GOP.
        let last = (last + 1..=end)
            .take_while(|&t| tr.alive(t, s) && !own.is_empty())
            .last()
            .unwrap_or(last);
        let at = |t: usize| (&frames[t], tr.rows[t][s] as usize);
        let run = !own.is_empty();
        for (k, t) in (start..=end).enumerate() {
            let (src, moved) = if !run {
                (first, None)
            } else if t < first {
                (
                    first,
                    extrapolate(frames, tr, s, first, first + 1, first - t, carry),
                )
            } else if t > last {
                (
                    last,
                    extrapolate(frames, tr, s, last, last.wrapping_sub(1), t - last, carry),
                )
            } else {
                (t, None)
            };
            let (g, i) = at(src);
            out[k].push_from(g, i);
            if let Some(p) = moved {
                *out[k].positions.last_mut().expect("just pushed") = p;
            }
        }
    }
    out
}

fn nearest_alive(tr: &Tracks, s: usize, t: usize) -> usize {
    (0..tr.rows.len())
        .filter(|&u| tr.alive(u, s))
        .min_by_key(|&u| (u.abs_diff(t), u))
        .expect("every slot shows a Gaussian at some frame")
}

/// The position at `from` carried `steps` frames away from `toward` (the neighbouring frame
/// of the same run) at the run's velocity, at most `carry` frames; `None` to keep it.
fn extrapolate(
    frames: &[Gaussians],
    tr: &Tracks,
    s: usize,
    from: usize,
    toward: usize,
    steps: usize,
    carry: usize,
) -> Option<[f32; 3]> {
    if toward >= tr.rows.len() || !tr.alive(toward, s) || !tr.alive(from, s) {
        return None;
    }
    let p = frames[from].positions[tr.rows[from][s] as usize];
    let q = frames[toward].positions[tr.rows[toward][s] as usize];
    let k = steps.min(carry) as f32;
    Some(std::array::from_fn(|ax| p[ax] + k * (p[ax] - q[ax])))
}
