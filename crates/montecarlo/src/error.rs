//! What can go wrong in a study: its setup, and its files.

use std::path::PathBuf;

use sysid_core::ProblemError;

/// A study that cannot start or cannot write its results.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// The scenario, the methods or the options are unusable.
    #[error("{0}")]
    Setup(String),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        source: std::io::Error,
    },
    /// A results file is not what a study writes (a line, with its number).
    #[error("{path}:{line}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The output directory holds a different study, or the shards do not belong together.
    #[error("{0}")]
    Mismatch(String),
}

impl From<ProblemError> for StudyError {
    fn from(e: ProblemError) -> Self {
        StudyError::Setup(e.to_string())
    }
}

impl StudyError {
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| StudyError::Io { path, source }
    }
}
