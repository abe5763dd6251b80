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
        _ => Err(Error::new(
            ErrorKind::Foreign {
                format: "splat",
                reason: format!("unknown file type: {}", path.display()),
            },
            0,
        )),
    }
}
