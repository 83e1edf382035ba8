//! Dual-quadric (ellipsoid) geometry for object-oriented SLAM.
//!
//! An object is an ellipsoid: a pose `T_wq` (world from quadric frame) and three semi-axes. Its
//! **dual quadric** `Q* = T_wq diag(a₁², a₂², a₃², −1) T_wqᵀ` projects through a camera
//! `P = K [I|0] T_cw` to the **dual conic** `C* = P Q* Pᵀ`, whose axis-aligned bounds are the box a
//! detector should report (Nicholson et al., "QuadricSLAM", RA-L 2019). This crate provides:
//!
//! * [`Ellipsoid`]: dual quadric, the "constrain" repair of a general symmetric 4×4, the 9-dof
//!   retraction (`[ω, v]` right SE(3) perturbation + additive semi-axes);
//! * [`Camera`] / [`Intrinsics`]: projection matrices (camera frame x right, y down, z forward);
//! * [`project`], [`DualConic`]: projection with errors for ellipsoids behind, straddling or around the
//!   camera, axis-aligned bounds and the **exact image-clipped bounds**;
//! * [`predict_box`]: predicted box under a [`BoundsModel`] with analytic Jacobians (4×6 camera,
//!   4×9 ellipsoid), the measurement model of the box factor;
//! * [`init`]: multi-view initialisers behind one trait: DQP (Tian et al. 2022), Tri, QuadricSLAM's
//!   SVD and the Conic method (Rubino et al.);
//! * [`metrics`]: IoU, e_trans, e_axe.
//!
//! Conventions follow gtsam-quadrics (checked against its vectors in `fixtures/oracle/`), except where
//! that library is wrong (its truncated bounds; its centre-only "behind" test).
//!
//! The only dependency is `nalgebra`; the `serde` feature derives serialisation for the value types.
//!
//! ```
//! use nalgebra::{Isometry3, Vector3};
//! use slam_quadric::{project, BBox, Camera, Ellipsoid, ImageSize, Intrinsics};
//!
//! let k = Intrinsics::new(721.5377, 721.5377, 609.5593, 172.854);
//! let camera = Camera::new(k, Isometry3::identity()); // world = camera frame
//! let car = Ellipsoid::new(Isometry3::translation(2.0, 0.9, 15.0), Vector3::new(2.1, 0.8, 0.85));
//! let conic = project(&car, &camera)?;
//! let b: BBox = conic.clipped_bounds(&ImageSize::new(1242.0, 375.0))?;
//! assert!(b.xmin > 550.0 && b.xmax < 900.0 && b.ymin > 172.0);
//! # Ok::<(), slam_quadric::ProjectionError>(())
//! ```

#![warn(missing_docs)]

pub mod bbox;
pub mod camera;
pub mod conic;
pub mod cuboid;
pub mod ellipsoid;
pub mod init;
pub mod metrics;
pub mod se3;

pub use bbox::{BBox, BoxError, ImageSize};
pub use camera::{Camera, Intrinsics};
pub use conic::{
    box_error, classify, predict_box, project, BoundsModel, BoxPrediction, BoxResidual, DualConic, Ellipse2,
    ProjectionError, Visibility,
};
pub use cuboid::{box_iou, cuboid_bounds, cuboid_corners, cuboid_signs};
pub use ellipsoid::{ConstrainError, Ellipsoid, Tangent9};
pub use init::{BoxView, InitError, Initializer};
/// The linear-algebra crate of the public API, re-exported so dependants use the same version.
pub use nalgebra;
