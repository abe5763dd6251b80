//! Timing hooks of the reader for the benchmarks and the threads test
//! (docs/benchmarks/python.md): the Rust `frame_at` timed inside Rust, without Python.

use dlgs_decoder::FrameOptions;

use crate::reader::Reader;

/// Seconds since the first call in this process (a clock shared by every thread).
pub fn since_epoch() -> f64 {
    static EPOCH: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
    EPOCH
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_secs_f64()
}

impl Reader {
    pub(crate) fn time_frames(&self, times: &[f64], language: bool) -> dlgs::Result<Vec<f64>> {
        let opts = FrameOptions {
            camera_center: [0.0; 3],
            language: language && self.scene.lang_width() > 0,
        };
        let mut d = self.dec()?;
        let mut out = Vec::with_capacity(times.len());
        for &t in times {
            let start = std::time::Instant::now();
            let f = d.frame_at(t, &opts)?;
            out.push(start.elapsed().as_secs_f64());
            drop(std::hint::black_box(f));
        }
        Ok(out)
    }
}
