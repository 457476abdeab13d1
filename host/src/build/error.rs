//! Errors of `marionette build`: every input problem names the file, the
//! 1-based line and the field.

use std::fmt;

use crate::blob::BlobError;
use crate::import::ImportError;

/// Why a build failed.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// A spec or example-set file is malformed or inconsistent.
    #[error("{0}")]
    Input(#[from] InputError),
    /// A mocap file could not be imported.
    #[error("{0}")]
    Import(#[from] ImportError),
    /// The core rejected a pose operation (skeleton too large, ...).
    #[error("{file}: {problem}")]
    Pose {
        /// The mocap file.
        file: String,
        /// What went wrong.
        problem: String,
    },
    /// The resampled table could not be written.
    #[error("table: {0}")]
    Blob(#[from] BlobError),
    /// The written table could not be read back by the core (a bug).
    #[error("reading the table back: {0}")]
    Readback(String),
    /// An output could not be written.
    #[error("{file}: cannot write: {source}")]
    Write {
        /// The output file.
        file: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A problem with the data as a whole (no example left after a
    /// hold-out, every cell invalid, ...).
    #[error("{0}")]
    Data(String),
}

/// A located problem in an input file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InputError {
    /// The file, as given on the command line or in the spec.
    pub file: String,
    /// 1-based line (0 when the file could not be read at all).
    pub line: usize,
    /// The field (a key path such as `axis[1].count` or `examples[3].pose[2]`).
    pub field: String,
    /// What is wrong.
    pub problem: String,
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}: {}: {}",
            self.file, self.line, self.field, self.problem
        )
    }
}

impl std::error::Error for InputError {}

/// An input file's text, for locating errors by byte offset.
#[derive(Debug, Clone)]
pub struct Source {
    /// The file name used in errors.
    pub file: String,
    /// The whole text.
    pub text: String,
}

impl Source {
    /// Reads `path`; a read failure is an [`InputError`] at line 0.
    pub fn read(path: &std::path::Path) -> Result<Self, InputError> {
        let file = path.display().to_string();
        match std::fs::read_to_string(path) {
            Ok(text) => Ok(Self { file, text }),
            Err(e) => Err(InputError {
                file,
                line: 0,
                field: "file".to_owned(),
                problem: format!("cannot read: {e}"),
            }),
        }
    }

    /// 1-based line of byte `offset`.
    #[must_use]
    pub fn line_of(&self, offset: usize) -> usize {
        let end = offset.min(self.text.len());
        1 + self
            .text
            .as_bytes()
            .get(..end)
            .map_or(0, |b| b.iter().filter(|&&c| c == b'\n').count())
    }

    /// An error at byte `offset`.
    #[must_use]
    pub fn error_at(&self, offset: usize, field: &str, problem: impl Into<String>) -> InputError {
        InputError {
            file: self.file.clone(),
            line: self.line_of(offset),
            field: field.to_owned(),
            problem: problem.into(),
        }
    }

    /// An error on a known line.
    #[must_use]
    pub fn error_line(&self, line: usize, field: &str, problem: impl Into<String>) -> InputError {
        InputError {
            file: self.file.clone(),
            line,
            field: field.to_owned(),
            problem: problem.into(),
        }
    }
}
