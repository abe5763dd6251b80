//! The encoder's context fit for raw Scaffold-GS anchors (`dlgs_encoder::scaffold_fit`, issue
//! 68) on arbitrary anchors: a few anchors whose every value (positions included) comes from
//! the input, NaN, infinities, huge and subnormal values among them, and arbitrary steps. The
//! fit must return a clear error or a payload that decodes to exactly the anchors it coded.
#![no_main]
use dlgs::model::hac_context::GridShape;
use dlgs::model::scaffold::{Anchors, ScaffoldCanonical, FEAT_DIM, N_OFFSETS, SCALING_DIM};
use dlgs_encoder::scaffold_fit::{fit_anchors, ContextFitSettings};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.len() < 5 {
        return;
    }
    let (head, body) = data.split_at(5);
    let n = 1 + head[0] as usize % 6;
    let n_static = head[1] as usize % (n + 1);
    // Steps 1e-4 .. about 1e4, or a raw value from the input (zero, negative, NaN).
    let step = |b: u8| if b == 255 { f32::NAN } else { 10f32.powf(b as f32 / 32.0 - 4.0) };
    let steps = [step(head[2]), step(head[3]), step(head[4])];
    let mut words = body.chunks(4).map(|c| {
        let mut w = [0u8; 4];
        w[..c.len()].copy_from_slice(c);
        f32::from_le_bytes(w)
    });
    let mut next = || words.next().unwrap_or(0.25);
    let mut a = Anchors::default();
    for _ in 0..n {
        a.positions.push([next(), next(), next()]);
        a.features.extend((0..FEAT_DIM).map(|_| next()));
        a.log_scalings.extend((0..SCALING_DIM).map(|_| next()));
        a.offsets.extend((0..3 * N_OFFSETS).map(|_| next()));
    }
    let c = ScaffoldCanonical::split_at(a, n_static);
    let shape = |resolutions: Vec<u32>| GridShape { resolutions, log2_table: 6, features: 2 };
    let s = ContextFitSettings {
        iterations: 3,
        hidden: 2,
        grids: Some((shape(vec![3, 5]), shape(vec![4]))),
        zstd_level: 1,
        ..ContextFitSettings::new(steps)
    };
    if let Ok((h, rep)) = fit_anchors(&c, &s, |_, _| {}) {
        let (p, sizes) = dlgs::chunks::ahac::encode_payload(&h, s.zstd_level).expect("a fitted model encodes");
        assert_eq!(sizes, rep.sizes);
        let mut scene = dlgs::SceneHeader::still(1, 0);
        scene.variant = dlgs::container::header::Variant::Scaffold;
        scene.n_static = h.n_static;
        scene.n_dynamic = h.n_dynamic;
        let (back, _) = dlgs::chunks::ahac::decode_full(&p, 0, &scene, &dlgs::Limits::default())
            .expect("what the encoder wrote decodes");
        assert_eq!(back, h);
    }
});
