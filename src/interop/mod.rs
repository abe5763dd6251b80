//! Readers and writers of the splat formats people already have (not part of `.dlgs`).

pub mod ply;
pub mod splat;
pub mod spz;
pub mod spz_write;

use crate::error::{Error, ErrorKind, Result};
use crate::limits::Limits;
use crate::model::Gaussians;

/// Read a PLY, `.splat` or SPZ file, chosen by extension (then by content).
pub fn read_splat_file(path: &std::path::Path) -> Result<Gaussians> {
    let data = std::fs::read(path)
        .map_err(|e| Error::new(ErrorKind::Io(format!("{}: {e}", path.display())), 0))?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "ply" => ply::read_ply(&data),
        "splat" => splat::read_splat(&data),
        "spz" => spz::read_spz(&data, &Limits::default()),
        _ if data.starts_with(b"ply") => ply::read_ply(&data),
        _ if data.starts_with(&[0x1f, 0x8b]) => spz::read_spz(&data, &Limits::default()),
        // PlayCanvas SOG (a zip of WebP images): the format we compete with, not one we read.
        "sog" => Err(Error::new(
            ErrorKind::Foreign {
                format: "splat",
                reason: format!(
                    "{}: PlayCanvas SOG is not read; convert it to PLY first, e.g. \
                     `npx @playcanvas/splat-transform {} scene.ply`",
                    path.display(),
                    path.display()
                ),
            },
            0,
        )),
        _ => Err(Error::new(
            ErrorKind::Foreign {
                format: "splat",
                reason: format!(
                    "unknown file type (PLY, .splat or SPZ expected): {}",
                    path.display()
                ),
            },
            0,
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
        match err.kind {
            ErrorKind::Foreign { reason, .. } => reason,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn sog_and_unknown_files_are_told_apart_in_the_error() {
        let sog = reason_for("frame.sog", b"PK\x03\x04 zip of WebP images");
        assert!(sog.contains("PlayCanvas SOG is not read"), "{sog}");
        assert!(sog.contains("splat-transform"), "{sog}");
        let unknown = reason_for("frame.xyz", b"not a splat");
        assert!(unknown.contains("PLY, .splat or SPZ expected"), "{unknown}");
    }
}
