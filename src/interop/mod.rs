//! Readers and writers of the splat formats people already have (not part of `.dlgs`).
//!
//! The readers of `.splat` and SOG take logarithms and exponentials with the platform's libm
//! (not part of the `.dlgs` decode, whose floats are fixed by format-spec Appendix B): the SOG
//! reader so that it matches splat-transform's own decode bit for bit, tested on glibc.

pub mod ply;
pub mod sog;
pub mod sog_write;
pub mod splat;
pub mod spz;
pub mod spz_write;

use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::Gaussians;

/// Read a PLY, `.splat`, SPZ or PlayCanvas SOG file (a `.sog` zip, or the `meta.json` of an
/// unbundled SOG), chosen by extension (then by content), within the default [`Limits`].
pub fn read_splat_file(path: &std::path::Path) -> Result<Gaussians> {
    read_splat_file_with_limits(path, &Limits::default())
}

/// [`read_splat_file`] within `limits`: the file itself must fit `max_alloc`, and each reader
/// checks its counts and buffers against the same limits.
pub fn read_splat_file_with_limits(path: &std::path::Path, limits: &Limits) -> Result<Gaussians> {
    if path.file_name().and_then(|n| n.to_str()) == Some("meta.json") {
        return sog::read_sog_dir(path, limits);
    }
    let io = |e: std::io::Error| Error::io(format!("reading {}", path.display()), e, 0);
    let size = std::fs::metadata(path).map_err(io)?.len();
    limits.check_alloc("splat file size", size, 0)?;
    let data = std::fs::read(path).map_err(io)?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "ply" => ply::read_ply(&data, limits),
        "splat" => splat::read_splat(&data, limits),
        "spz" => spz::read_spz(&data, limits),
        _ if data.starts_with(b"ply") => ply::read_ply(&data, limits),
        _ if data.starts_with(&[0x1f, 0x8b]) => spz::read_spz(&data, limits),
        "sog" => sog::read_sog(&data, limits),
        _ if data.starts_with(b"PK\x03\x04") => sog::read_sog(&data, limits),
        _ => Err(Error::foreign(
            "splat",
            format!(
                "unknown file type (PLY, .splat, SPZ or SOG expected): {}",
                path.display()
            ),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reason_for(name: &str, bytes: &[u8]) -> String {
        let dir = std::env::temp_dir().join(format!("dlgs-interop-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        let err = read_splat_file(&path).unwrap_err();
        std::fs::remove_file(&path).unwrap();
        match err.format_kind() {
            Some(crate::FormatErrorKind::Foreign { reason, .. }) => reason.clone(),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_broken_sog_and_an_unknown_file_say_what_they_are() {
        let sog = reason_for("frame.sog", b"PK\x03\x04 not really a zip");
        assert!(sog.contains("not a readable zip"), "{sog}");
        let unknown = reason_for("frame.xyz", b"not a splat");
        assert!(
            unknown.contains("PLY, .splat, SPZ or SOG expected"),
            "{unknown}"
        );
    }
}
