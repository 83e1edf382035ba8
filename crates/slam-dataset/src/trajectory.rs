//! Trajectory files: KITTI (row-major 3×4 per line, see [`crate::kitti::poses`]) and TUM
//! (`timestamp tx ty tz qx qy qz qw` per line, the format `evo` reads with `evo_ape tum`). Poses are
//! camera-to-world. Writers are atomic (temporary file, then rename).

use std::path::Path;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use crate::{parse_exact, read_text, DatasetError};

pub use crate::kitti::poses::{read_kitti_poses, write_kitti_poses};

/// Write a TUM trajectory: `timestamps[i] tx ty tz qx qy qz qw` (seconds, metres, unit quaternion).
pub fn write_tum(path: impl AsRef<Path>, timestamps: &[f64], poses: &[Isometry3<f64>]) -> Result<(), DatasetError> {
    let path = path.as_ref();
    if timestamps.len() != poses.len() {
        return Err(DatasetError::Invalid {
            path: path.to_path_buf(),
            message: format!("{} timestamps for {} poses", timestamps.len(), poses.len()),
        });
    }
    let mut out = String::new();
    for (t, p) in timestamps.iter().zip(poses) {
        let q = p.rotation.quaternion();
        let v = p.translation.vector;
        out.push_str(&format!("{t:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}\n", v.x, v.y, v.z, q.i, q.j, q.k, q.w));
    }
    Ok(slam_core::files::write_atomic(path, out.as_bytes())?)
}

/// Read a TUM trajectory; lines starting with `#` are comments.
pub fn read_tum(path: impl AsRef<Path>) -> Result<(Vec<f64>, Vec<Isometry3<f64>>), DatasetError> {
    let path = path.as_ref();
    let text = read_text(path, &slam_core::files::TABLE)?;
    parse_tum(path, &text)
}

/// Parse the contents of such a file, in the file's order; `path` only names it in error messages. A
/// time given twice is an error naming both lines (one time has one pose).
pub fn parse_tum(path: &Path, text: &str) -> Result<(Vec<f64>, Vec<Isometry3<f64>>), DatasetError> {
    let (mut ts, mut poses, mut lines) = (Vec::new(), Vec::new(), Vec::new());
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        let v = parse_exact(path, i + 1, &f, 8)?;
        let q = Quaternion::new(v[7], v[4], v[5], v[6]);
        if (q.norm() - 1.0).abs() > 1e-3 {
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line: i + 1,
                message: "quaternion is not unit".into(),
            });
        }
        let t = Translation3::new(v[1], v[2], v[3]);
        crate::kitti::poses::check_position(path, i + 1, &t.vector)?;
        ts.push(v[0]);
        lines.push(i + 1);
        poses.push(Isometry3::from_parts(t, UnitQuaternion::from_quaternion(q)));
    }
    let mut order: Vec<usize> = (0..ts.len()).collect();
    order.sort_by(|&a, &b| ts[a].total_cmp(&ts[b]).then(a.cmp(&b)));
    if let Some(w) = order.windows(2).find(|w| ts[w[0]] == ts[w[1]]) {
        return Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line: lines[w[1]],
            message: format!("time {} s again (first on line {}): one time has one pose", ts[w[1]], lines[w[0]]),
        });
    }
    Ok((ts, poses))
}
