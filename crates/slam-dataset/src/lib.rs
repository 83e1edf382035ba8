//! Dataset readers for quadric SLAM. Every reader returns [`DatasetError`] values that name the file
//! and, for parse errors, the 1-based line; none panics on malformed input. The writing side:
//! trajectories ([`trajectory`]) and output folders and files that are never half-written ([`output`]).

#![warn(missing_docs)]

pub mod check;
pub mod classes;
pub mod detections;
pub mod folders;
pub mod kitti;
pub mod layout;
pub mod output;
pub mod recording;
pub mod rig;
pub mod ros;
pub mod trajectory;

use std::path::{Path, PathBuf};

/// Errors of the dataset readers.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A line could not be parsed.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The file is not a regular file or larger than its reader takes ([`slam_core::files`]).
    #[error(transparent)]
    Read(#[from] slam_core::files::ReadError),
    /// A file could not be written (written atomically: [`slam_core::files`]).
    #[error(transparent)]
    Write(#[from] slam_core::files::WriteError),
    /// The file parsed but lacks something required.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is missing or inconsistent.
        message: String,
    },
}

/// Read a whole regular file of at most `limit` bytes as UTF-8 text ([`slam_core::files::read_text`]:
/// a folder, pipe or device is refused, the limit is in the error, a byte-order mark is dropped).
pub(crate) fn read_text(path: &Path, limit: &slam_core::files::Limit) -> Result<String, DatasetError> {
    use slam_core::files::ReadError;
    slam_core::files::read_text(path, limit).map_err(|e| match e {
        ReadError::Io { path, source } => DatasetError::Io { path, source },
        ReadError::NotUtf8 { path, line } => DatasetError::Parse { path, line, message: "not valid UTF-8".into() },
        other => DatasetError::Read(other),
    })
}

/// Parse whitespace-separated finite numbers of one line.
/// [`parse_numbers`] on a line that must hold exactly `n` fields.
pub(crate) fn parse_exact(path: &Path, line: usize, fields: &[&str], n: usize) -> Result<Vec<f64>, DatasetError> {
    if fields.len() != n {
        return Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line,
            message: format!("expected {n} numbers, found {}", fields.len()),
        });
    }
    parse_numbers(path, line, fields)
}

/// The lines of a file whose line k belongs to frame k (times, timestamps), with their 1-based line
/// numbers. Trailing blank lines are fine; a blank line followed by more lines is an error, because
/// skipping it would give every later frame its neighbour's line.
pub(crate) fn frame_lines<'a>(path: &Path, text: &'a str) -> Result<Vec<(usize, &'a str)>, DatasetError> {
    let mut out = Vec::new();
    let mut blank: Option<usize> = None;
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            blank.get_or_insert(i + 1);
            continue;
        }
        if let Some(b) = blank {
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line: b,
                message:
                    "blank line between frame lines (line k is frame k: skipping it would shift every later frame)"
                        .into(),
            });
        }
        out.push((i + 1, line));
    }
    Ok(out)
}

pub(crate) fn parse_numbers(path: &Path, line: usize, fields: &[&str]) -> Result<Vec<f64>, DatasetError> {
    fields
        .iter()
        .map(|f| match f.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => {
                Err(DatasetError::Parse { path: path.to_path_buf(), line, message: format!("non-finite number '{f}'") })
            }
            Err(_) => {
                Err(DatasetError::Parse { path: path.to_path_buf(), line, message: format!("not a number: '{f}'") })
            }
        })
        .collect()
}
