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
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said (part of the message, so not also a `source`: printed
        /// once).
        error: std::io::Error,
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
    /// Shards to merge are missing or have not finished.
    #[error("{0}")]
    Incomplete(String),
    /// The output directory holds files sysid did not write.
    #[error(
        "{} holds files sysid did not write ({}): choose another --out, or give --force to \
         write there anyway (replacing any of sysid's own files it holds: study.json, \
         trials.jsonl, summary.json, summary.md, basin.json, basin.md)",
        dir.display(),
        list(files)
    )]
    Foreign {
        /// The directory.
        dir: PathBuf,
        /// The files, sorted.
        files: Vec<String>,
    },
    /// Another run is writing the directory.
    #[error(
        "another sysid is writing to {} ({holder}): wait for it to end, or choose another --out",
        dir.display()
    )]
    Busy {
        /// The directory.
        dir: PathBuf,
        /// Who holds it.
        holder: String,
    },
    /// The caller stopped the run ([`stop_when`](sysid_core::observer::stop_when)): no trial
    /// or start was begun after it, and those running when it came are not kept (their fits
    /// were cut short). A study's complete trials stay in its `trials.jsonl` for `--resume`;
    /// no summary is written.
    #[error("{0}")]
    Interrupted(String),
}

/// "a, b, c and 4 more".
fn list(files: &[String]) -> String {
    const SHOWN: usize = 4;
    let mut text = files.iter().take(SHOWN).cloned().collect::<Vec<_>>().join(", ");
    if files.len() > SHOWN {
        text += &format!(" and {} more", files.len() - SHOWN);
    }
    text
}

impl From<ProblemError> for StudyError {
    fn from(e: ProblemError) -> Self {
        StudyError::Setup(e.to_string())
    }
}

impl StudyError {
    pub(crate) fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |error| StudyError::Io { path, error }
    }
}
