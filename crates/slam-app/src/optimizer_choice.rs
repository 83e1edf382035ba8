//! `--optimizer NAME`: which backend of the `slam_optim::Optimizer` seam solves every problem of a run.

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
