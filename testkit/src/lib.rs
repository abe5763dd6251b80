//! `dlgs-testkit`: what tests, benchmarks and the CLI's `synth` and `labels` commands build
//! their inputs from. No trained DLGStream model exists here, so every dynamic model is made
//! from a REAL scene with SYNTHETIC motion (`synth`), every benchmark scene from the real
//! scenes in `../shared/data` (`bench_scenes`), and the query test scene from REAL
//! per-Gaussian labels with SYNTHETIC language codes (`labels`, `code_layout`). Library
//! crates hold none of this.

pub mod bench_scenes;
pub mod code_layout;
pub mod labels;
pub mod motion;
pub mod synth;
