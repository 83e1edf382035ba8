//! How an object's ellipsoid is computed ([`FitMethod`]): the initialiser and whether the object
//! optimisation follows it. A file of its own: the mapper holds a method and the fitting runs it.

use std::sync::Arc;

use slam_quadric::init::{Conic, Dqp, Initializer, QSlamSvd, Tri};

/// How an object's ellipsoid is computed from its views: an initialiser (any
/// [`slam_quadric::Initializer`]), optionally followed by the object optimisation
/// ([`slam_optim::object::refine_with_cues`]: the initialiser's ellipsoid is one of its starts, texture
/// planes and the class prior enter there). Cheap to clone (the initialiser is shared).
#[derive(Clone)]
pub struct FitMethod {
    initializer: Arc<dyn Initializer>,
    refine: bool,
    name: String,
}

impl std::fmt::Debug for FitMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FitMethod").field("name", &self.name).field("refine", &self.refine).finish()
    }
}

impl PartialEq for FitMethod {
    /// Same name and stages (an initialiser's settings are part of its name for the built-in methods).
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name && self.refine == other.refine
    }
}

impl Default for FitMethod {
    /// The paper's method: DQP (Tri+Yaw) then the object optimisation.
    fn default() -> Self {
        Self::refined(Arc::new(Dqp::default()), "Tri+Yaw+refine")
    }
}

impl FitMethod {
    /// The names [`FitMethod::by_name`] accepts, in the order of the comparison tables.
    pub const NAMES: [&'static str; 5] = ["Tri+Yaw+refine", "Q-SLAM", "Conic", "Tri", "Tri+Yaw"];

    /// The initialiser's ellipsoid as it is.
    pub fn initial(initializer: Arc<dyn Initializer>, name: impl Into<String>) -> Self {
        Self { initializer, refine: false, name: name.into() }
    }

    /// The initialiser's ellipsoid refined by the object optimisation.
    pub fn refined(initializer: Arc<dyn Initializer>, name: impl Into<String>) -> Self {
        Self { initializer, refine: true, name: name.into() }
    }

    /// A built-in method by its table name ([`FitMethod::NAMES`]).
    pub fn by_name(name: &str) -> Option<Self> {
        match name {
            "Tri+Yaw+refine" => Some(Self::default()),
            "Q-SLAM" => Some(Self::qslam()),
            "Conic" => Some(Self::conic()),
            "Tri" => Some(Self::tri()),
            "Tri+Yaw" => Some(Self::tri_yaw()),
            _ => None,
        }
    }

    /// "Q-SLAM": QuadricSLAM's SVD (baseline).
    pub fn qslam() -> Self {
        Self::initial(Arc::new(QSlamSvd), "Q-SLAM")
    }

    /// "Conic": Rubino et al.'s conic method (baseline).
    pub fn conic() -> Self {
        Self::initial(Arc::new(Conic::default()), "Conic")
    }

    /// "Tri": triangulated centre and a full 3×3 block (baseline).
    pub fn tri() -> Self {
        Self::initial(Arc::new(Tri::default()), "Tri")
    }

    /// "Tri+Yaw": the paper's DQP as printed, without the object optimisation (baseline).
    pub fn tri_yaw() -> Self {
        Self::initial(Arc::new(Dqp::default()), "Tri+Yaw")
    }

    /// Short name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether the object optimisation follows the initialiser.
    pub fn refines(&self) -> bool {
        self.refine
    }

    /// The initialiser.
    pub fn initializer(&self) -> &dyn Initializer {
        &*self.initializer
    }
}
