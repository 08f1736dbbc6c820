//! Typed errors of the library. Every variant names the file (and where it applies the field)
//! that caused it, so the command line can print one clear line and exit with status 2.

use std::path::PathBuf;

/// Errors the library reports for bad input. The binary maps every one of them to exit status 2.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    /// A file was read but its content is wrong; `field` names the key, line or pixel.
    #[error("{path}: {field}: {message}")]
    Invalid {
        path: PathBuf,
        field: String,
        message: String,
    },
    /// A command-line value is wrong (no file involved).
    #[error("{field}: {message}")]
    Argument { field: String, message: String },
}

impl Error {
    pub fn io(path: impl Into<PathBuf>, err: impl std::fmt::Display) -> Self {
        Error::Io {
            path: path.into(),
            message: err.to_string(),
        }
    }
    pub fn invalid(
        path: impl Into<PathBuf>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Error::Invalid {
            path: path.into(),
            field: field.into(),
            message: message.into(),
        }
    }
    pub fn argument(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Argument {
            field: field.into(),
            message: message.into(),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
