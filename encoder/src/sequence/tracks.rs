//! Tracks through a sequence whose Gaussians move far and come and go. Every Gaussian of every
//! frame belongs to one *track* (a run of consecutive frames); tracks live in *slots*, the
//! dynamic Gaussians of the file. A slot holds one track, or (with intra GOPs) a later track
//! after its earlier one died in an earlier GOP, so within one GOP a slot shows at most one
//! run of frames: what `LIFE` (format-spec §6.14) can say.

use dlgs::model::Gaussians;
use dlgs::{Error, Result};

use super::joint_match::{match_joint, JointMatch};
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
    /// Frames where no consistent match with the previous frame existed: every track ended
    /// there and new ones began (the fallback).
    pub cuts: Vec<usize>,
}

/// What matching may do.
#[derive(Debug, Clone, Copy)]
pub struct TrackSettings {
    pub min_confident: f64,
    /// Start new tracks where frames cannot be matched (else refuse the sequence).
    pub allow_cuts: bool,
    /// Reuse the slot of a track that died in an earlier GOP (intra GOPs only: a residual
    /// between GOPs cannot jump from one Gaussian to another).
    pub reuse_slots: bool,
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

/// Match every frame onto the one before and cut the sequence into tracks.
pub fn track(
    frames: &[Gaussians],
    s: &TrackSettings,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(Tracks, Vec<PairReport>)> {
    let total = frames.len();
    let mut tr = Tracks {
        rows: Vec::with_capacity(total),
        slots: frames[0].len(),
        cuts: Vec::new(),
    };
    tr.rows.push((0..frames[0].len() as u32).collect());
    // Per slot: the last frame its current track was alive at.
    let mut last_alive: Vec<usize> = vec![0; tr.slots];
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
        let consistent = m.confident_share() >= s.min_confident
            && m.matched as f64 >= 0.5 * a.len().min(b.len()) as f64;
        let report = pair_report(t, &m, a.len(), b.len(), consistent);
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
                b.len()
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
        } else {
            tr.cuts.push(t);
            births.extend(0..b.len());
        }
        // Slots free for a newborn: their track died before this GOP began.
        let gop_start = t - t % s.gop_length;
        let mut free: Vec<usize> = if s.reuse_slots {
            (0..tr.slots)
                .filter(|&x| row[x] == NONE && last_alive[x] < gop_start && prev[x] == NONE)
                .collect()
        } else {
            Vec::new()
        };
        free.reverse();
        for j in births {
            let slot = match free.pop() {
                Some(x) => x,
                None => {
                    tr.slots += 1;
                    row.push(NONE);
                    last_alive.push(0);
                    for r in &mut tr.rows {
                        r.push(NONE);
                    }
                    tr.slots - 1
                }
            };
            row[slot] = j as u32;
        }
        for (x, &r) in row.iter().enumerate() {
            if r != NONE {
                last_alive[x] = t;
            }
        }
        tr.rows.push(row);
        pairs.push(report);
        progress(t + 1, total);
    }
    Ok((tr, pairs))
}

fn pair_report(t: usize, m: &JointMatch, na: usize, nb: usize, consistent: bool) -> PairReport {
    PairReport {
        frame: t,
        confident_share: m.confident_share(),
        mutual_share: m.matched as f64 / na.min(nb).max(1) as f64,
        max_distance: m.max_distance,
        median_distance: m.median_distance,
        spacing: m.spacing,
        births: if consistent { m.births() } else { nb },
        deaths: if consistent { na - m.matched } else { na },
        cut: !consistent,
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
