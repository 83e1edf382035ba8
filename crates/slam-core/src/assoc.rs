//! The association contract: detections of the current frame against object tracks.
//!
//! An [`Associator`] sees, for each track, what the pipeline knows: its class, the box of its projected
//! ellipsoid (if it has one yet), a motion-predicted box, and its region in the reference frame (the
//! frame the flow starts from: the caller's choice; the running system makes every frame the reference
//! of the next, so the flow spans one frame) from which keypoints were tracked. It returns which
//! detection belongs to which track.
//! Creating tracks for unmatched detections and retiring lost ones is the caller's job (see
//! `slam_assoc::ObjectTracker`), so associators stay small and swappable.

use slam_quadric::BBox;

use crate::detection::{ClassId, Detection, Region, TrackId};

/// A keypoint tracked from the reference frame to the current frame (after a forward-backward check).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointPair {
    /// Position in the reference frame (where the flow starts, see the module doc), pixels.
    pub reference: [f64; 2],
    /// Position in the current frame, pixels.
    pub current: [f64; 2],
}

/// What an associator may use about one track.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackView<'a> {
    /// Track identity.
    pub id: TrackId,
    /// Object class.
    pub class: ClassId,
    /// Box of the projected ellipsoid in the current frame, when the object has an ellipsoid.
    pub projected: Option<BBox>,
    /// Motion-predicted box in the current frame (e.g. from a Kalman filter).
    pub predicted: Option<BBox>,
    /// The box the track was last matched to.
    pub last: BBox,
    /// The track's region (mask or box) in the reference frame, when it was seen there.
    pub reference_region: Option<Region<'a>>,
}

/// Everything an associator is given for one frame.
#[derive(Debug, Clone, Copy)]
pub struct AssociationInput<'a> {
    /// Detections of the current frame.
    pub detections: &'a [Detection],
    /// Live tracks.
    pub tracks: &'a [TrackView<'a>],
    /// Keypoints tracked from the reference frame; may be empty.
    pub flow: &'a [PointPair],
}

/// Result of one association.
///
/// Invariants (checked by the conformance suite): every detection index appears exactly once, either
/// in `matches` or in `unmatched`; no track appears twice; a match never pairs different classes;
/// `matches` is sorted by detection index and `unmatched` ascending.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Assignment {
    /// `(detection index, track)` pairs.
    pub matches: Vec<(usize, TrackId)>,
    /// Detection indices left without a track.
    pub unmatched: Vec<usize>,
}

/// Assigns detections to tracks. Object-safe: pipelines hold a `Box<dyn Associator>`.
///
/// Contract: the result satisfies the [`Assignment`] invariants; it depends only on the input as a set
/// (permuting detections or tracks permutes the answer accordingly); identical inputs give identical
/// outputs; non-finite numbers in the input never cause a panic (such pairs are simply not matched).
pub trait Associator: Send {
    /// Short name for logs and tables.
    fn name(&self) -> &'static str;
    /// Associate one frame.
    fn associate(&mut self, input: &AssociationInput<'_>) -> Assignment;
}
