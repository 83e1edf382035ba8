//! A rectified KITTI sequence made into a raw rig's recording, to check rectification on data whose
//! answer is known: each image as a camera with lens distortion would have taken it
//! (`slam_frontend::rectify::raw_from_rectified`), the right camera turned away from the rectified pair,
//! written as a folder of `left/` and `right/` PNG images with `times.txt` and the rig's calibration in
//! both formats `run --calib` reads: Kalibr's `camchain.yaml` (the cameras and the right one's pose:
//! the run computes its own rectification) and ORB-SLAM's settings `orbslam.yaml` (each camera's `K,
//! D` and the exact rectification `R, P` that gives the original images back).
//!
//! The raw cameras keep the rectified focal length; the left camera is the rectified left one with
//! distortion, the right one is the rectified right camera turned by [`RawRigSpec::turn_deg`] about
//! [`RawRigSpec::axis`] (`x_raw = Q · x_rectified`), with distortion; both keep the originals' image
//! size. A camera with barrel distortion sees more than the rectified image it is made from shows:
//! those raw pixels are black (nothing is made up). The exact rectification (`orbslam.yaml`) gives
//! the originals back; Kalibr's rig is rectified by the run's own stereo rectification, whose view
//! may reach into that black margin.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix3x4, Rotation3, Unit, Vector3};
use slam_core::rig::{Distortion, RawCamera};
use slam_dataset::kitti::stereo::{open_stereo, Layout, StereoSequence};
use slam_frontend::{read_image, rectify::raw_from_rectified, write_image};

use crate::error::{Result, RunnerError};

/// The raw rig a sequence is made into.
#[derive(Debug, Clone, PartialEq)]
pub struct RawRigSpec {
    /// Left camera's plumb_bob coefficients (k1, k2, p1, p2, k3).
    pub d_left: [f64; 5],
    /// Right camera's.
    pub d_right: [f64; 5],
    /// How far the right camera is turned from the rectified pair, degrees.
    pub turn_deg: f64,
    /// About which axis (right camera's frame).
    pub axis: [f64; 3],
}

impl Default for RawRigSpec {
    /// KITTI's own raw grey cameras' distortion (2011_09_26 `calib_cam_to_cam.txt`, `D_00` and
    /// `D_01`: strong barrel distortion, as wide-angle automotive lenses have) without its k3, which
    /// Kalibr's four-coefficient radtan cannot hold (so both calibration files describe the same
    /// cameras), and a right camera turned
    /// 0.5° about an axis mostly vertical, with some tilt and roll: rows no longer aligned, as a rig
    /// knocked out of its rectification would be.
    fn default() -> Self {
        Self {
            d_left: [-3.728755e-01, 2.037299e-01, 2.219027e-03, 1.383707e-03, 0.0],
            d_right: [-3.644661e-01, 1.790019e-01, 1.148107e-03, -6.298563e-04, 0.0],
            turn_deg: 0.5,
            axis: [0.2, 1.0, 0.3],
        }
    }
}

/// What [`write_raw_rig`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct RawRig {
    /// The folder (with `left/`, `right/`, `times.txt`).
    pub dir: PathBuf,
    /// Kalibr's camchain.
    pub kalibr: PathBuf,
    /// ORB-SLAM's settings.
    pub orbslam: PathBuf,
    /// Frames written.
    pub frames: usize,
    /// The images' size.
    pub size: (u32, u32),
}

fn matrix_text(m: &[f64]) -> String {
    m.iter().map(|v| format!("{v:.12e}")).collect::<Vec<_>>().join(", ")
}

/// Write the first `frames` frames (all without a count) of the KITTI odometry sequence `seq` into
/// `out` (created; an existing folder is refused) as the raw rig `spec`.
pub fn write_raw_rig(seq: &Path, out: &Path, frames: Option<usize>, spec: &RawRigSpec) -> Result<RawRig> {
    let s = open_odometry(seq, out)?;
    let n = frames.unwrap_or(s.len()).min(s.len());
    let first = read_image(&s.left[0], false)?;
    let size = (first.width, first.height);
    let rig = RigGeometry::new(&s, spec, size);
    let tmp = partial_dir(out)?;
    write_frames(&s, n, &tmp, &rig)?;
    let times: String = s.times.iter().take(n).map(|t| format!("{t:.6}\n")).collect();
    let write = |name: &str, text: &str| {
        std::fs::write(tmp.join(name), text)
            .map_err(|e| RunnerError::Invalid(format!("{}: {e}", tmp.join(name).display())))
    };
    write("times.txt", &times)?;
    write("camchain.yaml", &kalibr_text(seq, spec, &rig))?;
    write("orbslam.yaml", &orbslam_text(seq, spec, &rig))?;
    std::fs::rename(&tmp, out).map_err(|e| RunnerError::Invalid(format!("{}: {e}", out.display())))?;
    Ok(RawRig {
        dir: out.to_path_buf(),
        kalibr: out.join("camchain.yaml"),
        orbslam: out.join("orbslam.yaml"),
        frames: n,
        size,
    })
}

/// The KITTI odometry sequence `seq`, checked to be one (grey, rectified) and `out` checked not to
/// exist yet.
fn open_odometry(seq: &Path, out: &Path) -> Result<StereoSequence> {
    let s = open_stereo(seq)?;
    if s.layout != Layout::Odometry {
        return Err(RunnerError::Invalid(format!(
            "{}: a KITTI odometry sequence (grey, rectified) is needed",
            seq.display()
        )));
    }
    if out.exists() {
        return Err(RunnerError::Invalid(format!(
            "{}: exists; the raw rig is written into a new folder",
            out.display()
        )));
    }
    Ok(s)
}

/// The raw rig's geometry: the rectified pair's intrinsics, baseline and image size, the right
/// camera's turn `Q`, each camera's exact rectification `R` and projection `P`, and the raw cameras.
struct RigGeometry {
    intrinsics: [f64; 4],
    baseline: f64,
    size: (u32, u32),
    q: Matrix3<f64>,
    k: Matrix3<f64>,
    r_left: Matrix3<f64>,
    r_right: Matrix3<f64>,
    p_left: Matrix3x4<f64>,
    p_right: Matrix3x4<f64>,
    left: RawCamera,
    right: RawCamera,
}

impl RigGeometry {
    /// The raw rig `spec` made from the rectified pair of `s`, with images of `size`.
    fn new(s: &StereoSequence, spec: &RawRigSpec, size: (u32, u32)) -> Self {
        let [fx, fy, cx, cy] = s.intrinsics;
        let b = s.baseline;
        let q = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::from(spec.axis)), spec.turn_deg.to_radians())
            .into_inner();
        // rectified right from raw right: Qᵀ
        let (r_left, r_right) = (Matrix3::identity(), q.transpose());
        let k = Matrix3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0);
        let p_left = Matrix3x4::new(fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0);
        let p_right = Matrix3x4::new(fx, 0.0, cx, -fx * b, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0);
        let left = RawCamera { k, distortion: Distortion::RadialTangential(spec.d_left.to_vec()), size };
        let right = RawCamera { k, distortion: Distortion::RadialTangential(spec.d_right.to_vec()), size };
        Self { intrinsics: s.intrinsics, baseline: b, size, q, k, r_left, r_right, p_left, p_right, left, right }
    }
}

/// A fresh hidden folder beside `out` with `left/` and `right/` inside, where the rig is written before
/// it is renamed to `out`.
fn partial_dir(out: &Path) -> Result<PathBuf> {
    let tmp = out.with_file_name(format!(
        ".{}.partial-{}",
        out.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&tmp);
    for sub in ["left", "right"] {
        std::fs::create_dir_all(tmp.join(sub)).map_err(|e| RunnerError::Invalid(format!("{}: {e}", tmp.display())))?;
    }
    Ok(tmp)
}

/// The first `n` frames of `s` as the raw cameras would have taken them, into `tmp`'s `left/` and
/// `right/`.
fn write_frames(s: &StereoSequence, n: usize, tmp: &Path, rig: &RigGeometry) -> Result<()> {
    for i in 0..n {
        let (l, r) = (read_image(&s.left[i], false)?, read_image(&s.right[i], false)?);
        let name = format!("{:06}.png", s.ids[i]);
        write_image(tmp.join("left").join(&name), &raw_from_rectified(&l, &rig.left, &rig.r_left, &rig.p_left)?)?;
        write_image(tmp.join("right").join(&name), &raw_from_rectified(&r, &rig.right, &rig.r_right, &rig.p_right)?)?;
    }
    Ok(())
}

/// Kalibr's `camchain.yaml` of the rig: both cameras and the right one's pose from the left.
fn kalibr_text(seq: &Path, spec: &RawRigSpec, rig: &RigGeometry) -> String {
    let ([fx, fy, cx, cy], b, size, q) = (rig.intrinsics, rig.baseline, rig.size, rig.q);
    // Kalibr: x_right = T · x_left with T = [Q | −Q (b, 0, 0)]
    let t = -(q * Vector3::new(b, 0.0, 0.0));
    let row = |r: usize| format!("  - [{:.12e}, {:.12e}, {:.12e}, {:.12e}]\n", q[(r, 0)], q[(r, 1)], q[(r, 2)], t[r]);
    let cam = |name: &str, d: &[f64; 5], extra: &str| {
        format!(
            "{name}:\n{extra}  camera_model: pinhole\n  distortion_model: radtan\n  distortion_coeffs: [{}]\n  intrinsics: [{fx}, {fy}, {cx}, {cy}]\n  resolution: [{}, {}]\n",
            matrix_text(&d[..4]),
            size.0,
            size.1
        )
    };
    format!(
        "# a raw rig made from {} by slam-runner's raw_rig\n{}{}",
        seq.display(),
        cam("cam0", &spec.d_left, ""),
        cam("cam1", &spec.d_right, &format!("  T_cn_cnm1:\n{}{}{}  - [0.0, 0.0, 0.0, 1.0]\n", row(0), row(1), row(2)))
    )
}

/// ORB-SLAM's `orbslam.yaml` of the rig: the rectified pair's settings and each camera's `K`, `D` and
/// exact rectification `R`, `P`.
fn orbslam_text(seq: &Path, spec: &RawRigSpec, rig: &RigGeometry) -> String {
    let ([fx, fy, cx, cy], b, size, k) = (rig.intrinsics, rig.baseline, rig.size, rig.k);
    let (r_left, r_right, p_left, p_right) = (rig.r_left, rig.r_right, rig.p_left, rig.p_right);
    let block = |name: &str, rows: usize, cols: usize, data: &[f64]| {
        format!(
            "{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [{}]\n",
            matrix_text(data)
        )
    };
    let row_major = |m: &Matrix3<f64>| (0..3).flat_map(|r| (0..3).map(move |c| m[(r, c)])).collect::<Vec<_>>();
    let row_major34 = |m: &Matrix3x4<f64>| (0..3).flat_map(|r| (0..4).map(move |c| m[(r, c)])).collect::<Vec<_>>();
    let mut orb = format!(
        "%YAML:1.0\n# a raw rig made from {}; LEFT/RIGHT R and P give the original rectified pair back\nCamera.fx: {fx}\nCamera.fy: {fy}\nCamera.cx: {cx}\nCamera.cy: {cy}\nCamera.k1: 0.0\nCamera.k2: 0.0\nCamera.p1: 0.0\nCamera.p2: 0.0\nCamera.width: {}\nCamera.height: {}\nCamera.fps: 10.0\nCamera.bf: {}\n",
        seq.display(),
        size.0,
        size.1,
        fx * b
    );
    for (side, d, r, p) in [("LEFT", &spec.d_left, &r_left, &p_left), ("RIGHT", &spec.d_right, &r_right, &p_right)] {
        orb.push_str(&format!("{side}.height: {}\n{side}.width: {}\n", size.1, size.0));
        orb.push_str(&block(&format!("{side}.D"), 1, 5, d));
        orb.push_str(&block(&format!("{side}.K"), 3, 3, &row_major(&k)));
        orb.push_str(&block(&format!("{side}.R"), 3, 3, &row_major(r)));
        orb.push_str(&block(&format!("{side}.P"), 3, 4, &row_major34(p)));
    }
    orb
}
