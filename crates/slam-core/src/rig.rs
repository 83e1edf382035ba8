//! A stereo rig's calibration as the readers give it and the front end rectifies it: a rectified
//! pair, or two raw cameras (intrinsics, lens distortion, image size) with the right camera's pose or
//! with their rectification given. Read from files by `slam_dataset::rig`; rectified by
//! `slam_frontend::rectify`.

use slam_quadric::nalgebra::{Isometry3, Matrix3, Matrix3x4};

/// Lens distortion of a raw camera.
#[derive(Debug, Clone, PartialEq)]
pub enum Distortion {
    /// None (a pinhole camera, or rectified images).
    None,
    /// Brown–Conrady, as OpenCV and ROS's `plumb_bob` order it: k1, k2, p1, p2 and optionally k3 (Kalibr's
    /// `radtan` is the first four).
    RadialTangential(Vec<f64>),
    /// The equidistant fisheye model, k1…k4 (Kalibr's `equidistant`, OpenCV's `fisheye`).
    Equidistant([f64; 4]),
}

impl Distortion {
    /// Whether it changes any pixel (some coefficient is not zero).
    pub fn is_some(&self) -> bool {
        match self {
            Distortion::None => false,
            Distortion::RadialTangential(d) => d.iter().any(|v| *v != 0.0),
            Distortion::Equidistant(d) => d.iter().any(|v| *v != 0.0),
        }
    }
}

/// A raw camera: intrinsic matrix, distortion, image size.
#[derive(Debug, Clone, PartialEq)]
pub struct RawCamera {
    /// `[fx 0 cx; 0 fy cy; 0 0 1]`.
    pub k: Matrix3<f64>,
    /// Lens distortion.
    pub distortion: Distortion,
    /// Image size `(width, height)`, pixels.
    pub size: (u32, u32),
}

/// What a calibration says about a stereo rig.
// one value per run: the rectified variant's smaller size saves nothing worth a box
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum RigCalibration {
    /// The images are a rectified pair: used as they are.
    Rectified {
        /// `[fx, fy, cx, cy]`, pixels.
        intrinsics: [f64; 4],
        /// Metres.
        baseline: f64,
        /// The image size the calibration is for, when it says.
        size: Option<(u32, u32)>,
    },
    /// Raw cameras and the right camera's pose: `x_right = right_from_left · x_left` (Kalibr's
    /// `T_cn_cnm1`). The front end computes a rectification.
    Extrinsic {
        /// Left camera.
        left: RawCamera,
        /// Right camera.
        right: RawCamera,
        /// Right camera from left camera.
        right_from_left: Isometry3<f64>,
    },
    /// Raw cameras with their rectification given: each camera's rotation into its rectified frame
    /// `R` and the rectified projection `P` (ORB-SLAM's `LEFT.R/P`, ROS's `CameraInfo.r/p`).
    Given {
        /// Left camera.
        left: RawCamera,
        /// Right camera.
        right: RawCamera,
        /// Rectified-left from raw-left rotation.
        r_left: Matrix3<f64>,
        /// Rectified-right from raw-right rotation.
        r_right: Matrix3<f64>,
        /// Left rectified projection.
        p_left: Matrix3x4<f64>,
        /// Right rectified projection (`P[0][3] = −fx · baseline`).
        p_right: Matrix3x4<f64>,
    },
}

impl RigCalibration {
    /// The intrinsics and baseline the images are tracked with when they need no rectifying.
    pub fn rectified(&self) -> Option<([f64; 4], f64)> {
        match self {
            RigCalibration::Rectified { intrinsics, baseline, .. } => Some((*intrinsics, *baseline)),
            _ => None,
        }
    }

    /// The left camera's own intrinsics and the distance between the cameras: what a rig that needs
    /// rectifying has before it is rectified.
    pub fn raw(&self) -> ([f64; 4], f64) {
        let k = |c: &RawCamera| [c.k[(0, 0)], c.k[(1, 1)], c.k[(0, 2)], c.k[(1, 2)]];
        match self {
            RigCalibration::Rectified { intrinsics, baseline, .. } => (*intrinsics, *baseline),
            RigCalibration::Extrinsic { left, right_from_left, .. } => {
                (k(left), right_from_left.translation.vector.norm())
            }
            RigCalibration::Given { left, p_right, .. } => (k(left), -p_right[(0, 3)] / p_right[(0, 0)]),
        }
    }

    /// The image size it is for, when it says.
    pub fn size(&self) -> Option<(u32, u32)> {
        match self {
            RigCalibration::Rectified { size, .. } => *size,
            RigCalibration::Extrinsic { left, .. } | RigCalibration::Given { left, .. } => Some(left.size),
        }
    }
}
