//! Outputs that appear only when complete. A long encode writes to a temporary file beside its
//! target and renames it over the target at the end, so an error or an interrupted run leaves
//! no truncated `.dlgs` behind, an existing file is kept until its replacement is whole, and
//! `dlgs encode x.dlgs -o x.dlgs` reads its input before replacing it.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

pub struct PendingFile {
    tmp: tempfile::NamedTempFile,
    path: PathBuf,
}

impl PendingFile {
    pub fn create(path: &Path) -> Result<PendingFile> {
        // Same directory, so the final rename stays on one file system.
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let tmp = tempfile::Builder::new()
            .prefix(".dlgs-")
            .suffix(".partial")
            .tempfile_in(dir)
            .with_context(|| format!("creating a temporary file for {}", path.display()))?;
        Ok(PendingFile {
            tmp,
            path: path.to_path_buf(),
        })
    }

    /// A buffered writer into the temporary file (flush it before [`PendingFile::commit`]).
    pub fn writer(&self) -> Result<BufWriter<File>> {
        let f =
            self.tmp.as_file().try_clone().with_context(|| {
                format!("opening the temporary file for {}", self.path.display())
            })?;
        Ok(BufWriter::new(f))
    }

    /// Flush `w` (from [`PendingFile::writer`]) and [`commit`](PendingFile::commit).
    pub fn commit_written(self, mut w: BufWriter<File>) -> Result<()> {
        std::io::Write::flush(&mut w)
            .with_context(|| format!("writing {}", self.path.display()))?;
        drop(w);
        self.commit()
    }

    /// Move the finished file into place. Dropping a `PendingFile` instead deletes it.
    pub fn commit(self) -> Result<()> {
        // Temporary files are private (0600); outputs get the usual 0644.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            self.tmp
                .as_file()
                .set_permissions(std::fs::Permissions::from_mode(0o644))
                .with_context(|| format!("setting permissions of {}", self.path.display()))?;
        }
        let path = self.path;
        self.tmp
            .persist(&path)
            .map_err(|e| e.error)
            .with_context(|| format!("writing {}", path.display()))?;
        Ok(())
    }
}
