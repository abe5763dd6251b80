//! `dlgs_decode_frame_view`: the Gaussians one camera sees, for both variants. A Scaffold-GS
//! file (variant 1) generates them per camera from its anchors (docs/scaffold.md); a 3DGS file
//! gives the same frame as `dlgs_decode_frame` with the camera's centre.

use dlgs_decoder::scaffold::ViewRequest;
use dlgs_render::Camera;
use glam::{Mat3, Vec3};

use crate::{
    decode_gs, decoder, fail, format_error, guarded, set_written, write_part, DlgsDecoder,
    DlgsFrameBuffers, DlgsStatus, Inner,
};

/// A camera: its centre, and for frustum culling (`cull` != 0) its orientation and
/// intrinsics, as a 3DGS `cameras.json` entry holds them.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct DlgsView {
    /// Camera centre in world coordinates: the viewpoint of the view-dependent decoders.
    pub camera_center: [f32; 3],
    /// World-to-camera rotation, row-major (x right, y down, z forward: OpenCV / 3DGS); the
    /// transpose of `cameras.json`'s camera-to-world `rotation`.
    pub world_to_camera: [f32; 9],
    /// Focal lengths and principal point in pixels.
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    /// Image size in pixels.
    pub width: u32,
    pub height: u32,
    /// Scaffold-GS files: non-zero decodes only the anchors whose Gaussians can reach into the
    /// image (the same picture, less time); 0 decodes every anchor (then only `camera_center`
    /// is read). Ignored for 3DGS files.
    pub cull: i32,
}

fn camera_of(v: &DlgsView) -> Result<Camera, String> {
    let finite = v
        .camera_center
        .iter()
        .chain(&v.world_to_camera)
        .all(|x| x.is_finite())
        && [v.fx, v.fy, v.cx, v.cy].iter().all(|x| x.is_finite());
    // `finite` first: the comparisons below then see no NaN.
    if !finite || v.width == 0 || v.height == 0 || v.fx <= 0.0 || v.fy <= 0.0 {
        return Err("the view needs finite values, width and height > 0, fx and fy > 0".into());
    }
    let m = &v.world_to_camera;
    Ok(Camera {
        width: v.width,
        height: v.height,
        fx: v.fx,
        fy: v.fy,
        cx: v.cx,
        cy: v.cy,
        // glam matrices are column-major: rows of the C array become columns of the transpose.
        rotation: Mat3::from_cols_array(m).transpose(),
        position: Vec3::from_array(v.camera_center),
        name: String::new(),
    })
}

/// Decode the Gaussians `view` sees at time `t` seconds into `buffers` (layout and
/// conventions of `dlgs_decode_frame`). For a Scaffold-GS file the neural Gaussians are given
/// as 3D Gaussians: log scales, opacities as logits, colour as SH degree 0 (DC); opacities
/// within 1e-7 of 0 or 1 are clamped there, and a negative language opacity becomes the logit
/// of 1e-7. Their number depends on the view: at most `DlgsInfo.n_gaussians`; a smaller
/// `capacity` that cannot hold this frame fails with `DLGS_STATUS_BUFFER_TOO_SMALL` and
/// `*written` (may be NULL) set to the count needed. Language is evaluated when `lang` or
/// `lang_opacity` is set. For a 3DGS file this is `dlgs_decode_frame(d, t,
/// view->camera_center, buffers, written)`.
///
/// # Safety
/// `d` is NULL or an open decoder not used by another thread during the call; `view` is NULL or a readable DlgsView; `buffers` is NULL or a DlgsFrameBuffers whose non-NULL pointers hold `capacity` Gaussians of their attribute; `written` is NULL or writable storage for one uint32_t.
#[no_mangle]
pub unsafe extern "C" fn dlgs_decode_frame_view(
    d: *mut DlgsDecoder,
    t: f64,
    view: *const DlgsView,
    buffers: *const DlgsFrameBuffers,
    written: *mut u32,
) -> DlgsStatus {
    guarded(|| {
        let Some(d) = decoder(d) else {
            return fail(DlgsStatus::NullArgument, "decoder must not be NULL");
        };
        // SAFETY: NULL or, by the C contract, a valid DlgsView for the call.
        let Some(v) = (unsafe { view.as_ref() }) else {
            return fail(DlgsStatus::NullArgument, "view must not be NULL");
        };
        // SAFETY: NULL or, by the C contract, a valid DlgsFrameBuffers for the call.
        let Some(b) = (unsafe { buffers.as_ref() }) else {
            return fail(DlgsStatus::NullArgument, "buffers must not be NULL");
        };
        let Inner::Scaffold(dec, _) = &mut d.inner else {
            return decode_gs(d, t, v.camera_center, b, written);
        };
        let scene = dec.scene();
        if !(t.is_finite() && (0.0..=scene.duration_seconds()).contains(&t)) {
            return fail(
                DlgsStatus::TimeOutOfRange,
                format!("t = {t} is outside [0, {}] s", scene.duration_seconds()),
            );
        }
        let has_lang = scene.lang_levels > 0;
        let language = has_lang && !(b.lang.is_null() && b.lang_opacity.is_null());
        let neural = if v.cull != 0 {
            let cam = match camera_of(v) {
                Ok(c) => c,
                Err(m) => return fail(DlgsStatus::BadArgument, m),
            };
            let in_view =
                |p: &[[f32; 3]], r: &[f32]| dlgs_render::cull::spheres_in_view(&cam, p, r);
            dec.frame_in_view(t, v.camera_center, language, &in_view)
                .map(|(f, _)| f)
        } else if v.camera_center.iter().all(|x| x.is_finite()) {
            let req = ViewRequest {
                camera_center: v.camera_center,
                language,
                visible: None,
            };
            dec.frame_at(t, &req)
        } else {
            return fail(DlgsStatus::BadArgument, "camera_center must be finite");
        };
        let g = match neural {
            Ok(f) => f.to_gaussians(),
            Err(e) => return format_error(e),
        };
        if b.capacity < g.len() {
            set_written(written, g.len());
            return fail(
                DlgsStatus::BufferTooSmall,
                format!(
                    "buffers hold {} Gaussians, this view's frame has {}",
                    b.capacity,
                    g.len()
                ),
            );
        }
        write_part(b, &g, 0, language);
        set_written(written, g.len());
        DlgsStatus::Ok
    })
}
