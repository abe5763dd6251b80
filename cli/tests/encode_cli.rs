//! `dlgs encode` end to end through the binary: octree or grid positions, `--fast-decode`
//! (checked with `info --channels`), failed and in-place encodes, a real SOG frame, and what
//! still scenes and streams code by default.

mod dlgs_binary;

use dlgs_binary::{dlgs, dlgs_fails, SCENE};

#[test]
fn encode_octree_positions_by_default_and_grid_positions_on_request() {
    // Format 1.10: the default codes static positions as an octree (CSOG layout 2);
    // `--grid-positions` keeps them in the grid (layout 0). Same quantised values, so both
    // render alike; the octree file is smaller on this real scene.
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let path = |n: &str| tmp.path().join(n).to_str().unwrap().to_owned();
    let (octree, grid) = (path("octree.dlgs"), path("grid.dlgs"));
    dlgs(&["encode", scene, "-o", &octree, "--quality", "medium"]);
    let g = ["encode", scene, "-o", &grid, "--quality", "medium"];
    dlgs(&[&g[..], &["--grid-positions"]].concat());
    let size = |p: &str| std::fs::metadata(p).unwrap().len();
    assert!(
        size(&octree) < size(&grid),
        "{} vs {}",
        size(&octree),
        size(&grid)
    );
    let psnr = |p: &str| -> f64 {
        let cmp = dlgs(&["compare", scene, p, "--json", "--orbit", "2"]);
        serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
            .as_f64()
            .unwrap()
    };
    let (a, b) = (psnr(&octree), psnr(&grid));
    assert!((a - b).abs() < 0.05 && a > 45.0, "{a} vs {b} dB");
    let err = dlgs_fails(&[&g[..], &["--sort-passes", "2"]].concat());
    assert!(err.contains("--grid-positions"), "{err}");
    dlgs(&[&g[..], &["--grid-positions", "--sort-passes", "2"]].concat());
    // Format 1.11: octree files are layout 3 with coarse rotations at factor 1 by default;
    // at factor 8 most of this scene's Gaussians turn coarser, so the file shrinks and the
    // image moves a little. Factor 0 writes layout 2.
    let coarse = path("coarse.dlgs");
    let c = ["encode", scene, "-o", &coarse, "--quality", "medium"];
    dlgs(&[&c[..], &["--coarse-rotations", "8"]].concat());
    assert!(
        size(&coarse) < size(&octree),
        "{} vs {}",
        size(&coarse),
        size(&octree)
    );
    let p = psnr(&coarse);
    assert!(p < a && p > a - 6.0, "{p} vs {a} dB");
    dlgs(&[&c[..], &["--coarse-rotations", "0"]].concat());
    let err = dlgs_fails(&[&g[..], &["--grid-positions", "--coarse-rotations", "1"]].concat());
    assert!(err.contains("octree positions"), "{err}");
    let err = dlgs_fails(&[&c[..], &["--coarse-rotations=-1"]].concat());
    assert!(err.contains("factor >= 0"), "{err}");
}

#[test]
fn fast_decode_codes_the_same_levels_without_mixed_contexts() {
    // The default (fast decoding, also `--fast-decode`) leaves codec 5's mixed modes out: on
    // this real scene at `high` `--max-compression` takes them (the file is smaller) and both
    // decode to the same Gaussians, octree positions and grid positions (layout 1 then, one
    // part) alike.
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let path = |n: &str| tmp.path().join(n).to_str().unwrap().to_owned();
    let size = |p: &str| std::fs::metadata(p).unwrap().len();
    let ply = |f: &str| {
        let p = format!("{f}.ply");
        dlgs(&["decode", f, "-o", &p]);
        std::fs::read(p).unwrap()
    };
    for extra in [&[][..], &["--grid-positions"][..]] {
        let (mixed, fast) = (path("mixed.dlgs"), path("fast.dlgs"));
        let e = ["encode", scene, "--quality", "high", "--no-meta"];
        dlgs(&[&e[..], &["-o", &mixed, "--max-compression"], extra].concat());
        dlgs(&[&e[..], &["-o", &fast], extra].concat());
        let named = path("named.dlgs");
        dlgs(&[&e[..], &["-o", &named, "--fast-decode"], extra].concat());
        assert_eq!(
            std::fs::read(&named).unwrap(),
            std::fs::read(&fast).unwrap()
        );
        assert!(
            size(&mixed) < size(&fast),
            "{extra:?}: {} vs {}",
            size(&mixed),
            size(&fast)
        );
        assert!(ply(&mixed) == ply(&fast), "{extra:?}");
        // `dlgs info --channels` shows it: no channel of the fast file takes mode 5 or 6.
        let codings = |f: &str| -> Vec<String> {
            let info = channel_info(f);
            let records = info["csog"][0]["records"].as_array().unwrap().clone();
            records
                .iter()
                .map(|r| r["coding"].as_str().unwrap().to_owned())
                .collect()
        };
        let mixed_modes = |c: &[String]| {
            c.iter()
                .filter(|c| c.contains("(mode 5)") || c.contains("(mode 6)"))
                .count()
        };
        let (cm, cf) = (codings(&mixed), codings(&fast));
        assert!(mixed_modes(&cm) > 0, "{extra:?}: {cm:?}");
        assert_eq!(mixed_modes(&cf), 0, "{extra:?}: {cf:?}");
        let octree = cm.iter().filter(|c| *c == "octree").count();
        assert_eq!(octree > 0, extra.is_empty(), "{extra:?}: {cm:?}");
        // The table a person reads: one row per record, then the bytes by attribute.
        let text = dlgs(&["info", &mixed, "--channels"]);
        let rows = text
            .lines()
            .filter(|l| l.starts_with("    static "))
            .count();
        assert_eq!(rows, cm.len(), "{text}");
        for says in ["bits/G  coding", "by attribute:", "sh_dc", "record heads"] {
            assert!(text.contains(says), "{says}: {text}");
        }
    }
    let lossless = ["--quality", "lossless"];
    let err = dlgs_fails(
        &[
            &["encode", scene, "-o", &path("x.dlgs"), "--fast-decode"],
            &lossless[..],
        ]
        .concat(),
    );
    assert!(err.contains("lossy --quality"), "{err}");

    // `--mixed-margin`: between the two. A 5 % margin lets fewer channels take the mixed
    // modes than --max-compression's 1 %, for a file between the two sizes, with the same
    // Gaussians.
    let e = ["encode", scene, "--quality", "high", "--no-meta", "-o"];
    let (one, five, none) = (path("m1.dlgs"), path("m5.dlgs"), path("m0.dlgs"));
    dlgs(&[&e[..], &[&one, "--max-compression"]].concat());
    dlgs(&[&e[..], &[&five, "--mixed-margin", "5"]].concat());
    dlgs(&[&e[..], &[&none]].concat());
    let mixed_records = |f: &str| {
        channel_info(f)["csog"][0]["records"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| {
                let c = r["coding"].as_str().unwrap();
                c.contains("(mode 5)") || c.contains("(mode 6)")
            })
            .count()
    };
    let (m1, m5) = (mixed_records(&one), mixed_records(&five));
    assert!(m1 > m5, "{m1} vs {m5} mixed records");
    assert!(
        size(&one) < size(&five) && size(&five) < size(&none),
        "{} {} {}",
        size(&one),
        size(&five),
        size(&none)
    );
    assert!(ply(&one) == ply(&five));
    let x = path("x.dlgs");
    let err = dlgs_fails(&[&e[..], &[&x, "--mixed-margin", "5", "--fast-decode"]].concat());
    assert!(err.contains("cannot be used with"), "{err}");
    let err = dlgs_fails(&[&e[..], &[&x, "--mixed-margin", "5", "--max-compression"]].concat());
    assert!(err.contains("cannot be used with"), "{err}");
    let err = dlgs_fails(&[&e[..], &[&x, "--mixed-margin", "200"]].concat());
    assert!(err.contains("from 0 to 100"), "{err}");
    let err = dlgs_fails(&[
        "encode",
        scene,
        "-o",
        &x,
        "--mixed-margin",
        "5",
        "--quality",
        "lossless",
    ]);
    assert!(err.contains("lossy --quality"), "{err}");
}

/// `dlgs info FILE --channels --json`, checked against the file: one `CSOG` chunk whose
/// parts hold every static Gaussian and whose records' bytes, with the record heads, make up
/// the chunk's payload.
fn channel_info(f: &str) -> serde_json::Value {
    let info: serde_json::Value =
        serde_json::from_str(&dlgs(&["info", f, "--channels", "--json"])).unwrap();
    let csog = info["csog"].as_array().unwrap();
    assert_eq!(csog.len(), 1, "{info}");
    let payload = csog[0]["payload_bytes"].as_u64().unwrap();
    assert_eq!(Some(payload), info["chunk_bytes_by_type"]["CSOG"].as_u64());
    let records = csog[0]["records"].as_array().unwrap();
    let coded: u64 = records.iter().map(|r| r["bytes"].as_u64().unwrap()).sum();
    // Heads, ranges and counts: a few bytes per record (14 in layout 1's full records).
    assert!(
        coded < payload && payload - coded < 16 * records.len() as u64,
        "{coded} of {payload}"
    );
    let mut parts: Vec<(u64, u64)> = records
        .iter()
        .filter(|r| r["set"] == "static")
        .map(|r| {
            (
                r["part"].as_u64().unwrap(),
                r["gaussians"].as_u64().unwrap(),
            )
        })
        .collect();
    parts.dedup();
    let n: u64 = parts.iter().map(|p| p.1).sum();
    assert_eq!(Some(n), info["header"]["n_static"].as_u64(), "{parts:?}");
    info
}

#[test]
fn a_failed_encode_leaves_no_file_and_an_in_place_re_encode_reads_its_input_first() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let out = tmp.path().join("x.dlgs");
    let out_s = out.to_str().unwrap();
    let listing = || {
        let mut names: Vec<String> = std::fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    };
    // Rejected settings: nothing is created, not even an empty file or a temporary one.
    let err = dlgs_fails(&["encode", scene, "-o", out_s, "--tiers", "0.1,0.2"]);
    assert!(err.contains("must not increase"), "{err}");
    let err = dlgs_fails(&[
        "encode",
        scene,
        "-o",
        out_s,
        "--refit-colours",
        "--quality",
        "lossless",
    ]);
    assert!(
        err.contains("--refit-colours refits the colours of a lossy coding"),
        "{err}"
    );
    assert!(listing().is_empty(), "{:?}", listing());
    // An existing output survives a failed encode unchanged.
    dlgs(&["encode", scene, "-o", out_s, "--quality", "high"]);
    let before = std::fs::read(&out).unwrap();
    dlgs_fails(&["encode", "/nonexistent/scene.ply", "-o", out_s]);
    assert_eq!(std::fs::read(&out).unwrap(), before);
    assert_eq!(listing(), ["x.dlgs"]);
    // Re-encoding a stream into itself: the input is read before it is replaced.
    let text = dlgs(&["encode", out_s, "-o", out_s, "--quality", "low"]);
    assert!(text.contains("% of input"), "{text}");
    let after = std::fs::read(&out).unwrap();
    assert!(
        after.len() < before.len(),
        "{} vs {}",
        after.len(),
        before.len()
    );
    dlgs(&["verify", out_s]);
    assert_eq!(listing(), ["x.dlgs"]);
}

#[test]
fn a_real_sog_frame_encodes_and_compares_bundled_or_not() {
    // The wave sequence's frames are PlayCanvas SOG v2 files nobody here wrote.
    let tmp = tempfile::tempdir().unwrap();
    let sog = dlgs_tests::data("sequence/playcanvas_wave_200f/wave_0001.sog");
    let sog = sog.to_str().unwrap();
    let path = |n: &str| tmp.path().join(n).to_str().unwrap().to_owned();
    let out = dlgs(&[
        "encode",
        sog,
        "-o",
        &path("a.dlgs"),
        "--quality",
        "medium",
        "--no-meta",
    ]);
    assert!(out.contains("% of input"), "{out}");
    let cmp = dlgs(&["compare", sog, &path("a.dlgs"), "--json", "--orbit", "2"]);
    let psnr = serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
        .as_f64()
        .unwrap();
    assert!(psnr > 55.0, "{psnr} dB");
    // The same frame unbundled (meta.json beside its textures) codes to the same file, and its
    // size is reported against all of its files, as the zip's is.
    let dir = tmp.path().join("unbundled");
    std::fs::create_dir(&dir).unwrap();
    let mut zip = zip::ZipArchive::new(std::fs::File::open(sog).unwrap()).unwrap();
    zip.extract(&dir).unwrap();
    let meta = dir.join("meta.json");
    let out_unbundled = dlgs(&[
        "encode",
        meta.to_str().unwrap(),
        "-o",
        &path("b.dlgs"),
        "--quality",
        "medium",
        "--no-meta",
    ]);
    // (`--no-meta`: the META chunk would name the two source files.)
    assert!(std::fs::read(path("a.dlgs")).unwrap() == std::fs::read(path("b.dlgs")).unwrap());
    let percent = |s: &str| -> f64 {
        let at = s.find("% of input").unwrap();
        s[..at].rsplit('(').next().unwrap().parse().unwrap()
    };
    let (a, b) = (percent(&out), percent(&out_unbundled));
    assert!((a - b).abs() < 2.0, "{a} % vs {b} %");
    // A damaged SOG names what is wrong.
    std::fs::write(path("bad.sog"), b"PK\x03\x04 not a zip").unwrap();
    let err = dlgs_fails(&["encode", &path("bad.sog"), "-o", &path("c.dlgs")]);
    assert!(err.contains("SOG: not a readable zip"), "{err}");
}

#[test]
fn still_scenes_encode_lossy_by_default_and_streams_stay_lossless() {
    // A codec asked to encode a still scene gives a visually lossless file (preset `high`);
    // `--quality lossless` keeps every float; re-encoding a `.dlgs` keeps its values.
    let tmp = tempfile::tempdir().unwrap();
    let scene = dlgs_tests::data(SCENE);
    let scene = scene.to_str().unwrap();
    let path = |n: &str| tmp.path().join(n).to_str().unwrap().to_owned();
    let canonical_chunk = |f: &str| {
        let info: serde_json::Value = serde_json::from_str(&dlgs(&["info", f, "--json"])).unwrap();
        let gop = &info["chunk_bytes_by_type"];
        ["CSOG", "CRAW"]
            .into_iter()
            .find(|c| gop.get(c).is_some())
            .unwrap_or_else(|| panic!("{info}"))
    };
    dlgs(&["encode", scene, "-o", &path("default.dlgs"), "--no-meta"]);
    dlgs(&[
        "encode",
        scene,
        "-o",
        &path("high.dlgs"),
        "--no-meta",
        "--quality",
        "high",
    ]);
    dlgs(&[
        "encode",
        scene,
        "-o",
        &path("exact.dlgs"),
        "--quality",
        "lossless",
    ]);
    assert_eq!(canonical_chunk(&path("default.dlgs")), "CSOG");
    assert!(
        std::fs::read(path("default.dlgs")).unwrap() == std::fs::read(path("high.dlgs")).unwrap(),
        "the default is `--quality high`"
    );
    assert_eq!(canonical_chunk(&path("exact.dlgs")), "CRAW");
    let size = |f: &str| std::fs::metadata(f).unwrap().len();
    assert!(size(&path("default.dlgs")) * 3 < size(&path("exact.dlgs")));
    let cmp = dlgs(&[
        "compare",
        scene,
        &path("default.dlgs"),
        "--json",
        "--orbit",
        "2",
    ]);
    let psnr = serde_json::from_str::<serde_json::Value>(&cmp).unwrap()["mean_psnr"]
        .as_f64()
        .unwrap();
    assert!(psnr > 45.0, "{psnr} dB");
    // Re-encoding a stream without --quality keeps the canonical floats.
    dlgs(&["encode", &path("exact.dlgs"), "-o", &path("again.dlgs")]);
    assert_eq!(canonical_chunk(&path("again.dlgs")), "CRAW");
}
