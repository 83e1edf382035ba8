//! KITTI calibration files in the `KEY: values` format (object / tracking `calib.txt`, odometry
//! `calib.txt`, raw `calib_*.txt`). Values are kept as text and parsed on request, so text entries
//! such as `calib_time: 09-Jan-2012 13:57:47` are tolerated and a missing or malformed key is reported
//! only when asked for, with the file and line.

use std::{collections::BTreeMap, path::Path};

use nalgebra::{Isometry3, Matrix3, Matrix3x4, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::{parse_numbers, read_text, DatasetError};

/// Largest difference, pixels, between the two cameras' focal lengths or principal points, and largest
/// skew, of a rectified pair. The system uses the left camera's intrinsics for both; a difference in
/// the principal point's x is a disparity offset, and 0.01 px changes a depth at 20 m on KITTI's rig
/// (fx·b = 380 px·m) by 0.05 %, a tenth of what `stereo-check` resolves. KITTI prints its matrices to 7
/// significant digits (0.0001 px).
pub const RECTIFIED_TOLERANCE_PX: f64 = 0.01;

/// Largest offset of the right camera across the baseline (y) or along the optical axis (z), as a share
/// of the baseline. A rectified pair's cameras differ by a translation along x only: an offset `ty`
/// moves a point's row between the two images by `fy·ty/z = d·ty/b` (d its disparity), so 1 % of the
/// baseline moves rows by 1 % of the disparity. KITTI's colour pair, P_rect_02 and P_rect_03 of its raw
/// calibration, has 0.5 % (2.7 mm over 0.53 m); its grey pairs have none.
pub const RECTIFIED_OFFSET_SHARE: f64 = 0.01;

/// Check one projection matrix `p` (named `key`) is a rectified camera's: `[fx 0 cx tx; 0 fy cy ty;
/// 0 0 1 tz]` with positive focal lengths (the intrinsics against the image: [`crate::check::calibration`]).
/// The error states the rule broken.
pub fn rectified_camera(p: &Matrix3x4<f64>, key: &str) -> Result<(), String> {
    let tol = RECTIFIED_TOLERANCE_PX;
    let (fx, fy) = (p[(0, 0)], p[(1, 1)]);
    if !(fx > 0.0 && fy > 0.0) {
        return Err(format!(
            "{key} has focal lengths fx {fx}, fy {fy}: a camera's focal lengths are positive (a negative one mirrors the image)"
        ));
    }
    if p[(0, 1)].abs() > tol || p[(1, 0)].abs() > tol {
        return Err(format!(
            "{key} has skew {:e} (row 1, column 2) and {:e} (row 2, column 1): a rectified camera has none (at most {tol} px)",
            p[(0, 1)],
            p[(1, 0)]
        ));
    }
    let third = [p[(2, 0)], p[(2, 1)], p[(2, 2)]];
    if third[0].abs() > 1e-6 || third[1].abs() > 1e-6 || (third[2] - 1.0).abs() > 1e-6 {
        return Err(format!(
            "{key}'s third row starts {third:?}: a rectified camera's is [0, 0, 1] (the depth along its optical axis)"
        ));
    }
    Ok(())
}

/// The intrinsics `[fx, fy, cx, cy]` and baseline (metres) of a rectified stereo pair from its two
/// projection matrices (`keys` name them in messages), after checking that they are one: each of the
/// form `[fx 0 cx tx; 0 fy cy ty; 0 0 1 tz]` with positive focal lengths, equal intrinsics, and the
/// right camera to the right of the left one along x only (within [`RECTIFIED_TOLERANCE_PX`] and
/// [`RECTIFIED_OFFSET_SHARE`]). Each error states the rule it found broken.
pub fn rectified_pair(
    left: &Matrix3x4<f64>,
    right: &Matrix3x4<f64>,
    (lk, rk): (&str, &str),
) -> Result<([f64; 4], f64), String> {
    let tol = RECTIFIED_TOLERANCE_PX;
    rectified_camera(left, lk)?;
    rectified_camera(right, rk)?;
    let k = |p: &Matrix3x4<f64>| [p[(0, 0)], p[(1, 1)], p[(0, 2)], p[(1, 2)]];
    let (kl, kr) = (k(left), k(right));
    for (i, name) in ["fx", "fy", "cx", "cy"].iter().enumerate() {
        if (kl[i] - kr[i]).abs() > tol {
            return Err(format!(
                "{lk} has {name} {} and {rk} {}: a rectified pair shares its intrinsics (to {tol} px), so these images are not rectified together",
                kl[i], kr[i]
            ));
        }
    }
    // the right camera's centre from the left's: K⁻¹ (p_r − p_l) of the fourth columns
    let [fx, fy, cx, cy] = kl;
    let d = right.column(3) - left.column(3);
    let tz = d[2];
    let (tx, ty) = ((d[0] - cx * tz) / fx, (d[1] - cy * tz) / fy);
    let baseline = (left[(0, 3)] - right[(0, 3)]) / fx;
    if !(baseline > 0.0 && baseline.is_finite()) {
        return Err(format!(
            "the baseline from {lk} and {rk} is {baseline:.4} m: the right camera lies to the right of the left one, so {rk}'s \
             fourth column starts with −fx·b for a baseline b > 0 (are the two cameras swapped?)"
        ));
    }
    if ty.abs() > RECTIFIED_OFFSET_SHARE * tx.abs() || tz.abs() > RECTIFIED_OFFSET_SHARE * tx.abs() {
        return Err(format!(
            "{rk} lies {ty:.4} m across and {tz:.4} m along the optical axis from {lk}, beside a baseline of {baseline:.4} m: a \
             rectified pair's cameras differ along x only (at most {} % of the baseline either way)",
            100.0 * RECTIFIED_OFFSET_SHARE
        ));
    }
    Ok(([fx, fy, cx, cy], baseline))
}

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
            // text entries (a raw calibration's date) stay text; a number must be finite, used or not
            if let Some(v) = values.iter().find(|v| v.parse::<f64>().is_ok_and(|x| !x.is_finite())) {
                return Err(DatasetError::Parse {
                    path: path.to_path_buf(),
                    line: i + 1,
                    message: format!(
                        "key '{key}' holds {v}, a non-finite number: every number of a calibration is finite"
                    ),
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
        // two sensors of one vehicle: no further apart than its size allows
        let d = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
        if d > MAX_SENSOR_OFFSET_M {
            return Err(DatasetError::Parse {
                path: self.path.clone(),
                line: self.entries.get(translation_key).map_or(0, |e| e.0),
                message: format!(
                    "{translation_key} puts the two sensors {d:.3} m apart; sensors mounted on one vehicle are at most \
                     {MAX_SENSOR_OFFSET_M} m apart (the diagonal of the largest road vehicle, 25.25 × 2.55 × 4 m; \
                     KITTI's lidar is 0.27 m from its camera): a translation in other units, or another rig's"
                ),
            });
        }
        let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix(&r));
        Ok(Isometry3::from_parts(Translation3::from(Vector3::new(t[0], t[1], t[2])), rot))
    }
}

/// Largest distance between two sensors of one rig (`T` of `calib_velo_to_cam.txt`,
/// `calib_imu_to_velo.txt`), metres: the diagonal of the largest road vehicle (25.25 × 2.55 × 4 m,
/// EU 96/53/EC), about 25.7 m, rounded up.
pub const MAX_SENSOR_OFFSET_M: f64 = 26.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn m(row: &str) -> Matrix3x4<f64> {
        let v: Vec<f64> = row.split_whitespace().map(|x| x.parse().expect("number")).collect();
        Matrix3x4::from_row_slice(&v)
    }

    // KITTI odometry 06's grey pair and raw 2011_09_26's colour pair, as printed
    const P0: &str = "707.0912 0 601.8873 0 0 707.0912 183.1104 0 0 0 1 0";
    const P1: &str = "707.0912 0 601.8873 -379.8145 0 707.0912 183.1104 0 0 0 1 0";
    const P2: &str = "721.5377 0 609.5593 44.85728 0 721.5377 172.854 0.2163791 0 0 1 0.002745884";
    const P3: &str = "721.5377 0 609.5593 -339.5242 0 721.5377 172.854 2.199936 0 0 1 0.002729905";

    #[test]
    fn kittis_pairs_are_rectified_and_broken_ones_are_named_with_their_rule() {
        let (k, b) = rectified_pair(&m(P0), &m(P1), ("P0", "P1")).expect("grey pair");
        assert_eq!(k, [707.0912, 707.0912, 601.8873, 183.1104]);
        assert!((b - 0.537150).abs() < 1e-6, "{b}");
        let (_, b) = rectified_pair(&m(P2), &m(P3), ("P_rect_02", "P_rect_03")).expect("colour pair");
        assert!((b - 0.5327).abs() < 1e-3, "{b}");
        // one number changed at a time: (matrix, field, value, what the message says)
        let cases = [
            ("P0", 1, "1e308", "skew"),
            ("P0", 10, "2", "third row"),
            ("P1", 0, "353.5456", "fx 707.0912 and P1 353.5456"),
            ("P1", 6, "283.1104", "cy 183.1104 and P1 283.1104"),
            ("P1", 7, "50", "across"),
            ("P1", 11, "0.2", "along the optical axis"),
            ("P1", 3, "379.8145", "the right camera lies to the right"),
            ("P0", 0, "-707.0912", "focal lengths are positive"),
        ];
        for (key, field, value, want) in cases {
            let change = |row: &str| {
                let mut f: Vec<&str> = row.split_whitespace().collect();
                f[field] = value;
                f.join(" ")
            };
            let (l, r) = if key == "P0" { (change(P0), P1.to_string()) } else { (P0.to_string(), change(P1)) };
            let e = rectified_pair(&m(&l), &m(&r), ("P0", "P1")).expect_err(want);
            assert!(e.contains(want), "{key}[{field}] = {value}: {e}");
        }
        // swapped cameras: a negative baseline, and the message says what to check
        let e = rectified_pair(&m(P1), &m(P0), ("P0", "P1")).expect_err("swapped");
        assert!(e.contains("-0.5372 m") && e.contains("swapped"), "{e}");
    }

    /// A sensor-to-sensor translation beyond one vehicle (R13: the lidar 1 km from the camera) names the
    /// key's line and both figures; KITTI's own is read.
    #[test]
    fn sensors_of_one_vehicle_are_near_each_other() {
        let text = |t: &str| format!("calib_time: 15-Mar-2012 11:37:16\nR: 1 0 0 0 1 0 0 0 1\nT: {t}\n");
        let path = Path::new("calib_velo_to_cam.txt");
        let ok = Calib::parse(path, &text("-4.069766e-03 -7.631618e-02 -2.717806e-01")).expect("parses");
        assert!((ok.rigid("R", "T").expect("KITTI's").translation.vector.z + 0.2717806).abs() < 1e-12);
        let far = Calib::parse(path, &text("1000 0 0")).expect("parses");
        let e = far.rigid("R", "T").expect_err("a kilometre").to_string();
        assert!(e.starts_with("calib_velo_to_cam.txt:3: T puts the two sensors 1000.000 m apart"), "{e}");
        assert!(e.contains("at most 26 m apart"), "{e}");
    }
}
