//! `dlgs play` of a Scaffold-GS stream (variant 1; the file, stdin or `--bandwidth-mbps`): the
//! same playback pipeline and frame loop as 3DGS streams (`play_cmd`), with the GOPs decoded by
//! `ScaffoldStreamDecoder` as their bytes arrive. Its Gaussians are generated per camera, so
//! frame f is decoded for camera f mod the cameras given (frustum-culled unless `--no-cull`);
//! orbit cameras are placed around GOP 0's anchors once it has arrived.

use std::time::Instant;

use anyhow::{bail, Context, Result};
use dlgs_decoder::pipeline::PlaybackStream;
use dlgs_decoder::scaffold::{ScaffoldGop, ScaffoldStreamDecoder, ViewRequest};

use crate::play_cmd::{pipeline_options, play_loop, print_report, PlayArgs, Source};

pub fn run(args: &PlayArgs, src: Source, opened: Instant) -> Result<()> {
    let dec = ScaffoldStreamDecoder::new(src, dlgs::Limits::default())
        .context("reading the stream header")?;
    let mut stream = PlaybackStream::spawn(dec, pipeline_options(args))?;
    let scene = stream.scene().clone();
    let fps = args.fps.unwrap_or(scene.fps());
    if !(fps > 0.0 && fps.is_finite()) {
        bail!("--fps must be a positive number, got {fps}");
    }
    let language = args.language && scene.lang_levels > 0;
    let mut cameras = Vec::new();
    let mut gaussians = 0usize;
    let index = |g: &ScaffoldGop| g.index;
    let mut report = play_loop(
        args,
        &scene,
        fps,
        &mut stream,
        opened,
        index,
        |gop, time, f| {
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
        },
    )?;
    report.gaussians_mean = Some(gaussians as f64 / f64::from(report.shown.max(1)));
    print_report(&report, args.json)
}
