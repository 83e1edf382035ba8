//! What a recording that is not KITTI's adds to its [`StereoSequence`](crate::kitti::stereo::StereoSequence):
//! a bag's frames (where each frame's two image messages are) and the rig to rectify. Apart from
//! [`super`] so that the sequence type can hold it without the reader and the sequence importing
//! each other.

use std::{path::PathBuf, sync::Arc};

use crate::{
    rig::RigCalibration,
    ros::bag::{Bag, IndexedImage},
};

/// One frame of a bag: its two image messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BagFrame {
    /// Left image.
    pub left: IndexedImage,
    /// Right image.
    pub right: IndexedImage,
}

/// Where a bag sequence's frames are.
#[derive(Debug, Clone)]
pub struct BagFrames {
    /// The indexed bag.
    pub bag: Arc<Bag>,
    /// Left and right topics.
    pub topics: (String, String),
    /// Their message types ([`IMAGE`](crate::ros::msgs::IMAGE) or [`COMPRESSED_IMAGE`](crate::ros::msgs::COMPRESSED_IMAGE)).
    pub schemas: (String, String),
    /// One entry per frame of the sequence.
    pub frames: Vec<BagFrame>,
}

/// What a recording that is not KITTI's adds to its sequence.
#[derive(Debug, Clone)]
pub struct Recording {
    /// A bag's frames (`None` for a folder of images).
    pub bag: Option<BagFrames>,
    /// The rig to rectify before tracking, when its images are not a rectified pair (the sequence's
    /// intrinsics and baseline are then the raw left camera's and the cameras' distance, until the
    /// front end has rectified it).
    pub rectify: Option<RigCalibration>,
    /// Where the calibration came from: the calibration file, or the bag (with its topics in `source`).
    pub calibration: PathBuf,
    /// The image size the calibration is for, when it says (the images are checked against it).
    pub calibrated_size: Option<(u32, u32)>,
    /// The input in one sentence: what was read, which cameras, why, and the calibration.
    pub source: String,
}

impl Recording {
    /// The entries of `keep` (positions in the sequence).
    pub(crate) fn select(&self, keep: &[usize]) -> Recording {
        Recording {
            bag: self
                .bag
                .as_ref()
                .map(|b| BagFrames { frames: keep.iter().map(|&k| b.frames[k]).collect(), ..b.clone() }),
            ..self.clone()
        }
    }

    /// Keep the first `n` entries.
    pub(crate) fn truncate(&mut self, n: usize) {
        if let Some(b) = &mut self.bag {
            b.frames.truncate(n);
        }
    }
}
