//! What the C-program tests share: the checksum both sides print, and building an example
//! program against this build's cdylib.

use std::path::{Path, PathBuf};
use std::process::Command;

/// FNV-1a over the little-endian bytes of `floats`, continuing from `h` (the C examples'
/// checksum).
pub fn fnv1a(mut h: u64, floats: &[f32]) -> u64 {
    for v in floats {
        for b in v.to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(1_099_511_628_211);
        }
    }
    h
}

/// The directory that holds `libdlgs_capi.so` for this build (next to the test binary).
fn library_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap();
    for d in [deps, deps.parent().unwrap()] {
        if d.join("libdlgs_capi.so").exists() {
            return d.to_path_buf();
        }
    }
    panic!("libdlgs_capi.so not found next to {}", exe.display());
}

/// `examples/{name}.c` compiled with the system C compiler (`CC`, default `cc`), warnings as
/// errors, linked against the cdylib; the executable is written into `out`.
pub fn compile_example(name: &str, out: &Path) -> PathBuf {
    let dir = env!("CARGO_MANIFEST_DIR");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let exe = out.join(name);
    let lib = library_dir();
    let status = Command::new(&cc)
        .args(["-O2", "-Wall", "-Wextra", "-Werror", "-std=c11"])
        .arg(format!("{dir}/examples/{name}.c"))
        .arg(format!("-I{dir}/include"))
        .arg(format!("-L{}", lib.display()))
        .arg("-ldlgs_capi")
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-o")
        .arg(&exe)
        .status()
        .unwrap_or_else(|e| panic!("running the C compiler `{cc}` (set CC): {e}"));
    assert!(status.success(), "compiling examples/{name}.c failed");
    exe
}
