//! What the runner's tests share: the settings of a run without a detector on a shipped sequence.

use std::{path::PathBuf, sync::Arc};

use slam_dataset::kitti::stereo::FrameSelection;
use slam_pipeline::{objects::FitMethod, system::SystemConfig};
use slam_runner::{DetectorChoice, RunSettings};

/// A shipped fixture's path (`rel` under `fixtures/`).
pub fn fixture(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures").join(rel)
}

/// Default settings on `sequence` (under `fixtures/`): the frames of `selection`, at most `max_frames`,
/// no detector, IoU association, no map.
pub fn settings(sequence: &str, selection: FrameSelection, max_frames: Option<usize>) -> RunSettings {
    RunSettings {
        path: fixture(sequence),
        source: Default::default(),
        selection,
        max_frames,
        tracking: slam_frontend::VoConfig::default(),
        system: SystemConfig::default(),
        optimizer: Arc::new(|| Arc::new(slam_lm::LevenbergMarquardt::default())),
        associator: Arc::new(|_| Box::new(slam_assoc::IouAssociator::default())),
        method: FitMethod::default(),
        names: ("IoU".into(), "Tri+Yaw+refine".into()),
        detector: DetectorChoice::None,
        labels: None,
        map: None,
        localise_only: false,
    }
}
