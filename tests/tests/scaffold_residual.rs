//! Residual GOPs of the Scaffold-GS variant (format 1.17, issue 51): the fixture
//! `fixtures/scaffold_run` written with GOP 1 as the reference stores it (an `RNTC` over the
//! anchor groups feature and offsets, from `ntc_2D.b`, `ntc_3D.b` and `ntc_mlp`; view MLPs
//! inherited), decoded along the residual chain and compared with the reference decoder's
//! tensors (`reference_decode/gop1.safetensors`) and with the same fixture written intra; frames
//! on 1 and 2 threads; a longer chain decoded cold and in order; damaged residuals and a
//! disallowed residual mode give typed errors.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use dlgs::chunks::tfea::TfeaBody;
use dlgs::container::ResidualMode;
use dlgs::model::ntc::NtcField;
use dlgs::model::scaffold::{AnchorDeformation, Anchors, ScaffoldCanonical, ScaffoldMlps};
use dlgs::model::TimeFeatures;
use dlgs_decoder::scaffold::{NeuralGaussians, ScaffoldDecoder, ViewRequest};
use dlgs_encoder::scaffold::{scaffold_scene, ResidualViewMlps, ScaffoldWriter};
use dlgs_ingest::hac::{self, HacGop, HacLimits};
use safetensors::SafeTensors;

/// Largest |ours - reference| of GOP 1's decoded features and offsets (measured 6.0e-7 for
/// features, 2.4e-7 for offsets: our
/// RNTC sums the MLP from the bias with fused multiply-adds and divides by the weight sum,
/// torch multiplies by its reciprocal and uses SLEEF's `expf` in the gate).
const CANONICAL_TOL: f32 = 1e-6;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scaffold_run")
}

fn tensor(file: &str, name: &str) -> Vec<f32> {
    let bytes = std::fs::read(fixture().join("reference_decode").join(file)).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let t = st.tensor(name).unwrap();
    assert_eq!(t.dtype(), safetensors::Dtype::F32, "{name}");
    t.data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

/// Both GOPs as `dlgs-ingest` decodes them (once per test binary).
fn gops() -> &'static [HacGop; 2] {
    static G: OnceLock<[HacGop; 2]> = OnceLock::new();
    G.get_or_init(|| {
        let dir = |g| fixture().join(format!("gop{g}_fixture/compression/best"));
        let g0 = hac::read_gop(&dir(0), None, HacLimits::default()).unwrap();
        let g1 = hac::read_gop(&dir(1), Some(&g0), HacLimits::default()).unwrap();
        [g0, g1]
    })
}

fn view_mlps(g: usize) -> ScaffoldMlps {
    gops()[0].mlps.view_mlps(Some(&gops()[g].mlps)).unwrap()
}

fn dynamic(g: usize) -> (AnchorDeformation, TfeaBody) {
    let m = &gops()[g].mlps;
    let n = gops()[0].anchors.len() - gops()[0].n_static;
    let f = TimeFeatures {
        n,
        keys: 7,
        channels: 16,
        data: tensor(&format!("gop{g}.safetensors"), "temporal_feat"),
    };
    let d = AnchorDeformation {
        bound_min: m.bounds.0,
        bound_max: m.bounds.1,
        mlps: m.deform.clone(),
    };
    (d, TfeaBody::Exact(f))
}

/// GOP 1's NTC as an `RNTC` field over anchor groups.
fn field() -> NtcField {
    let g1 = &gops()[1];
    let ntc = g1.ntc.as_ref().unwrap();
    hac::ntc::to_field(
        &ntc.plane_bits,
        &ntc.gate_bits,
        g1.mlps.ntc.as_ref().unwrap(),
        g1.bound_min,
        g1.bound_max,
    )
    .unwrap()
}

/// The fixture as a `.dlgs`: GOP 0 intra, then `gops` - 1 GOPs each GOP 1's residual (a chain
/// of `gops` - 1 residuals; the fixture itself has 2), or with `residual` false both GOPs intra
/// with the anchors `dlgs-ingest` decodes.
fn file(residual: bool, gops_n: u32) -> Vec<u8> {
    let g = gops();
    let ns = g[0].n_static;
    let mut scene = scaffold_scene(
        ns as u32,
        (g[0].anchors.len() - ns) as u32,
        true,
        30,
        60,
        10,
        60 * gops_n,
    );
    if residual {
        scene.residual_mode = ResidualMode::Sequential;
    }
    let mut w = ScaffoldWriter::new(Vec::new(), scene, 3).unwrap();
    let (d, f) = dynamic(0);
    w.push_gop(
        &ScaffoldCanonical::split_at(g[0].anchors.clone(), ns),
        &view_mlps(0),
        Some((&d, &f)),
    )
    .unwrap();
    let (d, f) = dynamic(1);
    for _ in 1..gops_n {
        if residual {
            w.push_residual_gop(&field(), ResidualViewMlps::Inherit, Some((&d, &f)))
                .unwrap();
        } else {
            w.push_gop(
                &ScaffoldCanonical::split_at(g[1].anchors.clone(), ns),
                &view_mlps(1),
                Some((&d, &f)),
            )
            .unwrap();
        }
    }
    w.finish().unwrap()
}

fn decoder(bytes: Vec<u8>) -> ScaffoldDecoder<std::io::Cursor<Vec<u8>>> {
    ScaffoldDecoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap()
}

fn joined(c: &ScaffoldCanonical, pick: fn(&Anchors) -> &Vec<f32>) -> Vec<f32> {
    let mut v = pick(&c.statics).clone();
    v.extend_from_slice(pick(&c.dynamics));
    v
}

fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// GOP 1 decoded through its `RNTC` equals the reference decoder's GOP-1 tensors within
/// `CANONICAL_TOL`; its positions and log-scalings are GOP 0's decoded ones exactly; the file
/// is far smaller than written intra.
#[test]
fn gop1_canonical_matches_the_reference_decode() {
    let bytes = file(true, 2);
    let mut dec = decoder(bytes.clone());
    let c0 = dec.canonical(0).unwrap();
    let c1 = dec.canonical(1).unwrap();
    let df = max_diff(
        &joined(&c1, |a| &a.features),
        &tensor("gop1.safetensors", "feat"),
    );
    let doff = max_diff(
        &joined(&c1, |a| &a.offsets),
        &tensor("gop1.safetensors", "offsets"),
    );
    println!("GOP 1 vs reference_decode: max |diff| feat {df:.3e}, offsets {doff:.3e}");
    assert!(df <= CANONICAL_TOL && doff <= CANONICAL_TOL, "{df} {doff}");
    assert!(joined(&c1, |a| &a.log_scalings) == joined(&c0, |a| &a.log_scalings));
    assert_eq!(c1.statics.positions, c0.statics.positions);
    assert_eq!(c1.dynamics.positions, c0.dynamics.positions);
    // The residual really changed something, and the plain row-major evaluation (§6.6.4 as
    // written) gives the lanes' rows bit for bit.
    assert!(max_diff(&joined(&c1, |a| &a.features), &joined(&c0, |a| &a.features)) > 1e-3);
    let f = field();
    let rows = f.residuals_at(&c0.statics.positions[..64]);
    for (i, p) in c0.statics.positions[..64].iter().enumerate() {
        assert_eq!(&rows[i * 80..(i + 1) * 80], f.residual_at(*p).as_slice());
    }
    // GOP 1's view MLPs are GOP 0's (the fixture's mlp_language is the same in both GOPs).
    let g1 = dec.gop(1).unwrap();
    assert_eq!(g1.mlps, view_mlps(0));
    let intra = file(false, 2);
    println!(
        "file bytes: residual {}, intra {}",
        bytes.len(),
        intra.len()
    );
    // GOP 1's ANCR (752 kB) and AMLP (81 kB) become a 55 kB RNTC.
    assert!(bytes.len() + 700_000 < intra.len());
}

fn frame(
    dec: &mut ScaffoldDecoder<std::io::Cursor<Vec<u8>>>,
    t: f64,
    cam: [f32; 3],
) -> NeuralGaussians {
    let req = ViewRequest {
        camera_center: cam,
        language: true,
        visible: None,
    };
    dec.frame_at(t, &req).unwrap()
}

const CAMERAS: [[f32; 3]; 2] = [[0.9, 0.3, -1.1], [-0.4, 0.8, 1.2]];
/// GOP 1's times: its first frame, between frames, its last frame.
const TIMES: [f64; 3] = [2.0, 2.0 + 25.5 / 30.0, 2.0 + 59.0 / 30.0];

/// GOP 1's frames at several times are the same bits on 1 and 2 threads.
#[test]
fn residual_frames_are_the_same_on_one_and_two_threads() {
    let bytes = file(true, 2);
    let run = |threads: usize| -> Vec<NeuralGaussians> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut dec = decoder(bytes.clone());
            let mut out = Vec::new();
            for t in TIMES {
                for cam in CAMERAS {
                    out.push(frame(&mut dec, t, cam));
                }
            }
            out
        })
    };
    let a = run(1);
    assert!(a.iter().all(|f| f.len() > 1000));
    assert!(a == run(2));
}

/// The residual file's GOP-1 frames against the same fixture written intra (the anchors
/// `dlgs-ingest` decodes with the reference's arithmetic): the same children, and every value
/// within `FRAME_TOL` (measured 4.3e-7).
#[test]
fn residual_and_intra_frames_agree() {
    const FRAME_TOL: f32 = 2e-6;
    let mut r = decoder(file(true, 2));
    let mut i = decoder(file(false, 2));
    let mut worst = 0f32;
    for t in TIMES {
        for cam in CAMERAS {
            let (a, b) = (frame(&mut r, t, cam), frame(&mut i, t, cam));
            assert_eq!(a.source, b.source, "t {t}: the same children");
            let flat3 = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
            let rot = |v: &[[f32; 4]]| v.iter().flatten().copied().collect::<Vec<f32>>();
            for d in [
                max_diff(&flat3(&a.positions), &flat3(&b.positions)),
                max_diff(&flat3(&a.scales), &flat3(&b.scales)),
                max_diff(&rot(&a.rotations), &rot(&b.rotations)),
                max_diff(&flat3(&a.colors), &flat3(&b.colors)),
                max_diff(&a.opacity, &b.opacity),
                max_diff(&a.lang_opacity, &b.lang_opacity),
                max_diff(&a.lang, &b.lang),
            ] {
                worst = worst.max(d);
            }
        }
    }
    println!("residual vs intra frames of GOP 1: max |diff| {worst:.3e}");
    assert!(worst <= FRAME_TOL, "{worst}");
}

/// A chain of 3 residuals (GOP 0 + 3 x GOP 1's field): GOP 3 decoded cold equals GOP 3 decoded
/// after 0, 1, 2 and after a seek back to 1, and equals the field applied three times.
#[test]
fn a_residual_chain_decodes_the_same_cold_in_order_and_after_seeks() {
    let bytes = file(true, 4);
    let cold = decoder(bytes.clone()).canonical(3).unwrap();
    let mut dec = decoder(bytes.clone());
    for g in 0..4 {
        dec.gop(g).unwrap();
    }
    assert_eq!(dec.canonical(3).unwrap(), cold);
    dec.gop(1).unwrap();
    dec.gop(0).unwrap();
    assert_eq!(dec.gop(3).unwrap().canonical, cold);
    let f = field();
    let mut c = dec.canonical(0).unwrap();
    for _ in 0..3 {
        c = c.with_residual(&f).unwrap();
    }
    assert_eq!(c, cold);
}

/// The in-order decoder over a plain `Read` (`dlgs play` from stdin) gives the random-access
/// decoder's GOPs along a residual chain and the same frames, bit for bit; a stream cut inside
/// a GOP fails at that GOP with a typed error after the GOPs before it.
#[test]
fn the_stream_decoder_gives_the_random_access_gops_and_frames() {
    use dlgs_decoder::scaffold::ScaffoldStreamDecoder;
    let bytes = file(true, 4);
    let mut dec = decoder(bytes.clone());
    let mut stream =
        ScaffoldStreamDecoder::new(std::io::Cursor::new(bytes.clone()), dlgs::Limits::default())
            .unwrap();
    let req = ViewRequest {
        camera_center: CAMERAS[1],
        language: true,
        visible: None,
    };
    for g in 0..4 {
        let s = stream.next_gop().unwrap().expect("4 GOPs");
        let r = dec.gop(g).unwrap();
        assert_eq!(s.index, g);
        assert_eq!((&s.canonical, &s.mlps), (&r.canonical, &r.mlps), "GOP {g}");
        assert_eq!(s.frame(3, 0.25, &req), r.frame(3, 0.25, &req), "GOP {g}");
    }
    assert!(stream.next_gop().unwrap().is_none());
    let cut = bytes[..bytes.len() - 1000].to_vec();
    let mut stream =
        ScaffoldStreamDecoder::new(std::io::Cursor::new(cut), dlgs::Limits::default()).unwrap();
    for _ in 0..3 {
        stream.next_gop().unwrap().expect("the GOPs before the cut");
    }
    let e = stream.next_gop().unwrap_err();
    assert!(e.to_string().contains("runcated"), "{e}");
}

/// Re-frames chunk `ty`'s payload after `edit` (the CRC made valid again, the length kept).
fn edit_chunk(bytes: &[u8], ty: &[u8; 4], edit: impl Fn(&mut [u8])) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let at = b.windows(4).position(|w| w == ty).unwrap();
    let len = u64::from_le_bytes(b[at + 12..at + 20].try_into().unwrap()) as usize;
    let p = at + 24;
    edit(&mut b[p..p + len]);
    let crc = crc32c::crc32c(&b[p..p + len]);
    b[p + len..p + len + 4].copy_from_slice(&crc.to_le_bytes());
    b
}

fn decode_gop1(b: Vec<u8>) -> dlgs::Result<()> {
    let mut dec = ScaffoldDecoder::new(std::io::Cursor::new(b), dlgs::Limits::default())?;
    dec.gop(1).map(|_| ())
}

/// Damaged `RNTC`s in a Scaffold-GS file give typed errors, never a panic.
#[test]
fn damaged_anchor_residuals_give_typed_errors() {
    let bytes = file(true, 2);
    decode_gop1(bytes.clone()).unwrap();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        // A 3DGS group bit (sh_dc) in an anchor residual.
        (
            "group bit 3",
            edit_chunk(&bytes, b"RNTC", |p| p[0] = 0b1011),
            "Payload",
        ),
        // log_scaling added: 86 outputs, the MLP stores 80.
        (
            "groups 0b111",
            edit_chunk(&bytes, b"RNTC", |p| p[0] = 0b111),
            "Payload",
        ),
        (
            "sets 4",
            edit_chunk(&bytes, b"RNTC", |p| p[1] = 4),
            "Payload",
        ),
        (
            "levels 0",
            edit_chunk(&bytes, b"RNTC", |p| p[5] = 0),
            "Payload",
        ),
        // bmax.x below bmin.x.
        (
            "box",
            edit_chunk(&bytes, b"RNTC", |p| {
                p[20..24].copy_from_slice(&(-9f32).to_le_bytes())
            }),
            "Payload",
        ),
        // A coded segment's first word changed: its bit count no longer matches.
        (
            "segment bits",
            edit_chunk(&bytes, b"RNTC", |p| {
                let s = 36 + 4 * 4 + 4;
                let first = (0..13)
                    .map(|i| {
                        u32::from_le_bytes(p[s + 8 * i + 4..s + 8 * i + 8].try_into().unwrap())
                    })
                    .position(|n| n > 0)
                    .unwrap();
                let skip: usize = (0..first)
                    .map(|i| {
                        u32::from_le_bytes(p[s + 8 * i + 4..s + 8 * i + 8].try_into().unwrap())
                            as usize
                    })
                    .sum();
                p[s + 8 * 13 + skip] ^= 0xA5;
            }),
            "Payload",
        ),
        // The weights' zstd frame one byte short (`wlen` - 1).
        (
            "weights",
            edit_chunk(&bytes, b"RNTC", |p| {
                let n = p.len();
                let k = (0..n - 4)
                    .rev()
                    .find(|&k| {
                        u32::from_le_bytes(p[k..k + 4].try_into().unwrap()) as usize == n - k - 4
                    })
                    .unwrap();
                let w = (n - k - 5) as u32;
                p[k..k + 4].copy_from_slice(&w.to_le_bytes());
            }),
            "Decompress",
        ),
    ];
    for (what, b, kind) in cases {
        let e = decode_gop1(b).unwrap_err();
        assert_eq!(e.name(), kind, "{what}: {e}");
    }
    // A flipped byte with the CRC left alone, and every cut of the residual GOP.
    let at = bytes.windows(4).position(|w| w == b"RNTC").unwrap();
    let mut b = bytes.clone();
    b[at + 60] ^= 1;
    assert_eq!(decode_gop1(b).unwrap_err().name(), "PayloadCrc");
    for cut in (at..bytes.len()).step_by(997) {
        assert!(decode_gop1(bytes[..cut].to_vec()).is_err());
    }
    // A language-only AMLP is valid only in a residual GOP.
    let scene = ScaffoldDecoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default())
        .unwrap()
        .scene()
        .clone();
    let lang = view_mlps(0).language.unwrap();
    let p = dlgs::chunks::amlp::encode_language_only(&lang, &scene, 3).unwrap();
    let e = dlgs::chunks::amlp::decode(&p, 0, &scene, &dlgs::Limits::default()).unwrap_err();
    assert_eq!(e.name(), "Payload", "{e}");
    let any = dlgs::chunks::amlp::decode_any(&p, 0, &scene, &dlgs::Limits::default()).unwrap();
    let resolved = any.resolve(Some(&view_mlps(0))).unwrap();
    assert_eq!(resolved, view_mlps(0));
}

/// A Scaffold-GS header with residual mode parallel (not defined for the variant) is refused
/// by the writer (`InvalidInput`) and by the reader (`Payload` of `HEAD`).
#[test]
fn a_parallel_scaffold_header_is_refused() {
    let bytes = file(true, 2);
    let mut scene = decoder(bytes.clone()).scene().clone();
    scene.residual_mode = ResidualMode::Parallel;
    let e = ScaffoldWriter::new(Vec::new(), scene, 3).err().unwrap();
    assert!(matches!(e, dlgs::Error::Input(_)), "{e}");
    // HEAD byte 1 = 2 (with 2 GOPs, GOP 1's reference GOP is 0 in both modes, so the index
    // stays valid and the header rule is what refuses it).
    let b = edit_chunk(&bytes, b"HEAD", |p| p[1] = 2);
    let e = ScaffoldDecoder::new(std::io::Cursor::new(b), dlgs::Limits::default())
        .err()
        .unwrap();
    assert_eq!(e.name(), "Payload", "{e}");
    // A residual GOP in an intra scene is refused by the writer.
    let mut w =
        ScaffoldWriter::new(Vec::new(), decoder(file(false, 2)).scene().clone(), 3).unwrap();
    let (d, f) = dynamic(0);
    w.push_gop(
        &ScaffoldCanonical::split_at(gops()[0].anchors.clone(), gops()[0].n_static),
        &view_mlps(0),
        Some((&d, &f)),
    )
    .unwrap();
    let e = w
        .push_residual_gop(&field(), ResidualViewMlps::Inherit, Some((&d, &f)))
        .unwrap_err();
    assert!(matches!(e, dlgs::Error::Input(_)), "{e}");
}

/// Timing (not asserted; `cargo test --release -p dlgs-tests --test scaffold_residual --
/// --ignored --nocapture`): GOP 1's canonical anchors from GOP 0's (the RNTC decoded and
/// applied), and frames of GOP 1 through `frame_in_view` (every anchor kept), median of 15.
#[test]
#[ignore]
fn timing_of_residual_gops_and_frames() {
    use std::time::Instant;
    let bytes = file(true, 2);
    let mut dec = decoder(bytes);
    dec.canonical(0).unwrap();
    let t0 = Instant::now();
    dec.canonical(1).unwrap();
    println!(
        "GOP 1 canonical from GOP 0's (RNTC decode + apply): {:.1} ms",
        t0.elapsed().as_secs_f64() * 1e3
    );
    dec.gop(1).unwrap();
    let all = |p: &[[f32; 3]], _: &[f32]| vec![true; p.len()];
    let mut ms = Vec::new();
    let mut anchors_ms = Vec::new();
    let mut reach_ms = Vec::new();
    for i in 0..15 {
        let t = 2.0 + i as f64 * 0.13;
        let s = Instant::now();
        let (f, kept) = dec.frame_in_view(t, CAMERAS[0], true, &all).unwrap();
        ms.push(s.elapsed().as_secs_f64() * 1e3);
        assert_eq!(kept, 2400);
        assert!(f.len() > 1000);
        let gop = dec.gop(1).unwrap();
        let tp = dec.scene().locate(t).unwrap();
        let s = Instant::now();
        let (_, state) = gop.anchors_at(tp.key, tp.delta);
        anchors_ms.push(s.elapsed().as_secs_f64() * 1e3);
        let s = Instant::now();
        let reach = gop.reach(&state);
        reach_ms.push(s.elapsed().as_secs_f64() * 1e3);
        assert_eq!(reach, dlgs_decoder::scaffold::anchor_reach(&state));
    }
    ms.sort_by(f64::total_cmp);
    anchors_ms.sort_by(f64::total_cmp);
    reach_ms.sort_by(f64::total_cmp);
    println!(
        "GOP 1 frame_in_view (2,400 anchors kept): median {:.2} ms (min {:.2}); anchors_at: median {:.3} ms (min {:.3}); reach: median {:.3} ms (min {:.3})",
        ms[7], ms[0], anchors_ms[7], anchors_ms[0], reach_ms[7], reach_ms[0]
    );
}

/// The chunk rules of a residual GOP (format-spec §3.3, §6.9): an `ANCR` in it is `Order`, no
/// `RNTC` is `MissingChunk`; an `RNTC` in an intra GOP is ignored.
#[test]
fn residual_gop_chunk_rules() {
    use dlgs::chunks::{adef, amlp, ancr, rntc, tfea};
    use dlgs::container::{ChunkType, Writer, FLAG_MUST_UNDERSTAND};
    let g = gops();
    let scene = decoder(file(true, 2)).scene().clone();
    let c0 = ScaffoldCanonical::split_at(g[0].anchors.clone(), g[0].n_static);
    let (d, f) = dynamic(1);
    let build = |scene: &dlgs::container::SceneHeader, gop1: &[ChunkType]| -> Vec<u8> {
        let mut w = Writer::new(Vec::new(), scene.clone()).unwrap();
        for kinds in [&[ChunkType::ANCR][..], gop1] {
            w.begin_gop().unwrap();
            for &ty in kinds
                .iter()
                .chain(&[ChunkType::AMLP, ChunkType::ADEF, ChunkType::TFEA])
            {
                let p = match ty {
                    ChunkType::ANCR => ancr::encode(&c0, scene, 3).unwrap(),
                    ChunkType::RNTC => rntc::encode(&field(), scene, 3).unwrap(),
                    ChunkType::AMLP => amlp::encode(&view_mlps(0), scene, 3).unwrap(),
                    ChunkType::ADEF => adef::encode(&d, 3).unwrap(),
                    _ => tfea::encode(&f, 3).unwrap(),
                };
                w.gop_chunk(ty, FLAG_MUST_UNDERSTAND, &p).unwrap();
            }
        }
        w.finish().unwrap()
    };
    let e = decode_gop1(build(&scene, &[ChunkType::ANCR])).unwrap_err();
    assert_eq!(e.name(), "Order", "{e}");
    let e = decode_gop1(build(&scene, &[])).unwrap_err();
    assert_eq!(e.name(), "MissingChunk", "{e}");
    decode_gop1(build(&scene, &[ChunkType::RNTC])).unwrap();
    // Intra scene: GOP 1 with ANCR and a stray RNTC decodes to its ANCR.
    let mut intra = scene.clone();
    intra.residual_mode = ResidualMode::Intra;
    let mut dec = decoder(build(&intra, &[ChunkType::ANCR, ChunkType::RNTC]));
    assert_eq!(dec.canonical(1).unwrap(), c0);
}
