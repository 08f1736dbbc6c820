//! Output folders written all at once: everything goes to a hidden sibling folder that replaces
//! the destination only when complete, so a failed command leaves no partial output, and an
//! existing non-empty destination is replaced only with `--force`.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

pub struct StagedFolder {
    destination: PathBuf,
    staging: PathBuf,
}

impl StagedFolder {
    /// Prepare to write `destination`; fails if it holds files and `force` is off.
    pub fn new(destination: &Path, force: bool) -> Result<Self> {
        if destination.exists() {
            let non_empty = std::fs::read_dir(destination)
                .map_err(|e| Error::io(destination, e))?
                .next()
                .is_some();
            if non_empty && !force {
                return Err(Error::invalid(
                    destination,
                    "output",
                    "folder exists and is not empty; pass --force to replace it",
                ));
            }
        }
        let name = destination
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out".into());
        let parent = destination
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        let staging = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(|e| Error::io(&staging, e))?;
        }
        std::fs::create_dir(&staging).map_err(|e| Error::io(destination, e))?;
        Ok(StagedFolder {
            destination: destination.to_path_buf(),
            staging,
        })
    }

    /// Where to write a file that will end up as `destination/name`.
    pub fn path(&self, name: &str) -> PathBuf {
        self.staging.join(name)
    }

    /// Move the complete folder into place.
    pub fn commit(self) -> Result<()> {
        if self.destination.exists() {
            std::fs::remove_dir_all(&self.destination)
                .map_err(|e| Error::io(&self.destination, e))?;
        }
        std::fs::rename(&self.staging, &self.destination)
            .map_err(|e| Error::io(&self.destination, e))?;
        std::mem::forget(self);
        Ok(())
    }
}

impl Drop for StagedFolder {
    /// An abandoned staging folder (an error on the way) is removed.
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.staging);
    }
}

/// Refuse to overwrite an existing file without `--force`.
pub fn check_overwrite(path: &Path, force: bool) -> Result<()> {
    if path.exists() && !force {
        return Err(Error::invalid(
            path,
            "output",
            "file exists; pass --force to replace it",
        ));
    }
    Ok(())
}
