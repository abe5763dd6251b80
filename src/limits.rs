//! Resource limits checked before anything is allocated (format-spec §8).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Upper bounds a reader enforces on declared sizes, and one budget every input-driven
/// allocation draws from. Every count read from a file is checked against these *and* against
/// the bytes actually present before memory is reserved.
///
/// Each buffer must fit [`max_alloc`](Self::max_alloc); together, the buffers drawn through
/// one budget must fit [`max_total_alloc`](Self::max_total_alloc). Clones share their budget;
/// [`Limits::fresh`] starts a new one with the same caps. The readers draw one budget per unit
/// of work: the decoders one per GOP (all its chunks), a foreign splat file one per file, the
/// reference-run ingest one per GOP folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Limits {
    /// Largest chunk payload accepted, in bytes.
    pub max_chunk_len: u64,
    /// Largest number of GOPs in one file.
    pub max_gops: u32,
    /// Largest number of Gaussians (static + dynamic) in one GOP.
    pub max_gaussians: u64,
    /// Largest single decoded buffer (e.g. a decompressed payload), in bytes.
    pub max_alloc: u64,
    /// Largest number of scene-level chunks before the first GOP.
    pub max_scene_chunks: u32,
    /// Largest number of chunks in one GOP.
    pub max_chunks_per_gop: u32,
    /// Largest total of the buffers drawn through one budget, in bytes.
    pub max_total_alloc: u64,
    /// What has been drawn so far (shared by clones; not compared by `==`).
    pub budget: Budget,
}

/// The bytes drawn so far from a [`Limits`] budget, shared by its clones.
#[derive(Debug, Clone, Default)]
pub struct Budget(Arc<AtomicU64>);

impl Budget {
    /// Bytes drawn so far.
    pub fn spent(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// Budgets are state, not configuration: two `Limits` are equal when their caps are.
impl PartialEq for Budget {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Eq for Budget {}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_chunk_len: 4 << 30,
            max_gops: 1 << 20,
            max_gaussians: 64 << 20,
            max_alloc: 8 << 30,
            max_scene_chunks: 4096,
            max_chunks_per_gop: 4096,
            max_total_alloc: 16 << 30,
            budget: Budget::default(),
        }
    }
}

impl Limits {
    /// The same caps with a new, empty budget.
    pub fn fresh(&self) -> Limits {
        Limits {
            budget: Budget::default(),
            ..self.clone()
        }
    }

    /// Draw a buffer of `bytes` for `what` (declared at byte `at`): `LimitExceeded` if it would
    /// pass `max_alloc`, or take the budget past `max_total_alloc`.
    pub fn check_alloc(&self, what: &'static str, bytes: u64, at: u64) -> crate::Result<()> {
        if bytes > self.max_alloc {
            return Err(crate::Error::limit(what, bytes, self.max_alloc, at));
        }
        let before = self.budget.0.fetch_add(bytes, Ordering::Relaxed);
        let total = before.saturating_add(bytes);
        if total > self.max_total_alloc {
            return Err(crate::Error::limit(
                "total of the buffers drawn from one budget",
                total,
                self.max_total_alloc,
                at,
            ));
        }
        Ok(())
    }

    /// `LimitExceeded` at `at` if `count` Gaussians would pass `max_gaussians`.
    pub fn check_gaussians(&self, what: &'static str, count: u64, at: u64) -> crate::Result<()> {
        if count > self.max_gaussians {
            return Err(crate::Error::limit(what, count, self.max_gaussians, at));
        }
        Ok(())
    }

    /// Small limits for fuzzing and untrusted input in tests.
    pub fn tiny() -> Self {
        Limits {
            max_chunk_len: 16 << 20,
            max_gops: 4096,
            max_gaussians: 1 << 20,
            max_alloc: 64 << 20,
            max_scene_chunks: 256,
            max_chunks_per_gop: 256,
            max_total_alloc: 256 << 20,
            budget: Budget::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_draw_from_one_budget_that_clones_share_and_fresh_resets() {
        let l = Limits {
            max_alloc: 100,
            max_total_alloc: 150,
            ..Limits::tiny()
        };
        let e = l.check_alloc("one", 101, 7).unwrap_err();
        assert_eq!(e.to_string(), "limit exceeded: one = 101 > 100 (at byte 7)");
        let shared = l.clone();
        l.check_alloc("a", 100, 0).unwrap();
        let e = shared.check_alloc("b", 60, 9).unwrap_err();
        assert_eq!(e.name(), "LimitExceeded");
        assert!(e.to_string().contains("160 > 150"), "{e}");
        let f = l.fresh();
        assert_eq!(f.budget.spent(), 0);
        assert_eq!(f, l, "equal caps, whatever was spent");
        f.check_alloc("c", 100, 0).unwrap();
        let huge = f
            .check_alloc("d", 100, 0)
            .and(f.check_alloc("e", u64::MAX / 2, 0));
        assert!(huge.is_err(), "no overflow past u64");
    }
}
