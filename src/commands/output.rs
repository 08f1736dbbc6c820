//! Outputs written all at once, never over an existing result without `--force`.
//!
//! | output | how |
//! | --- | --- |
//! | a folder ([`StagedFolder`]) | written to a hidden sibling folder that replaces the destination only when complete; folders created on the way to it are removed again if the command fails |
//! | a file | checked first ([`check_output_file`], [`check_overwrite`]), then written with [`crate::capture::atomic_file::write_atomically`] (temporary file beside it, then rename) |
//!
//! So a failed command leaves no partial output and no stray temporary file, and an existing
//! file or non-empty folder is replaced only with `--force`. Errors say what to do.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

pub struct StagedFolder {
    destination: PathBuf,
    staging: PathBuf,
    /// Folders that did not exist and were created to hold the destination, outermost first.
    created: Vec<PathBuf>,
}

impl StagedFolder {
    /// Prepare to write `destination`; fails if it holds files and `force` is off, or if it
    /// cannot be a folder.
    pub fn new(destination: &Path, force: bool) -> Result<Self> {
        if destination.exists() {
            if !destination.is_dir() {
                return Err(Error::invalid(
                    destination,
                    "output",
                    "is a file, but the output is a folder; choose another output path",
                ));
            }
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
        let parent = folder_of(destination);
        let folder = StagedFolder {
            destination: destination.to_path_buf(),
            staging: parent.join(format!(".{name}.partial-{}", std::process::id())),
            created: create_folders(parent)?,
        };
        if folder.staging.exists() {
            std::fs::remove_dir_all(&folder.staging).map_err(|e| Error::io(&folder.staging, e))?;
        }
        std::fs::create_dir(&folder.staging).map_err(|e| Error::io(destination, e))?;
        Ok(folder)
    }

    /// Where to write a file that will end up as `destination/name`.
    pub fn path(&self, name: &str) -> PathBuf {
        self.staging.join(name)
    }

    /// The staging folder itself (where files of the destination are written).
    pub fn staging(&self) -> &Path {
        &self.staging
    }

    /// Move the complete folder into place.
    pub fn commit(mut self) -> Result<()> {
        if self.destination.exists() {
            std::fs::remove_dir_all(&self.destination)
                .map_err(|e| Error::io(&self.destination, e))?;
        }
        std::fs::rename(&self.staging, &self.destination)
            .map_err(|e| Error::io(&self.destination, e))?;
        // The folders now hold the output: keep them.
        self.created.clear();
        Ok(())
    }
}

impl Drop for StagedFolder {
    /// An abandoned staging folder (an error on the way) is removed, and so are the folders
    /// created for it (only while empty: they may have been filled meanwhile by others).
    /// After [`StagedFolder::commit`] the staging folder no longer exists.
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.staging);
        for folder in self.created.iter().rev() {
            let _ = std::fs::remove_dir(folder);
        }
    }
}

/// The folder a path lives in, `.` for a bare name.
fn folder_of(path: &Path) -> &Path {
    path.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// Creates `folder` and its missing ancestors; returns those created, outermost first. A file
/// in the way is an error naming it.
fn create_folders(folder: &Path) -> Result<Vec<PathBuf>> {
    let missing: Vec<&Path> = folder
        .ancestors()
        .take_while(|a| !a.as_os_str().is_empty() && !a.exists())
        .collect();
    let existing = folder
        .ancestors()
        .find(|a| !a.as_os_str().is_empty() && a.exists());
    if let Some(existing) = existing.filter(|e| !e.is_dir()) {
        return Err(not_a_folder(existing));
    }
    let mut created = Vec::new();
    for folder in missing.into_iter().rev() {
        if let Err(e) = std::fs::create_dir(folder) {
            for done in created.iter().rev() {
                let _ = std::fs::remove_dir(done);
            }
            return Err(Error::io(folder, e));
        }
        created.push(folder.to_path_buf());
    }
    Ok(created)
}

fn not_a_folder(path: &Path) -> Error {
    Error::invalid(
        path,
        "output",
        "is a file, not a folder; choose an output path inside a folder",
    )
}

/// Refuse to overwrite an existing file without `--force`, and to write a file where a folder
/// is.
pub fn check_overwrite(path: &Path, force: bool) -> Result<()> {
    if path.is_dir() {
        return Err(Error::invalid(
            path,
            "output",
            "is a folder; expected the name of a file to write",
        ));
    }
    if path.exists() && !force {
        return Err(Error::invalid(
            path,
            "output",
            "file exists; pass --force to replace it",
        ));
    }
    Ok(())
}

/// [`check_overwrite`], and the file's folder must exist (commands that write one file do
/// not create folders).
pub fn check_output_file(path: &Path, force: bool) -> Result<()> {
    check_overwrite(path, force)?;
    let folder = folder_of(path);
    if folder.is_dir() {
        Ok(())
    } else if folder.exists() {
        Err(not_a_folder(folder))
    } else {
        match folder.ancestors().find(|a| a.exists() && !a.is_dir()) {
            Some(file) => Err(not_a_folder(file)),
            None => Err(Error::invalid(
                folder,
                "output",
                "folder does not exist; create it first or choose another output path",
            )),
        }
    }
}
