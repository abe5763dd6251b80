//! `AHAC` (format-spec §6.13): the fixture's GOP 0 re-packed HAC-style from the reference's
//! own integers, decoded symbol for symbol, the same bits on 1 and 2 threads, within one step
//! ulp of the reference decoder's values; a hand-sized chunk; damaged payloads give errors.

use std::path::{Path, PathBuf};
use std::time::Instant;

use bitvec::prelude::*;
use dlgs::chunks::ahac::{self, HacAnchors};
use dlgs::container::SceneHeader;
use dlgs::model::hac_context::{GridShape, HacContext, CONTEXT_OUT};
use dlgs::model::scaffold::ScaffoldCanonical;
use dlgs::{Error, FormatErrorKind, Limits};
use dlgs_encoder::scaffold::scaffold_scene;
use dlgs_ingest::hac::{self, HacGop, HacLimits};

fn gop_dir(g: usize) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(format!(
        "fixtures/scaffold_run/gop{g}_fixture/compression/best"
    ))
}

fn gop0() -> HacGop {
    hac::read_gop(&gop_dir(0), None, HacLimits::default()).unwrap()
}

fn scene_of(h: &HacAnchors) -> SceneHeader {
    scaffold_scene(h.n_static, h.n_dynamic, true, 30, 60, 10, 60)
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

fn bits(c: &ScaffoldCanonical) -> Vec<u32> {
    [&c.statics, &c.dynamics]
        .iter()
        .flat_map(|a| {
            a.positions
                .iter()
                .flatten()
                .chain(&a.features)
                .chain(&a.offsets)
                .chain(&a.log_scalings)
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        })
        .collect()
}

fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// The fixture's GOP 0: symbols identical to the reference's integers, positions bit-exact,
/// values within a few ulps of the step of the reference decoder's, the same bits on 1 and 2
/// threads, and smaller than the reference's files for the same anchors.
#[test]
fn fixture_gop0_round_trips_in_symbols() {
    let g = gop0();
    let h = g.hac_anchors().expect("GOP 0 carries its anchors");
    let scene = scene_of(&h);
    let (payload, sizes) = ahac::encode(&h, &scene, 19).unwrap();
    println!("AHAC {} bytes: {sizes:?}", payload.len());
    let reference_bytes = 14_528 + 3_262 + 50_787 + 16_094 + 31_786 + 4 * 27_375;
    assert!(payload.len() < reference_bytes, "{} bytes", payload.len());

    let run = |threads| {
        in_pool(threads, || {
            let t = Instant::now();
            let r = ahac::decode_full(&payload, 0, &scene, &Limits::default()).unwrap();
            println!(
                "decode on {threads} thread(s): {:.1} ms",
                t.elapsed().as_secs_f64() * 1e3
            );
            r
        })
    };
    let (d1, c1) = run(1);
    let (d2, c2) = run(2);
    assert_eq!(d1, h, "the chunk's content, symbols included");
    assert_eq!(d2, h);
    assert_eq!(bits(&c1), bits(&c2), "1 and 2 threads");

    // Against the reference decoder's values (the ingest's).
    let all = |c: &ScaffoldCanonical, f: fn(&dlgs::model::scaffold::Anchors) -> &Vec<f32>| {
        let mut v = f(&c.statics).clone();
        v.extend_from_slice(f(&c.dynamics));
        v
    };
    let pos: Vec<f32> = c1
        .statics
        .positions
        .iter()
        .chain(&c1.dynamics.positions)
        .flatten()
        .copied()
        .collect();
    let ref_pos: Vec<f32> = g.anchors.positions.iter().flatten().copied().collect();
    assert_eq!(pos, ref_pos, "positions are the reference's bits");
    let df = max_diff(&all(&c1, |a| &a.features), &g.anchors.features);
    let ds = max_diff(&all(&c1, |a| &a.log_scalings), &g.anchors.log_scalings);
    let dof = max_diff(&all(&c1, |a| &a.offsets), &g.anchors.offsets);
    println!("max |ours - reference|: feature {df:e}, log-scaling {ds:e}, offsets {dof:e}");
    // One ulp of Q times the integer: the integers reach ~10^4 for the log-scalings.
    assert!(df <= 2e-6 && ds <= 2e-6 && dof <= 2e-6);
    // And `HacAnchors::canonical` (what the encoder reports) is the decoder's result.
    assert_eq!(bits(&h.canonical()), bits(&c1));
}

/// A hand-sized chunk: 5 anchors (3 static), batches of 2, one-level grids of 4 entries.
pub fn tiny_hac() -> HacAnchors {
    tiny_hac_n(3, 2)
}

fn tiny_hac_n(n_static: u32, n_dynamic: u32) -> HacAnchors {
    let mut rng = fastrand::Rng::with_seed(11);
    let shape = |log2| GridShape {
        resolutions: vec![4],
        log2_table: log2,
        features: 2,
    };
    let (grid3, grid2) = (shape(3), shape(4));
    let levels = HacContext::level_bits(&grid3, &grid2)
        .into_iter()
        .map(|n| (0..n).map(|_| rng.bool()).collect::<BitVec<u64, Lsb0>>())
        .collect();
    let inputs = 2 + 3 * 2;
    let hidden = 3;
    let mut w = |n: usize, s: f32| (0..n).map(|_| (rng.f32() - 0.5) * s).collect::<Vec<f32>>();
    let context = HacContext {
        grid3,
        grid2,
        bound_min: [-1.0, 0.0, 2.0],
        bound_max: [1.0, 0.5, 3.0],
        q_base: [1.0, 0.001, 0.2],
        levels,
        hidden,
        w1: w(inputs * hidden, 2.0),
        b1: w(hidden, 1.0),
        w2: w(hidden * CONTEXT_OUT, 1.0),
        b2: w(CONTEXT_OUT, 1.0),
    };
    let n = (n_static + n_dynamic) as usize;
    let quantized = (0..n)
        .map(|_| [rng.u16(..), rng.u16(..), rng.u16(..)])
        .collect();
    let mut s = |c: usize| (0..n * c).map(|_| rng.i32(-3..4)).collect::<Vec<i32>>();
    HacAnchors {
        n_static,
        n_dynamic,
        batch: 2,
        context,
        quantized,
        symbols: [s(50), s(6), s(30)],
    }
}

#[test]
fn a_tiny_chunk_round_trips_and_a_zero_step_decodes_to_zeros() {
    let h = tiny_hac();
    let scene = scene_of(&h);
    let (p, _) = ahac::encode(&h, &scene, 19).unwrap();
    let (d, c) = ahac::decode_full(&p, 0, &scene, &Limits::tiny()).unwrap();
    assert_eq!(d, h);
    assert_eq!(bits(&c), bits(&h.canonical()));

    // tanh(adj) = -1: Q = 0 for the offsets; every offset decodes to 0, symbols still exact.
    let mut z = h.clone();
    z.context.b2[CONTEXT_OUT - 1] = -1e6;
    let (p, _) = ahac::encode(&z, &scene, 19).unwrap();
    let (d, c) = ahac::decode_full(&p, 0, &scene, &Limits::tiny()).unwrap();
    assert_eq!(d.symbols, z.symbols);
    assert!(c
        .statics
        .offsets
        .iter()
        .chain(&c.dynamics.offsets)
        .all(|&v| v == 0.0));
    assert!(c.statics.features.iter().any(|&v| v != 0.0));

    // One symbol value for a whole stream: no words.
    let mut one = h.clone();
    one.symbols[1].iter_mut().for_each(|v| *v = 2);
    let (p, _) = ahac::encode(&one, &scene, 19).unwrap();
    assert_eq!(
        ahac::decode_full(&p, 0, &scene, &Limits::tiny()).unwrap().0,
        one
    );
}

fn kind(e: &Error) -> Option<&FormatErrorKind> {
    e.format_kind()
}

/// Byte offset of batch header `k` (0-based over batches x attributes) in `tiny_hac`'s payload:
/// the streams follow the headers and end the payload.
fn batch_header_at(p: &[u8], k: usize, h: &HacAnchors) -> usize {
    let streams: usize = {
        let scene = scene_of(h);
        let (_, sizes) = ahac::encode(h, &scene, 19).unwrap();
        sizes.streams.iter().sum()
    };
    let nb = (h.n_static + h.n_dynamic).div_ceil(h.batch) as usize;
    p.len() - streams - 36 * nb + 12 * k
}

#[test]
fn invalid_tiny_chunks_give_typed_errors() {
    let h = tiny_hac();
    let scene = scene_of(&h);
    let (p, _) = ahac::encode(&h, &scene, 19).unwrap();
    let payload_err = |q: &[u8], what: &str| {
        let e = ahac::decode_full(q, 0, &scene, &Limits::tiny()).unwrap_err();
        assert!(
            matches!(kind(&e), Some(FormatErrorKind::Payload { .. })),
            "{what}: {e}"
        );
    };
    // Truncated anywhere: an error (Truncated inside a field, Payload/Decompress otherwise).
    for cut in 0..p.len() {
        assert!(
            ahac::decode_full(&p[..cut], 0, &scene, &Limits::tiny()).is_err(),
            "cut {cut}"
        );
    }
    assert!(matches!(
        kind(&ahac::decode_full(&p[..10], 0, &scene, &Limits::tiny()).unwrap_err()),
        Some(FormatErrorKind::Truncated { .. })
    ));
    // Trailing bytes.
    let mut q = p.clone();
    q.extend_from_slice(&[0; 4]);
    payload_err(&q, "trailing bytes");
    // Batch 0, feature: alphabet over the limit.
    let at = batch_header_at(&p, 0, &h);
    let mut q = p.clone();
    q[at + 4..at + 8].copy_from_slice(&(1i32 << 20).to_le_bytes());
    payload_err(&q, "alphabet over 2^16");
    // hi < lo.
    let mut q = p.clone();
    q[at + 4..at + 8].copy_from_slice(&(-100i32).to_le_bytes());
    payload_err(&q, "hi < lo");
    // bytes not a multiple of 4.
    let mut q = p.clone();
    let b = u32::from_le_bytes(q[at + 8..at + 12].try_into().unwrap());
    q[at + 8..at + 12].copy_from_slice(&(b + 1).to_le_bytes());
    assert!(ahac::decode_full(&q, 0, &scene, &Limits::tiny()).is_err());
    payload_err(&q, "bytes not a multiple of 4");
    // Counts that disagree with the scene; batch 0; output width not 175; reserved byte.
    for (off, val, what) in [(0usize, 9u32, "n_static"), (8, 0, "batch 0")] {
        let mut q = p.clone();
        q[off..off + 4].copy_from_slice(&val.to_le_bytes());
        payload_err(&q, what);
    }
    let mut q = p.clone();
    q[55] = 1;
    payload_err(&q, "reserved byte");
    // Non-finite box.
    let mut q = p.clone();
    q[12..16].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(ahac::decode_full(&q, 0, &scene, &Limits::tiny()).is_err());
}

/// Every single-byte change and many random multi-byte changes of the tiny payload: an error
/// or a decode, never a panic (the fuzz target `scaffold_payloads` runs this at scale).
#[test]
fn damaged_ahac_payloads_never_panic() {
    let h = tiny_hac();
    let scene = scene_of(&h);
    let (p, _) = ahac::encode(&h, &scene, 19).unwrap();
    let mut rng = fastrand::Rng::with_seed(5);
    let mut errors = 0;
    let mut total = 0;
    for i in 0..p.len() {
        for v in [0u8, 0xFF, p[i] ^ 1, p[i] ^ 0x80] {
            let mut q = p.clone();
            q[i] = v;
            total += 1;
            errors += ahac::decode_full(&q, 0, &scene, &Limits::tiny()).is_err() as usize;
        }
    }
    for _ in 0..3000 {
        let mut q = p.clone();
        for _ in 0..rng.usize(1..6) {
            let i = rng.usize(..q.len());
            q[i] = rng.u8(..);
        }
        q.truncate(rng.usize(q.len() / 2..=q.len()));
        total += 1;
        errors += ahac::decode_full(&q, 0, &scene, &Limits::tiny()).is_err() as usize;
    }
    println!("{errors} of {total} damaged payloads rejected, the rest decoded");
    assert!(errors > total / 4);
}

/// The fuzz seed of `fuzz_targets/scaffold_payloads.rs` (selector 4: an `AHAC` payload for its
/// scene of 2 static + 1 dynamic anchors); written with `DLGS_WRITE_FUZZ_SEEDS=1`.
#[test]
fn ahac_fuzz_seed() {
    let h = tiny_hac_n(2, 1);
    let scene = scene_of(&h);
    let (p, _) = ahac::encode(&h, &scene, 19).unwrap();
    assert_eq!(
        ahac::decode_full(&p, 0, &scene, &Limits::tiny()).unwrap().0,
        h
    );
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus/scaffold_payloads/seed-ahac");
    let mut seed = vec![4u8];
    seed.extend_from_slice(&p);
    if std::env::var("DLGS_WRITE_FUZZ_SEEDS").is_ok() {
        std::fs::write(&path, &seed).unwrap();
    }
    assert_eq!(
        std::fs::read(&path).unwrap(),
        seed,
        "regenerate with DLGS_WRITE_FUZZ_SEEDS=1"
    );
}

/// The fixture's GOP 0 written as a whole Scaffold-GS file with `AHAC` and read back by the
/// random-access decoder: the chunk decoder's anchors.
#[test]
fn a_file_with_ahac_decodes_through_the_scaffold_decoder() {
    use dlgs::chunks::tfea::TfeaBody;
    use dlgs::model::scaffold::AnchorDeformation;
    use dlgs::model::TimeFeatures;
    use dlgs_decoder::scaffold::ScaffoldDecoder;
    use dlgs_encoder::scaffold::ScaffoldWriter;
    let g = gop0();
    let h = g.hac_anchors().unwrap();
    let scene = scene_of(&h);
    let mlps = g.mlps.view_mlps(Some(&g.mlps)).unwrap();
    let d = AnchorDeformation {
        bound_min: g.mlps.bounds.0,
        bound_max: g.mlps.bounds.1,
        mlps: g.mlps.deform.clone(),
    };
    let f = TimeFeatures::zeros(h.n_dynamic as usize, 7, 16);
    let mut w = ScaffoldWriter::new(Vec::new(), scene.clone(), 3).unwrap();
    w.push_gop_hac(&h, &mlps, Some((&d, &TfeaBody::Exact(f))))
        .unwrap();
    let bytes = w.finish().unwrap();
    let mut dec = ScaffoldDecoder::new(std::io::Cursor::new(bytes), Limits::default()).unwrap();
    let gop = dec.gop(0).unwrap();
    assert_eq!(bits(&gop.canonical), bits(&h.canonical()));

    // A GOP with both ANCR and AHAC: Payload; with neither: MissingChunk (§6.9, §6.13).
    use dlgs::chunks::{adef, amlp, ancr, tfea};
    use dlgs::container::{ChunkType, Writer, FLAG_MUST_UNDERSTAND};
    let f = TimeFeatures::zeros(h.n_dynamic as usize, 7, 16);
    let parts = [
        (
            ChunkType::ANCR,
            ancr::encode(&h.canonical(), &scene, 3).unwrap(),
        ),
        (ChunkType::AHAC, ahac::encode(&h, &scene, 3).unwrap().0),
        (ChunkType::AMLP, amlp::encode(&mlps, &scene, 3).unwrap()),
        (ChunkType::ADEF, adef::encode(&d, 3).unwrap()),
        (
            ChunkType::TFEA,
            tfea::encode(&TfeaBody::Exact(f), 3).unwrap(),
        ),
    ];
    for (skip, want) in [(None, "Payload"), (Some(2), "MissingChunk")] {
        let mut w = Writer::new(Vec::new(), scene.clone()).unwrap();
        w.begin_gop().unwrap();
        for (k, (ty, p)) in parts.iter().enumerate() {
            if skip.is_some_and(|s| k < s) {
                continue;
            }
            w.gop_chunk(*ty, FLAG_MUST_UNDERSTAND, p).unwrap();
        }
        let bytes = w.finish().unwrap();
        let e = ScaffoldDecoder::new(std::io::Cursor::new(bytes), Limits::default())
            .and_then(|mut d| d.gop(0).map(|_| ()))
            .unwrap_err();
        assert_eq!(e.name(), want, "{e}");
    }
}

/// Decode time of a 100k-anchor `AHAC` (real positions voxelised from a real scene, synthetic
/// symbols from the fixture's context model: `dlgs_ingest::hac::synthetic`). Run with
/// `--ignored --nocapture`; `dlgs ahac-bench` prints the same with CPU times.
#[test]
#[ignore]
fn decode_time_100k_anchors() {
    let ply = std::fs::read("/work/shared/data/ply/v3dg_donut_mipsplatting_45624_sh0.ply").unwrap();
    let h = hac::synthetic::synthetic_anchors(&gop0().hac_anchors().unwrap(), &ply, 100_000, 1)
        .unwrap();
    let scene = scene_of(&h);
    let (p, _) = ahac::encode(&h, &scene, 19).unwrap();
    let mut out = Vec::new();
    for threads in [1, 2] {
        let (ms, c) = in_pool(threads, || {
            let t = Instant::now();
            let c = ahac::decode(&p, 0, &scene, &Limits::default()).unwrap();
            (t.elapsed().as_secs_f64() * 1e3, c)
        });
        println!(
            "100k anchors, {} bytes: decode {ms:.0} ms on {threads} thread(s)",
            p.len()
        );
        out.push(bits(&c));
    }
    assert_eq!(out[0], out[1]);
}

/// Near-lossless (`--anchor-step-scale`): steps `k` times larger, every value within half a
/// new step (`Q' <= 2 k Q_BASE`) of the lossless one, and fewer stream bytes on the fixture.
#[test]
fn requantized_anchors_stay_within_half_a_step() {
    let h = tiny_hac();
    for k in [2.0f32, 4.0] {
        let r = h.requantized(k).unwrap();
        let (a, b) = (h.canonical(), r.canonical());
        for (set_a, set_b) in [(&a.statics, &b.statics), (&a.dynamics, &b.dynamics)] {
            for (x, y, base) in [
                (&set_a.features, &set_b.features, h.context.q_base[0]),
                (
                    &set_a.log_scalings,
                    &set_b.log_scalings,
                    h.context.q_base[1],
                ),
                (&set_a.offsets, &set_b.offsets, h.context.q_base[2]),
            ] {
                let tol = k * base * (1.0 + 1e-5) + 1e-6 * max_diff(x, &vec![0.0; x.len()]);
                assert!(max_diff(x, y) <= tol, "k {k}: {} > {tol}", max_diff(x, y));
            }
        }
        let scene = scene_of(&r);
        let (p, _) = ahac::encode(&r, &scene, 19).unwrap();
        assert_eq!(
            ahac::decode_full(&p, 0, &scene, &Limits::tiny()).unwrap().0,
            r
        );
    }
    assert_eq!(h.requantized(1.0).unwrap(), h);
    assert!(h.requantized(0.0).is_err());
}

/// Re-coding a file's `AHAC` with larger steps (`dlgs rd` on Scaffold-GS files) from the
/// `.dlgs` alone: k = 1 gives the file back byte for byte, k = 2 the file written from the
/// requantised anchors directly; a file with raw anchors (`ANCR`) is refused with the reason.
#[test]
fn recoding_anchor_steps_from_a_file_is_writing_them_requantised() {
    use dlgs::chunks::tfea::TfeaBody;
    use dlgs::model::scaffold::AnchorDeformation;
    use dlgs::model::TimeFeatures;
    use dlgs_encoder::scaffold::ScaffoldWriter;
    use dlgs_encoder::scaffold_recode::recode_anchor_steps;
    let g = gop0();
    let h = g.hac_anchors().unwrap();
    let scene = scene_of(&h);
    let mlps = g.mlps.view_mlps(Some(&g.mlps)).unwrap();
    let d = AnchorDeformation {
        bound_min: g.mlps.bounds.0,
        bound_max: g.mlps.bounds.1,
        mlps: g.mlps.deform.clone(),
    };
    let body = TfeaBody::Exact(TimeFeatures::zeros(h.n_dynamic as usize, 7, 16));
    let write = |anchors: Option<&HacAnchors>| {
        let mut w = ScaffoldWriter::new(Vec::new(), scene.clone(), 3).unwrap();
        match anchors {
            Some(a) => {
                w.push_gop_hac(a, &mlps, Some((&d, &body))).unwrap();
            }
            None => w
                .push_gop(&h.canonical(), &mlps, Some((&d, &body)))
                .unwrap(),
        }
        w.finish().unwrap()
    };
    let file = write(Some(&h));
    let recode = |bytes: &[u8], k: f32| {
        recode_anchor_steps(
            std::io::Cursor::new(bytes.to_vec()),
            k,
            3,
            Limits::default(),
        )
    };
    let (same, report) = recode(&file, 1.0).unwrap();
    assert!(same == file, "k = 1 changed the file");
    assert_eq!(report.ahac_chunks, 1);
    let (k2, report) = recode(&file, 2.0).unwrap();
    assert!(k2 == write(Some(&h.requantized(2.0).unwrap())));
    assert!(report.ahac_bytes_after < report.ahac_bytes_before);
    // Raw anchors (`ANCR`) have no steps to scale: they are HAC-coded with the per-channel
    // prior (encoder/src/scaffold_prior.rs), at k times its default steps.
    let (prior, report) = recode(&write(None), 2.0).unwrap();
    assert_eq!((report.ahac_chunks, report.from_raw), (1, 1));
    assert!(report.ahac_bytes_after < report.ahac_bytes_before);
    let mut r = dlgs::container::FileReader::open(std::io::Cursor::new(&prior[..])).unwrap();
    let types: Vec<_> = r.gop_chunks(0).unwrap().iter().map(|c| c.ty).collect();
    assert!(
        types.contains(&dlgs::container::ChunkType::AHAC),
        "{types:?}"
    );
    assert!(
        !types.contains(&dlgs::container::ChunkType::ANCR),
        "{types:?}"
    );
    let e = recode(&file, 0.0).unwrap_err();
    assert!(matches!(e, Error::Input(_)), "{e}");
}
