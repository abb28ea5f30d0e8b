//! The one error type every crate of the workspace speaks.

use std::path::PathBuf;

use crate::method::Capability;

/// Everything that can go wrong in shadow-core and the method crates.
///
/// Errors about input name the input (a file path, or the object and element
/// index) and what is wrong with it, so that a user can fix the file rather than
/// guess. New kinds of failure may be added: match with a wildcard arm.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A mesh failed validation.
    #[error("invalid mesh {name:?}: {what}")]
    InvalidMesh { name: String, what: String },

    /// An environment map failed validation.
    #[error("invalid environment {source_name:?}: {what}")]
    InvalidEnvironment { source_name: String, what: String },

    /// A scene is not usable (no objects, mismatched frames, ...).
    #[error("invalid scene: {0}")]
    InvalidScene(String),

    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// A file was read but its format is malformed or unsupported.
    #[error("{path}: {what}")]
    Format { path: PathBuf, what: String },

    /// A method was asked for something it cannot do.
    #[error("{method} does not support {capability}")]
    Unsupported {
        method: String,
        capability: Capability,
    },

    /// A method stage was called out of order (e.g. `shade` before `update`).
    #[error("{method}: {what}")]
    Stage { method: String, what: String },

    /// A method was configured with settings it cannot run with (an
    /// unknown name, a resolution out of range, a SIMD path the CPU lacks).
    #[error("{method}: invalid configuration: {what}")]
    InvalidConfig { method: String, what: String },

    /// No GPU adapter, device loss, shader or read-back failure.
    #[error("GPU: {0}")]
    Gpu(String),
}

/// Result with the workspace's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// A stage called before the stages it needs (see
    /// [`ShadowMethod`](crate::ShadowMethod)).
    pub fn stage(method: impl Into<String>, what: impl Into<String>) -> Self {
        Error::Stage {
            method: method.into(),
            what: what.into(),
        }
    }

    /// A configuration `method` cannot run with.
    pub fn config(method: impl Into<String>, what: impl Into<String>) -> Self {
        Error::InvalidConfig {
            method: method.into(),
            what: what.into(),
        }
    }

    /// A format error on `path`.
    pub fn format(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        Error::Format {
            path: path.into(),
            what: what.into(),
        }
    }
}
