//! Scaffold-GS files (variant 1): the neural Gaussians one camera sees, generated per frame and
//! per camera by the anchors' MLPs (the native `ScaffoldDecoder` over the same sparse copy of
//! the file), given to the frame buffers as 3D Gaussians (`NeuralGaussians::to_gaussians`: the
//! CLI renderer's and the C ABI's conversion).

use dlgs_decoder::scaffold::{NeuralGaussians, ScaffoldDecoder, ViewRequest};
use wasm_bindgen::prelude::*;

use crate::errors::status;
use crate::sparse::Sparse;
use crate::{Player, DONE, NEED_BYTES};

impl Player {
    /// Whether the open file is a Scaffold-GS file.
    pub(crate) fn is_scaffold(&self) -> bool {
        self.scaffold.is_some()
    }

    /// The Scaffold-GS decoder (opened by `open`).
    fn scaffold(&mut self) -> Result<&mut ScaffoldDecoder<Sparse>, JsError> {
        self.scaffold
            .as_mut()
            .ok_or_else(|| JsError::new("Request: open() a Scaffold-GS file first"))
    }

    /// Decode GOP `g` of a Scaffold-GS file (anchors after the residual chain, deformation).
    pub(crate) fn scaffold_gop(&mut self, g: u32) -> Result<u32, JsError> {
        let r = self.scaffold()?.gop(g).map(|_| ());
        Ok(match status(self, r)? {
            Some(()) => DONE,
            None => NEED_BYTES,
        })
    }

    /// The neural Gaussians the camera at `center` sees at `t`; `None` when bytes are missing.
    fn neural(
        &mut self,
        t: f64,
        center: [f32; 3],
        language: bool,
    ) -> Result<Option<NeuralGaussians>, JsError> {
        self.store.borrow_mut().missing = None;
        let view = ViewRequest {
            camera_center: center,
            language,
            visible: None,
        };
        let r = self.scaffold()?.frame_at(t, &view);
        status(self, r)
    }

    /// The frame at `t` for the camera at `center` into the frame buffers (Scaffold-GS).
    pub(crate) fn scaffold_frame(
        &mut self,
        t: f64,
        center: [f32; 3],
        language: bool,
    ) -> Result<u32, JsError> {
        let Some(n) = self.neural(t, center, language)? else {
            return Ok(NEED_BYTES);
        };
        let g = n.to_gaussians();
        let b = &mut self.buf;
        b.positions = g.positions;
        b.log_scales = g.log_scales;
        b.rotations = g.rotations;
        b.opacity = g.opacity;
        b.lang_opacity = g.lang_opacity;
        b.sh = g.sh;
        b.lang = g.lang;
        b.sh_degree = g.sh_degree;
        b.lang_width = g.lang_width;
        self.rows = b.positions.len();
        Ok(DONE)
    }
}

#[wasm_bindgen]
impl Player {
    /// The anchors' positions at `t` (x, y, z each; Scaffold-GS), where the CLI's orbit
    /// cameras look (`anchor_stand_ins`). Empty when bytes are missing.
    pub fn anchor_positions(&mut self, t: f64) -> Result<Vec<f32>, JsError> {
        self.store.borrow_mut().missing = None;
        let r = self.scaffold()?.anchor_stand_ins(t);
        Ok(status(self, r)?
            .map(|g| g.positions.iter().flatten().copied().collect())
            .unwrap_or_default())
    }

    /// A Scaffold-GS frame as the conformance vectors list it (`valid/scaffold*.frames.f32`):
    /// the child count, then per child position, linear scales, rotation, colour, opacity,
    /// language opacity and the 9 language values (language on). Empty when bytes are missing.
    pub fn scaffold_values(
        &mut self,
        t: f64,
        cx: f32,
        cy: f32,
        cz: f32,
    ) -> Result<Vec<f32>, JsError> {
        let Some(f) = self.neural(t, [cx, cy, cz], true)? else {
            return Ok(Vec::new());
        };
        let mut out = vec![f.len() as f32];
        for i in 0..f.len() {
            out.extend_from_slice(&f.positions[i]);
            out.extend_from_slice(&f.scales[i]);
            out.extend_from_slice(&f.rotations[i]);
            out.extend_from_slice(&f.colors[i]);
            out.push(f.opacity[i]);
            // A scene without language lists zeros there.
            out.push(f.lang_opacity.get(i).copied().unwrap_or(0.0));
            match f.lang.get(9 * i..9 * i + 9) {
                Some(l) => out.extend_from_slice(l),
                None => out.extend_from_slice(&[0.0; 9]),
            }
        }
        Ok(out)
    }
}
