//! Where a run's images come from and how they reach the tracker: the options of a user's own recording
//! ([`SourceArgs`], a `clap` group with the feature `clap`), the rectification a rig needs (computed once,
//! [`rectifier_of`]), and [`FrameReader`], which gives frame `k`'s pair as the system tracks it, from
//! image files or from a bag's messages, decoded and, for raw cameras, rectified. The run's reader
//! thread, the overlays and the diagnosis of a run that did not track all read through it.

use std::{
    path::{Path, PathBuf},
    sync::Arc,
};

use slam_core::Image;
use slam_dataset::{
    kitti::stereo::StereoSequence,
    recording::{BagFrame, SourceOptions},
    ros::{
        bag::BagReader,
        msgs::{ImagePayload, COMPRESSED_IMAGE},
    },
};
use slam_frontend::{
    image_io::{decode_compressed_image, decode_raw_image},
    read_image,
    rectify::Rectifier,
};

use crate::error::{Result, RunnerError};

/// The options of a recording that is not KITTI's.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct SourceArgs {
    /// The rig's calibration, for a ROS 2 bag without CameraInfo or a folder of left/ and right/
    /// images: Kalibr's camchain.yaml (pinhole, radtan or equidistant, T_cn_cnm1) or ORB-SLAM's stereo
    /// settings (Camera.*, LEFT./RIGHT. K, D, R, P). Cameras with distortion or not row-aligned are
    /// rectified once per run; outputs stay in the left camera's own frame
    #[cfg_attr(feature = "clap", arg(long, value_name = "FILE"))]
    pub calib: Option<PathBuf>,
    /// A bag's left image topic (with --right; found by itself when the bag leaves no doubt)
    #[cfg_attr(feature = "clap", arg(long, value_name = "TOPIC", requires = "right"))]
    pub left: Option<String>,
    /// A bag's right image topic (with --left)
    #[cfg_attr(feature = "clap", arg(long, value_name = "TOPIC", requires = "left"))]
    pub right: Option<String>,
    /// Frames a second of a folder of left/ and right/ images without times.txt
    #[cfg_attr(feature = "clap", arg(long, value_name = "HZ"))]
    pub rate: Option<f64>,
}

impl SourceArgs {
    /// The reader's options.
    pub fn options(&self) -> SourceOptions {
        SourceOptions {
            calib: self.calib.clone(),
            left: self.left.clone(),
            right: self.right.clone(),
            rate_hz: self.rate,
        }
    }

    /// The files these options name, for the check that no output overwrites an input.
    pub fn files(&self) -> Vec<(&'static str, &Path)> {
        self.calib.iter().map(|p| ("--calib", p.as_path())).collect()
    }
}

/// The rectification a sequence's rig needs (none for a rectified pair), computed once; the sequence's
/// intrinsics and baseline become the rectified pair's.
pub fn rectifier_of(seq: &mut StereoSequence) -> Result<Option<Arc<Rectifier>>> {
    let Some(rig) = seq.recording.as_ref().and_then(|r| r.rectify.as_ref()) else { return Ok(None) };
    let calib = seq.recording.as_ref().map(|r| r.calibration.display().to_string()).unwrap_or_default();
    let r = Rectifier::new(rig)
        .map_err(|e| RunnerError::Invalid(format!("{calib}: cannot rectify the cameras: {e}")))?
        .map(Arc::new);
    if let Some(r) = &r {
        seq.intrinsics = r.intrinsics;
        seq.baseline = r.baseline;
        tracing::info!(
            "rectified once for the run: fx {:.2} px, baseline {:.4} m (raw left camera turned by {:.3}°)",
            r.intrinsics[0],
            r.baseline,
            slam_core::geometry::nalgebra::Rotation3::from_matrix_unchecked(r.left_rotation).angle().to_degrees()
        );
    }
    Ok(r)
}

/// Where a reader finds each frame's images.
enum Frames {
    Files(Vec<PathBuf>, Vec<PathBuf>),
    Bag { reader: Box<BagReader>, frames: Vec<BagFrame>, schemas: (String, String), topics: (String, String) },
}

/// Frame `k`'s images as the system tracks them: read (files) or taken from the bag (messages read by
/// their place in the file, chunks decompressed once), decoded (colour as the run reads it), rectified
/// when the rig needs it.
pub struct FrameReader {
    frames: Frames,
    colour: bool,
    rectifier: Option<Arc<Rectifier>>,
}

impl FrameReader {
    /// A reader of `seq`'s frames.
    pub fn new(seq: &StereoSequence, colour: bool, rectifier: Option<Arc<Rectifier>>) -> Self {
        let frames = match seq.recording.as_ref().and_then(|r| r.bag.as_ref()) {
            Some(b) => Frames::Bag {
                reader: Box::new(BagReader::new(&b.bag)),
                frames: b.frames.clone(),
                schemas: b.schemas.clone(),
                topics: b.topics.clone(),
            },
            None => Frames::Files(seq.left.clone(), seq.right.clone()),
        };
        Self { frames, colour, rectifier }
    }

    /// Frames it reads.
    pub fn len(&self) -> usize {
        match &self.frames {
            Frames::Files(l, _) => l.len(),
            Frames::Bag { frames, .. } => frames.len(),
        }
    }

    /// Whether it reads none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The pair of entry `k` before rectification.
    fn raw_pair(&mut self, k: usize) -> std::result::Result<(Image, Image), String> {
        let colour = self.colour;
        match &mut self.frames {
            Frames::Files(l, r) => {
                let (Some(l), Some(r)) = (l.get(k), r.get(k)) else { return Err(format!("no frame at position {k}")) };
                let li = read_image(l, colour).map_err(|e| e.to_string())?;
                let ri = read_image(r, colour).map_err(|e| e.to_string())?;
                Ok((li, ri))
            }
            Frames::Bag { reader, frames, schemas, topics } => {
                let Some(f) = frames.get(k).copied() else { return Err(format!("no frame at position {k}")) };
                let mut one = |schema: &str,
                               topic: &str,
                               at: slam_dataset::ros::bag::MessageRef|
                 -> std::result::Result<Image, String> {
                    let what = format!("{topic} message in the record at byte {}", at.record);
                    let payload = reader.image(schema, at).map_err(|e| e.to_string())?;
                    decode(&what, &payload, schema, colour).map_err(|e| e.to_string())
                };
                Ok((one(&schemas.0, &topics.0, f.left.at)?, one(&schemas.1, &topics.1, f.right.at)?))
            }
        }
    }

    /// The pair of entry `k`, rectified when the rig needs it.
    pub fn pair(&mut self, k: usize) -> std::result::Result<(Image, Image), String> {
        let (l, r) = self.raw_pair(k)?;
        match &self.rectifier {
            Some(rect) => rect.apply(&l, &r).map_err(|e| format!("rectifying frame at position {k}: {e}")),
            None => Ok((l, r)),
        }
    }
}

fn decode(
    what: &str,
    p: &ImagePayload,
    schema: &str,
    colour: bool,
) -> std::result::Result<Image, slam_frontend::FrontendError> {
    match p {
        ImagePayload::Raw { width, height, encoding, big_endian, step, data } => {
            decode_raw_image(what, (*width, *height), encoding, *big_endian, *step, data, colour)
        }
        ImagePayload::Compressed { data, .. } => {
            debug_assert_eq!(schema, COMPRESSED_IMAGE);
            decode_compressed_image(what, data, colour)
        }
    }
}
