//! `dlgs play` of a Scaffold-GS stream (variant 1; the file, stdin or `--bandwidth-mbps`): the
//! same reader thread and frame loop as 3DGS streams (`play_cmd`), with the GOPs decoded by
//! `ScaffoldStreamDecoder` as their bytes arrive. Its Gaussians are generated per camera, so
//! frame f is decoded for camera f mod the cameras given (frustum-culled unless `--no-cull`);
//! orbit cameras are placed around GOP 0's anchors once it has arrived.

use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Result};
use dlgs_decoder::scaffold::{ScaffoldGop, ScaffoldStreamDecoder, ViewRequest};

use crate::play_cmd::{play_loop, print_report, spawn_reader, GopStream, PlayArgs, Source};

impl GopStream for ScaffoldStreamDecoder<Source> {
    type Gop = ScaffoldGop;
    fn scene(&self) -> &dlgs::container::SceneHeader {
        ScaffoldStreamDecoder::scene(self)
    }
    fn next_gop(&mut self) -> dlgs::Result<Option<Arc<ScaffoldGop>>> {
        ScaffoldStreamDecoder::next_gop(self)
    }
    fn last_decode_time(&self) -> std::time::Duration {
        ScaffoldStreamDecoder::last_decode_time(self)
    }
}

fn open(src: Source) -> dlgs::Result<ScaffoldStreamDecoder<Source>> {
    ScaffoldStreamDecoder::new(src, dlgs::Limits::default())
}

pub fn run(args: &PlayArgs, src: Source, opened: Instant) -> Result<()> {
    let (scene, rx, reader) = spawn_reader(args, src, open)?;
    let fps = args.fps.unwrap_or(scene.fps());
    if !(fps > 0.0 && fps.is_finite()) {
        bail!("--fps must be a positive number, got {fps}");
    }
    let language = args.language && scene.lang_levels > 0;
    let mut cameras = Vec::new();
    let mut gaussians = 0usize;
    let index = |g: &ScaffoldGop| g.index;
    let mut report = play_loop(args, &scene, fps, &rx, opened, index, |gop, time, f| {
        if cameras.is_empty() {
            // Frame 0 is GOP 0's: the cameras `dlgs render` places around its anchors at t = 0.
            cameras = args.cams.resolve(&gop.stand_ins(0, 0.0, false))?;
        }
        let cam = &cameras[f as usize % cameras.len()];
        let frame = if args.no_cull {
            let view = ViewRequest {
                camera_center: cam.position.to_array(),
                language,
                visible: None,
            };
            gop.frame(time.key, time.delta, &view)
        } else {
            let in_view =
                |p: &[[f32; 3]], rad: &[f32]| dlgs_render::cull::spheres_in_view(cam, p, rad);
            let center = cam.position.to_array();
            gop.frame_in_view(time.key, time.delta, center, language, &in_view)?
                .0
        };
        gaussians += frame.len();
        drop(std::hint::black_box(frame));
        Ok(())
    })?;
    drop(rx);
    let _ = reader.join();
    report.gaussians_mean = Some(gaussians as f64 / f64::from(report.shown.max(1)));
    print_report(&report, args.json)
}
