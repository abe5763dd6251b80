//! Ingest of the reference implementation's trained outputs (issue 9), on the committed fixture
//! `tests/fixtures/reference_run` built by `scripts/reference_fixture.py` with the reference's
//! own libraries (torch.save, imagecodecs JPEG XL, torchac, the ffmpeg CLI). Its content is
//! SYNTHETIC on a REAL scene (fruit drops, real labels): no trained DLGStream model exists here.
//! `reference_decode/gop{g}.safetensors` holds what the reference's decoder computes from the
//! files; every tensor we read must equal it (bit for bit where the reference is lossless).

use std::path::{Path, PathBuf};

use dlgs::chunks::csog::QuantBits;
use dlgs::chunks::mlpw::WeightType;
use dlgs::Gaussians;
use dlgs_decoder::{Decoder, FrameOptions};
use dlgs_encoder::{CanonicalCodec, EncoderConfig, ResidualConfig, SortSpec};
use dlgs_ingest::run::{self, RefGop};
use dlgs_ingest::{convert, IngestError};
use dlgs_render::camera::{orbit_cameras, OrbitSpec};
use dlgs_render::{metrics, render, RenderOptions};
use safetensors::SafeTensors;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/reference_run")
}

fn gop_dirs() -> Vec<PathBuf> {
    run::resolve(&[fixture()]).unwrap()
}

fn read_all() -> Vec<RefGop> {
    run::read_run(&gop_dirs(), &dlgs::Limits::default(), |_| {}).unwrap()
}

struct Reference(Vec<u8>);

impl Reference {
    fn load(g: usize) -> Self {
        Reference(
            std::fs::read(fixture().join(format!("reference_decode/gop{g}.safetensors"))).unwrap(),
        )
    }
    fn get(&self, name: &str) -> Vec<f32> {
        let st = SafeTensors::deserialize(&self.0).unwrap();
        let t = st
            .tensor(name)
            .unwrap_or_else(|_| panic!("no tensor {name}"));
        t.data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    }
}

/// Our tensors in the reference's layout, by the reference's names.
fn tensor(g: &Gaussians, name: &str) -> Vec<f32> {
    let n = g.len();
    let c = g.coeffs();
    match name {
        "xyz" => g.positions.iter().flatten().copied().collect(),
        "scaling" => g.log_scales.iter().flatten().copied().collect(),
        "rotation" => g.rotations.iter().flatten().copied().collect(),
        "opacity" => (0..n)
            .flat_map(|i| [g.opacity[i], g.lang_opacity[i]])
            .collect(),
        "features_dc" => (0..n)
            .flat_map(|i| g.sh[i * 3 * c..i * 3 * c + 3].to_vec())
            .collect(),
        "features_rest" => (0..n)
            .flat_map(|i| g.sh[i * 3 * c + 3..(i + 1) * 3 * c].to_vec())
            .collect(),
        "language_feature" => g.lang.clone(),
        _ => unreachable!(),
    }
}

const ATTRS: [&str; 7] = [
    "xyz",
    "features_dc",
    "features_rest",
    "scaling",
    "rotation",
    "opacity",
    "language_feature",
];

/// Largest absolute difference and the count of values that differ in any bit.
fn compare(a: &[f32], b: &[f32]) -> (f32, usize) {
    assert_eq!(a.len(), b.len());
    let max = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max);
    let diff = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.to_bits() != y.to_bits())
        .count();
    (max, diff)
}

#[test]
fn every_tensor_equals_the_reference_decoder() {
    let gops = read_all();
    assert_eq!(gops.len(), 2);
    for (g, gop) in gops.iter().enumerate() {
        let r = Reference::load(g);
        for (set, suffix) in [(&gop.statics, ""), (&gop.dynamics, "_dynamic")] {
            for a in ATTRS {
                let name = format!("_{a}{suffix}");
                let (max, diff) = compare(&tensor(set, a), &r.get(&name));
                println!("GOP {g} {name:28} max |diff| {max:.3e}, {diff} values differ");
                // Lossless in the reference: bit for bit. SH DC is the reference's lossy JPEG XL
                // (level 100), decoded by jxl-oxide instead of libjxl; GOP 1's latent
                // residuals are a float32 matmul whose summation order PyTorch does not fix.
                let lossy = a == "features_dc" || (g > 0 && a != "xyz");
                if lossy {
                    // Measured: 1.6e-5 (SH DC, values within +-2.3), latent residuals below.
                    assert!(max <= 1e-4, "GOP {g} {name}: {max}");
                } else {
                    assert_eq!(diff, 0, "GOP {g} {name}: {diff} values differ (max {max})");
                }
            }
        }
        let (max, diff) = compare(&gop.features.data, &r.get("_point_feats"));
        println!("GOP {g} _point_feats max |diff| {max:.3e}, {diff} values differ");
        assert_eq!(diff, 0, "time features must decode bit for bit");
        for m in gop.mlps.iter() {
            let name = match m.role.name() {
                "lang" => "mlp_lang".to_string(),
                r => format!("mlp_{r}"),
            };
            for (l, key) in m.layers.iter().zip(["0.weight", "2.weight"]) {
                assert_eq!(l.weights, r.get(&format!("{name}.{key}")), "{name}.{key}");
            }
        }
        assert_eq!(
            gop.mlps.scale_offsets,
            g > 0,
            "mlp_cov scales apply from GOP 1 on"
        );
    }
}

fn encode_default(gops: &[RefGop]) -> Vec<u8> {
    convert::encode(gops, 30, EncoderConfig::default(), Vec::new(), |_| {}).unwrap()
}

#[test]
fn dlgs_decodes_to_the_ingested_model_bit_for_bit() {
    let gops = read_all();
    let bytes = encode_default(&gops);
    let mut dec =
        Decoder::new(std::io::Cursor::new(bytes.clone()), dlgs::Limits::default()).unwrap();
    for (g, gop) in gops.iter().enumerate() {
        let d = dec.gop(g as u32).unwrap();
        assert_eq!(d.canonical.statics, gop.statics, "GOP {g} statics");
        assert_eq!(d.canonical.dynamics, gop.dynamics, "GOP {g} dynamics");
        let dy = d.dynamic().unwrap().unwrap();
        assert_eq!(dy.features, gop.features, "GOP {g} features");
        assert_eq!(dy.mlps, gop.mlps, "GOP {g} decoders");
    }
    let report = convert::byte_report(&gops, &bytes).unwrap();
    for (g, r) in report.iter().enumerate() {
        println!(
            "GOP {g}: reference {} B counted, {} B with mlp_lang.pth; .dlgs {:.0} B ({:.1} % / {:.1} %)",
            r.reference_counted,
            r.reference_with_lang_mlp,
            r.dlgs,
            100.0 * r.dlgs / r.reference_counted as f64,
            100.0 * r.dlgs / r.reference_with_lang_mlp as f64
        );
    }
    let ours: f64 = report.iter().map(|r| r.dlgs).sum();
    let theirs: u64 = report.iter().map(|r| r.reference_with_lang_mlp).sum();
    // Reported, not asserted: lossless, the .dlgs is larger than the reference's packing; the
    // 70 % goal is met by `--quality near-lossless` (the test below).
    println!(
        "total: .dlgs {ours:.0} B vs reference {theirs} B incl. mlp_lang ({:.1} %)",
        100.0 * ours / theirs as f64
    );
    assert!(report
        .iter()
        .all(|r| r.dlgs > 0.0 && r.reference_counted > 0));
}

/// The reference's decoded model as Gaussians (from its safetensors), for rendering.
fn reference_gaussians(g: usize, like: &Gaussians, suffix: &str) -> Gaussians {
    let r = Reference::load(g);
    let mut out = like.clone();
    let get = |a: &str| r.get(&format!("_{a}{suffix}"));
    let (xyz, sc, rot, op, dc, rest, lang) = (
        get("xyz"),
        get("scaling"),
        get("rotation"),
        get("opacity"),
        get("features_dc"),
        get("features_rest"),
        get("language_feature"),
    );
    let c = like.coeffs();
    for i in 0..like.len() {
        out.positions[i] = [xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]];
        out.log_scales[i] = [sc[3 * i], sc[3 * i + 1], sc[3 * i + 2]];
        out.rotations[i] = [rot[4 * i], rot[4 * i + 1], rot[4 * i + 2], rot[4 * i + 3]];
        out.opacity[i] = op[2 * i];
        out.lang_opacity[i] = op[2 * i + 1];
        out.sh[i * 3 * c..i * 3 * c + 3].copy_from_slice(&dc[3 * i..3 * i + 3]);
        out.sh[i * 3 * c + 3..(i + 1) * 3 * c]
            .copy_from_slice(&rest[3 * (c - 1) * i..3 * (c - 1) * (i + 1)]);
        out.lang[9 * i..9 * i + 9].copy_from_slice(&lang[9 * i..9 * i + 9]);
    }
    out
}

/// 4 orbit views at 320x240 around the scene.
fn test_cameras(g: &Gaussians) -> Vec<dlgs_render::camera::Camera> {
    orbit_cameras(
        g,
        &OrbitSpec {
            count: 4,
            width: 320,
            height: 240,
            ..Default::default()
        },
    )
}

#[test]
fn rendered_psnr_against_the_reference_decode_is_at_least_60_db() {
    let gops = read_all();
    let bytes = encode_default(&gops);
    let mut dec = Decoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap();
    let cams = test_cameras(&gops[0].statics);
    let opts = RenderOptions::default();
    for g in 0..gops.len() {
        let statics = reference_gaussians(g, &gops[g].statics, "");
        let dynamics = reference_gaussians(g, &gops[g].dynamics, "_dynamic");
        let mut reference = statics.clone();
        reference.extend(&dynamics);
        // Canonical frame (key 0): compare the canonical states; the deformation itself is
        // the decoder's (checked against an f64 implementation by tests/tests/dynamic.rs).
        let ours = dec.gop(g as u32).unwrap().canonical.merged();
        for cam in &cams {
            let a = render(&ours, cam, &opts).unwrap();
            let b = render(&reference, cam, &opts).unwrap();
            let p = metrics::psnr(&a.color, &b.color);
            println!("GOP {g}: canonical PSNR vs the reference decode {p:.2} dB");
            assert!(p >= 60.0, "GOP {g}: {p} dB");
        }
    }
}

fn copy_fixture() -> (tempfile::TempDir, Vec<PathBuf>) {
    let tmp = tempfile::tempdir().unwrap();
    let mut dirs = Vec::new();
    for (g, d) in gop_dirs().iter().enumerate() {
        let to = tmp.path().join(format!("gop{g}"));
        std::fs::create_dir_all(&to).unwrap();
        for e in std::fs::read_dir(d).unwrap() {
            let e = e.unwrap();
            if e.file_name() != "model.pth" {
                std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
            }
        }
        dirs.push(to);
    }
    (tmp, dirs)
}

fn read_error(dirs: &[PathBuf]) -> String {
    match run::read_run(dirs, &dlgs::Limits::default(), |_| {}) {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn damaged_runs_give_clear_errors() {
    let (_tmp, dirs) = copy_fixture();
    let (g0, g1) = (&dirs[0], &dirs[1]);
    let restore = |p: &Path, bytes: &[u8]| std::fs::write(p, bytes).unwrap();

    // Missing file.
    let p = g0.join("_rotation.jxl");
    let saved = std::fs::read(&p).unwrap();
    std::fs::remove_file(&p).unwrap();
    let e = read_error(&dirs);
    assert!(e.contains("_rotation.jxl") && e.contains("missing"), "{e}");
    restore(&p, &saved);

    // Truncated video.
    let p = g0.join("_point_feats.mp4");
    let saved = std::fs::read(&p).unwrap();
    restore(&p, &saved[..saved.len() / 2]);
    let e = read_error(&dirs);
    assert!(e.contains("_point_feats.mp4"), "{e}");
    restore(&p, &saved);

    // Truncated / damaged latents.
    let p = g1.join("offset_compressed.pkl");
    let saved = std::fs::read(&p).unwrap();
    for cut in [0, 10, saved.len() / 3, saved.len() - 1] {
        restore(&p, &saved[..cut]);
        let e = read_error(&dirs);
        assert!(e.contains("offset_compressed.pkl"), "{e}");
    }
    restore(&p, &saved);

    // Wrong shape: the static positions of GOP 1 come from the dynamic image.
    let p = g1.join("_xyz_offset.jxl");
    let saved = std::fs::read(&p).unwrap();
    std::fs::copy(g1.join("_xyz_dynamic_offset.jxl"), &p).unwrap();
    let e = read_error(&dirs);
    assert!(e.contains("positions") || e.contains("shape"), "{e}");
    restore(&p, &saved);

    // Wrong shape in a decoder.
    let p = g0.join("mlp_cov.pth");
    let saved = std::fs::read(&p).unwrap();
    std::fs::copy(g0.join("mlp_lang.pth"), &p).unwrap();
    let gops = run::read_run(&dirs, &dlgs::Limits::default(), |_| {}).unwrap();
    let e = convert::encode(&gops, 30, EncoderConfig::default(), Vec::new(), |_| {}).unwrap_err();
    assert!(e.to_string().contains("cov"), "{e}");
    restore(&p, &saved);

    // Non-square grid: a CSV range pointing at an image of another attribute's width.
    let p = g0.join("compression_info.csv");
    let saved = std::fs::read_to_string(&p).unwrap();
    restore(&p, saved.replace("_xyz.jxl", "_xyz_dynamic.jxl").as_bytes());
    let e = read_error(&dirs);
    assert!(
        e.contains("wrong shape") && e.contains("576 Gaussians"),
        "{e}"
    );
    restore(&p, saved.as_bytes());

    // A grid that is not square: a 5x7 lossless float image (imagecodecs, see
    // tests/fixtures/README.md) as the static positions.
    let xyz = g0.join("_xyz.jxl");
    let saved_xyz = std::fs::read(&xyz).unwrap();
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/non_square_5x7.jxl"),
        &xyz,
    )
    .unwrap();
    let e = read_error(&dirs);
    assert!(
        e.contains("_xyz") && e.contains("35 Gaussians is not a square grid"),
        "{e}"
    );
    restore(&xyz, &saved_xyz);

    // NaN in a range: the CSV's min.
    let bad = saved.replacen("_opacity,-", "_opacity,nan,", 1);
    let bad = bad.replacen("nan,6", "nan,", 1);
    restore(&p, bad.as_bytes());
    let e = read_error(&dirs);
    assert!(e.contains("compression_info.csv"), "{e}");
    restore(&p, saved.as_bytes());

    // Not a run at all.
    let e = run::resolve(&[g0.join("nope")]).unwrap_err();
    assert!(matches!(e, IngestError::Missing { .. }), "{e}");
}

/// A run with only the checkpoints (GOP 0 `model.pth`, GOP 1 `model.pth` + `model_offset.pth`).
fn checkpoint_only_run() -> (tempfile::TempDir, Vec<PathBuf>) {
    let tmp = tempfile::tempdir().unwrap();
    let mut dirs = Vec::new();
    for (g, d) in gop_dirs().iter().enumerate() {
        let to = tmp
            .path()
            .join(format!("gop{g}_ckpt/compression/best/jxl_quant"));
        std::fs::create_dir_all(&to).unwrap();
        for f in ["model.pth", "model_offset.pth"] {
            if d.join(f).is_file() {
                std::fs::copy(d.join(f), to.join(f)).unwrap();
            }
        }
        dirs.push(to);
    }
    (tmp, dirs)
}

#[test]
fn a_run_with_only_checkpoints_reads_them_and_compressed_files_win_otherwise() {
    let (tmp, dirs) = checkpoint_only_run();
    // The scene folder resolves to the two GOP folders as for a compressed run.
    assert_eq!(run::resolve(&[tmp.path().to_path_buf()]).unwrap(), dirs);
    let gops = run::read_run(&dirs, &dlgs::Limits::default(), |_| {}).unwrap();
    let compressed = read_all();
    for (g, gop) in gops.iter().enumerate() {
        let r = Reference(
            std::fs::read(
                fixture().join(format!("reference_decode/gop{g}_checkpoint.safetensors")),
            )
            .unwrap(),
        );
        // GOP 0: model.pth's trained values; GOP 1: model_offset.pth's accumulated ones.
        let key = |a: &str, suffix: &str| match g {
            0 => format!("_{a}{suffix}"),
            _ => format!("_{a}{suffix}_offset"),
        };
        for (set, suffix) in [(&gop.statics, ""), (&gop.dynamics, "_dynamic")] {
            for a in ATTRS {
                let (max, diff) = compare(&tensor(set, a), &r.get(&key(a, suffix)));
                assert_eq!(diff, 0, "GOP {g} {}: max {max}", key(a, suffix));
            }
        }
        assert_eq!(gop.features.data, r.get("_point_feats"), "GOP {g} features");
        for m in gop.mlps.iter() {
            let name = format!("mlp_{}", m.role.name());
            for (l, k) in m.layers.iter().zip(["0.weight", "2.weight"]) {
                assert_eq!(l.weights, r.get(&format!("{name}.{k}")), "{name}.{k}");
            }
        }
        assert_eq!(gop.mlps.scale_offsets, g > 0);
        assert!(
            gop.files.is_empty(),
            "checkpoints are not the reference's packing"
        );
        // Where both exist the compressed files were read: the checkpoint's SH DC is the
        // trained value, the compressed run's is the lossy JPEG XL decode.
        let ck_dc = tensor(&gop.statics, "features_dc");
        let (max, _) = compare(&ck_dc, &tensor(&compressed[g].statics, "features_dc"));
        println!("GOP {g}: checkpoint vs compressed SH DC max |diff| {max:.2e}");
        assert!(
            max > 0.0,
            "GOP {g}: the full fixture must have been read from its JXL files"
        );
    }
    // The checkpoint run encodes (features through our own HEVC encoder) and decodes to the
    // checkpoint's attributes and decoders exactly.
    let bytes = encode_default(&gops);
    let mut dec = Decoder::new(std::io::Cursor::new(bytes), dlgs::Limits::default()).unwrap();
    for (g, gop) in gops.iter().enumerate() {
        let d = dec.gop(g as u32).unwrap();
        assert_eq!(d.canonical.statics, gop.statics, "GOP {g} statics");
        assert_eq!(d.canonical.dynamics, gop.dynamics, "GOP {g} dynamics");
        let dy = d.dynamic().unwrap().unwrap();
        assert_eq!(dy.mlps, gop.mlps, "GOP {g} decoders");
        // Lossy like the reference's own video (same crf 6): measured against the trained
        // features, ours vs what the reference's mp4 decodes to.
        let rms = |a: &[f32], b: &[f32]| {
            let s: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
            (s / a.len() as f64).sqrt()
        };
        let ours = rms(&dy.features.data, &gop.features.data);
        let theirs = rms(&compressed[g].features.data, &gop.features.data);
        let (max, _) = compare(&dy.features.data, &gop.features.data);
        let (max_ref, _) = compare(&compressed[g].features.data, &gop.features.data);
        println!(
            "GOP {g}: time features vs trained: .dlgs rms {ours:.2e} max {max:.2e}; \
             reference mp4 rms {theirs:.2e} max {max_ref:.2e}"
        );
        assert!(
            ours <= 1.5 * theirs,
            "GOP {g}: rms {ours} vs the reference's {theirs}"
        );
    }

    // Errors name the checkpoint: truncated, and a GOP 1 without model_offset.pth.
    let p = dirs[1].join("model_offset.pth");
    let saved = std::fs::read(&p).unwrap();
    std::fs::write(&p, &saved[..saved.len() / 2]).unwrap();
    let e = read_error(&dirs);
    assert!(e.contains("model_offset.pth"), "{e}");
    std::fs::remove_file(&p).unwrap();
    let e = read_error(&dirs);
    assert!(
        e.contains("model_offset.pth") && e.contains("missing"),
        "{e}"
    );
    // GOP 0's model.pth put in GOP 1's place: no accumulated tensors.
    std::fs::copy(dirs[0].join("model.pth"), &p).unwrap();
    let e = read_error(&dirs);
    assert!(e.contains("_offset"), "{e}");

    // A NaN in a checkpoint tensor: the archive rewritten with every storage's first value NaN.
    let p = dirs[0].join("model.pth");
    let mut src = zip::ZipArchive::new(std::fs::File::open(&p).unwrap()).unwrap();
    let mut out = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let stored =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for i in 0..src.len() {
        let mut f = src.by_index(i).unwrap();
        let name = f.name().to_string();
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut f, &mut bytes).unwrap();
        if name.contains("/data/") && bytes.len() >= 4 {
            bytes[..4].copy_from_slice(&f32::NAN.to_le_bytes());
        }
        out.start_file(name, stored).unwrap();
        std::io::Write::write_all(&mut out, &bytes).unwrap();
    }
    std::fs::write(&p, out.finish().unwrap().into_inner()).unwrap();
    match run::read_run(&dirs, &dlgs::Limits::default(), |_| {}) {
        Err(e @ IngestError::NonFinite { .. }) => {
            assert!(e.to_string().contains("model.pth"), "{e}")
        }
        other => panic!("expected a non-finite error, got {:?}", other.err()),
    }
}

/// `dlgs encode RUN --quality near-lossless`: sorted grids at the near-lossless bits, decoders
/// in f16, residual GOPs as lossy as GOP 0 (what `CodecArgs::config` builds for that preset).
fn near_lossless() -> EncoderConfig {
    EncoderConfig {
        coding: dlgs_encoder::CanonicalSettings {
            codec: CanonicalCodec::Sorted {
                bits: QuantBits::NEAR_LOSSLESS,
                sort: SortSpec::DEFAULT,
            },
            ..Default::default()
        },
        dynamic: dlgs_encoder::DynamicSettings {
            mlp_weights: WeightType::F16,
            residual: ResidualConfig {
                follow_quantisation: true,
                ..Default::default()
            },
            ..Default::default()
        },
        ..Default::default()
    }
}

#[test]
fn near_lossless_is_under_70_percent_of_the_reference_and_renders_above_60_db() {
    let gops = read_all();
    let lossless = encode_default(&gops);
    let small = convert::encode(&gops, 30, near_lossless(), Vec::new(), |_| {}).unwrap();
    let report = convert::byte_report(&gops, &small).unwrap();
    let ours: f64 = report.iter().map(|r| r.dlgs).sum();
    let theirs: u64 = report.iter().map(|r| r.reference_with_lang_mlp).sum();
    let share = ours / theirs as f64;
    println!(
        "near-lossless: {ours:.0} B vs the reference's {theirs} B incl. mlp_lang ({:.1} %; \
         lossless .dlgs {} B)",
        100.0 * share,
        lossless.len()
    );
    assert!(share <= 0.70, "{:.1} %", 100.0 * share);

    // Whole frames (deformed dynamics included) either side of the GOP boundary and inside
    // both GOPs, against the lossless file (= the reference decode, see the tests above).
    let mut a = Decoder::new(std::io::Cursor::new(lossless), dlgs::Limits::default()).unwrap();
    let mut b = Decoder::new(std::io::Cursor::new(small), dlgs::Limits::default()).unwrap();
    let cams = test_cameras(&gops[0].statics);
    let opts = RenderOptions::default();
    let mut worst = f64::INFINITY;
    for t in [0.5, 1.95, 2.0, 3.5] {
        for cam in &cams {
            let fo = FrameOptions {
                camera_center: cam.position.to_array(),
                language: false,
            };
            let fa = a.frame_at(t, &fo).unwrap().merged();
            let fb = b.frame_at(t, &fo).unwrap().merged();
            let p = metrics::psnr(
                &render(&fa, cam, &opts).unwrap().color,
                &render(&fb, cam, &opts).unwrap().color,
            );
            worst = worst.min(p);
        }
    }
    println!("near-lossless: worst PSNR vs lossless over 4 times x 4 cameras {worst:.2} dB");
    assert!(worst >= 60.0, "{worst} dB");
}

/// Ingest draws on the same limits as every other reader: a fixture's files over a small
/// `max_alloc`, or its Gaussians over a small `max_gaussians`, are refused with the limit named.
#[test]
fn ingest_stays_within_the_limits() {
    let dirs = gop_dirs();
    for limits in [
        dlgs::Limits {
            max_alloc: 64,
            ..dlgs::Limits::default()
        },
        dlgs::Limits {
            max_gaussians: 3,
            ..dlgs::Limits::default()
        },
    ] {
        let e = run::read_run(&dirs, &limits, |_| {}).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("limit exceeded"), "{text}");
    }
}
