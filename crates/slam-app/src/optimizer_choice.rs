//! `--optimizer NAME`: which backend of the `slam_optim::Optimizer` seam solves every problem of a run;
//! `--associator NAME`: which `slam_core::Associator` assigns detections to objects.

use std::sync::Arc;

use slam_optim::SharedOptimizer;

/// The optimiser backends this binary links.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OptimizerKind {
    /// Levenberg–Marquardt (`slam-lm`, the default).
    #[default]
    Lm,
    /// Powell's dog-leg (`slam-dogleg`).
    Dogleg,
}

impl OptimizerKind {
    /// A fresh backend with its default settings.
    pub fn build(self) -> SharedOptimizer {
        match self {
            OptimizerKind::Lm => Arc::new(slam_lm::LevenbergMarquardt::default()),
            OptimizerKind::Dogleg => Arc::new(slam_dogleg::DogLeg::default()),
        }
    }
}

/// The object associators this binary links.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AssociatorKind {
    /// The paper's object data association (`slam_assoc::Oda`, the default).
    #[default]
    Oda,
    /// IoU with each track's last box (`slam_assoc::IouAssociator`, the baseline).
    Iou,
}

impl AssociatorKind {
    /// A fresh associator; `projected_gate` is ODA's least IoU of a detection with an object's projected
    /// ellipsoid (`None`: the paper's cost alone; unused by IoU).
    pub fn build(self, projected_gate: Option<f64>) -> Box<dyn slam_core::Associator> {
        match self {
            AssociatorKind::Oda => Box::new(slam_assoc::Oda::new(slam_assoc::OdaConfig {
                min_projected_iou: projected_gate,
                ..slam_assoc::OdaConfig::default()
            })),
            AssociatorKind::Iou => Box::new(slam_assoc::IouAssociator::default()),
        }
    }

    /// Name in printed headers.
    pub fn name(self) -> &'static str {
        match self {
            AssociatorKind::Oda => "ODA",
            AssociatorKind::Iou => "IoU",
        }
    }
}
