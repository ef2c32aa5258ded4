//! What can go wrong when recording, reading or converting a recording.

use crate::transport::TransportError;
use std::path::PathBuf;

/// An error of a recording, with the file (or namespace) it concerns.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file cannot be created, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The MCAP library refused to write or read the file.
    #[error("{}: MCAP: {source}", path.display())]
    Mcap {
        path: PathBuf,
        #[source]
        source: mcap::McapError,
    },
    /// The file is not what was expected (extension, channels, a message that does not decode).
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
    /// The output exists (a recording never replaces a file without being asked to, and never
    /// writes through a symbolic link).
    #[error("{}: {kind} is there already; {}", path.display(), if *replaceable {
        "choose another name, or pass --force to replace it (a link is replaced, not followed)"
    } else {
        "choose another name"
    })]
    Exists {
        path: PathBuf,
        kind: &'static str,
        replaceable: bool,
    },
    /// Writing stopped (a full disk, an I/O error): what was written up to then was kept and
    /// the file closed so that it reads back.
    #[error("{}: {message}", path.display())]
    Write { path: PathBuf, message: String },
    /// The transport failed (opening the namespace's services).
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// The live view's server could not start or make a channel.
    #[error("vic view: {message}")]
    View { message: String },
    /// No board published a state in the namespace within the wait.
    #[error("no board in namespace \"{namespace}\" (no state within {waited_ms} ms)")]
    NoBoard { namespace: String, waited_ms: u64 },
}

impl RecordError {
    pub(crate) fn io(path: &std::path::Path, source: std::io::Error) -> RecordError {
        RecordError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
    pub(crate) fn mcap(path: &std::path::Path, source: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            path: path.to_path_buf(),
            source,
        }
    }
    pub(crate) fn format(path: &std::path::Path, message: impl Into<String>) -> RecordError {
        RecordError::Format {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}
