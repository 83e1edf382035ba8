//! KITTI calibration files in the `KEY: values` format (object / tracking `calib.txt`, odometry
//! `calib.txt`, raw `calib_*.txt`). Values are kept as text and parsed on request, so text entries
//! such as `calib_time: 09-Jan-2012 13:57:47` are tolerated and a missing or malformed key is reported
//! only when asked for, with the file and line.

use std::{collections::BTreeMap, path::Path};

use nalgebra::{Isometry3, Matrix3, Matrix3x4, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::{parse_numbers, read_text, DatasetError};

/// A parsed calibration file.
#[derive(Debug, Clone)]
pub struct Calib {
    path: std::path::PathBuf,
    entries: BTreeMap<String, (usize, Vec<String>)>,
}

impl Calib {
    /// Read `KEY: v1 v2 ...` (or `KEY v1 v2 ...`) lines; blank lines are skipped.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let text = read_text(path, &slam_core::files::SMALL)?;
        Self::parse(path, &text)
    }

    /// Parse the contents of such a file; `path` only names it in error messages.
    pub fn parse(path: &Path, text: &str) -> Result<Self, DatasetError> {
        let mut entries = BTreeMap::new();
        for (i, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let (key, rest) = match line.split_once(':') {
                Some((k, r)) if !k.contains(char::is_whitespace) => (k.trim().to_string(), r),
                _ => {
                    let mut it = line.splitn(2, char::is_whitespace);
                    let k = it.next().unwrap_or_default().to_string();
                    (k, it.next().unwrap_or_default())
                }
            };
            let values: Vec<String> = rest.split_whitespace().map(str::to_string).collect();
            if values.is_empty() {
                return Err(DatasetError::Parse {
                    path: path.to_path_buf(),
                    line: i + 1,
                    message: format!("key '{key}' has no values"),
                });
            }
            if let Some((first, _)) = entries.insert(key.clone(), (i + 1, values)) {
                return Err(DatasetError::Parse {
                    path: path.to_path_buf(),
                    line: i + 1,
                    message: format!("key '{key}' again (first on line {first}): which one holds is ambiguous"),
                });
            }
        }
        Ok(Self { path: path.to_path_buf(), entries })
    }

    /// The file it was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Keys present, sorted.
    pub fn keys(&self) -> impl Iterator<Item = &str> {
        self.entries.keys().map(String::as_str)
    }

    /// True when the key is present.
    pub fn has(&self, key: &str) -> bool {
        self.entries.contains_key(key)
    }

    /// The numbers of a key; `expected` checks their count.
    pub fn numbers(&self, key: &str, expected: Option<usize>) -> Result<Vec<f64>, DatasetError> {
        let Some((line, v)) = self.entries.get(key) else {
            return Err(DatasetError::Invalid { path: self.path.clone(), message: format!("missing key '{key}'") });
        };
        let fields: Vec<&str> = v.iter().map(String::as_str).collect();
        let nums = parse_numbers(&self.path, *line, &fields)?;
        if let Some(n) = expected {
            if nums.len() != n {
                return Err(DatasetError::Parse {
                    path: self.path.clone(),
                    line: *line,
                    message: format!("'{key}' needs {n} numbers, has {}", nums.len()),
                });
            }
        }
        Ok(nums)
    }

    /// A 3×4 matrix (12 numbers, row-major).
    pub fn matrix3x4(&self, key: &str) -> Result<Matrix3x4<f64>, DatasetError> {
        Ok(Matrix3x4::from_row_slice(&self.numbers(key, Some(12))?))
    }

    /// A 3×3 matrix (9 numbers, row-major).
    pub fn matrix3(&self, key: &str) -> Result<Matrix3<f64>, DatasetError> {
        Ok(Matrix3::from_row_slice(&self.numbers(key, Some(9))?))
    }

    /// A rotation matrix (9 numbers, row-major): `RᵀR` within 1e-3 of the identity (KITTI prints 6–7
    /// significant digits) and determinant +1, else an error naming the key's line.
    pub fn rotation(&self, key: &str) -> Result<Matrix3<f64>, DatasetError> {
        let r = self.matrix3(key)?;
        let err = (r.transpose() * r - Matrix3::identity()).norm();
        if !(err <= 1e-3 && r.determinant() > 0.0) {
            let line = self.entries.get(key).map_or(0, |e| e.0);
            return Err(DatasetError::Parse {
                path: self.path.clone(),
                line,
                message: format!("'{key}' is not a rotation (‖RᵀR − I‖ = {err:.2e}, det {:.3})", r.determinant()),
            });
        }
        Ok(r)
    }

    /// A rigid transform from a rotation key (9 numbers, checked by [`Calib::rotation`]) and a
    /// translation key (3 numbers), as in `calib_velo_to_cam.txt` (`R`, `T`); the rotation is
    /// re-orthonormalised.
    pub fn rigid(&self, rotation_key: &str, translation_key: &str) -> Result<Isometry3<f64>, DatasetError> {
        let r = self.rotation(rotation_key)?;
        let t = self.numbers(translation_key, Some(3))?;
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
        Ok(Isometry3::from_parts(Translation3::from(Vector3::new(t[0], t[1], t[2])), rot))
    }
}
