//! The Gaussians at a time into the frame buffers, and the pointers/lengths the page views
//! them through (typed arrays over wasm memory).

use dlgs_decoder::{FrameOptions, FrameSlices};
use wasm_bindgen::prelude::*;

use crate::errors::status;
use crate::{Player, DONE, NEED_BYTES};

#[derive(Default)]
pub(crate) struct Buffers {
    pub(crate) positions: Vec<[f32; 3]>,
    pub(crate) log_scales: Vec<[f32; 3]>,
    pub(crate) rotations: Vec<[f32; 4]>,
    pub(crate) opacity: Vec<f32>,
    pub(crate) lang_opacity: Vec<f32>,
    pub(crate) sh: Vec<f32>,
    pub(crate) lang: Vec<f32>,
    pub(crate) sh_degree: u8,
    pub(crate) lang_width: usize,
}

#[wasm_bindgen]
impl Player {
    /// The Gaussians at time `t` (static then dynamic rows) into the frame buffers.
    /// `cam`: camera centre (view-dependent decoders); `language`: run the language decoder.
    pub fn frame(
        &mut self,
        t: f64,
        cx: f32,
        cy: f32,
        cz: f32,
        language: bool,
    ) -> Result<u32, JsError> {
        self.store.borrow_mut().missing = None;
        if self.is_scaffold() {
            // Scaffold-GS: the Gaussians depend on the camera, not only its view direction.
            return self.scaffold_frame(t, [cx, cy, cz], language);
        }
        let d = self
            .dec
            .as_mut()
            .ok_or_else(|| JsError::new("Request: open() first"))?;
        let r = (|| {
            let g = d.scene().locate(t)?.gop;
            let gop = d.gop(g)?;
            let (s, y) = (&gop.canonical.statics, &gop.canonical.dynamics);
            let b = &mut self.buf;
            let rows = s.len() + y.len();
            b.positions.resize(rows, [0.0; 3]);
            b.log_scales.resize(rows, [0.0; 3]);
            b.rotations.resize(rows, [0.0; 4]);
            b.opacity.resize(rows, 0.0);
            b.lang_opacity
                .resize(s.lang_opacity.len() + y.lang_opacity.len(), 0.0);
            b.sh.resize(s.sh.len() + y.sh.len(), 0.0);
            b.lang.resize(s.lang.len() + y.lang.len(), 0.0);
            b.sh_degree = s.sh_degree;
            b.lang_width = s.lang_width;
            let opts = FrameOptions {
                camera_center: [cx, cy, cz],
                language,
            };
            d.frame_at_merged_into(
                t,
                &opts,
                FrameSlices {
                    positions: &mut b.positions,
                    log_scales: &mut b.log_scales,
                    rotations: &mut b.rotations,
                    opacity: &mut b.opacity,
                    lang_opacity: &mut b.lang_opacity,
                    sh: &mut b.sh,
                    lang: &mut b.lang,
                },
            )?;
            Ok(rows)
        })();
        match status(self, r)? {
            Some(rows) => {
                self.rows = rows;
                Ok(DONE)
            }
            None => Ok(NEED_BYTES),
        }
    }

    pub fn rows(&self) -> u32 {
        self.rows as u32
    }
    pub fn sh_degree(&self) -> u32 {
        self.buf.sh_degree as u32
    }
    pub fn lang_width(&self) -> u32 {
        self.buf.lang_width as u32
    }
    pub fn positions_ptr(&self) -> usize {
        self.buf.positions.as_ptr() as usize
    }
    pub fn log_scales_ptr(&self) -> usize {
        self.buf.log_scales.as_ptr() as usize
    }
    pub fn rotations_ptr(&self) -> usize {
        self.buf.rotations.as_ptr() as usize
    }
    pub fn opacity_ptr(&self) -> usize {
        self.buf.opacity.as_ptr() as usize
    }
    pub fn lang_opacity_ptr(&self) -> usize {
        self.buf.lang_opacity.as_ptr() as usize
    }
    pub fn lang_opacity_len(&self) -> usize {
        self.buf.lang_opacity.len()
    }
    pub fn sh_ptr(&self) -> usize {
        self.buf.sh.as_ptr() as usize
    }
    pub fn sh_len(&self) -> usize {
        self.buf.sh.len()
    }
    pub fn lang_ptr(&self) -> usize {
        self.buf.lang.as_ptr() as usize
    }
    pub fn lang_len(&self) -> usize {
        self.buf.lang.len()
    }
}
