//! The implementations this workspace links behind each seam, by name: the optimiser backend
//! ([`OptimizerKind`]), the object associator ([`AssociatorKind`]), the ellipsoid method ([`Method`]) and
//! what a box bounds in the object fits ([`Shape`]). With the `clap` feature each is a `ValueEnum`, so a
//! command line offers exactly these names, with these doc comments as help. A third optimiser is one
//! more variant here (docs/architecture.md).

use std::{path::PathBuf, sync::Arc};

use slam_dataset::kitti::stereo::FrameSelection;
use slam_optim::{object::BoxShape, SharedOptimizer};
use slam_pipeline::objects::FitMethod;

use crate::{settings::RunConfig, DetectorChoice, RunSettings};

/// The optimiser backends.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
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

/// The object associators.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
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

/// How an object's ellipsoid is made (ours and the baselines of the paper's comparison).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Method {
    /// DQP + object optimisation (ours)
    #[default]
    Refine,
    /// QuadricSLAM's SVD
    Qslam,
    /// Rubino et al.'s conic method
    Conic,
    /// Triangulated centre + full 3×3 block
    Tri,
    /// DQP as printed
    TriYaw,
}

impl Method {
    /// The pipeline's fit method.
    pub fn fit(self) -> FitMethod {
        match self {
            Method::Refine => FitMethod::default(),
            Method::Qslam => FitMethod::qslam(),
            Method::Conic => FitMethod::conic(),
            Method::Tri => FitMethod::tri(),
            Method::TriYaw => FitMethod::tri_yaw(),
        }
    }
}

/// What a detection box bounds in the object optimisation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Shape {
    /// The ellipsoid's projected ellipse (the paper)
    #[default]
    Ellipse,
    /// The ellipsoid's circumscribed cuboid
    Cuboid,
    /// Yaw from the cuboid model, then the ellipse model with that yaw held
    TwoStage,
}

impl Shape {
    /// The optimiser's box model.
    pub fn shape(self) -> BoxShape {
        match self {
            Shape::Ellipse => BoxShape::Ellipse,
            Shape::Cuboid => BoxShape::Cuboid,
            Shape::TwoStage => BoxShape::TwoStage,
        }
    }
}

/// The implementations a run wires together.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Wiring {
    /// Optimiser backend of every problem (two-frame BA, local BA, object fits).
    pub optimizer: OptimizerKind,
    /// Object associator.
    pub associator: AssociatorKind,
    /// Ellipsoid method.
    pub method: Method,
}

impl RunSettings {
    /// The settings of a run of `path` (frames `selection`, at most `max_frames`) with the effective
    /// settings `cfg`, the implementations `wiring`, the boxes of `detector`, scored against `labels`.
    pub fn new(
        path: PathBuf,
        selection: FrameSelection,
        max_frames: Option<usize>,
        cfg: &RunConfig,
        wiring: Wiring,
        detector: DetectorChoice,
        labels: Option<PathBuf>,
    ) -> Self {
        let Wiring { optimizer, associator, method } = wiring;
        RunSettings {
            path,
            source: Default::default(),
            selection,
            max_frames,
            tracking: cfg.tracking,
            system: cfg.system(cfg.objects.image),
            optimizer: Arc::new(move || optimizer.build()),
            associator: Arc::new(move |gate| associator.build(gate)),
            method: method.fit(),
            names: (associator.name().to_string(), method.fit().name().to_string()),
            detector,
            labels,
            map: None,
            localise_only: false,
        }
    }

    /// Every frame of `path`, the default wiring and no detector, with settings `cfg`: the runs of
    /// run-bench and track-bench.
    pub fn odometry_only(path: PathBuf, cfg: &RunConfig, max_frames: Option<usize>) -> Self {
        Self::new(path, FrameSelection::default(), max_frames, cfg, Wiring::default(), DetectorChoice::None, None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_builds_what_it_names() {
        assert_eq!(OptimizerKind::Lm.build().name(), "lm");
        assert_eq!(OptimizerKind::Dogleg.build().name(), "dogleg");
        assert_eq!(AssociatorKind::Oda.name(), "ODA");
        assert_eq!(AssociatorKind::Iou.name(), "IoU");
        assert_eq!(Method::Refine.fit().name(), FitMethod::default().name());
        assert_ne!(Method::Qslam.fit().name(), Method::Conic.fit().name());
        assert_eq!(Shape::TwoStage.shape(), BoxShape::TwoStage);
        let cfg = RunConfig::default();
        let wiring = Wiring { associator: AssociatorKind::Iou, method: Method::Tri, ..Wiring::default() };
        let s =
            RunSettings::new("x".into(), FrameSelection::default(), Some(3), &cfg, wiring, DetectorChoice::None, None);
        assert_eq!(s.names, ("IoU".to_string(), FitMethod::tri().name().to_string()));
        assert_eq!((s.max_frames, s.tracking), (Some(3), cfg.tracking));
        assert_eq!((s.optimizer)().name(), "lm");
    }
}
