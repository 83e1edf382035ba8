//! KITTI odometry-style pose files: one row-major 3×4 `[R | t]` per line (12 numbers).

use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::{parse_exact, read_text, DatasetError};

/// Farthest a pose may lie from its file's origin, metres: the Earth's diameter (1.27e7 m) is a bound no
/// trajectory in metres can pass; beyond it the file holds other units or a corrupt number.
pub const MAX_POSITION_M: f64 = 1.3e7;

/// An error naming `path` and `line` when a position coordinate lies beyond [`MAX_POSITION_M`].
pub(crate) fn check_position(path: &Path, line: usize, t: &Vector3<f64>) -> Result<(), DatasetError> {
    if t.amax() > MAX_POSITION_M {
        return Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line,
            message: format!(
                "position coordinate {:.3e} m: a drive's poses stay within {MAX_POSITION_M:.0e} m of the origin (wrong units or a corrupt line?)",
                t.amax()
            ),
        });
    }
    Ok(())
}

/// Read a KITTI pose file. Each line is a camera-to-world pose `T_w←c` (as KITTI ground truth and
/// ORB-SLAM3 write them). Blank lines are an error (they would shift frame indices).
pub fn read_kitti_poses(path: impl AsRef<Path>) -> Result<Vec<Isometry3<f64>>, DatasetError> {
    let path = path.as_ref();
    let text = read_text(path, &slam_core::files::TABLE)?;
    parse_kitti_poses(path, &text)
}

/// Parse the contents of such a file; `path` only names it in error messages.
pub fn parse_kitti_poses(path: &Path, text: &str) -> Result<Vec<Isometry3<f64>>, DatasetError> {
    let mut poses = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        let v = parse_exact(path, i + 1, &fields, 12)?;
        let r = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
        let err = (r.transpose() * r - Matrix3::identity()).norm();
        let det = r.determinant();
        if err > 1e-3 || det < 0.0 {
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line: i + 1,
                message: format!(
                    "rotation part is not a rotation (‖RᵀR − I‖ = {err:.2e}, det = {det:.3}{}): a rotation has \
                     orthonormal rows and det = +1",
                    if err <= 1e-3 { ": a reflection" } else { "" }
                ),
            });
        }
        let t = Vector3::new(v[3], v[7], v[11]);
        check_position(path, i + 1, &t)?;
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
        poses.push(Isometry3::from_parts(Translation3::from(Vector3::new(v[3], v[7], v[11])), rot));
    }
    if poses.is_empty() {
        return Err(DatasetError::Invalid { path: path.to_path_buf(), message: "no poses".into() });
    }
    Ok(poses)
}

/// Nominal time between two lines of a KITTI pose file, seconds: its line k is frame k, and KITTI
/// records ten frames a second.
pub const NOMINAL_FRAME_PERIOD_S: f64 = 0.1;

/// Refuse a ground-truth pose file (`poses/NN.txt`, `poses_orbslam3.txt`) with a step no vehicle makes:
/// a camera more than [`crate::kitti::raw::MAX_VEHICLE_SPEED_MPS`] × [`NOMINAL_FRAME_PERIOD_S`] (10 m)
/// from the line before; the error names the line. The OXTS packets are held to the same speed.
pub fn check_pose_steps(path: &Path, poses: &[Isometry3<f64>]) -> Result<(), DatasetError> {
    let reach = crate::kitti::raw::MAX_VEHICLE_SPEED_MPS * NOMINAL_FRAME_PERIOD_S;
    for (k, w) in poses.windows(2).enumerate() {
        let step = (w[1].translation.vector - w[0].translation.vector).norm();
        if step > reach {
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line: k + 2,
                message: format!(
                    "the camera moved {step:.1} m from the line before: ground truth at ten frames a second moves at most \
                     {reach} m a frame (a vehicle at {} m/s)",
                    crate::kitti::raw::MAX_VEHICLE_SPEED_MPS
                ),
            });
        }
    }
    Ok(())
}

/// [`read_kitti_poses`] of a ground-truth file, its steps checked ([`check_pose_steps`]).
pub fn read_ground_truth_poses(path: impl AsRef<Path>) -> Result<Vec<Isometry3<f64>>, DatasetError> {
    let path = path.as_ref();
    let poses = read_kitti_poses(path)?;
    check_pose_steps(path, &poses)?;
    Ok(poses)
}

/// Write poses in the same format (12 numbers per line, 9 significant decimals), atomically.
pub fn write_kitti_poses(path: impl AsRef<Path>, poses: &[Isometry3<f64>]) -> Result<(), DatasetError> {
    let path = path.as_ref();
    let mut out = String::new();
    for p in poses {
        let r = p.rotation.to_rotation_matrix().into_inner();
        let t = p.translation.vector;
        let row = |k: usize| format!("{:.9e} {:.9e} {:.9e} {:.9e}", r[(k, 0)], r[(k, 1)], r[(k, 2)], t[k]);
        out.push_str(&format!("{} {} {}\n", row(0), row(1), row(2)));
    }
    Ok(slam_core::files::write_atomic(path, out.as_bytes())?)
}
