//! Resource limits checked before anything is allocated (format-spec §8).

/// Upper bounds a reader enforces on declared sizes. Every count read from a file is checked
/// against these *and* against the bytes actually present before memory is reserved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_chunk_len: 4 << 30,
            max_gops: 1 << 20,
            max_gaussians: 64 << 20,
            max_alloc: 8 << 30,
            max_scene_chunks: 4096,
            max_chunks_per_gop: 4096,
        }
    }
}

impl Limits {
    /// `LimitExceeded` at `at` if a buffer of `bytes` would pass `max_alloc`.
    pub fn check_alloc(&self, what: &'static str, bytes: u64, at: u64) -> crate::Result<()> {
        if bytes > self.max_alloc {
            return Err(crate::Error::limit(what, bytes, self.max_alloc, at));
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
        }
    }
}
