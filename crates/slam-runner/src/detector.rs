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

/// The detection sources by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum DetectorKind {
    /// The shipped YOLOX-nano detector (or the model given with --model/--cfg/--weights/--onnx).
    Dnn,
    /// A detection JSON file (--detections; format in docs/detections.md).
    File,
    /// Ground-truth boxes from the sequence's labels (tracking layout), with --label-noise.
    Labels,
    /// No detector: odometry and map points only.
    None,
}

impl DetectorKind {
    /// Lower-case name, as on a command line.
    pub fn name(self) -> &'static str {
        match self {
            DetectorKind::Dnn => "dnn",
            DetectorKind::File => "file",
            DetectorKind::Labels => "labels",
            DetectorKind::None => "none",
        }
    }
}

/// The detection options as given (by a command line): the source named, and the options that only one
/// source takes (each implies its source).
#[derive(Debug, Clone, Default)]
pub struct DetectorOptions {
    /// The source named (`--detector`), if any.
    pub kind: Option<DetectorKind>,
    /// A detection JSON (`--detections`: the file source).
    pub detections: Option<PathBuf>,
    /// Box noise of the label source (`--label-noise`).
    pub label_noise: Option<f64>,
    /// The first model option given (`--cfg`, `--score`, …: the network source).
    pub model_option: Option<&'static str>,
}

impl DetectorOptions {
    /// The source: the one named, else the one the source-specific options imply, else the network. An
    /// option of another source than the one named is an error that names both.
    pub fn kind(&self) -> Result<DetectorKind> {
        let invalid = |m: String| Err(RunnerError::Invalid(m));
        if let Some(noise) = self.label_noise {
            let share = slam_core::check::Range::closed(0.0, 1.0);
            slam_core::check::number("--label-noise", noise, share, "(σ as a share of the box size)")?;
        }
        // each source-specific option implies its source: two of different sources conflict (an option
        // of a source not run would be silently ignored)
        let implied: Vec<(DetectorKind, &str)> = [
            self.detections.as_ref().map(|_| (DetectorKind::File, "--detections")),
            self.label_noise.map(|_| (DetectorKind::Labels, "--label-noise")),
            self.model_option.map(|flag| (DetectorKind::Dnn, flag)),
        ]
        .into_iter()
        .flatten()
        .collect();
        if let [(a, fa), (b, fb), ..] = implied[..] {
            return invalid(format!(
                "{fa} (detector {}) and {fb} (detector {}) conflict: each is an option of its own detection source",
                a.name(),
                b.name()
            ));
        }
        let implied = implied.first().copied();
        match (self.kind, implied) {
            (None, None) => Ok(DetectorKind::Dnn),
            (None, Some((kind, _))) | (Some(kind), None) => Ok(kind),
            (Some(kind), Some((wanted, _))) if kind == wanted => Ok(kind),
            (Some(kind), Some((wanted, flag))) => invalid(format!(
                "{flag} is an option of --detector {}, but --detector {} was given",
                wanted.name(),
                kind.name()
            )),
        }
    }

    /// The source ([`DetectorOptions::kind`]), for a run that localises only when `localise_only`
    /// ([`DetectorOptions::for_localising_only`]).
    pub fn checked(&self, localise_only: bool) -> Result<DetectorKind> {
        if localise_only {
            self.for_localising_only()?;
        }
        self.kind()
    }

    /// A run that localises only runs no detector (it maps no objects): an option of any detection
    /// source (`--detector` other than `none`, `--detections`, `--label-noise`, a model option) is an
    /// error naming it, as an option of another source is, rather than one accepted and ignored.
    pub fn for_localising_only(&self) -> Result<()> {
        let given = [
            self.kind.filter(|k| *k != DetectorKind::None).map(|k| format!("--detector {}", k.name())),
            self.detections.as_ref().map(|_| "--detections".to_string()),
            self.label_noise.map(|_| "--label-noise".to_string()),
            self.model_option.map(str::to_string),
        ];
        match given.into_iter().flatten().next() {
            Some(flag) => Err(RunnerError::Invalid(format!(
                "{flag} is an option of a detection source, but --localise-only runs no detector (it maps no objects)"
            ))),
            None => Ok(()),
        }
    }

    /// The run's detector choice; `network` loads the model when the run starts.
    pub fn choice(&self, network: NetworkLoader) -> Result<DetectorChoice> {
        Ok(match self.kind()? {
            DetectorKind::None => DetectorChoice::None,
            DetectorKind::Dnn => DetectorChoice::Network(network),
            DetectorKind::File => DetectorChoice::File(
                self.detections
                    .clone()
                    .ok_or_else(|| RunnerError::Invalid("--detector file needs --detections <file.json>".into()))?,
            ),
            DetectorKind::Labels => DetectorChoice::Labels { noise: self.label_noise.unwrap_or(0.0) },
        })
    }
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
            // the mapped classes are kept (and the rest counted) by `DetectionGuard`, for every source alike
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
                notes.extend(slam_detect::detectors::unused_frames(&path.display().to_string(), per_frame, &seq.ids));
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
                notes.extend(slam_detect::detectors::unused_frames("labels", per_frame, &seq.ids));
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
    fn the_source_follows_the_options_and_conflicts_name_both() {
        let o = |kind, detections: Option<&str>, label_noise, model_option| DetectorOptions {
            kind,
            detections: detections.map(PathBuf::from),
            label_noise,
            model_option,
        };
        assert_eq!(o(None, None, None, None).kind().expect("default"), DetectorKind::Dnn);
        assert_eq!(o(None, Some("d.json"), None, None).kind().expect("implied"), DetectorKind::File);
        assert_eq!(o(None, None, Some(0.1), None).kind().expect("implied"), DetectorKind::Labels);
        assert_eq!(o(Some(DetectorKind::None), None, None, None).kind().expect("named"), DetectorKind::None);
        let e = o(Some(DetectorKind::None), None, None, Some("--score")).kind().expect_err("conflict");
        assert!(e.to_string().contains("--score is an option of --detector dnn, but --detector none"), "{e}");
        assert!(o(None, Some("d.json"), Some(0.1), None).kind().is_err());
        // a network option with a detection file: the file would be read and the option ignored
        for flag in ["--score", "--mode", "--tiles"] {
            let e = o(None, Some("d.json"), None, Some(flag)).kind().expect_err(flag).to_string();
            assert!(e.contains("--detections (detector file)") && e.contains(&format!("{flag} (detector dnn)")), "{e}");
            assert!(o(Some(DetectorKind::File), Some("d.json"), None, Some(flag)).kind().is_err(), "{flag}");
        }
        // localising only: every source's option is refused, --detector none is not
        for (kind, file, noise, flag) in [
            (Some(DetectorKind::Labels), None, None, None),
            (None, Some("d.json"), None, None),
            (None, None, Some(0.1), None),
            (None, None, None, Some("--device")),
        ] {
            let e = o(kind, file, noise, flag).for_localising_only().expect_err("a source's option").to_string();
            assert!(e.contains("--localise-only runs no detector"), "{e}");
        }
        o(Some(DetectorKind::None), None, None, None).for_localising_only().expect("no detector");
        o(None, None, None, None).for_localising_only().expect("nothing given");
        let e = o(None, None, Some(f64::NAN), None).kind().expect_err("NaN noise");
        assert!(e.to_string().contains("--label-noise NaN: must be a finite number in [0, 1]"), "{e}");
        let network: NetworkLoader = Arc::new(|| Err("not loaded in this test".into()));
        let e = o(Some(DetectorKind::File), None, None, None).choice(network.clone()).expect_err("no file");
        assert!(e.to_string().contains("needs --detections"), "{e}");
        let c = o(None, None, Some(0.2), None).choice(network).expect("labels");
        assert!(matches!(c, DetectorChoice::Labels { noise } if noise == 0.2));
    }

    #[test]
    fn every_choice_is_described_as_the_header_names_it() {
        assert_eq!(DetectorChoice::None.describe(), "none");
        assert_eq!(DetectorChoice::File(PathBuf::from("d.json")).describe(), "detections from d.json");
        assert_eq!(DetectorChoice::Labels { noise: 0.1 }.describe(), "label boxes, noise 0.1");
        let load: NetworkLoader = Arc::new(|| Err("no model".into()));
        assert_eq!(DetectorChoice::Network(load).describe(), "the network (dnn)");
    }
}
