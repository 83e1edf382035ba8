//! The simulation study of Tian et al. (RA-L 2022, §VI-A), made precise, plus a drive-by geometry
//! closer to KITTI, comparing ellipsoid initialisers under pose and box noise.
//!
//! Protocol (also in `docs/simulation.md`):
//!
//! * Camera: KITTI colour intrinsics `fx = fy = 721.5377, cx = 609.5593, cy = 172.854`, image 1242×375.
//!   World = the reference (first) camera's frame: x right, y down, z forward.
//! * Object: semi-axes along its own x (length), y (height), z (width) drawn from
//!   `U[1.8, 2.4] × U[0.7, 0.9] × U[0.75, 0.95]` m; yaw about the vertical `U[−5°, 5°]`; centre 0.9 m
//!   below the cameras.
//! * [`Geometry::Arc`]: five level cameras evenly spaced on an 18° arc of radius 15 m centred on the
//!   object, each yawed so its optical axis passes through the object's centre (horizontally); the car
//!   is seen side-on by the reference camera.
//! * [`Geometry::DriveBy`]: a camera driving along +z at 1 m per frame (10 m/s, 10 Hz) past a car
//!   parked parallel to the road, 6 m to the right of the path, from 25 m before it until it is more
//!   than 40° off the optical axis; every 3rd frame is a keyframe (6 views).
//! * Noise ([`NoiseKind`]), zero-mean Gaussian, on every camera but the reference: translation, per-axis
//!   σ = p % of that camera's distance from the reference camera; rotation, a rotation vector with
//!   per-axis σ = p % of the camera's rotation angle from the reference (p % of 1° in the drive-by,
//!   where that angle is 0), applied on the right; box, σ = p % of the box width (x) or height (y) per
//!   coordinate. Boxes are the exact image-clipped bounds of the true ellipsoid.
//! * 10 objects × 10 noise seeds per cell; a trial fails when the method returns an error or a centre
//!   behind a (true) camera.

#![warn(missing_docs)]

mod methods;
pub mod report;
mod scene;
mod sweep;

pub use methods::{optimise_object, refine, Method, ObjectPrior, RefineConfig};
pub use scene::{perturb, Geometry, NoiseKind, Scene, IMAGE, KITTI_K};
pub use sweep::{breakdown_level, run_trial, sweep, CellStats, SweepConfig, TrialResult};
