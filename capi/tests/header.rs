//! The committed `include/dlgs.h` is exactly what cbindgen generates from `src/lib.rs`.
//! `DLGS_BLESS=1 cargo test -p dlgs-capi --test header` rewrites it after an API change.

#[test]
fn header_is_what_cbindgen_generates() {
    let dir = env!("CARGO_MANIFEST_DIR");
    let config = cbindgen::Config::from_file(format!("{dir}/cbindgen.toml")).unwrap();
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_crate(dir)
        .with_config(config)
        .generate()
        .expect("cbindgen runs")
        .write(&mut generated);
    let path = format!("{dir}/include/dlgs.h");
    if std::env::var_os("DLGS_BLESS").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let committed = std::fs::read(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "{path} is stale: run DLGS_BLESS=1 cargo test -p dlgs-capi --test header"
    );
    let text = String::from_utf8(generated).unwrap();
    for f in [
        "dlgs_open_path",
        "dlgs_open_memory",
        "dlgs_info",
        "dlgs_decode_frame",
        "dlgs_decode_frame_view",
        "DlgsView",
        "dlgs_last_error",
        "dlgs_close",
    ] {
        assert!(text.contains(f), "{f} missing from the header");
    }
}
