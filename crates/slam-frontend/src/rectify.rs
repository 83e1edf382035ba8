//! Stereo rectification of raw cameras (`slam_core::rig::RigCalibration`), computed once per run and
//! applied to every frame: OpenCV's stereo rectification (`stereoRectify`, or its fisheye form for the
//! equidistant model) when the rig is given by the right camera's pose, each camera's rectification as
//! given otherwise (ORB-SLAM's `LEFT/RIGHT.R, P`, ROS's `CameraInfo` `R, P`); then one remap table per
//! camera (`initUndistortRectifyMap`, positions as floats), applied with bilinear interpolation.
//!
//! The rectified pair keeps the raw image size. Stereo rectification is asked for the largest images
//! that hold only pixels the cameras saw (`alpha` 0, fisheye `balance` 0): a black border would give
//! the feature detector corners that are not in the scene. Its rectified left camera is turned from the
//! raw one by [`Rectifier::left_rotation`]; the run expresses its outputs in the raw left camera with it.

use opencv::{calib3d, core, imgproc, prelude::*};
use slam_core::{
    geometry::nalgebra::{Isometry3, Matrix3, Matrix3x4, Vector3},
    rig::{Distortion, RawCamera, RigCalibration},
    Image,
};

use crate::{
    image_io::{image_to_mat, mat_to_image},
    FrontendError,
};

/// Remap tables of both cameras and the rectified pair's calibration.
pub struct Rectifier {
    maps: [(Mat, Mat); 2],
    size: (u32, u32),
    /// `[fx, fy, cx, cy]` of the rectified pair, pixels.
    pub intrinsics: [f64; 4],
    /// Baseline of the rectified pair, metres.
    pub baseline: f64,
    /// Rectified-left from raw-left: `x_rectified = R · x_raw`.
    pub left_rotation: Matrix3<f64>,
    /// Rectified-right from raw-right.
    pub right_rotation: Matrix3<f64>,
}

impl std::fmt::Debug for Rectifier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Rectifier")
            .field("size", &self.size)
            .field("intrinsics", &self.intrinsics)
            .field("baseline", &self.baseline)
            .finish()
    }
}

fn mat3(m: &Matrix3<f64>) -> Result<Mat, FrontendError> {
    let rows: Vec<Vec<f64>> = (0..3).map(|r| (0..3).map(|c| m[(r, c)]).collect()).collect();
    Ok(Mat::from_slice_2d(&rows)?)
}

fn mat34(m: &Matrix3x4<f64>) -> Result<Mat, FrontendError> {
    let rows: Vec<Vec<f64>> = (0..3).map(|r| (0..4).map(|c| m[(r, c)]).collect()).collect();
    Ok(Mat::from_slice_2d(&rows)?)
}

fn from_mat3(m: &Mat) -> Result<Matrix3<f64>, FrontendError> {
    let mut out = Matrix3::zeros();
    for r in 0..3 {
        for c in 0..3 {
            out[(r, c)] = *m.at_2d::<f64>(r as i32, c as i32)?;
        }
    }
    Ok(out)
}

fn from_mat34(m: &Mat) -> Result<Matrix3x4<f64>, FrontendError> {
    let mut out = Matrix3x4::zeros();
    for r in 0..3 {
        for c in 0..4 {
            out[(r, c)] = *m.at_2d::<f64>(r as i32, c as i32)?;
        }
    }
    Ok(out)
}

fn coefficients(d: &Distortion) -> Result<Mat, FrontendError> {
    let v: Vec<f64> = match d {
        Distortion::None => vec![0.0; 4],
        Distortion::RadialTangential(v) => {
            let mut v = v.clone();
            v.resize(v.len().max(4), 0.0);
            v
        }
        Distortion::Equidistant(v) => v.to_vec(),
    };
    Ok(Mat::from_slice(&v)?.try_clone()?)
}

fn fisheye(c: &RawCamera) -> bool {
    matches!(c.distortion, Distortion::Equidistant(_))
}

fn size_of(c: &RawCamera) -> core::Size {
    core::Size::new(c.size.0 as i32, c.size.1 as i32)
}

/// The remap tables of one camera: raw pixel positions for every rectified pixel, as 32-bit floats
/// (OpenCV's fixed-point tables round positions to 1/32 px, up to a sixth of the 0.1 px sub-pixel
/// stereo resolves; on the distorted odometry 06 of docs/datasets.md the rounding alone moved the
/// aligned ATE by a third).
fn tables(c: &RawCamera, r: &Matrix3<f64>, p: &Matrix3x4<f64>) -> Result<(Mat, Mat), FrontendError> {
    let (k, d, r, p) = (mat3(&c.k)?, coefficients(&c.distortion)?, mat3(r)?, mat34(p)?);
    let (mut m1, mut m2) = (Mat::default(), Mat::default());
    if fisheye(c) {
        let p3 = p.col_range(&core::Range::new(0, 3)?)?.try_clone()?;
        calib3d::fisheye_init_undistort_rectify_map(&k, &d, &r, &p3, size_of(c), core::CV_32FC1, &mut m1, &mut m2)?;
    } else {
        calib3d::init_undistort_rectify_map(&k, &d, &r, &p, size_of(c), core::CV_32FC1, &mut m1, &mut m2)?;
    }
    Ok((m1, m2))
}

/// Each camera's rotation into its rectified frame and its rectified projection.
struct Rectification {
    r_left: Matrix3<f64>,
    r_right: Matrix3<f64>,
    p_left: Matrix3x4<f64>,
    p_right: Matrix3x4<f64>,
}

/// OpenCV's stereo rectification of two raw cameras from the right one's pose (fisheye or pinhole,
/// the same model for both): each camera's rotation `R` into its rectified frame and projection `P`.
fn stereo_rectification(
    left: &RawCamera,
    right: &RawCamera,
    right_from_left: &Isometry3<f64>,
) -> Result<Rectification, FrontendError> {
    if fisheye(left) != fisheye(right) {
        return Err(FrontendError::OpenCv(
            "one camera has the equidistant (fisheye) model and the other not: stereo rectification takes one model for both".into(),
        ));
    }
    let rot = right_from_left.rotation.to_rotation_matrix().into_inner();
    let t: Vector3<f64> = right_from_left.translation.vector;
    let (r, tv) = (mat3(&rot)?, Mat::from_slice_2d(&[[t.x], [t.y], [t.z]])?);
    let (kl, dl, kr, dr) =
        (mat3(&left.k)?, coefficients(&left.distortion)?, mat3(&right.k)?, coefficients(&right.distortion)?);
    let (mut r1, mut r2, mut p1, mut p2, mut q) =
        (Mat::default(), Mat::default(), Mat::default(), Mat::default(), Mat::default());
    if fisheye(left) {
        calib3d::fisheye_stereo_rectify(
            &kl,
            &dl,
            &kr,
            &dr,
            size_of(left),
            &r,
            &tv,
            &mut r1,
            &mut r2,
            &mut p1,
            &mut p2,
            &mut q,
            calib3d::CALIB_ZERO_DISPARITY,
            size_of(left),
            0.0,
            1.0,
        )?;
    } else {
        let (mut roi1, mut roi2) = (core::Rect::default(), core::Rect::default());
        calib3d::stereo_rectify(
            &kl,
            &dl,
            &kr,
            &dr,
            size_of(left),
            &r,
            &tv,
            &mut r1,
            &mut r2,
            &mut p1,
            &mut p2,
            &mut q,
            calib3d::CALIB_ZERO_DISPARITY,
            0.0,
            size_of(left),
            &mut roi1,
            &mut roi2,
        )?;
    }
    Ok(Rectification {
        r_left: from_mat3(&r1)?,
        r_right: from_mat3(&r2)?,
        p_left: from_mat34(&p1)?,
        p_right: from_mat34(&p2)?,
    })
}

impl Rectifier {
    /// Compute the rectification of `rig` once (a rectified pair needs none: `Ok(None)`).
    pub fn new(rig: &RigCalibration) -> Result<Option<Rectifier>, FrontendError> {
        let (left, right, r_left, r_right, p_left, p_right) = match rig {
            RigCalibration::Rectified { .. } => return Ok(None),
            RigCalibration::Given { left, right, r_left, r_right, p_left, p_right } => {
                (left, right, *r_left, *r_right, *p_left, *p_right)
            }
            RigCalibration::Extrinsic { left, right, right_from_left } => {
                let Rectification { r_left, r_right, p_left, p_right } =
                    stereo_rectification(left, right, right_from_left)?;
                (left, right, r_left, r_right, p_left, p_right)
            }
        };
        if left.size != right.size {
            return Err(FrontendError::OpenCv(format!(
                "the cameras' image sizes differ ({}×{} and {}×{}): a stereo pair has one size",
                left.size.0, left.size.1, right.size.0, right.size.1
            )));
        }
        let fx = p_left[(0, 0)];
        let baseline = -p_right[(0, 3)] / p_right[(0, 0)];
        if !(fx > 0.0 && baseline > 0.0 && baseline.is_finite()) {
            return Err(FrontendError::OpenCv(format!(
                "the rectified pair has fx {fx} px and baseline {baseline} m: the right camera must lie to the right of the left one"
            )));
        }
        let maps = [tables(left, &r_left, &p_left)?, tables(right, &r_right, &p_right)?];
        Ok(Some(Rectifier {
            maps,
            size: left.size,
            intrinsics: [fx, p_left[(1, 1)], p_left[(0, 2)], p_left[(1, 2)]],
            baseline,
            left_rotation: r_left,
            right_rotation: r_right,
        }))
    }

    /// The raw image size it rectifies.
    pub fn size(&self) -> (u32, u32) {
        self.size
    }

    /// Rectify one camera's image (`right` for the right camera).
    pub fn apply_one(&self, image: &Image, right: bool) -> Result<Image, FrontendError> {
        if (image.width, image.height) != self.size {
            return Err(FrontendError::OpenCv(format!(
                "an image of {}×{} pixels for a calibration of {}×{}",
                image.width, image.height, self.size.0, self.size.1
            )));
        }
        let (m1, m2) = &self.maps[usize::from(right)];
        let src = image_to_mat(image)?;
        let mut dst = Mat::default();
        imgproc::remap(&src, &mut dst, m1, m2, imgproc::INTER_LINEAR, core::BORDER_CONSTANT, core::Scalar::all(0.0))?;
        mat_to_image(&dst)
    }

    /// Rectify a stereo pair.
    pub fn apply(&self, left: &Image, right: &Image) -> Result<(Image, Image), FrontendError> {
        Ok((self.apply_one(left, false)?, self.apply_one(right, true)?))
    }
}

/// Where raw pixels `points` of `camera` (whose rectification is `r`, `p`) land in the rectified image:
/// OpenCV's iterative `undistortPoints`, iterated to 1e-10 px.
pub fn rectified_positions(
    points: &[(f64, f64)],
    camera: &RawCamera,
    r: &Matrix3<f64>,
    p: &Matrix3x4<f64>,
) -> Result<Vec<(f64, f64)>, FrontendError> {
    let pixels: core::Vector<core::Point2f> =
        points.iter().map(|&(x, y)| core::Point2f::new(x as f32, y as f32)).collect();
    let out = undistorted(&pixels, camera, r, p)?;
    Ok(out.iter().map(|q| (f64::from(q.x), f64::from(q.y))).collect())
}

fn undistorted(
    pixels: &core::Vector<core::Point2f>,
    camera: &RawCamera,
    r: &Matrix3<f64>,
    p: &Matrix3x4<f64>,
) -> Result<core::Vector<core::Point2f>, FrontendError> {
    let (k, d, rm, pm) = (mat3(&camera.k)?, coefficients(&camera.distortion)?, mat3(r)?, mat34(p)?);
    let mut out = core::Vector::<core::Point2f>::new();
    let criteria = core::TermCriteria::new(core::TermCriteria_COUNT + core::TermCriteria_EPS, 200, 1e-10)?;
    if fisheye(camera) {
        let p3 = pm.col_range(&core::Range::new(0, 3)?)?.try_clone()?;
        calib3d::fisheye_undistort_points(pixels, &mut out, &k, &d, &rm, &p3, criteria)?;
    } else {
        calib3d::undistort_points_iter(pixels, &mut out, &k, &d, &rm, &pm, criteria)?;
    }
    Ok(out)
}

/// The image a raw camera (`camera`, whose rectification is `r`, `p`) would have taken of the scene a
/// rectified image shows: what rectifying undoes. Each raw pixel is undistorted and rotated into the
/// rectified camera (OpenCV's iterative `undistortPoints`, iterated to 1e-10 px) and the rectified image
/// sampled there (bilinear; black outside). For making raw test data from rectified images.
pub fn raw_from_rectified(
    rectified: &Image,
    camera: &RawCamera,
    r: &Matrix3<f64>,
    p: &Matrix3x4<f64>,
) -> Result<Image, FrontendError> {
    let (w, h) = camera.size;
    let mut pixels = core::Vector::<core::Point2f>::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            pixels.push(core::Point2f::new(x as f32, y as f32));
        }
    }
    let out = undistorted(&pixels, camera, r, p)?;
    let mut map_x = Mat::new_rows_cols_with_default(h as i32, w as i32, core::CV_32FC1, core::Scalar::all(0.0))?;
    let mut map_y = map_x.clone();
    for (i, q) in out.iter().enumerate() {
        let (x, y) = ((i as u32 % w) as i32, (i as u32 / w) as i32);
        *map_x.at_2d_mut::<f32>(y, x)? = q.x;
        *map_y.at_2d_mut::<f32>(y, x)? = q.y;
    }
    let src = image_to_mat(rectified)?;
    let mut dst = Mat::default();
    imgproc::remap(
        &src,
        &mut dst,
        &map_x,
        &map_y,
        imgproc::INTER_LINEAR,
        core::BORDER_CONSTANT,
        core::Scalar::all(0.0),
    )?;
    mat_to_image(&dst)
}
