//! The Scaffold-GS parsers (ANCR, AMLP, ADEF, AHAC; since 1.17 RNTC over anchor groups and
//! language-only AMLP) directly against a fixed variant-1 scene header, and whole Scaffold-GS
//! files through the random-access decoder (every GOP, so residual chains too); what decodes is
//! turned into a frame (anchor deformation and neural Gaussians) or applied to anchors, so the
//! arithmetic meets arbitrary values.
#![no_main]
use dlgs::model::scaffold::{ScaffoldCanonical, ScaffoldMlps};
use dlgs_decoder::scaffold::{neural_gaussians, ScaffoldDecoder, ViewRequest};
use libfuzzer_sys::fuzz_target;

fn scene() -> dlgs::SceneHeader {
    let mut s = dlgs::SceneHeader::still(2, 0);
    s.variant = dlgs::container::header::Variant::Scaffold;
    s.deform_model = dlgs::container::header::DeformModel::PaperLerp;
    s.n_static = 2;
    s.n_dynamic = 1;
    s.time_channels = 16;
    s.gop_length = 60;
    s.key_interval = 10;
    s.frame_count = 60;
    s.lang_levels = 3;
    s.lang_dims = 3;
    s
}

fn view() -> ViewRequest<'static> {
    ViewRequest { camera_center: [0.5, -1.0, 2.0], language: true, visible: None }
}

fn frame(c: &ScaffoldCanonical, m: &ScaffoldMlps) {
    let mut all = c.statics.clone();
    all.positions.extend_from_slice(&c.dynamics.positions);
    all.features.extend_from_slice(&c.dynamics.features);
    all.offsets.extend_from_slice(&c.dynamics.offsets);
    all.log_scalings.extend_from_slice(&c.dynamics.log_scalings);
    let g = neural_gaussians(&all.positions, &all, m, &view());
    let _ = g.to_gaussians();
}

fuzz_target!(|data: &[u8]| {
    let s = scene();
    let limits = dlgs::Limits::tiny();
    let (sel, body) = data.split_first().unwrap_or((&0, &[]));
    match sel % 5 {
        0 => {
            if let Ok(c) = dlgs::chunks::ancr::decode(body, 0, &s, &limits) {
                let _ = dlgs_decoder::scaffold::anchor_reach(&c.statics);
            } else if let Ok(f) = dlgs::chunks::rntc::decode(body, 0, &s, &limits) {
                // An anchor residual (§6.6.1), applied to anchors inside and outside its box.
                let mut c = ScaffoldCanonical::default();
                for set in [&mut c.statics, &mut c.dynamics] {
                    set.positions = vec![f.bound_min, [0.5; 3], [1e30, 0.0, -1e30]];
                    set.features = vec![0.5; 150];
                    set.offsets = vec![0.1; 90];
                    set.log_scalings = vec![-2.0; 18];
                }
                let _ = c.with_residual(&f);
            }
        }
        1 => {
            let base = dlgs::chunks::amlp::decode(body, 0, &s, &limits).ok();
            let any = dlgs::chunks::amlp::decode_any(body, 0, &s, &limits).ok();
            let resolved = any.and_then(|a| a.resolve(base.as_ref()));
            if let Some(m) = base.or(resolved) {
                let mut c = ScaffoldCanonical::default();
                for set in [&mut c.statics, &mut c.dynamics] {
                    set.positions = vec![[0.1, 0.2, 0.3]];
                    set.features = vec![0.5; 50];
                    set.offsets = vec![0.1; 30];
                    set.log_scalings = vec![-2.0; 6];
                }
                frame(&c, &m);
            }
        }
        2 => {
            if let Ok(d) = dlgs::chunks::adef::decode(body, 0, &limits) {
                let mut a = dlgs::model::scaffold::Anchors::default();
                a.positions = vec![[0.1, 0.2, 0.3]];
                a.features = vec![0.5; 50];
                a.offsets = vec![0.1; 30];
                a.log_scalings = vec![-2.0; 6];
                let f = dlgs::model::TimeFeatures { n: 1, keys: 7, channels: 16, data: vec![0.25; 7 * 16] };
                let _ = dlgs_decoder::scaffold::deform_anchors(&a, &f, 2, 0.5, &d.mlps, (d.bound_min, d.bound_max));
            }
        }
        4 => {
            if let Ok(c) = dlgs::chunks::ahac::decode(body, 0, &s, &limits) {
                let _ = dlgs_decoder::scaffold::anchor_reach(&c.statics);
            }
        }
        _ => {
            if let Ok(mut dec) = ScaffoldDecoder::new(std::io::Cursor::new(body), limits) {
                let _ = dec.frame_at(0.0, &view());
                let _ = dec.frame_in_view(0.0, [0.0; 3], false, &|p, _| vec![true; p.len()]);
                let gops = dec.scene().gop_count.min(4);
                for g in (0..gops).rev() {
                    let _ = dec.canonical(g);
                }
                if gops > 1 {
                    let _ = dec.frame_at(2.0, &view());
                }
            }
        }
    }
});
