//! Decoding a `CSOG` payload: every part's octree and chains of records from one shared task
//! list, then each part dequantised into Gaussians.

use crate::container::ChunkType;
use crate::Error;
use rayon::prelude::*;

use super::channels::{channels, Kind, FIRST_ROTATION};
use super::quantiser::{dequantise, grid_width, levels, logit};
use super::records::{layout_of, read_parts, read_set, OctreeRecord, Record, SetForm, SetRecords};
use super::rotation_coarsening::{cells_by_shift, rotation_shift};
use super::{kd_layout, octree_positions};
use crate::bytes::ByteReader;
use crate::chunks::csog::adaptive_coder::Mode;
use crate::chunks::csog::grid_coder::{self, GridCodec};
use crate::container::SceneHeader;
use crate::error::Result;
use crate::limits::Limits;
use crate::model::{Canonical, Gaussians};
use crate::task_queue;

/// A set's records, read and split into chains, not yet decoded.
struct SetPlan<'a> {
    n: usize,
    sh_degree: u8,
    lang_width: usize,
    tree: Option<OctreeRecord<'a>>,
    coarsening: Option<(u8, f32)>,
    stored: Vec<Record<'a>>,
    /// Runs of records that decode in order, each after the one before it.
    chains: Vec<std::ops::Range<usize>>,
}

/// What every set record of one kind in a payload shares: the scene's channels, the reader's
/// limits and how the layout stores the set.
#[derive(Clone, Copy)]
struct SetShape<'l> {
    sh_degree: u8,
    lang_width: usize,
    limits: &'l Limits,
    form: SetForm,
    compact: bool,
}

/// Read one set's `n` Gaussians' records (§6.5.2) and split them into chains.
fn plan_set<'a>(r: &mut ByteReader<'a>, n: usize, shape: &SetShape) -> Result<SetPlan<'a>> {
    let SetShape {
        sh_degree,
        lang_width,
        limits,
        form,
        compact,
    } = *shape;
    let kinds = channels(&Gaussians::new(sh_degree, lang_width));
    limits.check_alloc(
        "CSOG channel cells",
        (n as u64) * 2 * kinds.len() as u64,
        r.offset(),
    )?;
    let SetRecords {
        tree,
        coarsening,
        records: stored,
        first,
    } = read_set(r, n, &kinds, form, compact)?;
    // Codec 4 and codec 5 modes 1-3 need the previous channel's final cells:
    // split the records into chains that start at an independent channel, decode the chains in
    // parallel and each chain in order (same cells whatever the thread count). The first
    // record after octree positions starts a chain: it has no previous channel (§6.5.2).
    let needs_previous = |s: &Record| match s.codec {
        GridCodec::HistogramDelta => true,
        GridCodec::Adaptive => s.mode().is_none_or(|m| m.needs_previous()),
        _ => false,
    };
    let needs_two = |s: &Record| s.mode().is_some_and(|m| m.needs_two_previous());
    let mut chains: Vec<std::ops::Range<usize>> = Vec::new();
    for j in first..stored.len() {
        match chains.last_mut() {
            Some(c) if needs_previous(&stored[j]) => c.end = j + 1,
            _ => chains.push(j..j + 1),
        }
        // Codec 5 mode 6 also reads the record before the previous one: when the previous
        // record starts a chain, this chain joins the one before it (whose last record that
        // is). Without such a record the chain stays as it is and decoding reports it.
        let k = chains.len();
        if needs_two(&stored[j]) && k >= 2 && chains[k - 1].start + 1 == j {
            let last = chains.pop().expect("two chains");
            chains[k - 2].end = last.end;
        }
    }
    Ok(SetPlan {
        n,
        sh_degree,
        lang_width,
        tree,
        coarsening,
        stored,
        chains,
    })
}

/// One unit of parallel decoding: a set's octree positions or one of its chains.
#[derive(Clone, Copy)]
enum Task {
    Octree(usize),
    Chain(usize, usize),
}

/// Decode sets (the parts of a `CSOG` payload) together. Every set's octree and chains go
/// into one pool, the costliest first, so that no long chain of one part is left to run alone
/// while the other thread idles, as when the parts decoded one after another. Each task's cells
/// depend only on its bytes: the same cells whatever the thread count or order.
fn decode_sets(plans: &[SetPlan]) -> Result<Vec<Gaussians>> {
    // Estimated cost, in units of a tree mode's byte: mixed modes take about twice as long per
    // byte (0.23 against 0.11 ms per KB on the 273k goal row); octrees about as long.
    let record_cost = |s: &Record| {
        let mixed = s
            .mode()
            .is_some_and(|m| matches!(m, Mode::Mixed(_) | Mode::MixedTwo(..)));
        s.data.len() * if mixed { 2 } else { 1 }
    };
    let mut tasks: Vec<(Task, usize)> = Vec::new();
    for (set, plan) in plans.iter().enumerate() {
        if let Some(t) = &plan.tree {
            tasks.push((Task::Octree(set), t.data.len()));
        }
        for (c, range) in plan.chains.iter().enumerate() {
            let cost = plan.stored[range.clone()].iter().map(record_cost).sum();
            tasks.push((Task::Chain(set, c), cost));
        }
    }
    tasks.sort_by_key(|&(_, cost)| std::cmp::Reverse(cost));
    let done: Vec<(Task, Vec<Vec<u16>>)> = task_queue::in_list_order(&tasks, |&(t, _)| match t {
        Task::Chain(set, c) => Ok((t, plans[set].decode_chain(c)?)),
        Task::Octree(set) => Ok((t, plans[set].decode_octree()?)),
    })
    .into_iter()
    .collect::<Result<_>>()?;
    let mut positions: Vec<Vec<Vec<u16>>> = vec![Vec::new(); plans.len()];
    let mut chains: Vec<Vec<Vec<Vec<u16>>>> = plans
        .iter()
        .map(|p| vec![Vec::new(); p.chains.len()])
        .collect();
    for (t, cells) in done {
        match t {
            Task::Octree(set) => positions[set] = cells,
            Task::Chain(set, c) => chains[set][c] = cells,
        }
    }
    Ok(plans
        .par_iter()
        .zip(positions)
        .zip(chains)
        .map(|((plan, positions), chains)| {
            // Back to record order: positions, then the chains in order.
            let cells = positions.into_iter().chain(chains.into_iter().flatten());
            plan.finish(cells.collect())
        })
        .collect())
}

impl SetPlan<'_> {
    /// The octree's cells, one channel per axis.
    fn decode_octree(&self) -> Result<Vec<Vec<u16>>> {
        let cells = self
            .tree
            .as_ref()
            .map(|r| octree_cells(r, self.n))
            .transpose()?;
        Ok(cells.map(Vec::from).unwrap_or_default())
    }

    /// The cells of chain `c`'s channels, in order.
    fn decode_chain(&self, c: usize) -> Result<Vec<Vec<u16>>> {
        let (stored, n, w) = (&self.stored, self.n, grid_width(self.n));
        let range = &self.chains[c];
        let mut out: Vec<Vec<u16>> = Vec::with_capacity(range.len());
        for j in range.clone() {
            let Record {
                bits,
                codec,
                ref data,
                at,
                ..
            } = stored[j];
            let prev = out.last().map(|p| (p.as_slice(), stored[j - 1].bits));
            let prev2 = out
                .len()
                .checked_sub(2)
                .map(|p| (out[p].as_slice(), stored[j - 2].bits));
            let r = ByteReader::new(data, at);
            let mut q = grid_coder::decode(codec, r, n, w.max(1), bits, prev, prev2)?;
            if codec == GridCodec::HistogramDelta {
                let (p, _) = prev.expect("codec 4 continues a chain (checked above)");
                grid_coder::undo_delta(&mut q, p, bits);
            }
            out.push(q);
        }
        Ok(out)
    }

    /// Dequantise a set's cells (positions first, then every channel record in order) into
    /// Gaussians.
    fn finish(&self, cells: Vec<Vec<u16>>) -> Gaussians {
        let (n, stored, coarsening) = (self.n, &self.stored, self.coarsening);
        let mut g = Gaussians::new(self.sh_degree, self.lang_width);
        let lang_width = self.lang_width;
        let mut decoded: Vec<(u8, Vec<f32>)> = stored
            .par_iter()
            .zip(cells)
            .map(|(s, q)| {
                let v = match s.kind {
                    Kind::RotIndex => q.iter().map(|&v| v as f32).collect(),
                    _ => q
                        .iter()
                        .map(|&v| dequantise(v, s.min, s.max, s.bits))
                        .collect(),
                };
                (s.bits, v)
            })
            .collect();
        // Layout 3: shifts from the decoded log-scales; rotation cells back to grid order.
        let shifts = coarsening.filter(|c| c.0 > 0).map(|(max_shift, t)| {
            let ls = &decoded[3..6];
            let shifts: Vec<u8> = (0..n)
                .into_par_iter()
                .map(|i| rotation_shift([ls[0].1[i], ls[1].1[i], ls[2].1[i]], t, max_shift))
                .collect();
            let by_shift = cells_by_shift(&shifts);
            decoded[FIRST_ROTATION - 1..FIRST_ROTATION + 3]
                .par_iter_mut()
                .for_each(|(_, v)| {
                    let mut grid = vec![0.0f32; n];
                    for (&i, &x) in by_shift.iter().zip(v.iter()) {
                        grid[i as usize] = x;
                    }
                    *v = grid;
                });
            shifts
        });
        let mut ch = decoded.into_iter();
        let mut next = || ch.next().expect("one decoded channel per kind");
        let zip3 = |a: Vec<f32>, b: Vec<f32>, c: Vec<f32>| -> Vec<[f32; 3]> {
            (0..n).map(|i| [a[i], b[i], c[i]]).collect()
        };
        g.positions = zip3(next().1, next().1, next().1);
        g.log_scales = zip3(next().1, next().1, next().1);
        let idx = next().1;
        let rest = zip3(next().1, next().1, next().1);
        g.rotations = (0..n)
            .map(|i| {
                let mut r = rest[i];
                if let Some(s) = &shifts {
                    // Exact: a power of two (§6.5.6).
                    let up = (1u32 << s[i]) as f32;
                    r = r.map(|v| v * up);
                }
                let big = (1.0 - (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]))
                    .max(0.0)
                    .sqrt();
                let m = idx[i] as usize;
                let mut q = [0.0; 4];
                let mut j = 0;
                for (a, v) in q.iter_mut().enumerate() {
                    if a == m {
                        *v = big;
                    } else {
                        *v = r[j];
                        j += 1;
                    }
                }
                q
            })
            .collect();
        let (ob, o) = next();
        g.opacity = logit(o, ob);
        let stride = g.sh_stride();
        let sh: Vec<Vec<f32>> = (0..stride).map(|_| next().1).collect();
        g.sh = (0..n * stride)
            .map(|x| sh[x % stride][x / stride])
            .collect();
        if lang_width > 0 {
            let (lb, lo) = next();
            g.lang_opacity = logit(lo, lb);
            let l: Vec<Vec<f32>> = (0..lang_width).map(|_| next().1).collect();
            g.lang = (0..n * lang_width)
                .map(|x| l[x % lang_width][x / lang_width])
                .collect();
        }
        g
    }
}

/// The octree's `n` points laid out in grid order: the three position channels' cells.
fn octree_cells(t: &OctreeRecord, n: usize) -> Result<[Vec<u16>; 3]> {
    let points = octree_positions::decode(ByteReader::new(&t.data, t.at), n, t.bits)?;
    let step = t
        .ranges
        .map(|(min, max)| (max as f64 - min as f64).max(0.0) / levels(t.bits) as f64);
    let order = kd_layout::kd_layout(&points, step);
    let axis = |a: usize| order.iter().map(|&i| points[i as usize][a]).collect();
    Ok([axis(0), axis(1), axis(2)])
}

/// Read a set stored as parts (§6.5.7) into one plan per part.
fn plan_parts<'a>(r: &mut ByteReader<'a>, n: usize, shape: &SetShape) -> Result<Vec<SetPlan<'a>>> {
    let mut plans = Vec::new();
    read_parts(r, n, shape.compact, |r, np| {
        plans.push(plan_set(r, np, shape)?);
        Ok(())
    })?;
    Ok(plans)
}

/// One set from its parts' Gaussians, in part order.
fn join_parts(parts: Vec<Gaussians>, sh_degree: u8, lang_width: usize) -> Gaussians {
    let mut parts = parts.into_iter();
    let mut g = parts
        .next()
        .unwrap_or_else(|| Gaussians::new(sh_degree, lang_width));
    for part in parts {
        g.extend(&part);
    }
    g
}

/// Decode a `CSOG` payload that starts at absolute `offset`, checking it against the scene.
pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<Canonical> {
    let mut r = ByteReader::new(p, offset);
    let at = r.offset();
    let version = r.u8("CSOG layout version")?;
    let (sh, lw) = (scene.sh_degree, scene.lang_width());
    let (ns, nd) = (scene.n_static as usize, scene.n_dynamic as usize);
    // Both sets and all their parts are read first and then decoded together (`decode_sets`).
    let grid = SetShape {
        sh_degree: sh,
        lang_width: lw,
        limits,
        form: SetForm::Grid,
        compact: false,
    };
    let (static_plans, dynamic_plans) = match layout_of(version, at)? {
        None => (
            vec![plan_set(&mut r, ns, &grid)?],
            vec![plan_set(&mut r, nd, &grid)?],
        ),
        // Dynamic sets are grid sets in every layout.
        Some((form, compact)) => (
            plan_parts(
                &mut r,
                ns,
                &SetShape {
                    form,
                    compact,
                    ..grid
                },
            )?,
            plan_parts(&mut r, nd, &SetShape { compact, ..grid })?,
        ),
    };
    if r.remaining() != 0 {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("{} bytes after the last channel", r.remaining()),
            r.offset(),
        ));
    }
    let split = static_plans.len();
    let plans: Vec<SetPlan> = static_plans.into_iter().chain(dynamic_plans).collect();
    // Every part's cells are held at once until the parts are dequantised.
    let kinds = channels(&Gaussians::new(sh, lw)).len() as u64;
    limits.check_alloc("CSOG channel cells", ((ns + nd) as u64) * 2 * kinds, at)?;
    let mut sets = decode_sets(&plans)?;
    let dynamics = join_parts(sets.split_off(split), sh, lw);
    Ok(Canonical {
        statics: join_parts(sets, sh, lw),
        dynamics,
    })
}
