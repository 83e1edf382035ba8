//! The compared methods, and the refinement by object optimisation.

pub use slam_optim::object::{optimise_object, refine, ObjectPrior, RefineConfig};
use slam_quadric::{
    init::{BoxView, Conic, Dqp, InitError, Initializer, QSlamSvd, Tri},
    Ellipsoid, ImageSize,
};

/// A compared method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Method {
    /// QuadricSLAM's SVD.
    QSlam,
    /// Rubino et al.'s conic method (inscribed ellipses).
    Conic,
    /// Triangulated centre, then the full 3×3 block.
    Tri,
    /// DQP as printed (Tri+Yaw).
    TriYaw,
    /// DQP with our box-centre correction.
    TriYawCc,
    /// DQP followed by object optimisation (box error with Huber, prior axis lengths).
    TriYawRefine,
}

impl Method {
    /// All methods, in table order.
    pub const ALL: [Method; 6] =
        [Method::QSlam, Method::Conic, Method::Tri, Method::TriYaw, Method::TriYawCc, Method::TriYawRefine];

    /// Short name for tables.
    pub fn name(&self) -> &'static str {
        match self {
            Method::QSlam => "Q-SLAM",
            Method::Conic => "Conic",
            Method::Tri => "Tri",
            Method::TriYaw => "Tri+Yaw",
            Method::TriYawCc => "Tri+Yaw+cc",
            Method::TriYawRefine => "Tri+Yaw+refine",
        }
    }

    /// Run the method on noisy views.
    pub fn run(&self, views: &[BoxView], image: &ImageSize, prior: &ObjectPrior) -> Result<Ellipsoid, InitError> {
        match self {
            Method::QSlam => QSlamSvd.initialize(views),
            Method::Conic => Conic::default().initialize(views),
            Method::Tri => Tri::default().initialize(views),
            Method::TriYaw => Dqp::default().initialize(views),
            Method::TriYawCc => Dqp::with_centre_correction().initialize(views),
            Method::TriYawRefine => {
                refine(views, image, prior, &RefineConfig::default(), &slam_lm::LevenbergMarquardt::default())
            }
        }
    }
}
