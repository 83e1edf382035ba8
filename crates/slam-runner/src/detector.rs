//! Where a run's boxes come from: the choice the app fills from its options, and the factory that turns
//! it into a `DetectionSource` for one sequence (with reports of detections no played frame uses).

use std::{path::PathBuf, sync::Arc};

use slam_core::DetectionSource;
use slam_dataset::{
    detections::{DetectionFile, GroundTruthDetections, GroundTruthNoise},
    kitti::{stereo::StereoSequence, tracking::TrackingLabel},
};
use slam_eval::LabelGeometry;
use slam_quadric::ImageSize;

use crate::error::{BoxError, Context, Result, RunnerError};

/// Loads the network detector (the app knows the model options); called once per run, so a bench can
/// run the same choice several times.
pub type NetworkLoader = Arc<dyn Fn() -> std::result::Result<Box<dyn DetectionSource>, BoxError> + Send + Sync>;

/// The detection source of a run.
#[derive(Clone)]
pub enum DetectorChoice {
    /// No detector: odometry and map points only.
    None,
    /// A network detector, loaded when the run starts.
    Network(NetworkLoader),
    /// A detection JSON file (docs/detections.md).
    File(PathBuf),
    /// Ground-truth boxes from the sequence's labels, with box noise `noise` (σ as a share of box size).
    Labels {
        /// Box noise, σ as a share of the box size.
        noise: f64,
    },
}

impl std::fmt::Debug for DetectorChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe())
    }
}

impl DetectorChoice {
    /// The source as the run's header names it.
    pub fn describe(&self) -> String {
        match self {
            DetectorChoice::None => "none".to_string(),
            DetectorChoice::Network(_) => "the network (dnn)".to_string(),
            DetectorChoice::File(f) => format!("detections from {}", f.display()),
            DetectorChoice::Labels { noise } => format!("label boxes, noise {noise}"),
        }
    }

    /// The detection source for `seq` (images of size `image`), or `None` for no detector. `labels` are
    /// the run's labels and their geometry (needed by [`DetectorChoice::Labels`]); `notes` collects
    /// reports of detections that no played frame uses.
    pub fn build(
        &self,
        seq: &StereoSequence,
        image: ImageSize,
        labels: Option<&(Vec<TrackingLabel>, LabelGeometry)>,
        notes: &mut Vec<String>,
    ) -> Result<Option<Box<dyn DetectionSource>>> {
        Ok(match self {
            DetectorChoice::None => None,
            // the mapped classes are kept by `ClassFilter`, for every source alike
            DetectorChoice::Network(load) => Some(load().context_with(|| "loading the detector".into())?),
            DetectorChoice::File(path) => {
                let file = DetectionFile::read(path)?;
                if let Some([w, h]) = file.image_size {
                    if (w as f64, h as f64) != (image.width, image.height) {
                        return Err(RunnerError::Invalid(format!(
                            "{}: detections for {w}×{h} images, but {} is {}×{}",
                            path.display(),
                            seq.left.iter().find(|p| p.is_file()).unwrap_or(&seq.left[0]).display(),
                            image.width,
                            image.height
                        )));
                    }
                }
                let per_frame = file.frames.iter().map(|(&f, d)| (f, d.len()));
                notes.extend(slam_frontend::detectors::unused_frames(&path.display().to_string(), per_frame, &seq.ids));
                Some(Box::new(file))
            }
            DetectorChoice::Labels { noise } => {
                let (labels, geometry) = labels.ok_or_else(|| {
                    RunnerError::Invalid(format!(
                        "--detector labels: {} has no labels (tracking layout with label_02/): give --labels <label_02.txt>",
                        seq.dir.display()
                    ))
                })?;
                let truth = geometry.detections(labels);
                let per_frame = truth.iter().map(|(&f, d)| (f, d.len()));
                notes.extend(slam_frontend::detectors::unused_frames("labels", per_frame, &seq.ids));
                let noise = GroundTruthNoise { box_sigma: *noise, ..GroundTruthNoise::default() };
                Some(Box::new(GroundTruthDetections::new(truth, noise, [image.width, image.height])))
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_choice_is_described_as_the_header_names_it() {
        assert_eq!(DetectorChoice::None.describe(), "none");
        assert_eq!(DetectorChoice::File(PathBuf::from("d.json")).describe(), "detections from d.json");
        assert_eq!(DetectorChoice::Labels { noise: 0.1 }.describe(), "label boxes, noise 0.1");
        let load: NetworkLoader = Arc::new(|| Err("no model".into()));
        assert_eq!(DetectorChoice::Network(load).describe(), "the network (dnn)");
    }
}
