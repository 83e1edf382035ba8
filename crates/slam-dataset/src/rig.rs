//! The calibration of a stereo rig for a recording that is not KITTI's: what it says about the two
//! cameras ([`RigCalibration`]), read from the formats people have their rig's calibration in:
//!
//! * Kalibr's `camchain.yaml` ([`read_kalibr`]): per camera `intrinsics: [fu, fv, pu, pv]`,
//!   `camera_model: pinhole`, `distortion_model: radtan` (k1, k2, p1, p2) or `equidistant`
//!   (k1…k4), `resolution: [w, h]`, optionally `rostopic`; `cam1.T_cn_cnm1`, the 4 × 4 transform that
//!   takes a point from camera 0's frame into camera 1's. The rig is rectified by the front end
//!   (stereo rectification) unless it is rectified already.
//! * ORB-SLAM's stereo settings ([`read_orbslam`], the OpenCV `FileStorage` YAML of its examples):
//!   `Camera.fx, fy, cx, cy, bf, width, height` and, for cameras that need rectifying,
//!   `LEFT.K, D, R, P` and `RIGHT.K, D, R, P` (`!!opencv-matrix` blocks) with `LEFT.width/height`:
//!   the rectification is given, as ORB-SLAM applies it.
//! * a pair of ROS `CameraInfo` messages ([`from_camera_infos`]): rectified (no distortion, `K` equal
//!   to `P`'s left 3 × 3) or given by their `K, D, R, P`.
//!
//! Every reader names the file and the key in its errors; the values are checked (finite, positive
//! focal lengths, a 3 × 3 rotation that is one, a right camera to the right of the left one).

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Matrix3x4, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3};
pub use slam_core::rig::{Distortion, RawCamera, RigCalibration};
use yaml_rust2::Yaml;

use crate::{kitti::calib::rectified_pair, ros::msgs::CameraInfo, DatasetError};

/// A calibration file as the user named it, with the topics it names (Kalibr's `rostopic`).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationFile {
    /// The file.
    pub path: PathBuf,
    /// The rig.
    pub rig: RigCalibration,
    /// The left and right cameras' topics, when the file names them.
    pub topics: Option<(String, String)>,
    /// The format, for messages (`Kalibr camchain`, `ORB-SLAM settings`).
    pub format: &'static str,
}

/// Read a calibration file, recognising its format: a Kalibr camchain has `cam0` and `cam1`, ORB-SLAM's
/// settings have `Camera.fx`.
pub fn read_calibration(path: &Path) -> Result<CalibrationFile, DatasetError> {
    let doc = load_yaml(path)?;
    if !doc["cam0"].is_badvalue() {
        read_kalibr_doc(path, &doc)
    } else if !doc["Camera.fx"].is_badvalue() || !doc["LEFT.K"].is_badvalue() {
        read_orbslam_doc(path, &doc)
    } else {
        Err(DatasetError::Invalid {
            path: path.to_path_buf(),
            message: "not a calibration this program reads: expected a Kalibr camchain (cam0, cam1) or ORB-SLAM's stereo settings (Camera.fx, …, LEFT.K/D/R/P, RIGHT.K/D/R/P)".into(),
        })
    }
}

/// Read Kalibr's `camchain.yaml`.
pub fn read_kalibr(path: &Path) -> Result<CalibrationFile, DatasetError> {
    read_kalibr_doc(path, &load_yaml(path)?)
}

/// Read ORB-SLAM's stereo settings YAML.
pub fn read_orbslam(path: &Path) -> Result<CalibrationFile, DatasetError> {
    read_orbslam_doc(path, &load_yaml(path)?)
}

fn load_yaml(path: &Path) -> Result<Yaml, DatasetError> {
    let text = crate::read_text(path, &slam_core::files::SMALL)?;
    // OpenCV's FileStorage writes a `%YAML:1.0` directive that YAML 1.2 does not know: the line is
    // blanked (so line numbers stay those of the file)
    let text = match text.strip_prefix("%YAML:1.0") {
        Some(rest) => format!("{:9}{rest}", ""),
        None => text,
    };
    // and accepts a key glued to its list (`data:[1, 2]`), which YAML reads as one word
    let text: String = text
        .lines()
        .map(|l| match l.find(":[") {
            Some(i) if l[..i].trim_start().chars().all(|c| c.is_alphanumeric() || c == '_' || c == '.') => {
                format!("{}: {}\n", &l[..i], &l[i + 1..])
            }
            _ => format!("{l}\n"),
        })
        .collect();
    let docs = yaml_rust2::YamlLoader::load_from_str(&text).map_err(|e| DatasetError::Parse {
        path: path.to_path_buf(),
        line: e.marker().line(),
        message: e.info().to_string(),
    })?;
    docs.into_iter().next().ok_or_else(|| DatasetError::Invalid { path: path.to_path_buf(), message: "empty".into() })
}

/// Reads keys of one YAML document, naming the file and the key in its errors.
struct Keys<'a> {
    path: &'a Path,
}

impl Keys<'_> {
    fn err(&self, key: &str, message: impl std::fmt::Display) -> DatasetError {
        DatasetError::Invalid { path: self.path.to_path_buf(), message: format!("{key}: {message}") }
    }

    fn number(&self, key: &str, v: &Yaml) -> Result<f64, DatasetError> {
        let x = match v {
            Yaml::Real(_) => v.as_f64(),
            Yaml::Integer(i) => Some(*i as f64),
            Yaml::BadValue => return Err(self.err(key, "missing")),
            _ => None,
        };
        match x {
            Some(x) if x.is_finite() => Ok(x),
            Some(x) => Err(self.err(key, format!("{x} is not a finite number"))),
            None => Err(self.err(key, format!("{v:?} is not a number"))),
        }
    }

    fn numbers(&self, key: &str, v: &Yaml, n: Option<usize>) -> Result<Vec<f64>, DatasetError> {
        let list = v.as_vec().ok_or_else(|| {
            if v.is_badvalue() {
                self.err(key, "missing")
            } else {
                self.err(key, "expected a list of numbers")
            }
        })?;
        if n.is_some_and(|n| list.len() != n) {
            return Err(self.err(key, format!("{} numbers, expected {}", list.len(), n.unwrap_or(0))));
        }
        list.iter().enumerate().map(|(i, x)| self.number(&format!("{key}[{i}]"), x)).collect()
    }

    /// An OpenCV matrix (`rows`, `cols`, `data`) of `rows × cols`, row-major.
    fn matrix(&self, key: &str, v: &Yaml, rows: usize, cols: usize) -> Result<Vec<f64>, DatasetError> {
        if v.is_badvalue() {
            return Err(self.err(key, "missing"));
        }
        let (r, c) =
            (self.number(&format!("{key}.rows"), &v["rows"])?, self.number(&format!("{key}.cols"), &v["cols"])?);
        // a distortion vector may be written as a row or a column
        let fits = (r as usize, c as usize) == (rows, cols)
            || (rows == 1 && (r as usize) * (c as usize) >= 4 && (r == 1.0 || c == 1.0));
        if !fits {
            return Err(self.err(key, format!("a {r}×{c} matrix, expected {rows}×{cols}")));
        }
        self.numbers(&format!("{key}.data"), &v["data"], Some((r * c) as usize))
    }

    fn size(&self, key: &str, w: &Yaml, h: &Yaml) -> Result<(u32, u32), DatasetError> {
        self.size_of(key, self.number(&format!("{key} width"), w)?, self.number(&format!("{key} height"), h)?)
    }

    fn size_of(&self, key: &str, w: f64, h: f64) -> Result<(u32, u32), DatasetError> {
        if !(w >= 1.0 && h >= 1.0 && w <= 65535.0 && h <= 65535.0 && w.fract() == 0.0 && h.fract() == 0.0) {
            return Err(self.err(key, format!("image size {w} × {h}: whole numbers of pixels in 1-65535 expected")));
        }
        Ok((w as u32, h as u32))
    }
}

fn intrinsic_matrix(keys: &Keys<'_>, key: &str, [fx, fy, cx, cy]: [f64; 4]) -> Result<Matrix3<f64>, DatasetError> {
    if !(fx > 0.0 && fy > 0.0) {
        return Err(keys.err(key, format!("focal lengths {fx}, {fy}: they are positive")));
    }
    Ok(Matrix3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0))
}

/// A rotation matrix that is one: orthonormal to 1e-6 with determinant +1 (a rotation printed to 7
/// significant digits, as calibration tools print at least, is off by 1e-7; a mirrored, scaled or
/// sheared matrix is not one).
fn rotation(keys: &Keys<'_>, key: &str, m: Matrix3<f64>) -> Result<Matrix3<f64>, DatasetError> {
    let off = (m.transpose() * m - Matrix3::identity()).abs().max();
    if off > 1e-6 || m.determinant() < 0.0 {
        return Err(keys.err(
            key,
            format!("not a rotation (RᵀR differs from the identity by {off:.2e}, det {:.6})", m.determinant()),
        ));
    }
    Ok(m)
}

fn read_kalibr_doc(path: &Path, doc: &Yaml) -> Result<CalibrationFile, DatasetError> {
    let keys = Keys { path };
    let camera = |name: &str| -> Result<(RawCamera, Option<String>), DatasetError> {
        let c = &doc[name];
        if c.is_badvalue() {
            return Err(keys.err(name, "missing: a stereo camchain has cam0 and cam1"));
        }
        let model = c["camera_model"].as_str().unwrap_or("pinhole");
        if model != "pinhole" {
            return Err(keys.err(&format!("{name}.camera_model"), format!("'{model}': only pinhole cameras are read")));
        }
        let i = keys.numbers(&format!("{name}.intrinsics"), &c["intrinsics"], Some(4))?;
        let k = intrinsic_matrix(&keys, &format!("{name}.intrinsics"), [i[0], i[1], i[2], i[3]])?;
        let res = keys.numbers(&format!("{name}.resolution"), &c["resolution"], Some(2))?;
        let size = keys.size_of(&format!("{name}.resolution"), res[0], res[1])?;
        let model = c["distortion_model"].as_str().unwrap_or("none");
        let d = if c["distortion_coeffs"].is_badvalue() {
            Vec::new()
        } else {
            keys.numbers(&format!("{name}.distortion_coeffs"), &c["distortion_coeffs"], None)?
        };
        let distortion = match (model, d.len()) {
            ("none", _) => Distortion::None,
            ("radtan", 4) => Distortion::RadialTangential(d),
            ("equidistant", 4) => Distortion::Equidistant([d[0], d[1], d[2], d[3]]),
            ("radtan" | "equidistant", n) => {
                return Err(keys.err(&format!("{name}.distortion_coeffs"), format!("{n} coefficients, {model} has 4")))
            }
            (other, _) => {
                return Err(keys.err(
                    &format!("{name}.distortion_model"),
                    format!("'{other}': radtan, equidistant or none are read"),
                ))
            }
        };
        Ok((RawCamera { k, distortion, size }, c["rostopic"].as_str().map(str::to_string)))
    };
    let (left, lt) = camera("cam0")?;
    let (right, rt) = camera("cam1")?;
    let t = &doc["cam1"]["T_cn_cnm1"];
    let rows =
        t.as_vec().ok_or_else(|| keys.err("cam1.T_cn_cnm1", "missing: camera 1's pose from camera 0 (4 × 4)"))?;
    if rows.len() != 4 {
        return Err(keys.err("cam1.T_cn_cnm1", format!("{} rows, expected 4", rows.len())));
    }
    let mut m = Matrix4::zeros();
    for (r, row) in rows.iter().enumerate() {
        let v = keys.numbers(&format!("cam1.T_cn_cnm1[{r}]"), row, Some(4))?;
        for c in 0..4 {
            m[(r, c)] = v[c];
        }
    }
    if (m.row(3) - nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0)).abs().max() > 1e-9 {
        return Err(keys.err("cam1.T_cn_cnm1", "its last row is not [0, 0, 0, 1]"));
    }
    let r = rotation(&keys, "cam1.T_cn_cnm1", m.fixed_view::<3, 3>(0, 0).into_owned())?;
    let t = Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    let right_from_left = Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    );
    // camera 1's centre in camera 0's frame, −Rᵀt: the right camera lies to the right (positive x)
    let centre = -(r.transpose() * t);
    // (NaN refused too)
    if centre.x.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Err(keys.err(
            "cam1.T_cn_cnm1",
            format!("camera 1 lies at x = {:.4} m from camera 0: the right camera lies to the right of the left one (cameras swapped?)", centre.x),
        ));
    }
    let rig = rectified_extrinsic(&left, &right, &right_from_left).unwrap_or(RigCalibration::Extrinsic {
        left,
        right,
        right_from_left,
    });
    Ok(CalibrationFile { path: path.to_path_buf(), rig, topics: lt.zip(rt), format: "Kalibr camchain" })
}

/// Largest rotation between two cameras, degrees, that still counts as row-aligned: 0.001° moves no
/// pixel of a 2000-pixel-wide camera (f ≈ 1000 px) by more than 0.02 px, a fifth of what sub-pixel
/// stereo matching resolves (0.1 px).
const ALIGNED_DEG: f64 = 0.001;

/// A rig given by extrinsics that is already a rectified pair: no distortion, the same intrinsics, no
/// rotation between the cameras and the right one along x.
fn rectified_extrinsic(
    left: &RawCamera,
    right: &RawCamera,
    right_from_left: &Isometry3<f64>,
) -> Option<RigCalibration> {
    if left.distortion.is_some() || right.distortion.is_some() || left.size != right.size {
        return None;
    }
    if right_from_left.rotation.angle().to_degrees() > ALIGNED_DEG {
        return None;
    }
    let p = |k: &Matrix3<f64>, t: Vector3<f64>| {
        let mut p = Matrix3x4::zeros();
        p.fixed_view_mut::<3, 3>(0, 0).copy_from(k);
        p.set_column(3, &(k * t));
        p
    };
    let (intrinsics, baseline) = rectified_pair(
        &p(&left.k, Vector3::zeros()),
        &p(&right.k, right_from_left.translation.vector),
        ("cam0", "cam1"),
    )
    .ok()?;
    Some(RigCalibration::Rectified { intrinsics, baseline, size: Some(left.size) })
}

fn read_orbslam_doc(path: &Path, doc: &Yaml) -> Result<CalibrationFile, DatasetError> {
    let keys = Keys { path };
    let n = |key: &str| keys.number(key, &doc[key]);
    if !doc["LEFT.K"].is_badvalue() || !doc["RIGHT.K"].is_badvalue() {
        let camera = |side: &str| -> Result<(RawCamera, Matrix3<f64>, Matrix3x4<f64>), DatasetError> {
            let key = |k: &str| format!("{side}.{k}");
            let kv = keys.matrix(&key("K"), &doc[key("K").as_str()], 3, 3)?;
            let k = Matrix3::from_row_slice(&kv);
            intrinsic_matrix(&keys, &key("K"), [k[(0, 0)], k[(1, 1)], k[(0, 2)], k[(1, 2)]])?;
            let d = keys.matrix(&key("D"), &doc[key("D").as_str()], 1, 5)?;
            let r = rotation(
                &keys,
                &key("R"),
                Matrix3::from_row_slice(&keys.matrix(&key("R"), &doc[key("R").as_str()], 3, 3)?),
            )?;
            let p = Matrix3x4::from_row_slice(&keys.matrix(&key("P"), &doc[key("P").as_str()], 3, 4)?);
            let size = keys.size(side, &doc[key("width").as_str()], &doc[key("height").as_str()])?;
            let distortion = if d.len() > 5 {
                return Err(keys.err(&key("D"), format!("{} coefficients: k1, k2, p1, p2 and k3 are read", d.len())));
            } else {
                Distortion::RadialTangential(d)
            };
            Ok((RawCamera { k, distortion, size }, r, p))
        };
        let (left, r_left, p_left) = camera("LEFT")?;
        let (right, r_right, p_right) = camera("RIGHT")?;
        // the rectified pair the settings describe must be one (the P matrices)
        rectified_pair(&p_left, &p_right, ("LEFT.P", "RIGHT.P")).map_err(|m| keys.err("LEFT.P, RIGHT.P", m))?;
        let rig = RigCalibration::Given { left, right, r_left, r_right, p_left, p_right };
        return Ok(CalibrationFile { path: path.to_path_buf(), rig, topics: None, format: "ORB-SLAM settings" });
    }
    let intrinsics = [n("Camera.fx")?, n("Camera.fy")?, n("Camera.cx")?, n("Camera.cy")?];
    intrinsic_matrix(&keys, "Camera.fx", intrinsics)?;
    for k in ["Camera.k1", "Camera.k2", "Camera.p1", "Camera.p2", "Camera.k3"] {
        if !doc[k].is_badvalue() && n(k)? != 0.0 {
            return Err(keys.err(
                k,
                "distortion of a stereo rig without LEFT./RIGHT. K, D, R, P: ORB-SLAM takes stereo images as rectified; give the rectification (LEFT.K/D/R/P, RIGHT.K/D/R/P) or a Kalibr camchain",
            ));
        }
    }
    let bf = n("Camera.bf")?;
    let baseline = bf / intrinsics[0];
    if baseline.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Err(keys.err("Camera.bf", format!("{bf}: fx times the baseline is positive")));
    }
    let size = match (&doc["Camera.width"], &doc["Camera.height"]) {
        (Yaml::BadValue, _) | (_, Yaml::BadValue) => None,
        (w, h) => Some(keys.size("Camera", w, h)?),
    };
    Ok(CalibrationFile {
        path: path.to_path_buf(),
        rig: RigCalibration::Rectified { intrinsics, baseline, size },
        topics: None,
        format: "ORB-SLAM settings",
    })
}

/// The rig a pair of `CameraInfo` messages describes. Images with no distortion whose `K` equals `P`'s
/// left 3 × 3 are taken as rectified already (their `R` then records a rectification that was applied,
/// as KITTI's raw calibration does); otherwise they are rectified with their own `K, D, R, P`, as ROS's
/// `image_proc` does. `names` name the two topics in errors.
pub fn from_camera_infos(left: &CameraInfo, right: &CameraInfo, names: (&str, &str)) -> Result<RigCalibration, String> {
    let p = |c: &CameraInfo| Matrix3x4::from_row_slice(&c.p);
    let k = |c: &CameraInfo| Matrix3::from_row_slice(&c.k);
    for (c, name) in [(left, names.0), (right, names.1)] {
        if c.p.iter().chain(&c.k).chain(&c.r).chain(&c.d).any(|v| !v.is_finite()) {
            return Err(format!("{name}: a calibration value is not a finite number"));
        }
        if c.p.iter().all(|v| *v == 0.0) {
            return Err(format!("{name}: P is all zeros (an uncalibrated camera)"));
        }
    }
    let (pl, pr) = (p(left), p(right));
    let (intrinsics, baseline) = rectified_pair(&pl, &pr, (names.0, names.1))?;
    let plain = |c: &CameraInfo| {
        let d = c.d.iter().all(|v| *v == 0.0);
        let kp = (k(c) - p(c).fixed_view::<3, 3>(0, 0)).abs().max() <= crate::kitti::calib::RECTIFIED_TOLERANCE_PX;
        d && kp
    };
    let size = (left.width, left.height);
    if plain(left) && plain(right) {
        return Ok(RigCalibration::Rectified { intrinsics, baseline, size: Some(size) });
    }
    let raw = |c: &CameraInfo, name: &str| -> Result<RawCamera, String> {
        let distortion = match c.distortion_model.as_str() {
            "plumb_bob" | "rational_polynomial" if c.d.len() <= 5 => Distortion::RadialTangential(c.d.clone()),
            "equidistant" if c.d.len() == 4 => Distortion::Equidistant([c.d[0], c.d[1], c.d[2], c.d[3]]),
            "" if c.d.is_empty() => Distortion::None,
            m => return Err(format!("{name}: distortion model '{m}' with {} coefficients is not read (plumb_bob with up to 5, equidistant with 4)", c.d.len())),
        };
        Ok(RawCamera { k: k(c), distortion, size: (c.width, c.height) })
    };
    let rot = |c: &CameraInfo, name: &str| -> Result<Matrix3<f64>, String> {
        let m = Matrix3::from_row_slice(&c.r);
        let off = (m.transpose() * m - Matrix3::identity()).abs().max();
        if off > 1e-6 || m.determinant() < 0.0 {
            return Err(format!("{name}: R is not a rotation (RᵀR differs from the identity by {off:.2e})"));
        }
        Ok(m)
    };
    Ok(RigCalibration::Given {
        left: raw(left, names.0)?,
        right: raw(right, names.1)?,
        r_left: rot(left, names.0)?,
        r_right: rot(right, names.1)?,
        p_left: pl,
        p_right: pr,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("rig-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write");
        p
    }

    const KALIBR: &str = "cam0:
  camera_model: pinhole
  distortion_coeffs: [-0.28, 0.07, 0.0002, 0.00002]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  T_cn_cnm1:
  - [0.9999972, -0.0023171, -0.0002343, -0.1100738]
  - [0.0023172, 0.9999961, 0.0017052, 0.0003990]
  - [0.0002303, -0.0017057, 0.9999985, -0.0008536]
  - [0.0, 0.0, 0.0, 1.0]
  camera_model: pinhole
  distortion_coeffs: [-0.28, 0.07, -0.0001, -0.00001]
  distortion_model: radtan
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  resolution: [752, 480]
  rostopic: /cam1/image_raw
";

    #[test]
    fn a_kalibr_camchain_gives_raw_cameras_and_their_pose() {
        let c = read_calibration(&write("camchain.yaml", KALIBR)).expect("reads");
        assert_eq!(c.format, "Kalibr camchain");
        assert_eq!(c.topics, Some(("/cam0/image_raw".into(), "/cam1/image_raw".into())));
        let RigCalibration::Extrinsic { left, right, right_from_left } = &c.rig else { panic!("{:?}", c.rig) };
        assert_eq!((left.k[(0, 0)], left.size, right.k[(1, 2)]), (458.654, (752, 480), 255.238));
        assert!(matches!(&left.distortion, Distortion::RadialTangential(d) if d.len() == 4 && d[0] == -0.28));
        assert!((right_from_left.translation.vector.x + 0.1100738).abs() < 1e-12);
        assert!((c.rig.raw().1 - 0.11008).abs() < 1e-4);
        // equidistant, and the errors: a camera to the left, a matrix that is no rotation, a missing key
        let fisheye = KALIBR.replace("radtan", "equidistant");
        let c = read_calibration(&write("fisheye.yaml", &fisheye)).expect("reads");
        assert!(
            matches!(&c.rig, RigCalibration::Extrinsic { left, .. } if matches!(left.distortion, Distortion::Equidistant(_)))
        );
        let swapped = KALIBR.replace("-0.1100738", "0.1100738");
        let e = read_calibration(&write("swapped.yaml", &swapped)).expect_err("swapped").to_string();
        assert!(e.contains("swapped.yaml: cam1.T_cn_cnm1") && e.contains("cameras swapped"), "{e}");
        let scaled = KALIBR.replace("[0.9999972,", "[1.9999972,");
        let e = read_calibration(&write("scaled.yaml", &scaled)).expect_err("scaled").to_string();
        assert!(e.contains("not a rotation"), "{e}");
        let e = read_calibration(&write(
            "short.yaml",
            &KALIBR.replace("intrinsics: [457.587, 456.134, 379.999, 255.238]", "intrinsics: [1, 2]"),
        ))
        .expect_err("short")
        .to_string();
        assert!(e.contains("cam1.intrinsics: 2 numbers, expected 4"), "{e}");
        let e = read_calibration(&write("omni.yaml", &KALIBR.replacen("pinhole", "omni", 1)))
            .expect_err("omni")
            .to_string();
        assert!(e.contains("cam0.camera_model: 'omni'"), "{e}");
    }

    #[test]
    fn a_rectified_kalibr_pair_is_taken_as_it_is() {
        let text = "cam0:\n  intrinsics: [700, 700, 600, 180]\n  resolution: [1200, 360]\n  distortion_model: radtan\n  distortion_coeffs: [0, 0, 0, 0]\n\
                    cam1:\n  intrinsics: [700, 700, 600, 180]\n  resolution: [1200, 360]\n  distortion_model: radtan\n  distortion_coeffs: [0, 0, 0, 0]\n\
                    \x20 T_cn_cnm1:\n  - [1, 0, 0, -0.5]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n  - [0, 0, 0, 1]\n";
        let c = read_calibration(&write("rect.yaml", text)).expect("reads");
        assert_eq!(c.rig.rectified(), Some(([700.0, 700.0, 600.0, 180.0], 0.5)));
    }

    const ORB: &str = "%YAML:1.0
Camera.fx: 435.2046959714599
Camera.fy: 435.2046959714599
Camera.cx: 367.4517211914062
Camera.cy: 252.2008514404297
Camera.k1: 0.0
Camera.k2: 0.0
Camera.p1: 0.0
Camera.p2: 0.0
Camera.width: 752
Camera.height: 480
Camera.bf: 47.90639384423901
LEFT.height: 480
LEFT.width: 752
LEFT.D: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data:[-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.0]
LEFT.K: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [458.654, 0.0, 367.215, 0.0, 457.296, 248.375, 0.0, 0.0, 1.0]
LEFT.R:  !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
LEFT.P:  !!opencv-matrix
   rows: 3
   cols: 4
   dt: d
   data: [435.2046959714599, 0, 367.4517211914062, 0,  0, 435.2046959714599, 252.2008514404297, 0,  0, 0, 1, 0]
RIGHT.height: 480
RIGHT.width: 752
RIGHT.D: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data:[-0.28368365, 0.07451284, -0.00010473, -3.555907e-05, 0.0]
RIGHT.K: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [457.587, 0.0, 379.999, 0.0, 456.134, 255.238, 0.0, 0.0, 1]
RIGHT.R:  !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [0.999997035, -0.002300597, -0.000798274, 0.002299397, 0.999996230, -0.001500918, 0.000801724, 0.001499078, 0.999998555]
RIGHT.P:  !!opencv-matrix
   rows: 3
   cols: 4
   dt: d
   data: [435.2046959714599, 0, 367.4517211914062, -47.90639384423901, 0, 435.2046959714599, 252.2008514404297, 0, 0, 0, 1, 0]
";

    #[test]
    fn orbslam_settings_give_the_rectification_or_a_rectified_pair() {
        let c = read_calibration(&write("orb.yaml", ORB)).expect("reads");
        assert_eq!(c.format, "ORB-SLAM settings");
        let RigCalibration::Given { left, p_right, r_right, .. } = &c.rig else { panic!("{:?}", c.rig) };
        assert_eq!((left.size, p_right[(0, 3)]), ((752, 480), -47.90639384423901));
        assert!((r_right[(0, 1)] + 0.002300597).abs() < 1e-12);
        assert!((c.rig.raw().1 - 47.90639384423901 / 435.2046959714599).abs() < 1e-12);
        // without LEFT/RIGHT: rectified, baseline from bf
        let plain: String = ORB.lines().take(12).map(|l| format!("{l}\n")).collect();
        let c = read_calibration(&write("plain.yaml", &plain)).expect("reads");
        let (k, b) = c.rig.rectified().expect("rectified");
        assert_eq!(k[0], 435.2046959714599);
        assert!((b - 47.90639384423901 / 435.2046959714599).abs() < 1e-12);
        let e = read_calibration(&write("dist.yaml", &plain.replace("Camera.k1: 0.0", "Camera.k1: -0.2")))
            .expect_err("k1")
            .to_string();
        assert!(e.contains("Camera.k1: distortion"), "{e}");
        let e = read_calibration(&write("badp.yaml", &ORB.replace("-47.90639384423901", "47.9")))
            .expect_err("p")
            .to_string();
        assert!(e.contains("badp.yaml: LEFT.P, RIGHT.P") && e.contains("swapped"), "{e}");
        let e = read_calibration(&write("nan.yaml", &ORB.replace("Camera.bf: 47.90639384423901", "Camera.bf: .nan")))
            .expect("LEFT/RIGHT do not need bf");
        assert!(matches!(e.rig, RigCalibration::Given { .. }));
        let e = read_calibration(&write("none.yaml", "a: 1\n")).expect_err("neither").to_string();
        assert!(e.contains("Kalibr camchain") && e.contains("ORB-SLAM"), "{e}");
        let e = read_calibration(&write("broken.yaml", "cam0: [1, 2\nx: {\n")).expect_err("yaml").to_string();
        assert!(e.contains("broken.yaml:"), "{e}");
    }

    #[test]
    fn camera_infos_are_rectified_or_rectified_with_their_own_r_and_p() {
        let header = crate::ros::msgs::Header { stamp_ns: 0, frame_id: String::new() };
        let left = CameraInfo {
            header,
            width: 1242,
            height: 375,
            distortion_model: "plumb_bob".into(),
            d: vec![0.0; 5],
            k: [721.5377, 0.0, 609.5593, 0.0, 721.5377, 172.854, 0.0, 0.0, 1.0],
            r: [
                0.9999239,
                0.00983776,
                -0.007445048,
                -0.009869795,
                0.9999421,
                -0.004278459,
                0.007402527,
                0.004351614,
                0.9999631,
            ],
            p: [721.5377, 0.0, 609.5593, 0.0, 0.0, 721.5377, 172.854, 0.0, 0.0, 0.0, 1.0, 0.0],
        };
        let mut right = left.clone();
        right.p[3] = -387.5744;
        // KITTI's rectified images with the applied R_rect: taken as they are
        let rig = from_camera_infos(&left, &right, ("left", "right")).expect("rig");
        let (k, b) = rig.rectified().expect("rectified");
        assert_eq!(k, [721.5377, 721.5377, 609.5593, 172.854]);
        assert!((b - 387.5744 / 721.5377).abs() < 1e-12);
        // distortion: rectified with K, D, R, P
        right.d[0] = -0.37;
        assert!(matches!(
            from_camera_infos(&left, &right, ("left", "right")).expect("rig"),
            RigCalibration::Given { .. }
        ));
        // swapped cameras, an uncalibrated one
        let e = from_camera_infos(&right, &left, ("/a/camera_info", "/b/camera_info")).expect_err("swapped");
        assert!(e.contains("swapped"), "{e}");
        right.p = [0.0; 12];
        assert!(from_camera_infos(&left, &right, ("l", "r")).expect_err("zero").contains("all zeros"));
    }
}
