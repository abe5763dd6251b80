//! `dlgs play` of a Scaffold-GS file (variant 1): its Gaussians are generated per camera, so
//! each frame is decoded for a camera (frame f for camera f mod the cameras given, frustum-culled
//! unless `--no-cull`), at its presentation time, dropping the frames it is too late for. The
//! file is read with random access (`ScaffoldDecoder`): no stdin, no `--bandwidth-mbps`.

use std::fs::File;
use std::io::BufReader;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use dlgs_decoder::scaffold::{ScaffoldDecoder, ViewRequest};

use crate::play_cmd::{print_report, PlayArgs, PlayReport};
use crate::scene_io::Source;

pub fn run(args: &PlayArgs) -> Result<()> {
    if args.bandwidth_mbps.is_some() {
        bail!(
            "--bandwidth-mbps: a Scaffold-GS file is played from the file with random access \
             (no streaming reader for variant 1 yet)"
        );
    }
    let opened = Instant::now();
    let name = args.file.display().to_string();
    // The cameras: placed around the anchors of GOP 0, as `dlgs render` places them.
    let cameras = {
        let mut src = Source::open(&args.file)?;
        args.cams.resolve(&src.canonical(0.0)?)?
    };
    let f = File::open(&args.file).with_context(|| format!("opening {name}"))?;
    let mut dec = ScaffoldDecoder::new(BufReader::new(f), dlgs::Limits::default())
        .with_context(|| format!("opening {name}"))?;
    let scene = dec.scene().clone();
    let fps = args.fps.unwrap_or(scene.fps());
    if !(fps > 0.0 && fps.is_finite()) {
        bail!("--fps must be a positive number, got {fps}");
    }
    let language = args.language && scene.lang_levels > 0;
    let period = 1.0 / fps;
    let mut r = PlayReport {
        frames: scene.frame_count,
        fps,
        ..Default::default()
    };
    let mut decode_ms = Vec::new();
    let mut gaussians = 0usize;
    let mut gop = None;
    let mut clock_start: Option<Instant> = None;
    for f in 0..scene.frame_count {
        if let (Some(start), false) = (clock_start, args.max_speed) {
            if start.elapsed().as_secs_f64() > (f as f64 + 1.0) * period {
                r.dropped += 1;
                continue;
            }
        }
        let t = f as f64 / scene.fps();
        let g = scene.locate(t)?.gop;
        if gop != Some(g) {
            // The GOP's anchors, MLPs and time features, decoded once (timed apart).
            let t0 = Instant::now();
            dec.gop(g)
                .with_context(|| format!("decoding GOP {g} of {name}"))?;
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            r.gop_decode_ms.push(ms);
            r.gop_ready_ms.push(ms);
            if clock_start.is_some() {
                r.stall_ms += ms;
            }
            gop = Some(g);
        }
        let cam = &cameras[f as usize % cameras.len()];
        let t0 = Instant::now();
        let frame = if args.no_cull {
            let view = ViewRequest {
                camera_center: cam.position.to_array(),
                language,
                visible: None,
            };
            dec.frame_at(t, &view)
        } else {
            let in_view =
                |p: &[[f32; 3]], rad: &[f32]| dlgs_render::cull::spheres_in_view(cam, p, rad);
            dec.frame_in_view(t, cam.position.to_array(), language, &in_view)
                .map(|(n, _)| n)
        }
        .with_context(|| format!("decoding frame {f} of {name}"))?;
        decode_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        gaussians += frame.len();
        drop(std::hint::black_box(frame));
        r.shown += 1;
        let start = *clock_start.get_or_insert_with(|| {
            r.time_to_first_frame_ms = opened.elapsed().as_secs_f64() * 1e3;
            Instant::now()
        });
        if !args.max_speed {
            let due = Duration::from_secs_f64((f as f64 + 1.0) * period);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
    }
    r.wall_s = clock_start.map_or(0.0, |s| s.elapsed().as_secs_f64());
    r.gaussians_mean = Some(gaussians as f64 / f64::from(r.shown.max(1)));
    r.summarise(decode_ms);
    print_report(&r, args.json)
}
