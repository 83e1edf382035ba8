//! Checks every [`StereoTracker`] must pass, as `slam-assoc` and `slam-optim` have for their seams. A
//! tracker crate runs them from its own tests on a few stereo pairs it can track:
//! `slam_core::tracker_conformance::check_all(&mut || Subject { .. }, &frames)`.
//!
//! The suite plays the frames as the pipeline does: the map belongs to the caller of
//! [`StereoTracker::track`], which counts each frame's sightings and inserts the keyframe a frame hands
//! over before the next call. From the second frame on, a region in the middle of the image is marked
//! as a moving object. Each check returns `Err(description)` on the first violation: these are test
//! helpers, for a test to assert on and print.

use slam_map::CreationPolicy;
use slam_quadric::BBox;

use crate::{
    source::Image,
    tracking::{BoxQuery, Map, MovingRegion, ObjectMeasurements, StereoTracker, TrackedFrame},
};

/// A tracker and the map it tracks against, fresh: what the suite plays frames through.
pub struct Subject {
    /// The tracker under test.
    pub tracker: Box<dyn StereoTracker>,
    /// An empty map for the tracker's rig.
    pub map: Map,
    /// How the map's owner makes map points of a keyframe handed over.
    pub policy: CreationPolicy,
}

/// A factory of fresh subjects (a tracker keeps state between frames).
pub type Factory<'a> = &'a mut dyn FnMut() -> Subject;

/// Run every check on the stereo pairs `frames` (left, right; consecutive frames of one sequence).
pub fn check_all(make: Factory<'_>, frames: &[(Image, Image)]) -> Result<(), String> {
    let played = play(make, frames)?;
    check_deterministic(make, frames, &played)?;
    Ok(())
}

/// The moving region of frame `i` (none on the first frame): the middle of the image, its whole depth.
fn moving_region(i: usize, left: &Image) -> Vec<MovingRegion> {
    let (w, h) = (f64::from(left.width), f64::from(left.height));
    (i > 0)
        .then(|| MovingRegion { bbox: BBox::new(0.4 * w, 0.3 * h, 0.6 * w, 0.7 * h), depth: None })
        .into_iter()
        .collect()
}

/// Play `frames` through a fresh subject, checking each frame's result ([`check_frame`]) and the
/// queries a tracker answers about its last frame ([`check_queries`]); the results.
pub fn play(make: Factory<'_>, frames: &[(Image, Image)]) -> Result<Vec<TrackedFrame>, String> {
    let Subject { mut tracker, mut map, policy } = make();
    let mut out = Vec::with_capacity(frames.len());
    for (i, (left, right)) in frames.iter().enumerate() {
        let exclude = moving_region(i, left);
        let tf = tracker.track(i, left, right, &exclude, &map).map_err(|e| format!("frame {i}: {e}"))?;
        check_frame(i, &tf, &exclude, &map).map_err(|e| format!("frame {i}: {e}"))?;
        check_queries(tracker.as_mut(), left).map_err(|e| format!("frame {i}: {e}"))?;
        map.count_sightings(&tf.sightings.visible, &tf.sightings.found);
        if let Some(kf) = &tf.keyframe {
            map.insert_keyframe(kf.clone(), &policy).map_err(|e| format!("frame {i}: keyframe not inserted: {e}"))?;
        }
        out.push(tf);
    }
    Ok(out)
}

/// One frame's result against the contract of [`TrackedFrame`].
pub fn check_frame(i: usize, tf: &TrackedFrame, exclude: &[MovingRegion], map: &Map) -> Result<(), String> {
    let pose = &tf.world_from_camera;
    if !(pose.translation.vector.iter().all(|x| x.is_finite()) && pose.rotation.coords.iter().all(|x| x.is_finite())) {
        return Err(format!("pose not finite: {pose:?}"));
    }
    if i == 0 && tf.state.is_measured() && tf.state != crate::TrackState::Initialised {
        return Err(format!("a fresh tracker's first frame is {}, not initialised or lost", tf.state.name()));
    }
    if !tf.state.is_measured() {
        if tf.tracked_map_points != 0 || !tf.reprojection_rms_px.is_nan() {
            return Err(format!(
                "a {} frame accepted no pose, yet reports {} map points at {} px",
                tf.state.name(),
                tf.tracked_map_points,
                tf.reprojection_rms_px
            ));
        }
        if !tf.sightings.visible.is_empty() || !tf.sightings.found.is_empty() {
            return Err(format!("a {} frame reports sightings", tf.state.name()));
        }
    }
    if let Some(p) = tf.sightings.found.iter().find(|p| !tf.sightings.visible.contains(p)) {
        return Err(format!("point {p:?} found but not in the view"));
    }
    if let Some(kf) = &tf.keyframe {
        if kf.id != map.next_keyframe_id() || kf.frame != i {
            return Err(format!(
                "keyframe {:?} of frame {} handed over; the map's next is {:?} at frame {i}",
                kf.id,
                kf.frame,
                map.next_keyframe_id()
            ));
        }
    }
    let covered = |o: &[f64; 3], z: f64| exclude.iter().any(|r| r.covers(o[0], o[1], Some(z)));
    let inputs = &tf.object_inputs;
    if let Some(p) = inputs.points.iter().find(|p| covered(&p.observation, p.camera_point.z)) {
        return Err(format!("point at {:?} lies on a moving region", p.observation));
    }
    if let Some(p) = inputs.masked_points.iter().find(|p| !covered(&p.observation, p.camera_point.z)) {
        return Err(format!("masked point at {:?} lies on no moving region", p.observation));
    }
    if tf.joined.is_some() && !tf.placed {
        return Err("a frame that joins its segment to the map is not placed".into());
    }
    Ok(())
}

/// The object side's queries about the last frame ([`ObjectMeasurements`]): flow starts inside the
/// regions asked about, and dense box points come one list per query, inside the box (to the pixel)
/// and at its depths.
pub fn check_queries<T: ObjectMeasurements + ?Sized>(tracker: &mut T, left: &Image) -> Result<(), String> {
    let (w, h) = (f64::from(left.width), f64::from(left.height));
    let regions = [BBox::new(0.0, 0.0, 0.5 * w, h), BBox::new(0.6 * w, 0.2 * h, 0.9 * w, 0.8 * h)];
    let inside = |p: &[f64; 2]| regions.iter().any(|b| b.contains_point(p[0], p[1]));
    for (name, pairs) in [("flow", tracker.flow(&regions)), ("stereo flow", tracker.stereo_flow(&regions))] {
        let pairs = pairs.map_err(|e| format!("{name}: {e}"))?;
        if let Some(p) = pairs.iter().find(|p| !inside(&p.reference)) {
            return Err(format!("{name} starts at {:?}, outside the regions asked about", p.reference));
        }
    }
    let queries = [
        BoxQuery { bbox: BBox::new(0.3 * w, 0.3 * h, 0.5 * w, 0.7 * h), depth: (0.0, 80.0) },
        BoxQuery { bbox: BBox::new(0.6 * w, 0.4 * h, 0.7 * w, 0.6 * h), depth: (5.0, 20.0) },
    ];
    let lists = tracker.box_points(&queries).map_err(|e| format!("box points: {e}"))?;
    if lists.len() != queries.len() {
        return Err(format!("{} lists of box points for {} queries", lists.len(), queries.len()));
    }
    for (q, list) in queries.iter().zip(&lists) {
        let (near, far) = q.depth;
        // inside the box to the pixel: a dense search samples the pixels the box overlaps
        let grown = BBox::new(q.bbox.xmin - 1.0, q.bbox.ymin - 1.0, q.bbox.xmax + 1.0, q.bbox.ymax + 1.0);
        if let Some(p) = list.iter().find(|p| {
            !grown.contains_point(p.observation[0], p.observation[1]) || !(near..=far).contains(&p.camera_point.z)
        }) {
            return Err(format!(
                "box point at {:?}, depth {} m, outside its query {q:?}",
                p.observation, p.camera_point.z
            ));
        }
    }
    Ok(())
}

/// Two fresh subjects on the same frames give the same results (times aside), compared field by field
/// through their `Debug` text, which writes every float so that it reads back the same and compares
/// NaN (a keypoint without a right match, a frame without a pose) equal to itself.
pub fn check_deterministic(make: Factory<'_>, frames: &[(Image, Image)], first: &[TrackedFrame]) -> Result<(), String> {
    let again = play(make, frames)?;
    for (i, (a, b)) in first.iter().zip(&again).enumerate() {
        let fields = |t: &TrackedFrame| {
            [
                (
                    "pose",
                    format!("{:?} {:?} {} {:?} {:?}", t.world_from_camera, t.reference, t.placed, t.segment, t.joined),
                ),
                (
                    "state",
                    format!("{:?} {} {} {}", t.state, t.stereo_points, t.tracked_map_points, t.reprojection_rms_px),
                ),
                ("object inputs", format!("{:?}", t.object_inputs)),
                ("keyframe", format!("{:?}", t.keyframe)),
                ("sightings", format!("{:?}", t.sightings)),
            ]
        };
        let differ: Vec<&str> =
            fields(a).iter().zip(fields(b).iter()).filter(|(x, y)| x.1 != y.1).map(|(x, _)| x.0).collect();
        if !differ.is_empty() {
            return Err(format!("frame {i} tracked differently by a second fresh tracker: {}", differ.join(", ")));
        }
    }
    Ok(())
}
