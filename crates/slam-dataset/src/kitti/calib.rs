//! KITTI calibration files in the `KEY: numbers` format (object / tracking `calib.txt`, odometry
//! `calib.txt`). Unknown keys are kept; missing keys are an error only when asked for.

use std::{collections::BTreeMap, path::Path};

use nalgebra::Matrix3x4;

use crate::{parse_numbers, read_text, DatasetError};

/// A parsed calibration file: key → numbers, with the file path for error messages.
#[derive(Debug, Clone)]
pub struct Calib {
    path: std::path::PathBuf,
    entries: BTreeMap<String, (usize, Vec<f64>)>,
}

impl Calib {
    /// Read `KEY: v1 v2 ...` (or `KEY v1 v2 ...`) lines; blank lines are skipped.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let text = read_text(path)?;
        let mut entries = BTreeMap::new();
        for (i, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let mut fields = line.split_whitespace();
            let Some(key) = fields.next() else { continue };
            let key = key.trim_end_matches(':').to_string();
            let rest: Vec<&str> = fields.collect();
            if rest.is_empty() {
                return Err(DatasetError::Parse {
                    path: path.to_path_buf(),
                    line: i + 1,
                    message: format!("key '{key}' has no values"),
                });
            }
            let values = parse_numbers(path, i + 1, &rest)?;
            entries.insert(key, (i + 1, values));
        }
        Ok(Self { path: path.to_path_buf(), entries })
    }

    /// Keys present, sorted.
    pub fn keys(&self) -> impl Iterator<Item = &str> {
        self.entries.keys().map(String::as_str)
    }

    /// A 3×4 matrix (12 numbers, row-major), or an error naming the file when missing or malformed.
    pub fn matrix3x4(&self, key: &str) -> Result<Matrix3x4<f64>, DatasetError> {
        let Some((line, v)) = self.entries.get(key) else {
            return Err(DatasetError::Invalid { path: self.path.clone(), message: format!("missing key '{key}'") });
        };
        if v.len() != 12 {
            return Err(DatasetError::Parse {
                path: self.path.clone(),
                line: *line,
                message: format!("'{key}' needs 12 numbers, has {}", v.len()),
            });
        }
        Ok(Matrix3x4::from_row_slice(v))
    }
}
