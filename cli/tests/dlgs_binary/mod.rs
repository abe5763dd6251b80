//! Running the `dlgs` binary in the CLI's integration tests, and the real scene they code.

use std::process::Command;

pub const SCENE: &str = "ply/gs3d-fork_lod3_tile_0_1971_sh3.ply";

pub fn dlgs(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_dlgs"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "dlgs {}: {text}{}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

pub fn dlgs_fails(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_dlgs"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    assert!(!out.status.success(), "dlgs {} should fail", args.join(" "));
    String::from_utf8_lossy(&out.stderr).into_owned()
}
