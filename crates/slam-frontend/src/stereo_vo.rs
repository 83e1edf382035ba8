//! Stereo visual odometry against the map, in parts a reader finds by name:
//!
//! - [`config`]: the rig and the settings; `settings`: their valid ranges;
//! - `features`: ORB features of each image, spread over it; `frame`: the stereo frame: stereo matching
//!   along rectified rows (mutual best, sub-pixel);
//! - `local_map`: the points of the keyframes around the view (those observing what the last frame
//!   matched and their best covisible neighbours), in the reference keyframe's frame;
//! - `tracker`: the local map's points projected from a guess into windows sized by its uncertainty
//!   (within their distance range and viewing angle, at the level their distance predicts), PnP
//!   RANSAC, a second search at the found pose; `refine`: the robust pose refinement with staged
//!   outlier rejection (keyframes fixed, points free with their keyframe observations);
//! - `motion`: the constant-velocity motion model; `checks`: every pose is checked for support and
//!   for consistency with a vehicle's motion before it is accepted ([`TrackState`]);
//! - `pose_only`: the small Gauss–Newton solver `refine` calls for one pose with its points held;
//! - `relocaliser`: when the prediction fails: along the motion, by descriptors against the local map,
//!   by retrieval of any keyframe of the map (`keyframe_index`: the descriptor index of every keyframe);
//! - `keyframe_policy`: when a frame becomes a keyframe and what it hands over (`keyframe_motion`: whether
//!   the view moved since the keyframe); `flow`: optical flow for the association and the scene flow.
//!
//! [`StereoVo`] holds one of each and runs them per frame ([`StereoVo::process`]) against a map it
//! reads but never changes ([`slam_map::Map`]: its owner inserts the keyframes handed over and applies
//! local mapping's edits). The thresholds and why they hold beyond one sequence are in
//! `docs/system.md` ("Tracking").

use std::time::Instant;

use nalgebra::Isometry3;
use opencv::prelude::*;
use slam_core::{
    geometry::BBox, BoxQuery, FramePoint, Image, KeyframeId, MovingRegion, ObjectInputs, ObjectMeasurements, PointId,
    PointPair, SegmentJoin, Sightings, StageTimes, StereoTracker, TrackError, TrackState, TrackedFrame,
};
use slam_map::{CreationPolicy, Map};
use slam_optim::SharedOptimizer;

use crate::disparity::DisparityPair;
use crate::image_io::{image_to_mat, FrontendError};

mod box_stereo;
mod checks;
pub mod config;
mod features;
mod flow;
mod frame;
mod grey;
mod keyframe_index;
mod keyframe_motion;
mod keyframe_policy;
mod local_map;
mod motion;
mod pose_only;
mod pose_search;
mod refine;
mod relocaliser;
mod settings;
#[cfg(test)]
mod synthetic;

pub use checks::{motion_consistent, motion_limits, support, Support};
pub use config::{StereoRig, VoConfig};
pub use frame::StereoKeypoint;

use checks::judge;
use features::Extractor;
use flow::FlowHistory;
use frame::{Frame, StereoMatcher};
use grey::GreyView;
use keyframe_policy::{new_keyframe, KeyframePolicy, View};
use local_map::LocalMap;
use motion::MotionModel;
use pose_search::{PoseSearch, Route};
use refine::Refined;
use relocaliser::{Context, Relocalisation, Relocaliser};

/// Stereo visual odometry against a map.
pub struct StereoVo {
    /// ORB features of each image (the left one, and the right one's extractor for when the two run
    /// side by side).
    features: Extractor,
    features_right: Extractor,
    /// Stereo matching of each frame.
    stereo: StereoMatcher,
    /// Pose search and refinement (holds the rig, the settings, the optimiser, the image size).
    pose_search: PoseSearch,
    /// The constant-velocity motion model and its frame gaps (poses relative to the reference).
    motion: MotionModel,
    /// The reference keyframe: the one the last frame shared the most points with (or the last
    /// keyframe made); `None` before the first keyframe.
    reference: Option<KeyframeId>,
    /// The map points the last measured frame matched (they choose the next frame's local map).
    last_matched: Vec<PointId>,
    /// When a frame becomes a keyframe.
    policy: KeyframePolicy,
    /// Every keyframe's descriptors, for relocalisation by retrieval.
    relocaliser: Relocaliser,
    /// The last two frames' grey images and keypoints (optical flow).
    flow: FlowHistory,
    /// Stereo correspondences of tracked frames with their keyframe (up to `keep_disparity_pairs`).
    pairs: Vec<DisparityPair>,
    /// This tracker placed a frame in the map or made a keyframe: until then a map that holds
    /// keyframes was loaded from an earlier run, and each frame is localised in it by retrieval.
    started: bool,
    /// The first frame not placed in a loaded map, while none has been.
    unplaced_since: Option<usize>,
    /// Tracking in a segment started beside a loaded map it was never placed in: that segment's first
    /// keyframe. Its poses are in the segment's own frame, not the map's ([`TrackedFrame::placed`]
    /// false), until a frame of it is placed in the map and the segment joins it
    /// ([`TrackedFrame::joined`]).
    segment: Option<KeyframeId>,
}

/// What [`StereoVo::prepare`] makes of a stereo pair: the frame, its stereo points for the object side
/// (those on the moving regions, kept out of the frame, apart), and the extraction and stereo times, ms.
type Prepared = (Frame, ObjectInputs, (f64, f64));

/// The stereo keypoints of one rectified pair exactly as the tracker measures them (features, stereo
/// matching, sub-pixel disparity, `config`'s depth range and disparity offset): for checks of the
/// stereo depth against another reference (`slam-app depth-check`).
pub fn stereo_keypoints(
    rig: StereoRig,
    config: &VoConfig,
    left: &Image,
    right: &Image,
) -> Result<Vec<StereoKeypoint>, FrontendError> {
    let mut features = Extractor::new(config.features, config.spread_features)?;
    let (lm, rm) = (StereoVo::grey_of(left)?, StereoVo::grey_of(right)?);
    let (lf, rf) = (features.extract(&lm)?, features.extract(&rm)?);
    let frame = StereoMatcher::new(rig, config).frame(&lf, &rf, (&GreyView::of(&lm)?, &GreyView::of(&rm)?));
    Ok(frame.stereo_keypoints())
}

impl StereoVo {
    /// Odometry for a rig; its refinements use `optimizer`.
    pub fn new(rig: StereoRig, config: VoConfig, optimizer: SharedOptimizer) -> Result<Self, FrontendError> {
        Ok(Self {
            features: Extractor::new(config.features, config.spread_features)?,
            features_right: Extractor::new(config.features, config.spread_features)?,
            stereo: StereoMatcher::new(rig, &config),
            pose_search: PoseSearch { rig, config, optimizer, image_size: (1.0, 1.0) },
            motion: MotionModel::default(),
            reference: None,
            last_matched: Vec::new(),
            policy: KeyframePolicy::default(),
            relocaliser: Relocaliser::default(),
            flow: FlowHistory::default(),
            pairs: Vec::new(),
            started: false,
            unplaced_since: None,
            segment: None,
        })
    }

    /// The settings.
    fn config(&self) -> &VoConfig {
        &self.pose_search.config
    }

    /// The map's point-creation policy that goes with these settings: stereo points nearer than
    /// `far_baselines` at once, and at least `min_points` of the nearest.
    pub fn creation_policy(&self, min_points: usize) -> CreationPolicy {
        CreationPolicy { near_baselines: self.config().far_baselines, min_points }
    }

    fn grey_of(img: &Image) -> Result<Mat, FrontendError> {
        let m = image_to_mat(img)?;
        if m.channels() == 3 {
            let mut g = Mat::default();
            opencv::imgproc::cvt_color_def(&m, &mut g, opencv::imgproc::COLOR_BGR2GRAY)?;
            Ok(g)
        } else {
            Ok(m)
        }
    }

    /// Stereo correspondences kept so far for offset self-calibration
    /// ([`crate::disparity::estimate_disparity_offset`]).
    pub fn disparity_pairs(&self) -> &[DisparityPair] {
        &self.pairs
    }

    /// Track one rectified stereo pair (grey or colour; colour is converted) against `map`: features
    /// and stereo points ([`StereoVo::prepare`]), the pose ([`StereoVo::find_pose`]) and its state
    /// ([`StereoVo::decide`]), the motion model ([`StereoVo::record`]), and the keyframe the frame
    /// becomes when the map needs one (handed over in [`TrackedFrame::keyframe`] for the map's owner
    /// to insert before the next frame).
    pub fn process(
        &mut self,
        frame_index: usize,
        left: &Image,
        right: &Image,
        exclude: &[MovingRegion],
        map: &Map,
    ) -> Result<TrackedFrame, FrontendError> {
        let (frame, object_inputs, times) = self.prepare(left, right, exclude)?;
        self.track_frame(frame_index, frame, object_inputs, times, map)
    }

    /// The reference keyframe for this frame and the local map around the view: the keyframes
    /// observing what the last frame matched (its own reference's points when it matched none) and
    /// their neighbours; the reference becomes the one observing the most (the motion model follows it).
    fn local_map(&mut self, map: &Map, reference: KeyframeId) -> (KeyframeId, LocalMap) {
        let c = *self.config();
        let seeds: Vec<PointId> = if self.last_matched.is_empty() {
            map.keyframe(reference).map(|k| k.observations().map(|(_, p)| p).collect()).unwrap_or_default()
        } else {
            self.last_matched.clone()
        };
        let local = map.local_keyframes(&seeds, c.local_neighbours, c.local_keyframes);
        let mut reference = reference;
        if let Some(best) = local.reference.filter(|&b| b != reference) {
            if let (Some(old), Some(new)) = (map.keyframe_pose(reference), map.keyframe_pose(best)) {
                tracing::debug!(from = reference, to = best, "reference switched");
                self.motion.rebase_to(&(new.inverse() * old));
                reference = best;
            }
        }
        self.reference = Some(reference);
        (reference, LocalMap::of(map, reference, &local.keyframes))
    }

    /// Track a prepared frame (its stereo points for the object side, handed over as they are; the
    /// extraction and stereo times, ms) against `map`: everything [`StereoVo::process`]
    /// does after the images are turned into a frame.
    fn track_frame(
        &mut self,
        frame_index: usize,
        frame: Frame,
        object_inputs: ObjectInputs,
        (extraction, stereo): (f64, f64),
        map: &Map,
    ) -> Result<TrackedFrame, FrontendError> {
        let t2 = Instant::now();
        let times = |t3: Instant| StageTimes { extraction, stereo, tracking: (t3 - t2).as_secs_f64() * 1e3 };
        let stereo_points = frame.points.len();
        self.unplace_if_lost_long(frame_index);
        let Some(reference) = self.reference.filter(|r| map.keyframe_pose(*r).is_some()) else {
            let mut tf = if !self.started && map.keyframe_count() > 0 {
                self.localise(frame, frame_index, map)?
            } else {
                self.initialise(frame, frame_index, map)
            };
            (tf.times, tf.object_inputs) = (times(Instant::now()), object_inputs);
            return Ok(tf);
        };
        let (reference, local) = self.local_map(map, reference);
        let world_from_ref = map.keyframe_pose(reference).unwrap_or_else(Isometry3::identity);
        self.motion.advance(frame_index);
        let predicted = self.motion.predicted(); // curr ← keyframe
        tracing::debug!(frame = frame_index, reference, predicted = ?predicted.inverse().translation.vector.as_slice(), last = ?self.motion.kf_from_last.translation.vector.as_slice(), velocity = ?self.motion.velocity.translation.vector.as_slice(), "prediction");
        let (found, fallback, retrieved) = self.find_pose(map, &local, &frame, &predicted)?;
        let route = found.as_ref().map(|f| f.2);
        let (reference, world_from_ref, local) =
            self.adopt_retrieved(map, (route, retrieved), (reference, world_from_ref, local));
        let (state, curr_from_ref, refined, support) = self.decide(frame_index, found, &frame, predicted);
        let kf_from_curr = curr_from_ref.inverse();
        let measured = refined.is_some();
        self.record(frame_index, state, refined.as_ref(), (&local, &frame), &curr_from_ref);
        let tracked_map_points = refined.as_ref().map_or(0, |r| r.inliers.len());
        let rms = refined.as_ref().map_or(f64::NAN, |r| r.rms);
        let world_from_curr = world_from_ref * kf_from_curr;
        if measured && matches!(route, Some(Route::Retrieved(_) | Route::Descriptors)) {
            self.motion.forget_velocity();
        }
        let seen = match &refined {
            Some(_) => self.in_view(&local, &curr_from_ref),
            None => Vec::new(),
        };
        let sightings = refined.as_ref().map(|r| sightings_of(&local, &seen, r)).unwrap_or_default();
        if let Some(r) = &refined {
            self.last_matched = r.inliers.iter().map(|&(i, _)| local.ids[i]).collect();
        }
        if let Some(r) = refined.as_ref().filter(|_| tracing::enabled!(tracing::Level::DEBUG)) {
            self.log_tracked(frame_index, r, &local, &seen);
        }
        let since_measured = self.motion.since_measured;
        let view = View { frame: &frame, map: &local, refined: refined.as_ref(), seen: &seen };
        let rig = self.pose_search.rig;
        let wants = !self.config().localise_only
            && self.policy.wants(&self.pose_search.config, &rig, support, &view, map, since_measured);
        // a segment in a frame of its own tries to place itself in the map wherever it would take a
        // keyframe (a view the map may not hold yet, at a fully supported pose): placed, it joins it
        if let (Some(root), true) = (self.segment, wants && support == Support::Full) {
            if let Some(mut tf) = self.join(frame_index, &frame, root, &world_from_curr, map)? {
                (tf.times, tf.object_inputs) = (times(Instant::now()), object_inputs);
                return Ok(tf);
            }
        }
        let keyframe = if wants {
            // a frame lost for too long starts a new map segment: no parent, no matched points, at the
            // first unverified candidate pose when there was one, else at the motion prediction
            let (parent, world_from_kf) = if measured {
                (Some(reference), world_from_curr)
            } else {
                tracing::warn!(frame = frame_index, "tracking lost: new map segment from this frame");
                // a segment of its own frame lost: the new one has a frame of its own too
                if self.segment.is_some() {
                    self.segment = Some(map.next_keyframe_id());
                }
                (None, world_from_ref * fallback.unwrap_or(curr_from_ref).inverse())
            };
            let kf = new_keyframe(
                (map.next_keyframe_id(), frame_index),
                &frame,
                self.pose_search.image_size,
                (world_from_kf, parent),
                refined.as_ref().map(|r| (r, &local)),
            );
            self.take_keyframe(&kf, frame_index, parent.is_none());
            Some(kf)
        } else {
            self.motion.kf_from_last = kf_from_curr;
            None
        };
        // a keyframe is its own reference: its pose in the trajectory is the keyframe's, which local
        // bundle adjustment then refines together with the frames that follow it
        let (reference, world_from_camera) = match &keyframe {
            Some(kf) => ((kf.id, Isometry3::identity()), kf.pose),
            None => ((reference, kf_from_curr), world_from_curr),
        };
        Ok(TrackedFrame {
            world_from_camera,
            reference,
            state,
            stereo_points,
            object_inputs,
            tracked_map_points,
            reprojection_rms_px: rms,
            keyframe,
            sightings,
            times: times(Instant::now()),
            placed: self.segment.is_none(),
            segment: self.segment,
            joined: None,
        })
    }

    /// A retrieved keyframe becomes the reference, and the map its inliers index the local map; else
    /// the reference, its pose and the local map stay.
    fn adopt_retrieved(
        &mut self,
        map: &Map,
        (route, retrieved): (Option<Route>, Option<LocalMap>),
        (reference, world_from_ref, local): (KeyframeId, Isometry3<f64>, LocalMap),
    ) -> (KeyframeId, Isometry3<f64>, LocalMap) {
        match (route, retrieved) {
            (Some(Route::Retrieved(id)), Some(m)) => {
                let world_from_new = map.keyframe_pose(id).unwrap_or(world_from_ref);
                self.motion.rebase_to(&(world_from_new.inverse() * world_from_ref));
                self.reference = Some(id);
                (id, world_from_new, m)
            }
            _ => (reference, world_from_ref, local),
        }
    }

    /// Localising only, a frame lost for longer than a new segment would wait is no longer placed: it is
    /// localised again from scratch rather than predicted on and on.
    fn unplace_if_lost_long(&mut self, frame_index: usize) {
        let period = self.config().period();
        if self.config().localise_only
            && self.started
            && self.motion.failed
            && frame_index.saturating_sub(self.motion.measured_index) as f64 * period > self.config().max_lost_s
        {
            tracing::warn!(frame = frame_index, "lost in the loaded map: localising again from scratch");
            (self.started, self.reference, self.unplaced_since) = (false, None, None);
            self.last_matched.clear();
        }
    }

    /// The debug line of a tracked frame: the local map, its points seen only from one camera, those in
    /// view, and the inliers (far ones apart).
    fn log_tracked(&self, frame_index: usize, r: &Refined, local: &LocalMap, seen: &[Option<(f64, f64)>]) {
        let near = self.config().far_baselines * self.pose_search.rig.baseline;
        let far_inliers =
            r.inliers.iter().filter(|&&(i, _)| (r.pose * nalgebra::Point3::from(local.points[i])).z >= near).count();
        let mono_map = local.views.iter().filter(|v| v.iter().all(|(_, o)| o[2].is_nan())).count();
        tracing::debug!(
            frame = frame_index,
            local = local.len(),
            keyframes = local.slots.len(),
            mono_map,
            visible = seen.iter().filter(|s| s.is_some()).count(),
            inliers = r.inliers.len(),
            far_inliers,
            "tracked"
        );
    }

    /// Where each local-map point is seen from `curr_from_ref` when it is in the view: inside the image,
    /// in front of the camera, within its distance range and viewing angle.
    fn in_view(&self, local: &LocalMap, curr_from_ref: &Isometry3<f64>) -> Vec<Option<(f64, f64)>> {
        let centre = curr_from_ref.inverse().translation.vector;
        let (w, h) = self.pose_search.image_size;
        (0..local.len())
            .map(|i| {
                let ((u, v), ..) = self.pose_search.projection(local, i, curr_from_ref, &centre)?;
                (u >= 0.0 && v >= 0.0 && u < w && v < h).then_some((u, v))
            })
            .collect()
    }

    /// ORB features of both images, the stereo points (as the pipeline sees them), the stereo points
    /// on the `exclude` regions apart, and the grey image and keypoints kept for optical flow; with the
    /// extraction and stereo times, ms. Keypoints on an `exclude` region ([`MovingRegion::covers`]) are
    /// dropped after stereo matching (their depth decides), so neither tracking, the map, the optical
    /// flow of association nor the pipeline's object points see them; their stereo points are handed
    /// over apart (`ObjectInputs::masked_points`) and the stereo points' optical flow (the scene flow)
    /// still starts from them.
    fn prepare(&mut self, left: &Image, right: &Image, exclude: &[MovingRegion]) -> Result<Prepared, FrontendError> {
        let t0 = Instant::now();
        let (lm, rm) = (Self::grey_of(left)?, Self::grey_of(right)?);
        self.pose_search.image_size = (lm.cols().max(1) as f64, lm.rows().max(1) as f64);
        let (lf, rf) = if self.config().parallel_extraction {
            let (left_x, right_x) = (&mut self.features, &mut self.features_right);
            std::thread::scope(|s| {
                let right = s.spawn(|| right_x.extract(&rm));
                let left = left_x.extract(&lm);
                (left, right.join().unwrap_or(Err(FrontendError::Thread("feature extraction"))))
            })
        } else {
            (self.features.extract(&lm), self.features.extract(&rm))
        };
        let (lf, rf) = (lf?, rf?);
        let t1 = Instant::now();
        let (lg, rg) = (GreyView::of(&lm)?, GreyView::of(&rm)?);
        let all = self.stereo.frame(&lf, &rf, (&lg, &rg));
        // every stereo keypoint, masked or not, is followed by the scene flow
        let flow_keypoints: Vec<(f64, f64)> =
            all.keypoints.iter().zip(&all.of_keypoint).filter(|(_, q)| q.is_some()).map(|(k, _)| *k).collect();
        let (frame, masked) = if exclude.is_empty() {
            (all, Vec::new())
        } else {
            let keep: Vec<bool> = lf
                .points
                .iter()
                .zip(&all.of_keypoint)
                .map(|(&(u, v), q)| {
                    let z = q.map(|q| all.points[q].z);
                    !exclude.iter().any(|r| r.covers(u, v, z))
                })
                .collect();
            let masked: Vec<FramePoint> = all
                .of_keypoint
                .iter()
                .zip(&keep)
                .filter_map(|(q, &k)| q.filter(|_| !k))
                .map(|q| FramePoint { camera_point: all.points[q], observation: all.obs[q] })
                .collect();
            (all.retain_keypoints(&keep), masked)
        };
        let object_inputs = ObjectInputs { points: frame.stereo_points(), masked_points: masked };
        let t2 = Instant::now();
        self.flow.push((lm, rm), frame.keypoints.clone(), flow_keypoints);
        Ok((frame, object_inputs, ((t1 - t0).as_secs_f64() * 1e3, (t2 - t1).as_secs_f64() * 1e3)))
    }

    /// The first frame of the run, or of a map whose reference keyframe is gone: the first keyframe, at
    /// the origin (times left at zero).
    fn initialise(&mut self, frame: Frame, frame_index: usize, map: &Map) -> TrackedFrame {
        let stereo_points = frame.points.len();
        let kf = new_keyframe(
            (map.next_keyframe_id(), frame_index),
            &frame,
            self.pose_search.image_size,
            (Isometry3::identity(), None),
            None,
        );
        self.take_keyframe(&kf, frame_index, true);
        self.motion.start(frame_index);
        TrackedFrame {
            world_from_camera: Isometry3::identity(),
            reference: (kf.id, Isometry3::identity()),
            state: TrackState::Initialised,
            stereo_points,
            object_inputs: ObjectInputs::default(),
            tracked_map_points: 0,
            reprojection_rms_px: f64::NAN,
            keyframe: Some(kf),
            sightings: Sightings::default(),
            times: StageTimes::default(),
            placed: self.segment.is_none(),
            segment: self.segment,
            joined: None,
        }
    }

    /// A frame in a map loaded from an earlier run, before any frame was placed there: the map's
    /// keyframes are indexed for retrieval (once), and the frame is placed by retrieval alone
    /// ([`Relocaliser::retrieve`]: PnP RANSAC on the descriptor matches of a retrieved keyframe's
    /// local map, a second search at the pose found, the refinement, full support). Placed, it is
    /// relocalised and tracking goes on from that keyframe; not placed, it is lost without a pose
    /// ([`TrackedFrame::placed`] false) until `max_lost_s` has passed, after which a run that may
    /// extend the map starts a new map segment at this frame (when it has `min_inliers` stereo points,
    /// as a lost run's new segment needs): a segment in its own frame, so its frames get no pose in
    /// the map's either.
    fn localise(&mut self, frame: Frame, frame_index: usize, map: &Map) -> Result<TrackedFrame, FrontendError> {
        if self.relocaliser.index.is_empty() {
            self.index_map(map);
        }
        let cx = Context { pose_search: &self.pose_search, motion: &self.motion, map, among: 0..KeyframeId::MAX };
        let Some((r, ransac, id, local)) = self.relocaliser.retrieve(&cx, &frame)? else {
            let since = *self.unplaced_since.get_or_insert(frame_index);
            let waited = (frame_index.saturating_sub(since) + 1) as f64 * self.config().period();
            let c = self.config();
            if !c.localise_only && waited > c.max_lost_s && frame.points.len() >= c.min_inliers {
                tracing::warn!(
                    frame = frame_index,
                    "not placed in the loaded map: a new map segment from this frame, in its own frame (no pose in the map's)"
                );
                self.segment = Some(map.next_keyframe_id());
                return Ok(self.initialise(frame, frame_index, map));
            }
            tracing::debug!(frame = frame_index, "not placed in the loaded map");
            return Ok(TrackedFrame {
                world_from_camera: Isometry3::identity(),
                reference: (0, Isometry3::identity()),
                state: TrackState::Lost,
                stereo_points: frame.points.len(),
                object_inputs: ObjectInputs::default(),
                tracked_map_points: 0,
                reprojection_rms_px: f64::NAN,
                keyframe: None,
                sightings: Sightings::default(),
                times: StageTimes::default(),
                placed: false,
                segment: None,
                joined: None,
            });
        };
        tracing::info!(frame = frame_index, keyframe = id, inliers = r.inliers.len(), "placed in the loaded map");
        self.started = true;
        self.reference = Some(id);
        let kf_from_curr = r.pose.inverse();
        self.motion.start(frame_index);
        (self.motion.kf_from_last, self.motion.kf_from_measured) = (kf_from_curr, kf_from_curr);
        self.policy.reset();
        self.last_matched = r.inliers.iter().map(|&(i, _)| local.ids[i]).collect();
        let world_from_kf = map.keyframe_pose(id).unwrap_or_else(Isometry3::identity);
        Ok(self.placed_by_retrieval(&frame, &r, ransac, &local, (id, kf_from_curr), world_from_kf * kf_from_curr, None))
    }

    /// The record of a frame placed in the map by retrieval ([`Relocaliser::retrieve`]: refined pose `r`
    /// against keyframe `reference.0`, `ransac` RANSAC inliers, the retrieved keyframe's local map):
    /// relocalised, with what it saw of that local map; `joined` when a segment joins the map with it.
    #[allow(clippy::too_many_arguments)]
    fn placed_by_retrieval(
        &self,
        frame: &Frame,
        r: &Refined,
        ransac: usize,
        local: &LocalMap,
        reference: (KeyframeId, Isometry3<f64>),
        world_from_camera: Isometry3<f64>,
        joined: Option<SegmentJoin>,
    ) -> TrackedFrame {
        let seen = self.in_view(local, &r.pose);
        let sightings = Sightings {
            visible: local.ids.iter().zip(&seen).filter(|(_, s)| s.is_some()).map(|(id, _)| *id).collect(),
            found: self.last_matched.clone(),
        };
        TrackedFrame {
            world_from_camera,
            reference,
            state: TrackState::Relocalised { inliers: ransac },
            stereo_points: frame.points.len(),
            object_inputs: ObjectInputs::default(),
            tracked_map_points: r.inliers.len(),
            reprojection_rms_px: r.rms,
            keyframe: None,
            sightings,
            times: StageTimes::default(),
            placed: true,
            segment: None,
            joined,
        }
    }

    /// A frame tracked in a segment of its own frame (the segment from keyframe `root` on, the frame at
    /// `world_from_curr` there) placed in the map by retrieval among the keyframes before the segment
    /// ([`Relocaliser::retrieve`]: the map's own points of a retrieved keyframe, PnP RANSAC, its local map
    /// searched at the pose found, the refinement, full support), as a run's first frame in a loaded
    /// map is placed. The two poses of the frame give the segment's frame in the map's; the frame is
    /// relocalised in the map, the segment joins it ([`TrackedFrame::joined`]), and tracking goes on
    /// from the keyframe it was placed against, the motion model's velocity kept (a step between two
    /// frames is the same step in either frame). `None`: not placed, the segment goes on.
    fn join(
        &mut self,
        frame_index: usize,
        frame: &Frame,
        root: KeyframeId,
        world_from_curr: &Isometry3<f64>,
        map: &Map,
    ) -> Result<Option<TrackedFrame>, FrontendError> {
        let cx = Context { pose_search: &self.pose_search, motion: &self.motion, map, among: 0..root };
        let Some((r, ransac, id, local)) = self.relocaliser.retrieve(&cx, frame)? else {
            tracing::debug!(frame = frame_index, "segment not placed in the loaded map yet");
            return Ok(None);
        };
        let Some(world_from_kf) = map.keyframe_pose(id) else { return Ok(None) };
        let kf_from_curr = r.pose.inverse();
        let world_from_placed = world_from_kf * kf_from_curr;
        let map_from_segment = world_from_placed * world_from_curr.inverse();
        tracing::info!(
            frame = frame_index,
            keyframe = id,
            inliers = r.inliers.len(),
            segment = root,
            moved_m = map_from_segment.translation.vector.norm(),
            "placed in the loaded map: the segment tracked so far joins it"
        );
        (self.segment, self.started, self.reference) = (None, true, Some(id));
        (self.motion.kf_from_last, self.motion.kf_from_measured) = (kf_from_curr, kf_from_curr);
        self.policy.reset();
        self.last_matched = r.inliers.iter().map(|&(i, _)| local.ids[i]).collect();
        let joined = Some(SegmentJoin { root, map_from_segment, anchor: id });
        Ok(Some(self.placed_by_retrieval(frame, &r, ransac, &local, (id, kf_from_curr), world_from_placed, joined)))
    }

    /// The frame's pose: 1. the local map searched from the constant-velocity prediction
    /// (`predicted`, `curr_from_ref`) in windows of the motion limits; 2. wider, around the last pose;
    /// 3. relocalisation ([`Relocaliser::relocalise`]). Returns what relocalisation returns, the first
    /// candidate pose of any stage as the fallback.
    fn find_pose(
        &self,
        whole: &Map,
        map: &LocalMap,
        frame: &Frame,
        predicted: &Isometry3<f64>,
    ) -> Result<Relocalisation, FrontendError> {
        let (config, m) = (self.config(), &self.motion);
        let n = m.since_measured;
        let bounds = if m.velocity_known {
            motion_limits(&m.step_config(config), m.steps(n))
        } else {
            (config.max_speed * n as f64 * config.period(), 0.1)
        };
        let accept = |r: &Refined, route: Route| self.judge(r, route, frame) != Support::Rejected;
        let mut fallback = None;
        let wider = (bounds.0 + m.velocity.translation.vector.norm(), bounds.1 + m.velocity.rotation.angle());
        for (guess, b) in [(*predicted, bounds), (m.kf_from_last.inverse(), wider)] {
            if let Some((r, ransac)) = self.pose_search.track_from(map, frame, &guess, b, &m.kf_from_measured)? {
                fallback.get_or_insert(r.pose);
                if accept(&r, Route::Motion) {
                    return Ok((Some((r, ransac, Route::Motion)), fallback, None));
                }
            }
        }
        // a segment in a frame of its own relocalises in itself: a keyframe of the map would put the
        // frame in another frame (the segment joins the map through a placement, `StereoVo::join`)
        let among = self.segment.unwrap_or(0)..KeyframeId::MAX;
        let cx = Context { pose_search: &self.pose_search, motion: m, map: whole, among };
        let (found, first, retrieved) = self.relocaliser.relocalise(&cx, map, frame, &accept)?;
        Ok((found, fallback.or(first), retrieved))
    }

    /// The state of a frame from what [`StereoVo::find_pose`] found: tracked or weak by its support,
    /// relocalised after a failed frame or by a relocalisation route; lost (the first failed frame)
    /// or predicted (the next ones) at the prediction when nothing was accepted. Returns the state,
    /// `curr_from_ref`, the refined pose when one was accepted and its support
    /// ([`Support::Rejected`] when none was).
    fn decide(
        &self,
        frame_index: usize,
        found: Option<(Refined, usize, Route)>,
        frame: &Frame,
        predicted: Isometry3<f64>,
    ) -> (TrackState, Isometry3<f64>, Option<Refined>, Support) {
        let support = found.as_ref().map(|(r, _, route)| self.judge(r, *route, frame));
        let was_measured = !self.motion.failed;
        match (found, support) {
            (Some((r, ransac, route)), Some(s)) if s != Support::Rejected => {
                // against the local map without the prediction, right after a measured frame and within
                // the speed limit of it, is tracking (the motion model broke, the map did not: a
                // reversal, a start after a standstill); anything else after a failure, or along the
                // motion, or by retrieval, or a jump no vehicle makes, is relocalisation
                let tracking = match route {
                    Route::Motion => true,
                    Route::Descriptors => self.within_speed_limit(&r),
                    _ => false,
                };
                let state = if !was_measured || !tracking {
                    tracing::info!(frame = frame_index, inliers = r.inliers.len(), ?route, "relocalised");
                    TrackState::Relocalised { inliers: ransac }
                } else if s == Support::Full {
                    TrackState::Tracked { inliers: ransac }
                } else {
                    TrackState::Weak { inliers: ransac }
                };
                (state, r.pose, Some(r), s)
            }
            _ => {
                let state = if was_measured { TrackState::Lost } else { TrackState::Predicted };
                (state, predicted, None, Support::Rejected)
            }
        }
    }

    /// Whether a pose (`curr_from_ref`) lies within the vehicle's top speed of the last measured pose
    /// over the frames since ([`motion_consistent`] without a known velocity).
    fn within_speed_limit(&self, r: &Refined) -> bool {
        let m = &self.motion;
        let frames = m.steps(m.since_measured);
        motion_consistent(
            &m.step_config(self.config()),
            &r.pose.inverse(),
            &m.kf_from_measured,
            &m.kf_from_measured,
            frames,
            false,
        )
    }

    /// After a frame's state is decided: the velocity (from a tracked or weak frame right after a
    /// measured one), the disparity pairs kept for self-calibration, and the last measured pose; or
    /// the failure when no pose was accepted.
    fn record(
        &mut self,
        frame_index: usize,
        state: TrackState,
        refined: Option<&Refined>,
        (map, frame): (&LocalMap, &Frame),
        curr_from_ref: &Isometry3<f64>,
    ) {
        let kf_from_curr = curr_from_ref.inverse();
        let Some(r) = refined else {
            self.motion.failed = true;
            let stereo_points = frame.points.len();
            tracing::warn!(frame = frame_index, stereo_points, state = state.name(), "no pose accepted");
            return;
        };
        if matches!(state, TrackState::Tracked { .. }) && self.pairs.len() < self.config().keep_disparity_pairs {
            let (a, b): (Vec<[f64; 3]>, Vec<[f64; 3]>) = r
                .inliers
                .iter()
                .filter_map(|&(i, c)| {
                    let (_, o) = map.views[i].iter().find(|(slot, o)| *slot == 0 && o[2].is_finite())?;
                    Some((*o, frame.obs[frame.of_keypoint.get(c).copied().flatten()?]))
                })
                .unzip();
            self.pairs.push(DisparityPair { keyframe: a, frame: b, frame_from_keyframe: *curr_from_ref });
        }
        let steady = matches!(state, TrackState::Tracked { .. } | TrackState::Weak { .. });
        self.motion.measured(frame_index, kf_from_curr, steady);
    }

    /// The frame becomes keyframe `kf` (a new map segment when `segment`): it is the reference from
    /// now on, its descriptors go into the retrieval index, and the motion model and the keyframe
    /// policy start from it.
    fn take_keyframe(&mut self, kf: &slam_core::NewKeyframe, frame_index: usize, segment: bool) {
        self.started = true;
        self.reference = Some(kf.id);
        self.relocaliser.index(kf.id, &kf.features.descriptors);
        if segment {
            self.motion.restart(frame_index);
            self.last_matched.clear();
        }
        self.motion.rebase();
        self.policy.reset();
    }

    /// Place one rectified stereo pair in `map` from scratch, as a run in a loaded map places its first
    /// frame ([`StereoVo::localise`]: retrieval, PnP RANSAC, the search at the pose found, the
    /// refinement, full support), without changing what the tracker follows (its reference, motion
    /// model and keyframes; the pair does become the frame optical flow starts from): the keyframe it
    /// was placed against, its pose (world from camera) and the refinement's inliers; `None` when it
    /// is not placed. The map's keyframes are indexed on the first call.
    pub fn place(
        &mut self,
        left: &Image,
        right: &Image,
        map: &Map,
    ) -> Result<Option<(KeyframeId, Isometry3<f64>, usize)>, FrontendError> {
        if self.relocaliser.index.is_empty() {
            self.index_map(map);
        }
        let (frame, ..) = self.prepare(left, right, &[])?;
        let motion = MotionModel::default();
        let cx = Context { pose_search: &self.pose_search, motion: &motion, map, among: 0..KeyframeId::MAX };
        Ok(self.relocaliser.retrieve(&cx, &frame)?.and_then(|(r, _, id, _)| {
            let world_from_kf = map.keyframe_pose(id)?;
            Some((id, world_from_kf * r.pose.inverse(), r.inliers.len()))
        }))
    }

    /// Index every keyframe of a loaded map for retrieval.
    fn index_map(&mut self, map: &Map) {
        let t0 = Instant::now();
        for k in map.keyframes() {
            self.relocaliser.index.insert(k.id, &k.features.descriptors);
        }
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        tracing::info!(keyframes = map.keyframe_count(), ms, "loaded map's keyframes indexed for retrieval");
    }

    /// Whether a refined pose found by `route` is accepted ([`checks`]).
    fn judge(&self, r: &Refined, route: Route, frame: &Frame) -> Support {
        judge(self.config(), self.pose_search.image_size, &self.motion, r, route, frame)
    }

    /// Forward-backward Lucas-Kanade flow of the previous frame's keypoints inside `regions` into the
    /// current frame (with `stereo_only`, the keypoints with a stereo point, those the frame's moving
    /// regions kept out of tracking included), up to `flow_points_per_region` per region evenly spaced;
    /// pairs whose round trip misses by more than a pixel are dropped.
    pub fn optical_flow(&self, regions: &[BBox], stereo_only: bool) -> Result<Vec<PointPair>, FrontendError> {
        self.flow.optical_flow(regions, stereo_only, self.config().flow_points_per_region)
    }
}

impl StereoVo {
    /// Dense stereo points inside each query's box of the last frame ([`box_stereo`]); they also start
    /// the next frame's scene flow (the objects' own points followed into it).
    pub fn dense_box_points(&mut self, queries: &[BoxQuery]) -> Result<Vec<Vec<FramePoint>>, FrontendError> {
        let Some((left, right)) = self.flow.current_pair() else { return Ok(vec![Vec::new(); queries.len()]) };
        let points = box_stereo::box_points(left, right, &self.stereo.rig, self.stereo.disparity_offset, queries)?;
        self.flow.add_flow_keypoints(points.iter().flatten().map(|p| (p.observation[0], p.observation[1])));
        Ok(points)
    }
}

/// The map points a tracked frame's view held (`seen`, from [`StereoVo::in_view`]) and those its
/// refined pose kept.
fn sightings_of(local: &LocalMap, seen: &[Option<(f64, f64)>], r: &Refined) -> Sightings {
    Sightings {
        visible: local.ids.iter().zip(seen).filter(|(_, s)| s.is_some()).map(|(id, _)| *id).collect(),
        found: r.inliers.iter().map(|&(i, _)| local.ids[i]).collect(),
    }
}

impl StereoTracker for StereoVo {
    fn track(
        &mut self,
        frame: usize,
        left: &Image,
        right: &Image,
        exclude: &[MovingRegion],
        map: &Map,
    ) -> Result<TrackedFrame, TrackError> {
        self.process(frame, left, right, exclude, map).map_err(TrackError::backend)
    }

    fn load_map(&mut self, map: &Map) {
        if self.relocaliser.index.is_empty() {
            self.index_map(map);
        }
    }
}

impl ObjectMeasurements for StereoVo {
    fn flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        self.optical_flow(regions, false).map_err(TrackError::backend)
    }

    fn stereo_flow(&mut self, regions: &[BBox]) -> Result<Vec<PointPair>, TrackError> {
        self.optical_flow(regions, true).map_err(TrackError::backend)
    }

    fn box_points(&mut self, queries: &[BoxQuery]) -> Result<Vec<Vec<FramePoint>>, TrackError> {
        self.dense_box_points(queries).map_err(TrackError::backend)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use slam_core::rng::SimRng;
    use slam_map::{KeypointGrid, ScalePyramid};
    use slam_quadric::Intrinsics;
    use std::collections::HashMap;

    /// A synthetic keyframe: stereo observations of `points` (camera frame), each keypoint on the
    /// pyramid level its depth gives (a corner twice as near looks twice as large: about four levels
    /// coarser).
    fn keyframe_of(k: &Intrinsics, b: f64, points: &[Vector3<f64>], desc: &[[u8; 32]]) -> Frame {
        let rig = StereoRig { k: *k, baseline: b };
        let obs: Vec<[f64; 3]> = points.iter().map(|x| rig.observe(x)).collect();
        let n = points.len();
        Frame {
            points: points.to_vec(),
            desc: desc.to_vec(),
            obs: obs.clone(),
            of_keypoint: (0..n).map(Some).collect(),
            keypoints: obs.iter().map(|o| (o[0], o[1])).collect(),
            keypoint_desc: desc.to_vec(),
            octave: points.iter().map(|x| ((20.0 / x.z).ln() / 1.2f64.ln()).floor().clamp(0.0, 7.0) as i32).collect(),
            angle: vec![10.0; n],
            grid: KeypointGrid::new(&obs.iter().map(|o| (o[0], o[1])).collect::<Vec<_>>()),
        }
    }

    /// The local-map scene: 240 random points (inside the view of every camera below, the nearest
    /// 8 m away) with random descriptors; keyframe 0 at the origin sees them all, keyframe 1, 1.2 m
    /// ahead, misses the last 30.
    struct Scene {
        k: Intrinsics,
        b: f64,
        world: Vec<Vector3<f64>>,
        desc: Vec<[u8; 32]>,
        seen: usize,
    }

    fn scene() -> Scene {
        let mut rng = SimRng::new(11);
        let world: Vec<Vector3<f64>> = (0..240)
            .map(|_| {
                let z = rng.uniform(8.0, 40.0);
                Vector3::new(rng.uniform(-0.4, 0.4) * z, rng.uniform(-0.15, 0.15) * z, z)
            })
            .collect();
        let desc: Vec<[u8; 32]> = (0..world.len())
            .map(|_| std::array::from_fn(|_| (rng.uniform(0.0, 256.0) as u32).min(255) as u8))
            .collect();
        let seen = world.len() - 30;
        Scene { k: Intrinsics::new(707.0, 707.0, 601.9, 183.1), b: 0.54, world, desc, seen }
    }

    /// `pts` (world) in the camera at `world_from_camera`.
    fn in_camera(world_from_camera: &Isometry3<f64>, pts: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        pts.iter().map(|x| (world_from_camera.inverse() * nalgebra::Point3::from(*x)).coords).collect()
    }

    /// A tracker and the map of the scene's two keyframes (every stereo point made a map point,
    /// keyframe 1's points matched to keyframe 0's), the reference keyframe 1.
    fn tracker_of(s: &Scene) -> (StereoVo, Map) {
        let world_from = |z: f64| Isometry3::translation(0.0, 0.0, z);
        let optimizer = std::sync::Arc::new(slam_lm::LevenbergMarquardt::default());
        let rig = StereoRig { k: s.k, baseline: s.b };
        let mut vo = StereoVo::new(rig, VoConfig::default(), optimizer).expect("ORB");
        vo.pose_search.image_size = (1241.0, 376.0);
        let mut map = Map::new(rig, ScalePyramid::default());
        let every = CreationPolicy { near_baselines: f64::INFINITY, min_points: 0 };
        let f0 = keyframe_of(&s.k, s.b, &in_camera(&world_from(0.0), &s.world), &s.desc);
        let kf0 = new_keyframe((0, 0), &f0, vo.pose_search.image_size, (world_from(0.0), None), None);
        map.insert_keyframe(kf0, &every).expect("keyframe 0");
        let f1 = keyframe_of(&s.k, s.b, &in_camera(&world_from(1.2), &s.world[..s.seen]), &s.desc[..s.seen]);
        let mut kf1 = new_keyframe((1, 1), &f1, vo.pose_search.image_size, (world_from(1.2), Some(0)), None);
        let first = map.keyframe(0).expect("keyframe 0").points.clone();
        kf1.matched = first[..s.seen].to_vec();
        map.insert_keyframe(kf1, &every).expect("keyframe 1");
        vo.reference = Some(1);
        (vo, map)
    }

    /// Local-map tracking: points the reference keyframe did not see (lost in that frame) are found
    /// again from a covisible keyframe, and the refinement recovers the pose; the motion guard accepts
    /// the true pose and rejects it moved by 5 m.
    #[test]
    fn local_map_recovers_points_lost_for_one_frame_and_the_guard_rejects_a_5m_jump() {
        let s = scene();
        // the current frame, 2.4 m from the origin, sees every point
        let truth = Isometry3::translation(0.0, 0.0, 2.4);
        let frame = keyframe_of(&s.k, s.b, &in_camera(&truth, &s.world), &s.desc);
        let curr_from_ref = truth.inverse() * Isometry3::translation(0.0, 0.0, 1.2);
        let (vo, whole) = tracker_of(&s);
        let ids_of_world: HashMap<PointId, usize> =
            whole.keyframe(0).expect("kf").observations().map(|(kp, p)| (p, kp)).collect();
        for (keyframes, expect_recovered) in [(vec![1], false), (vec![1, 0], true)] {
            let map = LocalMap::of(&whole, 1, &keyframes);
            let skip = vec![false; map.len()];
            let taken = vec![false; frame.keypoints.len()];
            // the prediction is off by 0.3 m and a little turn
            let guess = Isometry3::new(Vector3::new(0.1, 0.0, 0.3), Vector3::new(0.0, 0.01, 0.0)) * curr_from_ref;
            let t = &vo.pose_search;
            let matches = t.search(&map, &guess, &frame, &|c, l| t.window(c, l, (0.35, 0.03)), (&skip, &taken));
            let recovered: Vec<usize> =
                matches.iter().map(|&(i, _)| ids_of_world[&map.ids[i]]).filter(|&w| w >= s.seen).collect();
            assert_eq!(!recovered.is_empty(), expect_recovered, "{keyframes:?}: {recovered:?}");
            for &(i, c) in &matches {
                assert_eq!(ids_of_world[&map.ids[i]], c, "every match is right");
            }
            if !expect_recovered {
                continue;
            }
            assert_eq!(recovered.len(), 30, "all the points the reference missed");
            let r = vo
                .pose_search
                .refiner()
                .refine(&map, &frame, &matches, &guess, &Isometry3::identity())
                .expect("refined");
            let err = r.pose * curr_from_ref.inverse();
            assert!(err.translation.vector.norm() < 1e-3 && err.rotation.angle() < 1e-5, "{err:?}");
            assert_eq!(r.inliers.len(), s.world.len(), "all inliers");
            assert!(r.rms < 1e-3, "rms {}", r.rms);
            // the motion guard: the camera moves 1.2 m per frame and the last frame was the reference
            let mut vo = tracker_of(&s).0;
            vo.motion.velocity = Isometry3::translation(0.0, 0.0, 1.2);
            vo.motion.velocity_known = true;
            assert_eq!(vo.judge(&r, Route::Motion, &frame), Support::Full);
            let jump = Refined {
                pose: Isometry3::translation(3.0, 0.0, -4.0) * r.pose,
                inliers: r.inliers.clone(),
                rms: r.rms,
            };
            assert_eq!(vo.judge(&jump, Route::Motion, &frame), Support::Rejected, "a 5 m jump");
        }
    }

    /// A weak pose (fewer than `min_inliers` inliers) is taken only where the motion model's prediction
    /// vouches for it: with the velocity known it is accepted as weak, with the velocity unknown (the
    /// frame after a relocalisation, where only the 5 m speed limit would apply) it is rejected, while
    /// the same pose with full support is still taken; and a weak frame never becomes a keyframe, even
    /// when the view has moved on, where a fully supported one does.
    #[test]
    fn a_weak_pose_needs_the_motion_model_and_never_becomes_a_keyframe() {
        let s = scene();
        let truth = Isometry3::translation(0.0, 0.0, 2.4);
        let frame = keyframe_of(&s.k, s.b, &in_camera(&truth, &s.world), &s.desc);
        let curr_from_ref = truth.inverse() * Isometry3::translation(0.0, 0.0, 1.2);
        let (mut vo, map) = tracker_of(&s);
        let local = LocalMap::of(&map, 1, &[1, 0]);
        let (skip, taken) = (vec![false; local.len()], vec![false; frame.keypoints.len()]);
        let t = &vo.pose_search;
        let matches = t.search(&local, &curr_from_ref, &frame, &|c, l| t.window(c, l, (0.35, 0.03)), (&skip, &taken));
        let full =
            t.refiner().refine(&local, &frame, &matches, &curr_from_ref, &Isometry3::identity()).expect("refined");
        // every 12th inlier: 20 of them, spread over the view
        let weak =
            Refined { pose: full.pose, inliers: full.inliers.iter().step_by(12).copied().collect(), rms: full.rms };
        assert_eq!(weak.inliers.len(), 20);
        vo.motion.velocity = Isometry3::translation(0.0, 0.0, 1.2);
        vo.motion.velocity_known = true;
        assert_eq!(vo.judge(&weak, Route::Motion, &frame), Support::Weak, "the prediction vouches for it");
        vo.motion.velocity_known = false;
        assert_eq!(vo.judge(&weak, Route::Motion, &frame), Support::Rejected, "the speed limit alone does not");
        assert_eq!(vo.judge(&full, Route::Motion, &frame), Support::Full, "full support within the speed limit");
        let seen = vec![None; local.len()];
        let c = *vo.config();
        let rig = vo.pose_search.rig;
        for (r, support, wanted) in [(&weak, Support::Weak, false), (&full, Support::Full, true)] {
            let view = View { frame: &frame, map: &local, refined: Some(r), seen: &seen };
            let mut policy = KeyframePolicy::default();
            assert_eq!(policy.wants(&c, &rig, support, &view, &map, 0), wanted, "{support:?}: the view moved on");
        }
    }

    /// Image `i` of camera `cam` (`image_0`, `image_1`) of the shipped odometry 06 excerpt.
    fn odometry_06_image(cam: &str, i: usize) -> slam_core::Image {
        let root =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/kitti_odom_06/sequences/06"));
        crate::read_image(root.join(cam).join(format!("{i:06}.png")), false).expect("fixture image")
    }

    /// The excerpt's rig (its calib.txt's P0 and P1).
    fn odometry_06_rig() -> StereoRig {
        StereoRig { k: Intrinsics::new(707.0912, 707.0912, 601.8873, 183.1104), baseline: 379.8145 / 707.0912 }
    }

    /// The keyframe index on real frames: after tracking odometry 06 frames 0-30, every frame's own
    /// descriptors (keyframe or not) retrieve, as the best candidate, a keyframe taken within a few
    /// frames of it, never one of the far end of the run.
    #[test]
    fn the_index_retrieves_a_nearby_keyframe_for_real_frames() {
        let (read, rig) = (odometry_06_image, odometry_06_rig());
        let mut odo =
            crate::Odometry::new(rig, VoConfig::default(), std::sync::Arc::new(slam_lm::LevenbergMarquardt::default()))
                .expect("ORB");
        let mut keyframe_at: HashMap<KeyframeId, usize> = HashMap::new();
        let frames = 31;
        for i in 0..frames {
            let t = odo.track(i, &read("image_0", i), &read("image_1", i), &[]).expect("tracks");
            if let Some(kf) = t.keyframe {
                keyframe_at.insert(kf.id, kf.frame);
            }
        }
        assert!(keyframe_at.len() >= 6, "{keyframe_at:?}");
        assert_eq!(odo.vo.relocaliser.index.len(), keyframe_at.len(), "every keyframe indexed");
        for i in (1..frames).step_by(3) {
            let grey = StereoVo::grey_of(&read("image_0", i)).expect("grey");
            let f = odo.vo.features.extract(&grey).expect("ORB");
            let best = odo.vo.relocaliser.index.query(&f.desc, 3);
            let at = keyframe_at[&best[0].0];
            assert!(at.abs_diff(i) <= 4, "frame {i}: best keyframe at frame {at}: {best:?}");
        }
    }

    /// Extracting the two images on two threads changes nothing: over odometry 06 frames 0-7 the poses,
    /// stereo points and tracked map points equal those of extracting them one after the other.
    #[test]
    fn parallel_extraction_tracks_exactly_as_serial_extraction() {
        let (read, rig) = (odometry_06_image, odometry_06_rig());
        let run = |parallel_extraction: bool| {
            let config = VoConfig { parallel_extraction, ..VoConfig::default() };
            let mut odo =
                crate::Odometry::new(rig, config, std::sync::Arc::new(slam_lm::LevenbergMarquardt::default()))
                    .expect("ORB");
            (0..8)
                .map(|i| {
                    let t = odo.track(i, &read("image_0", i), &read("image_1", i), &[]).expect("tracks");
                    (t.world_from_camera.to_homogeneous(), t.stereo_points, t.tracked_map_points, t.keyframe.is_some())
                })
                .collect::<Vec<_>>()
        };
        let (serial, parallel) = (run(false), run(true));
        assert!(
            serial.iter().all(|f| f.1 > 300),
            "frames with stereo points: {:?}",
            serial.iter().map(|f| f.1).collect::<Vec<_>>()
        );
        assert_eq!(serial, parallel);
    }

    /// A tracker started on a map it did not make (a loaded map): a view of the mapped scene is placed
    /// by retrieval at its true pose and relocalised; a view of another scene is lost without a pose
    /// and no keyframe until `max_lost_s` has passed, then starts a new map segment; localising only,
    /// it never does.
    #[test]
    fn a_loaded_map_places_a_view_of_its_scene_and_never_guesses_another() {
        let s = scene();
        let (_, map) = tracker_of(&s);
        let fresh = |localise_only: bool| {
            let optimizer = std::sync::Arc::new(slam_lm::LevenbergMarquardt::default());
            let config = VoConfig { localise_only, ..VoConfig::default() };
            let mut vo = StereoVo::new(StereoRig { k: s.k, baseline: s.b }, config, optimizer).expect("ORB");
            vo.pose_search.image_size = (1241.0, 376.0);
            vo.load_map(&map);
            vo
        };
        let at = Isometry3::translation(0.1, 0.0, 0.6);
        let view = keyframe_of(&s.k, s.b, &in_camera(&at, &s.world), &s.desc);
        let mut vo = fresh(false);
        let tf = vo.track_frame(7, view, ObjectInputs::default(), (0.0, 0.0), &map).expect("tracks");
        assert!(tf.placed && matches!(tf.state, TrackState::Relocalised { .. }), "{:?}", tf.state);
        assert!((tf.world_from_camera.translation.vector - at.translation.vector).norm() < 0.01);
        assert!(tf.keyframe.is_none());

        // another street: other points, other descriptors
        let mut rng = SimRng::new(99);
        let other: Vec<Vector3<f64>> =
            s.world.iter().map(|x| Vector3::new(-x.x, x.y, x.z + rng.uniform(0.0, 5.0))).collect();
        let desc: Vec<[u8; 32]> = (0..other.len())
            .map(|_| std::array::from_fn(|_| (rng.uniform(0.0, 256.0) as u32).min(255) as u8))
            .collect();
        for localise_only in [false, true] {
            let mut vo = fresh(localise_only);
            let mut keyframes = Vec::new();
            for i in 0..8usize {
                let f = keyframe_of(
                    &s.k,
                    s.b,
                    &in_camera(&Isometry3::translation(0.0, 0.0, i as f64 * 0.5), &other),
                    &desc,
                );
                let tf = vo.track_frame(i, f, ObjectInputs::default(), (0.0, 0.0), &map).expect("tracks");
                assert!(!tf.placed, "frame {i}: never a pose in the map's frame");
                if let Some(k) = &tf.keyframe {
                    keyframes.push((i, k.parent));
                } else if keyframes.is_empty() {
                    assert_eq!(tf.state, TrackState::Lost, "frame {i}");
                } else {
                    assert!(tf.state.is_measured(), "frame {i}: tracked in its own segment: {:?}", tf.state);
                }
            }
            // 0.5 s at 0.1 s a frame: the sixth frame not placed starts a segment of its own
            let first = keyframes.first().copied();
            assert_eq!(first, (!localise_only).then_some((5, None)), "localise only: {localise_only}");
        }

        // localising only, a placed run that loses the map is localised from scratch again after
        // `max_lost_s`, not predicted on: its frames are no longer placed
        let mut vo = fresh(true);
        let view = keyframe_of(&s.k, s.b, &in_camera(&at, &s.world), &s.desc);
        assert!(vo.track_frame(0, view, ObjectInputs::default(), (0.0, 0.0), &map).expect("tracks").placed);
        let placed: Vec<bool> = (1..9usize)
            .map(|i| {
                let f = keyframe_of(&s.k, s.b, &in_camera(&Isometry3::translation(0.0, 0.0, 0.6), &other), &desc);
                vo.track_frame(i, f, ObjectInputs::default(), (0.0, 0.0), &map).expect("tracks").placed
            })
            .collect();
        assert_eq!(placed, [true, true, true, true, true, false, false, false], "predicted for 0.5 s, then not placed");
    }
}
