//! Object data association for quadric SLAM.
//!
//! * [`Oda`]: the ODA associator of Tian et al. (RA-L 2022, §VI). For detection `j` and track `i`,
//!   `a_ij = 0.8 a^p + 1.0 a^g + 0.8 a^k`, where `a^p` is one minus the share of keypoints inside the
//!   detection whose tracked position in the reference keyframe falls inside the track's region there,
//!   `a^g` is one minus the IoU of the projected ellipsoid's box, and `a^k` one minus the IoU of the
//!   Kalman-predicted box. Missing cues are dropped and the remaining weights renormalised. Pairs of
//!   different classes or above a maximum cost are gated out; the rest are assigned by the Hungarian
//!   method (`pathfinding`'s Kuhn–Munkres).
//! * [`IouAssociator`]: the simpler baseline (IoU of the detection with the track's last box, as
//!   QuadricSLAM associates).
//! * [`KalmanBoxFilter`]: SORT-style constant-velocity filter on `(u, v, area, aspect)`.
//! * [`ObjectTracker`]: keeps tracks, predicts them, calls any [`Associator`], creates tracks for
//!   unmatched detections and retires tracks after missed frames.
//! * [`conformance`]: checks any [`Associator`] must pass.
//!
//! The simulated scenes that compare associators, and the `slam-app assoc` study, are in `slam-studies`.

#![warn(missing_docs)]

pub mod conformance;
mod hungarian;
mod iou;
mod kalman;
mod object_tracks;
mod oda;

pub use hungarian::{assign, Cost};
pub use iou::{IouAssociator, IouConfig};
pub use kalman::KalmanBoxFilter;
pub use object_tracks::{ObjectTracker, OwnedRegion, Track, TrackerConfig, TrackerInput, TrackerOutput};
pub use oda::{Oda, OdaConfig, OdaWeights};
pub use slam_core::{Assignment, AssociationInput, Associator, PointPair, TrackView};
