//! Ellipsoid initialisation from boxes seen in several calibrated views.
//!
//! Every method implements [`Initializer`], so callers can swap them:
//!
//! | type | method | unknowns |
//! |---|---|---|
//! | [`Dqp`] | Tian et al. 2022, "Tri+Yaw": centre by triangulating box centres, then a yaw-only linear solve | 3 + 5 |
//! | [`Tri`] | centre by triangulation, then the full upper 3×3 block of `Q*` | 3 + 7 |
//! | [`QSlamSvd`] | Nicholson et al. 2018 (QuadricSLAM): all 10 entries of `Q*` from the box planes by SVD | 10 |
//! | [`Conic`] | Rubino et al. 2017: ellipses inscribed in the boxes, solved jointly with one scale per view | 10 + n |
//!
//! All methods return an [`InitError`] — never NaN, never a panic — when the views are too few or
//! degenerate, or when the solution is not a real ellipsoid wholly in front of every camera.
//! The maths, and the corrections to the printed equations of Tian et al., are in `docs/quadric-maths.md`.

mod conic_method;
mod dqp;
mod linalg;
mod qslam;
mod triangulate;

use std::fmt;

pub use conic_method::Conic;
pub use dqp::{printed_eq7, refine_centre, Dqp, Reference, Tri};
pub use qslam::QSlamSvd;
pub use triangulate::{triangulate_box_centres, TriangulationConfig};

use crate::{
    bbox::{BBox, BoxError},
    camera::Camera,
    conic::{classify, Visibility},
    ellipsoid::{ConstrainError, Ellipsoid},
};

/// One observation: a camera (intrinsics + world-from-camera pose) and the object's box in its image.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BoxView {
    /// The observing camera.
    pub camera: Camera,
    /// The detected box, pixels.
    pub bbox: BBox,
}

impl BoxView {
    /// A view from a camera and a box.
    pub const fn new(camera: Camera, bbox: BBox) -> Self {
        Self { camera, bbox }
    }
}

/// Why an initialiser produced no ellipsoid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InitError {
    /// Fewer views than the method needs.
    TooFewViews {
        /// Views given.
        got: usize,
        /// Views needed.
        need: usize,
    },
    /// A view has a NaN/infinite pose or intrinsics, or an unusable box.
    InvalidView {
        /// Index of the view.
        view: usize,
        /// What is wrong with its box, if it is the box.
        reason: Option<BoxError>,
    },
    /// The views cannot determine the ellipsoid.
    Degenerate(Degeneracy),
    /// The linear solution is not a real ellipsoid.
    NotEllipsoid(ConstrainError),
    /// The solution is not wholly in front of this view's camera.
    BehindCamera {
        /// Index of the view.
        view: usize,
    },
    /// The solution contains this view's camera centre.
    CameraInside {
        /// Index of the view.
        view: usize,
    },
}

/// The kinds of degenerate view configurations.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Degeneracy {
    /// All camera centres coincide: no baseline to triangulate from.
    SingleCentre,
    /// The rays through the box centres are (nearly) parallel.
    ParallelRays,
    /// The linear system has no isolated solution (a null space of dimension > 1, or a zero scale).
    RankDeficient,
}

impl fmt::Display for InitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            InitError::TooFewViews { got, need } => write!(f, "too few views: got {got}, need {need}"),
            InitError::InvalidView { view, reason: Some(r) } => write!(f, "view {view}: {r}"),
            InitError::InvalidView { view, reason: None } => {
                write!(f, "view {view}: camera pose or intrinsics not finite")
            }
            InitError::Degenerate(Degeneracy::SingleCentre) => write!(f, "degenerate views: all cameras at one centre"),
            InitError::Degenerate(Degeneracy::ParallelRays) => {
                write!(f, "degenerate views: rays through the box centres are parallel")
            }
            InitError::Degenerate(Degeneracy::RankDeficient) => {
                write!(f, "degenerate views: linear system is rank deficient")
            }
            InitError::NotEllipsoid(e) => write!(f, "solution is not an ellipsoid: {e}"),
            InitError::BehindCamera { view } => write!(f, "solution is not in front of camera {view}"),
            InitError::CameraInside { view } => write!(f, "solution contains camera {view}"),
        }
    }
}

impl std::error::Error for InitError {}

impl From<ConstrainError> for InitError {
    fn from(e: ConstrainError) -> Self {
        InitError::NotEllipsoid(e)
    }
}

/// A multi-view ellipsoid initialiser. Object-safe, so a pipeline can hold a `Box<dyn Initializer>`.
///
/// Contract: `initialize` returns `Ok` only for a finite ellipsoid with positive semi-axes that lies
/// wholly in front of every view's camera and does not contain any camera centre; otherwise an
/// [`InitError`]. It never panics on finite or non-finite input.
pub trait Initializer: Send + Sync {
    /// Short name for tables and logs ("DQP", "Tri", "Q-SLAM", "Conic").
    fn name(&self) -> &'static str;
    /// Smallest number of views the method accepts.
    fn min_views(&self) -> usize;
    /// Estimate the ellipsoid seen in `views`.
    fn initialize(&self, views: &[BoxView]) -> Result<Ellipsoid, InitError>;
}

/// Relative distance under which camera centres count as one centre.
const SAME_CENTRE_REL: f64 = 1e-9;

/// Checks shared by all methods: enough views, finite cameras, valid boxes, more than one centre.
pub(crate) fn validate_views(views: &[BoxView], need: usize) -> Result<(), InitError> {
    if views.len() < need {
        return Err(InitError::TooFewViews { got: views.len(), need });
    }
    for (i, v) in views.iter().enumerate() {
        let pose_ok = v.camera.world_from_camera.translation.vector.iter().all(|x| x.is_finite())
            && v.camera.world_from_camera.rotation.coords.iter().all(|x| x.is_finite());
        if !pose_ok || !v.camera.intrinsics.is_valid() {
            return Err(InitError::InvalidView { view: i, reason: None });
        }
        v.bbox.validated().map_err(|e| InitError::InvalidView { view: i, reason: Some(e) })?;
    }
    let c0 = views[0].camera.centre();
    let spread = views.iter().map(|v| (v.camera.centre() - c0).norm()).fold(0.0, f64::max);
    let scale = views.iter().map(|v| v.camera.centre().norm()).fold(1.0, f64::max);
    if spread <= SAME_CENTRE_REL * scale {
        return Err(InitError::Degenerate(Degeneracy::SingleCentre));
    }
    Ok(())
}

/// Accept an ellipsoid only if it is valid and wholly in front of every camera.
pub(crate) fn check_result(e: Ellipsoid, views: &[BoxView]) -> Result<Ellipsoid, InitError> {
    if !e.is_valid() {
        return Err(InitError::NotEllipsoid(ConstrainError::NotFinite));
    }
    for (i, v) in views.iter().enumerate() {
        match classify(&e, &v.camera) {
            Visibility::InFront => {}
            Visibility::CameraInside => return Err(InitError::CameraInside { view: i }),
            Visibility::Behind | Visibility::Straddles => return Err(InitError::BehindCamera { view: i }),
        }
    }
    Ok(e)
}

/// All initialisers with default settings, in the order used by the comparison tables.
pub fn all_methods() -> Vec<Box<dyn Initializer>> {
    vec![Box::new(QSlamSvd), Box::new(Conic::default()), Box::new(Tri::default()), Box::new(Dqp::default())]
}
