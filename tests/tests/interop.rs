//! Readers of real third-party splat files (../shared/data; nobody on this project wrote them).

use dlgs::interop::{ply, sog, splat, spz};
use dlgs::Limits;
use dlgs_tests::{data, load, REAL_SCENES};

#[test]
fn every_real_scene_loads_with_its_declared_count_and_degree() {
    for (rel, n, deg) in REAL_SCENES {
        let g = load(rel);
        assert_eq!(g.len(), *n, "{rel}");
        assert_eq!(g.sh_degree, *deg, "{rel}");
        g.check_shapes().unwrap();
        g.check_finite().unwrap_or_else(|e| panic!("{rel}: {e}"));
    }
}

#[test]
fn the_same_three_gaussians_in_ply_splat_and_spz_agree() {
    let p = load("tiny/metalsplatter_3-points-from-train.ply");
    let s = splat::read_splat(
        &std::fs::read(data("tiny/metalsplatter_3-points-from-train.splat")).unwrap(),
        &Limits::default(),
    )
    .unwrap();
    let z = spz::read_spz(
        &std::fs::read(data("tiny/metalsplatter_3-points-from-train.spz")).unwrap(),
        &Limits::default(),
    )
    .unwrap();
    assert_eq!(z.sh_degree, 3);
    for i in 0..3 {
        for a in 0..3 {
            // .splat keeps f32 positions; SPZ uses 12 fractional bits (1/4096).
            assert!(
                (p.positions[i][a] - s.positions[i][a]).abs() < 1e-6,
                "splat pos {i}"
            );
            assert!(
                (p.positions[i][a] - z.positions[i][a]).abs() <= 0.5 / 4096.0 + 1e-6,
                "spz pos {i}/{a}: {} vs {}",
                p.positions[i][a],
                z.positions[i][a]
            );
            assert!(
                (p.log_scales[i][a] - z.log_scales[i][a]).abs() <= 1.0 / 32.0 + 1e-4,
                "spz scale {i}"
            );
            assert!(
                (p.log_scales[i][a] - s.log_scales[i][a]).abs() < 1e-4,
                "splat scale {i}"
            );
        }
        // Quaternions agree up to sign after normalisation.
        let n = |q: [f32; 4]| {
            let l = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            q.map(|v| v / l)
        };
        let (qp, qz) = (n(p.rotations[i]), n(z.rotations[i]));
        let dot: f32 = qp.iter().zip(qz).map(|(a, b)| a * b).sum();
        assert!(dot.abs() > 0.995, "spz rotation {i}: {qp:?} vs {qz:?}");
        // SH DC within SPZ's 8-bit colour step; rest within its SH step.
        for k in 0..16 {
            for c in 0..3 {
                let (a, b) = (p.sh_of(i)[k * 3 + c], z.sh_of(i)[k * 3 + c]);
                // SPZ buckets SH degree 1 to 5 bits and higher degrees to 4 bits (steps of 8 and 16 / 128).
                let tol = match k {
                    0 => 1.0 / (0.15 * 255.0),
                    1..=3 => 4.5 / 128.0,
                    _ => 8.5 / 128.0,
                };
                assert!(
                    (a - b).abs() <= tol,
                    "spz SH {i} coef {k} ch {c}: {a} vs {b}"
                );
            }
        }
    }
}

#[test]
fn ply_write_read_round_trip_is_exact_with_and_without_language() {
    for rel in [
        "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply",
        "ply/v3dg_donut_mipsplatting_45624_sh0.ply",
    ] {
        let g = load(rel);
        assert_eq!(
            ply::read_ply(&ply::write_ply(&g).unwrap(), &Limits::default()).unwrap(),
            g
        );
        let l = dlgs_tests::with_synthetic_language(&g);
        assert_eq!(
            ply::read_ply(&ply::write_ply(&l).unwrap(), &Limits::default()).unwrap(),
            l
        );
    }
}

#[test]
fn malformed_foreign_files_give_errors_not_panics() {
    let good = std::fs::read(data("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply")).unwrap();
    for cut in [0, 3, 10, 200, 1000, good.len() / 2, good.len() - 1] {
        assert!(
            ply::read_ply(&good[..cut], &Limits::default()).is_err(),
            "PLY cut at {cut}"
        );
    }
    let mut huge = String::from_utf8_lossy(
        &good[..good.windows(10).position(|w| w == b"end_header").unwrap()],
    )
    .replace("element vertex 1971", "element vertex 4000000000");
    huge.push_str("end_header\n");
    assert!(ply::read_ply(huge.as_bytes(), &Limits::default()).is_err());
    assert!(splat::read_splat(&[0u8; 33], &Limits::default()).is_err());
    // Foreign readers draw on the same limits as the container: a real scene over a small
    // budget is refused with the limit named, not read.
    let small = Limits {
        max_gaussians: 1000,
        ..Limits::default()
    };
    for e in [
        ply::read_ply(&good, &small).unwrap_err(),
        splat::read_splat(
            &std::fs::read(data("splat/marcelpadilla_plant.splat")).unwrap(),
            &small,
        )
        .unwrap_err(),
    ] {
        assert!(
            matches!(e, dlgs::Error::Limit(dlgs::LimitError { limit: 1000, .. })),
            "{e}"
        );
    }
    let tight = Limits {
        max_alloc: 1 << 16,
        ..Limits::default()
    };
    let e = dlgs::interop::read_splat_file_with_limits(
        &data("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply"),
        &tight,
    )
    .unwrap_err();
    assert!(
        matches!(
            e,
            dlgs::Error::Limit(dlgs::LimitError {
                what: "splat file size",
                ..
            })
        ),
        "{e}"
    );
    let spz_good = std::fs::read(data("tiny/metalsplatter_3-points-from-train.spz")).unwrap();
    for cut in 0..spz_good.len() {
        assert!(
            spz::read_spz(&spz_good[..cut], &Limits::default()).is_err(),
            "SPZ cut at {cut}"
        );
    }
}

fn fixture(name: &str) -> Vec<u8> {
    std::fs::read(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fixtures")
            .join(name),
    )
    .unwrap()
}

/// splat-transform's SPZ v4 of an SH-0 scene has five streams (no SH stream): read, and it
/// holds the source frame's Gaussians (SPZ's 12-bit positions, 8-bit colours).
#[test]
fn spz_v4_without_its_sh_stream_is_read() {
    let bytes = fixture("wave_0001_sh0.v4.spz");
    assert_eq!(bytes[15], 5, "the fixture's stream count");
    let g = spz::read_spz(&bytes, &Limits::default()).unwrap();
    let src = load("sequence/playcanvas_wave_200f/wave_0001.sog");
    assert_eq!((g.len(), g.sh_degree), (src.len(), 0));
    let lo = |g: &dlgs::Gaussians| {
        let (lo, hi) = g.bounds().unwrap();
        (
            lo.map(|v| (v * 10.0).round()),
            hi.map(|v| (v * 10.0).round()),
        )
    };
    assert_eq!(lo(&g), lo(&src), "same extent (to 0.1)");
    // Five streams with SH bands declared is still refused.
    let mut bad = bytes.clone();
    bad[12] = 1;
    assert!(spz::read_spz(&bad, &Limits::default()).is_err());
}

#[test]
fn spz_v4_from_splat_transform_matches_its_v3_and_the_source_ply() {
    let v4 = spz::read_spz(&fixture("gs3d_lod3_1971.v4.spz"), &Limits::default()).unwrap();
    let v3 = spz::read_spz(&fixture("gs3d_lod3_1971.v3.spz"), &Limits::default()).unwrap();
    let src = load("ply/gs3d-fork_lod3_tile_0_1971_sh3.ply");
    assert_eq!((v4.len(), v4.sh_degree), (1971, 3));
    assert!(v4 == v3, "v4 and v3 of the same encoder differ");
    for i in 0..src.len() {
        for a in 0..3 {
            assert!(
                (v4.positions[i][a] - src.positions[i][a]).abs() <= 0.5 / 4096.0 + 1e-5,
                "position {i}"
            );
            // SPZ stores u8((s + 10) * 16): log-scales outside [-10, 5.94] are clamped.
            let want = src.log_scales[i][a].clamp(-10.0, 255.0 / 16.0 - 10.0);
            assert!(
                (v4.log_scales[i][a] - want).abs() <= 1.0 / 32.0 + 1e-4,
                "scale {i}: {} vs {}",
                v4.log_scales[i][a],
                src.log_scales[i][a]
            );
        }
    }
    let tiny = spz::read_spz(
        &fixture("metalsplatter_3-points.v4.spz"),
        &Limits::default(),
    )
    .unwrap();
    assert_eq!(tiny.len(), 3);
    // Damaged v4 files fail cleanly.
    let good = fixture("gs3d_lod3_1971.v4.spz");
    for cut in (0..good.len()).step_by(97) {
        assert!(
            spz::read_spz(&good[..cut], &Limits::default()).is_err(),
            "cut {cut}"
        );
    }
    let mut bad = good.clone();
    bad[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(spz::read_spz(&bad, &Limits::default()).is_err());
}

/// The floats of `g` in the order `scripts/sog_golden.py` hashes them.
fn model_floats(g: &dlgs::Gaussians) -> Vec<f32> {
    let mut v: Vec<f32> = g.positions.iter().flatten().copied().collect();
    v.extend(g.log_scales.iter().flatten());
    v.extend(g.rotations.iter().flatten());
    v.extend(&g.opacity);
    v.extend(&g.sh);
    v
}

#[test]
fn sog_reads_bit_for_bit_as_splat_transform_decodes_it() {
    use sha2::Digest;
    let goldens: serde_json::Value = serde_json::from_slice(&fixture("sog_goldens.json")).unwrap();
    let mut seen = 0;
    for gold in goldens["files"].as_array().unwrap() {
        let bytes = match gold["name"].as_str().unwrap() {
            "wave_0001" => {
                std::fs::read(data("sequence/playcanvas_wave_200f/wave_0001.sog")).unwrap()
            }
            "fruit_every8th_591" => fixture("fruit_every8th_591.sog"),
            other => panic!("no file for golden {other}"),
        };
        let g = sog::read_sog(&bytes, &Limits::default()).unwrap();
        let name = gold["name"].as_str().unwrap();
        assert_eq!(g.len() as u64, gold["count"].as_u64().unwrap(), "{name}");
        assert_eq!(
            g.sh_degree as u64,
            gold["sh_degree"].as_u64().unwrap(),
            "{name}"
        );
        g.check_finite().unwrap();
        // A few Gaussians value by value, so that a mismatch says where.
        for (i, want) in gold["samples"].as_object().unwrap() {
            let i: usize = i.parse().unwrap();
            let got: [(&str, Vec<f32>); 5] = [
                ("positions", g.positions[i].to_vec()),
                ("log_scales", g.log_scales[i].to_vec()),
                ("rotations", g.rotations[i].to_vec()),
                ("opacity", vec![g.opacity[i]]),
                (
                    "sh",
                    g.sh[i * g.sh_stride()..(i + 1) * g.sh_stride()].to_vec(),
                ),
            ];
            for (key, values) in got {
                let want: Vec<f32> = want[key]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap() as f32)
                    .collect();
                assert_eq!(values, want, "{name}: Gaussian {i}, {key}");
            }
        }
        // Then every float.
        let mut h = sha2::Sha256::new();
        for f in model_floats(&g) {
            h.update(f.to_le_bytes());
        }
        let digest: String = h.finalize().iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(digest, gold["sha256_f32"].as_str().unwrap(), "{name}");
        seen += 1;
    }
    assert_eq!(seen, 2);
}

#[test]
fn an_unbundled_sog_reads_as_its_zip_does() {
    let bytes = fixture("fruit_every8th_591.sog");
    let bundled = sog::read_sog(&bytes, &Limits::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&bytes)).unwrap();
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).unwrap();
        let mut out = std::fs::File::create(dir.path().join(entry.name())).unwrap();
        std::io::copy(&mut entry, &mut out).unwrap();
    }
    let unbundled = dlgs::interop::read_splat_file(&dir.path().join("meta.json")).unwrap();
    assert!(unbundled == bundled);
    // A texture missing beside meta.json is named in the error.
    std::fs::remove_file(dir.path().join("quats.webp")).unwrap();
    let e = dlgs::interop::read_splat_file(&dir.path().join("meta.json")).unwrap_err();
    assert!(e.to_string().contains("quats.webp"), "{e}");
}

/// `fixture`'s SOG zip with `meta.json` passed through `edit` (stored entries, as SOG writes).
fn sog_with_meta(edit: impl Fn(&mut serde_json::Value)) -> Vec<u8> {
    use std::io::{Read, Write};
    let bytes = fixture("fruit_every8th_591.sog");
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&bytes)).unwrap();
    let mut out = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let stored =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).unwrap();
        let mut content = Vec::new();
        entry.read_to_end(&mut content).unwrap();
        if entry.name() == "meta.json" {
            let mut meta: serde_json::Value = serde_json::from_slice(&content).unwrap();
            edit(&mut meta);
            content = serde_json::to_vec(&meta).unwrap();
        }
        out.start_file(entry.name(), stored).unwrap();
        out.write_all(&content).unwrap();
    }
    out.finish().unwrap().into_inner()
}

#[test]
fn a_damaged_sog_is_refused_with_what_is_wrong() {
    let reason = |edit: &dyn Fn(&mut serde_json::Value)| -> String {
        match sog::read_sog(&sog_with_meta(edit), &Limits::default()) {
            Ok(g) => format!("read {} Gaussians", g.len()),
            Err(e) => e.to_string(),
        }
    };
    // The rewritten zip itself reads as the original does.
    let same = sog::read_sog(&sog_with_meta(|_| {}), &Limits::default()).unwrap();
    assert!(same == sog::read_sog(&fixture("fruit_every8th_591.sog"), &Limits::default()).unwrap());
    type MetaEdit<'a> = &'a dyn Fn(&mut serde_json::Value);
    let cases: [(&str, MetaEdit); 11] = [
        ("version 1", &|m| {
            m.as_object_mut().unwrap().remove("version");
        }),
        ("version 3", &|m| m["version"] = 3.into()),
        ("pixels for 99999 Gaussians", &|m| {
            m["count"] = 99_999.into()
        }),
        ("past the palette", &|m| m["shN"]["count"] = 3.into()),
        ("shN.bands is 4", &|m| m["shN"]["bands"] = 4.into()),
        ("entries (1 to 256 expected)", &|m| {
            m["scales"]["codebook"] = serde_json::json!([])
        }),
        ("nowhere.webp", &|m| {
            m["quats"]["files"][0] = "nowhere.webp".into()
        }),
        // Codebooks cut short: the textures' bytes then index past their ends.
        ("scales: Gaussian 0 indexes entry", &|m| {
            m["scales"]["codebook"] = serde_json::json!([0.0])
        }),
        ("shN_centroids.webp: palette entry", &|m| {
            m["shN"]["codebook"] = serde_json::json!([0.0])
        }),
        // Numbers JSON holds but f32 cannot: refused, not decoded to infinities.
        ("which decodes to a position past f32", &|m| {
            m["means"]["maxs"][1] = 1e3.into()
        }),
        ("sh0.codebook holds 1e300", &|m| {
            m["sh0"]["codebook"][7] = 1e300.into()
        }),
    ];
    for (want, edit) in cases {
        let got = reason(edit);
        assert!(got.contains(want), "expected '{want}' in: {got}");
    }
    // A count past the limit is refused before any texture is decoded.
    let huge = sog_with_meta(|m| m["count"] = (1u64 << 40).into());
    let e = sog::read_sog(&huge, &Limits::tiny()).map(|g| g.len());
    assert!(format!("{e:?}").contains("SOG Gaussian count"), "{e:?}");
    // Truncated anywhere, the file fails cleanly.
    let good = fixture("fruit_every8th_591.sog");
    for cut in (0..good.len()).step_by(211) {
        assert!(
            sog::read_sog(&good[..cut], &Limits::default()).is_err(),
            "cut {cut}"
        );
    }
    // Bytes flipped inside the textures: an error or Gaussians, never a panic.
    for at in (0..good.len()).step_by(509) {
        let mut bad = good.clone();
        bad[at] ^= 0x5a;
        let _ = sog::read_sog(&bad, &Limits::tiny());
    }
}

#[test]
fn sog_reads_the_same_floats_on_any_thread_count() {
    let bytes = fixture("fruit_every8th_591.sog");
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| sog::read_sog(&bytes, &Limits::default()).unwrap())
    };
    let one = on(1);
    for threads in [2, 5] {
        assert!(on(threads) == one, "{threads} threads");
    }
}
