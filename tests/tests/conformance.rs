//! Walks format-spec/vectors: valid files decode to the listed checksums (both readers),
//! invalid files fail with the listed error, and the committed files are exactly what the
//! generator builds today (so spec, vectors and code change together).

use std::collections::BTreeMap;
use std::path::PathBuf;

use dlgs::chunks::craw::canonical_digest;
use dlgs::Limits;
use dlgs_tests::{decode_all_random, decode_all_stream, vectors};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../format-spec/vectors")
}

fn table(file: &str) -> Vec<Vec<String>> {
    std::fs::read_to_string(root().join(file))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(str::to_string).collect())
        .collect()
}

#[test]
fn valid_vectors_decode_to_the_listed_checksums() {
    let mut want: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for row in table("expected.txt") {
        want.entry(row[0].clone()).or_default().push(row[2].clone());
    }
    assert!(want.len() >= 4);
    for (name, sums) in &want {
        let bytes = std::fs::read(root().join("valid").join(format!("{name}.dlgs"))).unwrap();
        for gops in [
            decode_all_random(&bytes, Limits::default()).unwrap(),
            decode_all_stream(&bytes, Limits::default()).unwrap(),
        ] {
            let got: Vec<String> = gops.iter().map(canonical_digest).collect();
            assert_eq!(&got, sums, "{name}");
        }
    }
}

#[test]
fn invalid_vectors_fail_with_the_listed_error() {
    let rows = table("expected-errors.txt");
    assert!(rows.len() >= 8);
    for row in rows {
        let bytes = std::fs::read(root().join("invalid").join(format!("{}.dlgs", row[0]))).unwrap();
        let e = decode_all_random(&bytes, Limits::default()).expect_err(&row[0]);
        assert_eq!(e.name(), row[1], "{} (random access): {e}", row[0]);
        let e = decode_all_stream(&bytes, Limits::default()).expect_err(&row[0]);
        // The stream reader cannot see a missing tail before reading the body, so it may name
        // the first problem it meets; both must fail. A third column names the stream
        // reader's error where §5.3 gives it another.
        if row[0] != "x-truncated" {
            let want = row.get(2).unwrap_or(&row[1]).as_str();
            assert_eq!(e.name(), want, "{} (stream): {e}", row[0]);
        }
        assert_eq!(
            row.get(2).map(String::as_str),
            vectors::errors::stream_error(&row[0]),
            "{}",
            row[0]
        );
    }
}

#[test]
fn committed_vectors_equal_what_the_generator_builds() {
    // The HEVC vectors hold libx265 output, which may differ between x265 builds; their
    // frames are checked against the listed ones instead.
    for v in vectors::all()
        .into_iter()
        .filter(|v| !vectors::X265_VECTORS.contains(&v.name))
    {
        let dir = if v.error.is_some() {
            "invalid"
        } else {
            "valid"
        };
        let on_disk = std::fs::read(root().join(dir).join(format!("{}.dlgs", v.name))).unwrap();
        assert!(
            on_disk == v.bytes,
            "{dir}/{}.dlgs is stale: run `cargo run -p dlgs-tests --bin gen_vectors`",
            v.name
        );
    }
}

/// A valid vector's bytes and its listed decoded values (`valid/<name>.<kind>.f32`).
fn vector_and_values(name: &str, kind: &str) -> (Vec<u8>, Vec<f32>) {
    let valid = root().join("valid");
    let bytes = std::fs::read(valid.join(format!("{name}.dlgs"))).unwrap();
    let values = std::fs::read(valid.join(format!("{name}.{kind}.f32")))
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    (bytes, values)
}

fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn dynamic_vectors_decode_to_the_listed_frames() {
    for name in vectors::FRAME_VECTORS {
        dynamic_vector_decodes_to_its_frames(name);
    }
}

fn dynamic_vector_decodes_to_its_frames(name: &str) {
    let (bytes, want) = vector_and_values(name, "frames");
    let got = vectors::dynamic_frames(&bytes);
    // N dynamic Gaussians (128; 32 in the smaller vectors) x (3+3+4+1+1+48+9) values x 5 times.
    let n = dlgs::FileReader::open(std::io::Cursor::new(&bytes))
        .unwrap()
        .scene()
        .n_dynamic as usize;
    assert!(n == 128 || n == 32, "{name}: {n} dynamic Gaussians");
    assert_eq!(got.len(), n * 69 * vectors::FRAME_TIMES.len());
    assert_eq!(got.len(), want.len());
    let worst = max_abs_diff(&got, &want);
    println!("{name}: max |decoded - listed| = {worst:e}");
    assert!(worst <= vectors::FRAME_TOLERANCE, "{worst}");
    // Since 1.15 sin and acos are the format's own (Appendix B): this decoder gives the listed
    // bits on every platform, not just values within the tolerance.
    let differing = got
        .iter()
        .zip(&want)
        .filter(|(a, b)| a.to_bits() != b.to_bits())
        .count();
    assert_eq!(
        differing, 0,
        "{name}: values not bit for bit the listed ones"
    );
    // The frames move: the listed times are not all the same frame.
    let per_time = want.len() / vectors::FRAME_TIMES.len();
    assert!(want[..per_time] != want[per_time..2 * per_time]);
}

#[test]
fn language_decoder_vector_decodes_to_the_listed_embeddings() {
    let name = vectors::LAED_VECTOR;
    let (bytes, want) = vector_and_values(name, "embeddings");
    let got = vectors::laed_embeddings(&bytes);
    // 3 Gaussians x 3 levels x 16 dims, then 2 negatives x 16.
    assert_eq!(got.len(), 3 * 3 * 16 + 2 * 16);
    assert_eq!(got.len(), want.len());
    let worst = max_abs_diff(&got, &want);
    assert!(worst <= 1e-6, "{name}: max |decoded - listed| = {worst:e}");
    // Unit vectors (or zero for an all-zero feature; negatives are stored in f16, so only
    // unit to f16 precision), and not all the same.
    for (k, e) in got.chunks_exact(16).enumerate() {
        let n = e.iter().map(|x| x * x).sum::<f32>().sqrt();
        let tol = if k < 9 { 1e-5 } else { 1e-3 };
        assert!(n == 0.0 || (n - 1.0).abs() < tol, "embedding {k}: norm {n}");
    }
    assert!(got[..16] != got[16..32]);
}

#[test]
fn path_vectors_still_take_their_paths() {
    // Each vector of `vectors::paths` exists for one decoding path (a grid codec, a codec-5
    // mode, an RDLT codec, an RNTC scope, a deform model, a TFEA codec): check the committed
    // file still takes it, so a change to the writer cannot quietly drop the coverage.
    let mut checked = 0;
    for row in table("expected.txt") {
        if row[1] != "0" {
            continue;
        }
        let bytes = std::fs::read(root().join("valid").join(format!("{}.dlgs", row[0]))).unwrap();
        if let Some(r) = vectors::paths::claims(&row[0], &bytes) {
            r.unwrap();
            checked += 1;
        }
    }
    assert_eq!(checked, 14);
}

/// The `LIFE` vector's listed frames (since 1.18, §6.14): exactly the Gaussians its entries
/// hide at each listed time have colour and language opacity `-1e4`; every other dynamic
/// Gaussian keeps an opacity the decoders give (the frames equal the decoder's bit for bit,
/// checked above).
#[test]
fn life_vector_hides_exactly_the_gaussians_outside_their_frames() {
    let (bytes, want) = vector_and_values(vectors::paths::LIFE_VECTOR, "frames");
    let scene = dlgs::FileReader::open(std::io::Cursor::new(&bytes))
        .unwrap()
        .scene()
        .clone();
    let n = scene.n_dynamic as usize;
    let per_time = n * 69;
    let mut hidden_seen = 0;
    for (k, &t) in vectors::FRAME_TIMES.iter().enumerate() {
        // §4.3, §6.4: the frame shown at t, its GOP, the GOP-local frame.
        let f = ((t * scene.fps()) + 1e-6).floor() as u32;
        let f = f.min(scene.frame_count - 1);
        let g = (f / scene.gop_length).min(scene.gop_count - 1);
        let local = f - g * scene.gop_length;
        let frame = &want[k * per_time..(k + 1) * per_time];
        let (opacity, lang_opacity) = (&frame[10 * n..11 * n], &frame[11 * n..12 * n]);
        for i in 0..n {
            let hidden = vectors::paths::LIVES[g as usize]
                .iter()
                .any(|&(j, first, last)| {
                    j as usize == i && !(first as u32 <= local && local <= last as u32)
                });
            let at = (opacity[i].to_bits(), lang_opacity[i].to_bits());
            if hidden {
                hidden_seen += 1;
                assert_eq!(at, (0xC61C_4000, 0xC61C_4000), "t {t} Gaussian {i}");
            } else {
                assert!(
                    opacity[i] > -1e3 && lang_opacity[i] > -1e3,
                    "t {t} Gaussian {i}"
                );
            }
        }
    }
    // t 0: 3 and 12; 0.5: 3, 7, 12; 1.2345: 7, 12; 2.0: 20; 3.95: 3.
    assert_eq!(hidden_seen, 9);
}

/// The Scaffold-GS vectors: the committed files are what the generator builds; the valid one
/// decodes to its listed frames bit for bit (the reference decoder) and the invalid ones fail
/// with the listed error through the Scaffold-GS decoder.
#[test]
fn scaffold_vectors_decode_to_their_frames_and_errors() {
    use dlgs_decoder::scaffold::ScaffoldDecoder;
    let listed = table("expected-scaffold.txt");
    let built = vectors::scaffold::all();
    assert_eq!(listed.len(), built.len());
    let mut claims = 0;
    for (row, v) in listed.iter().zip(&built) {
        assert_eq!(row[0], v.name);
        let dir = if v.error.is_some() {
            "invalid"
        } else {
            "valid"
        };
        let bytes = std::fs::read(root().join(dir).join(format!("{}.dlgs", v.name))).unwrap();
        assert!(
            bytes == v.bytes,
            "{dir}/{}.dlgs is stale: run gen_vectors",
            v.name
        );
        match v.error {
            None => {
                let (_, want) = vector_and_values(v.name, "frames");
                assert_eq!(
                    vectors::scaffold::frames(v.name, &bytes),
                    want,
                    "{}",
                    v.name
                );
                // The in-order decoder gives the same frames (bit for bit).
                assert_eq!(
                    vectors::scaffold::stream_frames(v.name, &bytes).unwrap(),
                    want,
                    "{} (stream)",
                    v.name
                );
                assert!(want[0] > 0.0, "frames with children");
                if let Some(r) = vectors::scaffold::claims(v.name, &bytes) {
                    r.unwrap();
                    claims += 1;
                }
            }
            Some(e) => {
                let got = ScaffoldDecoder::new(std::io::Cursor::new(&bytes), Limits::default())
                    .and_then(|mut d| {
                        (0..d.scene().gop_count).try_for_each(|g| d.gop(g).map(|_| ()))
                    })
                    .expect_err(v.name);
                assert_eq!(got.name(), e, "{}: {got}", v.name);
                assert_eq!(row[1], e);
                let got = vectors::scaffold::stream_frames(v.name, &bytes).expect_err(v.name);
                assert_eq!(got.name(), e, "{} (stream): {got}", v.name);
            }
        }
    }
    assert_eq!(
        claims, 3,
        "the AHAC scope 1, dense AHAC and refresh vectors"
    );
}
