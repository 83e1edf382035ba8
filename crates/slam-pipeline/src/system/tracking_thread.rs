//! The tracking thread's state and its per-frame step: the stereo tracker, the object mapper's
//! association and the hand-over of keyframes to local mapping.
//!
//! This thread owns the live map ([`slam_core::Map`]): its tracker reads it, the keyframes it hands
//! over are inserted into it, and local mapping's edits (made on snapshots) are applied to it here;
//! nothing else changes it. When the run ends it becomes the run's saved map
//! ([`crate::saved_map::SavedMap::from_live`], in [`super::System::finish`]).

use std::{collections::VecDeque, time::Instant};

use crossbeam_channel::{Receiver, Sender};
use nalgebra::{Isometry3, Point3, Vector3};
use slam_core::{
    figure::median,
    geometry::{BBox, Camera, ImageSize, Intrinsics},
    BoxQuery, ClassId, DetectError, Detection, FramePoint, KeyframeId, KeyframePoint, Map, MovingRegion, PointPair,
    StereoTracker, TrackState, TrackedFrame,
};

use super::{
    threads::{DetectTimes, MapperReply, MapperRequest},
    FrameInput, FrameRecord, FrameTimes, FrameView, RunCounts, SystemConfig, SystemError,
};
use crate::{
    mapping::LocalMapper,
    objects::{
        class_prior, scene_flow, suppress_duplicate_boxes, FlowedPoint, ObjectMapper, PointsCentroid, SceneFlow,
        StereoNoise,
    },
    saved_map::{pose_to_array, FramePose},
};

/// The tracking thread's state: what one [`TrackingThread::step`] per frame reads and updates.
pub struct TrackingThread {
    pub(crate) tracker: Box<dyn StereoTracker>,
    /// The live map: the tracker reads it, keyframes go in here, local mapping's edits are applied here.
    pub(crate) map: Map,
    pub(crate) objects: ObjectMapper,
    config: SystemConfig,
    requests: Sender<MapperRequest>,
    replies: Receiver<MapperReply>,
    pub(crate) records: Vec<FrameRecord>,
    pub(crate) trajectory: Vec<FramePose>,
    pub(crate) counts: RunCounts,
    /// Records of keyframes whose mapper reply has not been applied yet, oldest first.
    pending: VecDeque<usize>,
    last_reference: Option<(u64, Isometry3<f64>)>,
    prev_boxes: Vec<BBox>,
    /// The previous frame's id, stereo points and pose when it was measured (scene flow of objects).
    prev_points: Option<(usize, Vec<FramePoint>, Isometry3<f64>)>,
    /// The scene-flow readings of the previous frame's boxes, with the frame's id.
    prev_flows: (usize, Vec<(BBox, SceneFlow)>),
    /// Where the objects found moving are expected in the next frame (kept out of its tracking).
    moving_regions: Vec<MovingRegion>,
    last_done: Instant,
    /// The last frame's pose at tracking time (`None` when it was unreadable).
    last_pose: Option<Isometry3<f64>>,
    /// The keyframes whose local mapping was applied before the last frame was tracked (kept for
    /// [`FrameView`]).
    applied: Vec<KeyframeId>,
    /// The map was loaded from an earlier run: a frame is written without a pose until one is placed
    /// in it.
    loaded: bool,
    /// Frames written without a pose while tracked in a segment of its own frame beside the loaded
    /// map: the trajectory entry, the segment (its first keyframe) and the frame's reference keyframe;
    /// they get their pose in the map when the segment joins it.
    segment_frames: Vec<(usize, KeyframeId, KeyframeId)>,
    /// The last frame tracked in such a segment: the segment and the frame's reference (an unreadable
    /// frame holds it).
    segment_reference: Option<(KeyframeId, (KeyframeId, Isometry3<f64>))>,
}

impl TrackingThread {
    /// Tracking state talking to local mapping through `requests` and `replies`.
    pub(crate) fn new(
        tracker: Box<dyn StereoTracker>,
        map: Map,
        objects: ObjectMapper,
        config: SystemConfig,
        requests: Sender<MapperRequest>,
        replies: Receiver<MapperReply>,
    ) -> Self {
        let loaded = map.keyframe_count() > 0;
        Self {
            loaded,
            tracker,
            map,
            objects,
            config,
            requests,
            replies,
            records: Vec::new(),
            trajectory: Vec::new(),
            counts: RunCounts::default(),
            pending: VecDeque::new(),
            last_reference: None,
            prev_boxes: Vec::new(),
            prev_points: None,
            prev_flows: (0, Vec::new()),
            moving_regions: Vec::new(),
            last_done: Instant::now(),
            last_pose: None,
            applied: Vec::new(),
            segment_frames: Vec::new(),
            segment_reference: None,
        }
    }

    /// Records of the frames stepped so far.
    pub fn records(&self) -> &[FrameRecord] {
        &self.records
    }

    /// Counts so far.
    pub fn counts(&self) -> &RunCounts {
        &self.counts
    }

    /// The object mapper (objects so far).
    pub fn objects(&self) -> &ObjectMapper {
        &self.objects
    }

    /// The live map.
    pub fn map(&self) -> &Map {
        &self.map
    }

    /// The last frame's pose at tracking time, world from camera (`None` before the first frame and
    /// after an unreadable one).
    pub fn last_pose(&self) -> Option<Isometry3<f64>> {
        self.last_pose
    }

    /// The last frame as an observer sees it (`input` is that frame's input); `None` before the first.
    pub(crate) fn view<'a>(&'a self, input: &'a FrameInput) -> Option<FrameView<'a>> {
        Some(FrameView {
            record: self.records.last()?,
            world_from_camera: self.last_pose,
            left: input.images.as_ref().ok().map(|(left, _)| left),
            map: &self.map,
            mapped: &self.applied,
            objects: &self.objects,
        })
    }

    /// One frame after detection (its boxes, or why there are none, and the detector's time): apply the
    /// mapper's replies that are due, track the pair, associate the boxes, hand a keyframe and its fit
    /// jobs to local mapping; returns the frame's record.
    pub(crate) fn step(
        &mut self,
        input: &FrameInput,
        dets: Result<Vec<Detection>, DetectError>,
        det: DetectTimes,
    ) -> Result<&FrameRecord, SystemError> {
        let i = input.index;
        self.applied.clear();
        self.apply_due_replies()?;
        self.counts.frames += 1;
        let detections = self.accept_detections(i, dets);
        let times = FrameTimes { detection: det.whole, detector_forward: det.forward, ..FrameTimes::default() };
        let record = match &input.images {
            Ok((left, right)) => self.track_pair(i, left, right, detections, times)?,
            Err(why) => self.unreadable(i, why, times),
        };
        self.records.push(record);
        Ok(&self.records[self.records.len() - 1])
    }

    /// Apply the replies to keyframes made `correction_lag` played frames ago or earlier (counted in
    /// records, not frame ids: with a stride or gaps in the ids the lag stays the same number of
    /// tracked frames), waiting for them if need be.
    fn apply_due_replies(&mut self) -> Result<(), SystemError> {
        while let Some(&rec) = self.pending.front() {
            if rec + self.config.correction_lag > self.records.len() {
                break;
            }
            self.apply_next_reply(rec)?;
            self.pending.pop_front();
        }
        Ok(())
    }

    /// Wait for the next reply of local mapping (to the keyframe of record `rec`) and apply it: its edits
    /// to the live map, its object fits.
    fn apply_next_reply(&mut self, rec: usize) -> Result<(), SystemError> {
        let reply = self.replies.recv().map_err(|_| SystemError::Thread("local mapping"))?;
        self.map.apply(&reply.report.edits);
        for fit in reply.fits {
            self.objects.apply(fit);
        }
        let r = &reply.report;
        self.counts.implausible_fits = self.objects.implausible_fits();
        self.counts.culled_observations += r.culled_observations;
        self.counts.culled_points += r.points.0;
        self.counts.triangulated_points += r.points.1;
        self.counts.fused_points += r.points.2;
        self.counts.culled_keyframes += r.culled_keyframes.len();
        if let Some(rec) = self.records.get_mut(rec) {
            rec.times.bundle_adjustment = r.ba_ms;
            rec.times.map_maintenance = r.maintenance_ms;
            rec.times.objects = reply.fit_ms;
        }
        // kept until the next frame, for the frame's observers
        self.applied.push(r.keyframe);
        Ok(())
    }

    /// Apply every outstanding reply (end of input).
    pub(crate) fn drain_replies(&mut self) -> Result<(), SystemError> {
        while let Some(rec) = self.pending.pop_front() {
            self.apply_next_reply(rec)?;
        }
        Ok(())
    }

    /// Stop local mapping (after [`TrackingThread::drain_replies`]).
    pub(crate) fn stop_mapping(&self) {
        // the thread may have stopped already; joining it reports that
        let _ = self.requests.send(MapperRequest::Finish);
    }

    /// The frame's detections: duplicates suppressed (counted), a detector failure counted and logged.
    fn accept_detections(&mut self, frame: usize, dets: Result<Vec<Detection>, DetectError>) -> Vec<Detection> {
        match dets {
            Ok(d) if self.config.suppress_duplicates => {
                let (kept, dropped) = suppress_duplicate_boxes(d);
                self.counts.suppressed_boxes += dropped;
                kept
            }
            Ok(d) => d,
            Err(e) => {
                self.counts.detector_errors += 1;
                tracing::warn!(frame, "detector failed: {e}; frame has no boxes");
                Vec::new()
            }
        }
    }

    /// An unreadable frame: counted and logged, its pose held at the last reference.
    fn unreadable(&mut self, i: usize, why: &str, times: FrameTimes) -> FrameRecord {
        self.counts.unreadable += 1;
        self.last_pose = None;
        tracing::warn!(frame = i, "unreadable: {why}; pose held");
        // in a loaded map, a frame before the first placed one has no pose to hold
        let (kf, rel) = match (self.last_reference, self.segment_reference) {
            (Some((k, rel)), _) => (Some(k), rel),
            // in a segment of its own frame: held there, placed if the segment joins the map
            (None, Some((root, (k, rel)))) => {
                self.segment_frames.push((self.trajectory.len(), root, k));
                (None, rel)
            }
            (None, None) => ((!self.loaded).then_some(0), Isometry3::identity()),
        };
        self.trajectory.push(FramePose {
            frame: i,
            keyframe: kf,
            relative: pose_to_array(&rel),
            state: "unreadable".into(),
        });
        self.prev_boxes.clear();
        self.prev_points = None;
        FrameRecord {
            index: i,
            state: None,
            keyframe: false,
            tracked_map_points: 0,
            reprojection_rms_px: f64::NAN,
            detections: Vec::new(),
            tracks: Vec::new(),
            times,
        }
    }

    /// Track a readable pair and map its boxes.
    fn track_pair(
        &mut self,
        i: usize,
        left: &slam_core::Image,
        right: &slam_core::Image,
        detections: Vec<Detection>,
        mut times: FrameTimes,
    ) -> Result<FrameRecord, SystemError> {
        let exclude: &[MovingRegion] = if self.config.exclude_moving { &self.moving_regions } else { &[] };
        let tf = self
            .tracker
            .track(i, left, right, exclude, &self.map)
            .map_err(|source| SystemError::Tracker { frame: i, source })?;
        times.extraction = tf.times.extraction;
        times.stereo = tf.times.stereo;
        times.tracking = tf.times.tracking;
        if let Some(join) = &tf.joined {
            self.join_segment(i, join)?;
        }
        self.last_pose = tf.placed.then_some(tf.world_from_camera);
        self.count_state(i, &tf);
        self.map.count_sightings(&tf.sightings.visible, &tf.sightings.found);
        let keyframe = match &tf.keyframe {
            Some(kf) => self.insert_keyframe(i, kf)?,
            None => None,
        };
        let keyframe_points = keyframe.map(|id| self.keyframe_points(id));
        // objects need a pose in the map; localising only adds none
        let tracks = if tf.placed && !self.config.localise_only {
            self.map_boxes(i, &tf, keyframe_points.as_ref(), &detections, &mut times)
        } else {
            self.prev_boxes.clear();
            self.prev_points = None;
            vec![None; detections.len()]
        };
        if tf.placed {
            self.last_reference = Some(tf.reference);
        } else if let Some(root) = tf.segment {
            self.segment_frames.push((self.trajectory.len(), root, tf.reference.0));
            self.segment_reference = Some((root, tf.reference));
        }
        self.trajectory.push(FramePose {
            frame: i,
            keyframe: tf.placed.then_some(tf.reference.0),
            relative: pose_to_array(&tf.reference.1),
            state: tf.state.name().into(),
        });
        let is_kf = keyframe.is_some();
        if let Some(id) = keyframe {
            self.counts.keyframes += 1;
            let mut jobs = self.objects.fit_jobs();
            for job in &mut jobs {
                job.locate(|p| self.map.position(p));
                job.repose(|k| self.map.keyframe_pose(k));
            }
            let job = LocalMapper::job(&self.config.mapping, &self.map, id);
            self.requests
                .send(MapperRequest::Keyframe(Box::new(job), jobs))
                .map_err(|_| SystemError::Thread("local mapping"))?;
            self.pending.push_back(self.records.len());
        }
        times.interval = self.last_done.elapsed().as_secs_f64() * 1e3;
        self.last_done = Instant::now();
        Ok(FrameRecord {
            index: i,
            state: Some(tf.state),
            keyframe: is_kf,
            tracked_map_points: tf.tracked_map_points,
            reprojection_rms_px: tf.reprojection_rms_px,
            detections,
            tracks,
            times,
        })
    }

    /// Insert the keyframe the tracker handed over, once local mapping's work on every earlier keyframe
    /// is in the map (waiting for it if need be: the snapshot of the next job must hold it, whatever the
    /// threads' timing). `None` (logged) when the map refuses it.
    fn insert_keyframe(
        &mut self,
        frame: usize,
        kf: &slam_core::NewKeyframe,
    ) -> Result<Option<KeyframeId>, SystemError> {
        self.drain_replies()?;
        if kf.parent.is_none() && kf.id > 0 {
            self.counts.new_segments += 1;
        }
        match self.map.insert_keyframe(kf.clone(), &self.config.mapping.creation_policy()) {
            Ok(inserted) => Ok(Some(inserted.id)),
            Err(e) => {
                tracing::warn!(frame, "keyframe not inserted: {e}");
                Ok(None)
            }
        }
    }

    /// A segment tracked in a frame of its own joins the loaded map (frame `frame` of it was placed
    /// there, [`slam_core::SegmentJoin`]): once local mapping's work on its keyframes is in the map (a
    /// reply computed in the segment's frame must not land after the move), its keyframes and points
    /// move into the map's frame ([`Map::join_segment`]); the newest keyframe of the segment and its
    /// best covisible ones are fused with the keyframe it was placed against and that one's best
    /// covisible ones (a corner both saw becomes one point, and the two parts share points from then
    /// on, so local bundle adjustment holds them together); and the frames tracked in the segment get
    /// their poses in the map.
    fn join_segment(&mut self, frame: usize, join: &slam_core::SegmentJoin) -> Result<(), SystemError> {
        self.drain_replies()?;
        let (keyframes, points) = self.map.join_segment(join.root, &join.map_from_segment, join.anchor);
        if keyframes == 0 {
            // the segment's first keyframe is not in the map (it was refused when handed over): its
            // frames keep no pose rather than name a keyframe the map lacks
            tracing::warn!(
                frame,
                segment = join.root,
                "the segment to join is not in the map: its frames stay without a pose"
            );
            self.segment_frames.retain(|f| f.1 != join.root);
            self.segment_reference = None;
            return Ok(());
        }
        // as local mapping fuses a new keyframe: its best covisible keyframes, and theirs
        let window = slam_core::map::local::WindowConfig::default();
        let best = |m: &Map, k: KeyframeId, n: usize| std::iter::once(k).chain(m.covisibility().best(k, n)).collect();
        let newest = self.map.keyframes().map(|k| k.id).filter(|&k| k >= join.root).max();
        let ours: Vec<KeyframeId> = newest.map(|k| best(&self.map, k, window.second_neighbours)).unwrap_or_default();
        let theirs: Vec<KeyframeId> = best(&self.map, join.anchor, window.neighbours);
        let fusion = slam_core::map::fusion::Fusion::default();
        let mut merged = 0;
        for k in ours {
            merged += self.map.fuse(k, &theirs, &fusion).merged;
        }
        self.counts.fused_points += merged;
        let mut placed = 0;
        let trajectory = &mut self.trajectory;
        self.segment_frames.retain(|&(at, root, kf)| {
            if root != join.root {
                return true;
            }
            if let Some(f) = trajectory.get_mut(at) {
                f.keyframe = Some(kf);
                placed += 1;
            }
            false
        });
        self.segment_reference = None;
        self.counts.joined_segments += 1;
        tracing::info!(
            frame,
            keyframes,
            points,
            merged,
            frames = placed,
            moved_m = join.map_from_segment.translation.vector.norm(),
            "the segment tracked beside the loaded map joined it: its keyframes, points and frames now in the map's frame"
        );
        Ok(())
    }

    /// The points keyframe `id` observes, as the object cues read them (a stereo keypoint's own stereo
    /// point, else the map point seen from the keyframe), and its pose.
    fn keyframe_points(&self, id: KeyframeId) -> (Vec<KeyframePoint>, Isometry3<f64>) {
        let Some(kf) = self.map.keyframe(id) else { return (Vec::new(), Isometry3::identity()) };
        let camera = *self.map.camera();
        let from_world = kf.pose.inverse();
        let points = kf
            .observations()
            .filter_map(|(kp, p)| {
                let k = &kf.features.keypoints[kp];
                let camera_point = k
                    .stereo_point(&camera)
                    .or_else(|| self.map.position(p).map(|x| (from_world * Point3::from(x)).coords))?;
                Some(KeyframePoint { id: p, camera_point, observation: k.observation() })
            })
            .collect();
        (points, kf.pose)
    }

    /// Count the frame's tracking state (a lost frame is logged).
    fn count_state(&mut self, i: usize, tf: &TrackedFrame) {
        match tf.state {
            TrackState::Initialised => {}
            TrackState::Tracked { .. } => self.counts.tracked += 1,
            TrackState::Weak { .. } => self.counts.weak += 1,
            TrackState::Lost => {
                self.counts.lost += 1;
                // a frame not placed in a loaded map is counted, said once in the summary
                if tf.placed {
                    tracing::warn!(frame = i, stereo_points = tf.stereo_points, "tracking lost");
                }
            }
            TrackState::Predicted => self.counts.predicted += 1,
            TrackState::Relocalised { .. } => self.counts.relocalised += 1,
        }
    }

    /// Optical flow from the previous frame's boxes, association of the detections with the objects,
    /// their stereo points on a keyframe, and the boxes of moving objects kept out of the next frame's
    /// tracking. Returns each detection's object.
    fn map_boxes(
        &mut self,
        i: usize,
        tf: &TrackedFrame,
        keyframe: Option<&(Vec<KeyframePoint>, Isometry3<f64>)>,
        detections: &[Detection],
        times: &mut FrameTimes,
    ) -> Vec<Option<slam_core::TrackId>> {
        let t = Instant::now();
        let flow = if self.prev_boxes.is_empty() {
            Vec::new()
        } else {
            self.tracker.flow(&self.prev_boxes).unwrap_or_else(|e| {
                tracing::debug!(frame = i, "optical flow failed: {e}");
                Vec::new()
            })
        };
        times.flow = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let rig = *self.map.camera();
        let camera = Camera::new(rig.k, tf.world_from_camera);
        let tracks = self.objects.associate(i, &camera, Some(tf.reference), detections, &flow);
        let geometry = PointGeometry {
            noise: StereoNoise {
                focal_baseline: rig.focal_baseline(),
                disparity_sigma_px: self.config.disparity_sigma_px,
                core: self.config.object_core,
            },
            k: rig.k,
            image: self.config.objects.image,
        };
        // each box's own dense stereo points (a tracker without them gives none: the frame's stereo
        // points stand in), at the depths the box's class allows
        let dense = if tf.state.is_measured() && !detections.is_empty() {
            let queries: Vec<BoxQuery> =
                detections.iter().map(|d| BoxQuery { bbox: d.bbox, depth: box_depths(d, &geometry) }).collect();
            self.tracker.box_points(&queries).unwrap_or_else(|e| {
                tracing::debug!(frame = i, "dense stereo in the boxes failed: {e}");
                vec![Vec::new(); detections.len()]
            })
        } else {
            vec![Vec::new(); detections.len()]
        };
        let own = |k: usize| -> &[FramePoint] {
            match dense.get(k) {
                Some(p) if !p.is_empty() => p,
                _ => &tf.object_inputs.points,
            }
        };
        // each detection's object in its stereo points: where they put it, the depths they span
        let on_frame: Vec<FrameObject> = detections
            .iter()
            .enumerate()
            .map(|(k, d)| {
                let (kept, centroid) = object_points(own(k), &tf.world_from_camera, d, &geometry);
                let surface = if centroid.is_some() { surface_sample(&kept, &geometry.noise) } else { Vec::new() };
                FrameObject { centroid, depths: centroid.map(|_| depth_span(&kept)), surface }
            })
            .collect();
        self.attach_points(tf, keyframe, detections, &tracks, (&geometry, &on_frame));
        // the scene flow reads every stereo point of the frame, those on moving regions too (kept out of
        // tracking, the map and the objects' points above): a masked object goes on being measured
        // (the frame's own points first, then the masked ones)
        let all_points: Vec<FramePoint> = if self.config.scene_flow {
            tf.object_inputs.all_points().chain(dense.iter().flatten()).copied().collect()
        } else {
            Vec::new()
        };
        // the optical flow of the stereo points counts as flow, the rest as association
        let mut stereo_flow_ms = 0.0;
        if self.config.scene_flow && !self.prev_boxes.is_empty() {
            let t = Instant::now();
            let pairs = self.tracker.stereo_flow(&self.prev_boxes);
            stereo_flow_ms = t.elapsed().as_secs_f64() * 1e3;
            // a box takes its depths from the masked points too only when it is the masked object's box
            // again (it overlaps a region this frame was masked with, IoU ≥ 0.5): another object's box
            // on the same bearing would otherwise take the masked object's depth cluster, and its
            // motion, for its own; any box reads the flowed points at its depths, masked or not
            let masked_object =
                |d: &Detection| self.moving_regions.iter().any(|r| r.bbox.iou(&d.bbox) >= SAME_OBJECT_IOU);
            let flow_objects: Vec<FrameObject> = detections
                .iter()
                .zip(&on_frame)
                .map(|(d, o)| {
                    if tf.object_inputs.masked_points.is_empty() || !masked_object(d) {
                        return o.clone();
                    }
                    let (kept, centroid) = object_points(&all_points, &tf.world_from_camera, d, &geometry);
                    FrameObject { centroid, depths: centroid.map(|_| depth_span(&kept)), surface: Vec::new() }
                })
                .collect();
            match pairs {
                Ok(pairs) => {
                    self.attach_flow((i, tf), &all_points, detections, &tracks, &pairs, (&geometry, &flow_objects))
                }
                Err(e) => tracing::debug!(frame = i, "optical flow of stereo points failed: {e}"),
            }
            times.flow += stereo_flow_ms;
        }
        if tf.state.is_measured() {
            self.objects.check_free_space(&camera, &tf.object_inputs.points, &geometry.noise);
            self.counts.free_space_removals = self.objects.free_space_removals();
        }
        // where each moving object is expected in the next frame, from its points in this one (not
        // the masked ones: after its first masked frame an object has few points of its own left, and
        // its region then covers its whole box)
        let objects = &self.objects;
        self.moving_regions = detections
            .iter()
            .zip(&tracks)
            .zip(&on_frame)
            .filter(|((_, t), _)| t.and_then(|id| objects.object(id)).is_some_and(|o| o.moving))
            .map(|((d, _), o)| moving_region(d, o.depths, &geometry.noise))
            .collect();
        self.prev_boxes = detections.iter().map(|d| d.bbox).collect();
        self.prev_points =
            (self.config.scene_flow && tf.state.is_measured()).then_some((i, all_points, tf.world_from_camera));
        times.association = t.elapsed().as_secs_f64() * 1e3 - stereo_flow_ms;
        tracks
    }

    /// Give each associated object the scene flow of its points from the frame before ([`flowed_points`],
    /// [`ObjectMapper::add_flow`]): both frames measured; the flowed points that end inside the box at
    /// the depths of the object's points ([`object_points`]: its depth cluster).
    fn attach_flow(
        &mut self,
        (frame, tf): (usize, &TrackedFrame),
        points: &[FramePoint],
        detections: &[Detection],
        tracks: &[Option<slam_core::TrackId>],
        pairs: &[PointPair],
        (geometry, on_frame): (&PointGeometry, &[FrameObject]),
    ) {
        let Some((before_id, before, world_from_before)) = &self.prev_points else { return };
        let gap = frame.saturating_sub(*before_id);
        if !tf.state.is_measured() || pairs.is_empty() {
            return;
        }
        let flowed = flowed_points((before, world_from_before), (points, &tf.world_from_camera), pairs, geometry);
        let camera = tf.world_from_camera.translation.vector;
        // the readings of the frame before, for the box that overlaps each one now: the same physical
        // object whatever track the association gave it in either frame
        let (prev_frame, prev_flows) = std::mem::take(&mut self.prev_flows);
        let earlier = |b: &BBox| -> Option<SceneFlow> {
            (prev_frame + gap == frame)
                .then(|| {
                    prev_flows
                        .iter()
                        .map(|(pb, f)| (pb.iou(b), f))
                        .filter(|(iou, _)| *iou >= SAME_OBJECT_IOU)
                        .max_by(|a, b| a.0.total_cmp(&b.0))
                        .map(|(_, f)| *f)
                })
                .flatten()
        };
        let mut now_flows = Vec::new();
        for ((d, t), o) in detections.iter().zip(tracks).zip(on_frame) {
            let (Some(id), Some((near, far))) = (t, o.depths) else { continue };
            // the flowed points in the box at the depths of the box's object, masked or not: a masked
            // point there is that object's (its depths come from the unmasked points alone unless the box
            // is the masked object's again)
            let on: Vec<FlowedPoint> = flowed
                .iter()
                .filter(|(_, now)| {
                    let at = now.observation;
                    d.bbox.contains_point(at[0], at[1]) && (near..=far).contains(&now.camera_point.z)
                })
                .map(|(f, _)| *f)
                .collect();
            if let Some(flow) = scene_flow(&on, &camera) {
                tracing::trace!(frame, object = %id, bbox = ?d.bbox, sigmas = flow.sigmas(), points = flow.points, "scene flow of a box");
                self.objects.add_flow(*id, (frame, gap), &flow, earlier(&d.bbox).as_ref());
                now_flows.push((d.bbox, flow));
            }
        }
        self.prev_flows = (frame, now_flows);
    }

    /// Give each associated object its stereo points in this frame and where they put it: the centroid
    /// from the frame's stereo points in every measured frame (the motion test and the stereo evidence
    /// then do not depend on which frames became keyframes), the map-point ids on a keyframe. A tracker
    /// that hands over no frame points gives centroids on keyframes only.
    fn attach_points(
        &mut self,
        tf: &TrackedFrame,
        keyframe: Option<&(Vec<KeyframePoint>, Isometry3<f64>)>,
        detections: &[Detection],
        tracks: &[Option<slam_core::TrackId>],
        (geometry, on_frame): (&PointGeometry, &[FrameObject]),
    ) {
        let measured = tf.state.is_measured();
        for ((d, t), o) in detections.iter().zip(tracks).zip(on_frame) {
            let Some(id) = t else { continue };
            let on_keyframe = keyframe.map(|(points, pose)| object_points(points, pose, d, geometry));
            let centroid = match (&on_keyframe, measured && !tf.object_inputs.points.is_empty()) {
                (_, true) => o.centroid,
                (Some((_, c)), false) => *c,
                (None, false) => None,
            };
            let ids: Vec<u64> = on_keyframe.map(|(kept, _)| kept.iter().map(|p| p.id).collect()).unwrap_or_default();
            if keyframe.is_some() || centroid.is_some() {
                self.objects.add_points(*id, &ids, centroid);
            }
            if measured && !o.surface.is_empty() {
                self.objects.add_surface(*id, &o.surface);
            }
        }
    }
}

/// A stereo point as the object cues read it: a keyframe's (with its map-point id) or a frame's.
trait BoxPoint {
    /// `[u_left, v, u_right]`, pixels.
    fn observation(&self) -> [f64; 3];
    /// Position in the left-camera frame, metres.
    fn camera_point(&self) -> Vector3<f64>;
}

impl BoxPoint for KeyframePoint {
    fn observation(&self) -> [f64; 3] {
        self.observation
    }
    fn camera_point(&self) -> Vector3<f64> {
        self.camera_point
    }
}

impl BoxPoint for FramePoint {
    fn observation(&self) -> [f64; 3] {
        self.observation
    }
    fn camera_point(&self) -> Vector3<f64> {
        self.camera_point
    }
}

/// The stereo points of the frame before followed into this frame by optical flow (`pairs`, from
/// keypoint to keypoint: the flow starts at a keypoint of the frame before that has a stereo point,
/// and must end within 2 px of a stereo point of this frame: the same corner found again, whose
/// position an ORB keypoint of pyramid level 3 gives on a 1.7 px grid), with their world positions in
/// both frames and noise, and the stereo point they end at.
fn flowed_points<'a>(
    (before, world_from_before): (&[FramePoint], &Isometry3<f64>),
    (now, world_from_now): (&'a [FramePoint], &Isometry3<f64>),
    pairs: &[PointPair],
    g: &PointGeometry,
) -> Vec<(FlowedPoint, &'a FramePoint)> {
    let (before_grid, now_grid) = (PointGrid::of(before), PointGrid::of(now));
    let across = |z: f64| z / g.k.fx;
    let mut out = Vec::new();
    // a keypoint inside two boxes of the frame before is followed once per box: count it once
    let mut seen = std::collections::HashSet::new();
    for pair in pairs {
        // the flow starts at the keypoint itself (to float rounding)
        let Some(b) = before_grid.nearest(pair.reference, 0.01) else { continue };
        if !seen.insert((b.observation[0].to_bits(), b.observation[1].to_bits())) {
            continue;
        }
        let Some(n) = now_grid.nearest(pair.current, 2.0) else { continue };
        let (zb, zn) = (b.camera_point.z, n.camera_point.z);
        out.push((
            FlowedPoint {
                before: (world_from_before * Point3::from(b.camera_point)).coords,
                now: (world_from_now * Point3::from(n.camera_point)).coords,
                sigma_along: g.noise.depth_sigma(zb).hypot(g.noise.depth_sigma(zn)),
                sigma_across: across(zb).hypot(across(zn)),
            },
            n,
        ));
    }
    out
}

/// Nearest and farthest depth of points.
fn depth_span(points: &[&FramePoint]) -> (f64, f64) {
    points.iter().map(|p| p.camera_point.z).fold((f64::INFINITY, f64::NEG_INFINITY), |(n, f), z| (n.min(z), f.max(z)))
}

/// A detection's object in the frame's stereo points ([`object_points`]): where they put it, and the
/// nearest and farthest depth among them (both `None` below [`MIN_OBJECT_POINTS`] points).
#[derive(Clone)]
struct FrameObject {
    centroid: Option<PointsCentroid>,
    depths: Option<(f64, f64)>,
    /// A sample of its points (left-camera frame) with their depth σ, for the surface cue of its fits.
    surface: Vec<(Vector3<f64>, f64)>,
}

/// Most of an object's points kept per frame for the surface cue of its fits: enough for its faces
/// (two faces, each from a dozen points), few enough that a fit of 20 views stays a few hundred terms.
const SURFACE_POINTS_PER_FRAME: usize = 30;

/// Up to [`SURFACE_POINTS_PER_FRAME`] of `kept`, evenly spaced over the list, each with its depth σ.
fn surface_sample<P: BoxPoint>(kept: &[&P], noise: &StereoNoise) -> Vec<(Vector3<f64>, f64)> {
    let step = kept.len().div_ceil(SURFACE_POINTS_PER_FRAME).max(1);
    kept.iter().step_by(step).map(|p| (p.camera_point(), noise.depth_sigma(p.camera_point().z))).collect()
}

/// Stereo points in square cells of their left-image position, for nearest-point lookups.
struct PointGrid<'p> {
    cells: std::collections::HashMap<(i64, i64), Vec<&'p FramePoint>>,
}

impl<'p> PointGrid<'p> {
    /// Cell side, pixels: at least the largest lookup radius (2 px).
    const CELL: f64 = 4.0;

    fn key(u: f64, v: f64) -> (i64, i64) {
        ((u / Self::CELL).floor() as i64, (v / Self::CELL).floor() as i64)
    }

    fn of(points: &'p [FramePoint]) -> Self {
        let mut cells: std::collections::HashMap<(i64, i64), Vec<&'p FramePoint>> = Default::default();
        for p in points {
            cells.entry(Self::key(p.observation[0], p.observation[1])).or_default().push(p);
        }
        Self { cells }
    }

    /// The point nearest to `(u, v)` within `radius` pixels (at most the cell side).
    fn nearest(&self, [u, v]: [f64; 2], radius: f64) -> Option<&'p FramePoint> {
        let (cu, cv) = Self::key(u, v);
        (cu - 1..=cu + 1)
            .flat_map(|x| (cv - 1..=cv + 1).map(move |y| (x, y)))
            .filter_map(|c| self.cells.get(&c))
            .flatten()
            .map(|p| ((p.observation[0] - u).hypot(p.observation[1] - v), *p))
            .filter(|(d, _)| *d <= radius)
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, p)| p)
    }
}

/// Where a moving object of this frame is expected in the next: its box grown by 10 % on each side
/// (it moves between frames), and the depths its stereo points span widened by the class's
/// half-length `a` and twice the depth noise on each side (the far side of the object lies up to its
/// length behind its nearest visible point; `a` also covers a frame's change of its distance for
/// traffic moving with the camera); no depth limit when too few points measured it.
fn moving_region(d: &Detection, depths: Option<(f64, f64)>, noise: &StereoNoise) -> MovingRegion {
    let b = d.bbox;
    let (mx, my) = (0.1 * (b.xmax - b.xmin), 0.1 * (b.ymax - b.ymin));
    let bbox = BBox::new(b.xmin - mx, b.ymin - my, b.xmax + mx, b.ymax + my);
    let depth = depths.map(|(near, far)| {
        let a = class_prior(d.class).axes.x;
        let far = far.max(near + 2.0 * a);
        (near - a - 2.0 * noise.depth_sigma(near), far + a + 2.0 * noise.depth_sigma(far))
    });
    MovingRegion { bbox, depth }
}

/// Box overlap (IoU) at which two boxes of consecutive frames are taken for one physical object (the
/// usual criterion for one object in two boxes; between frames at 10 Hz a car's box changes far less).
const SAME_OBJECT_IOU: f64 = 0.5;

/// Fewest map points in a box for its centroid to count.
const MIN_OBJECT_POINTS: usize = 5;

/// Heights an object of a class group can have, metres: vehicles from a low car to a lorry (1.2–4.5),
/// people and riders 0.9–2.1, anything else 0.3–5.
fn height_range(class: ClassId) -> (f64, f64) {
    match class.0 {
        2 | 5 | 7 => (1.2, 4.5),
        0 | 1 | 3 => (0.9, 2.1),
        _ => (0.3, 5.0),
    }
}

/// The depths a detection's object can lie at: where the class's heights fill the box's height (no
/// near limit for a box the image border cuts: part of the object is outside).
fn box_depths(d: &Detection, g: &PointGeometry) -> (f64, f64) {
    let (hmin, hmax) = height_range(d.class);
    let bh = d.bbox.height().max(1.0);
    let cut = d.bbox.touches_border(&g.image, 2.0);
    (if cut { 0.0 } else { g.k.fy * hmin / bh }, g.k.fy * hmax / bh)
}

/// What [`object_points`] needs besides the keyframe and the box.
struct PointGeometry {
    /// Depth noise, and the central part of the box whose points count.
    noise: StereoNoise,
    k: Intrinsics,
    image: ImageSize,
}

/// The stereo points (of a keyframe or a frame, taken at `world_from_camera`) that lie on the object
/// of a detection, and where they put it.
///
/// Candidates: points inside the central part of the box (`core` of its width and height) whose depth
/// fits the box height for some height the class can have (no near limit for a box cut by the image
/// border: its height understates the object's). Among them the object is the densest depth cluster:
/// windows `[z, z + 2w]` with `w = max(a, 2 σ_z(z))`, `a` the class's half-length (a car seen obliquely
/// spans its length in depth) and `σ_z = z² σ_d / (f b)` the stereo depth noise; the object is the
/// nearest window holding at least half as many points as the densest one (it hides what lies behind
/// it). The centroid is the points' median world position (`None` below [`MIN_OBJECT_POINTS`] points).
fn object_points<'a, P: BoxPoint>(
    points: &'a [P],
    world_from_camera: &Isometry3<f64>,
    d: &Detection,
    g: &PointGeometry,
) -> (Vec<&'a P>, Option<PointsCentroid>) {
    let sigma_z = |z: f64| g.noise.depth_sigma(z);
    let cand = box_candidates(points, d, g);
    let half_length = class_prior(d.class).axes.x;
    let windows: Vec<usize> = (0..cand.len())
        .map(|i| {
            let z0 = cand[i].camera_point().z;
            let top = z0 + 2.0 * half_length.max(2.0 * sigma_z(z0));
            cand[i..].iter().take_while(|p| p.camera_point().z <= top).count()
        })
        .collect();
    // the nearest window holding at least half as many points as the densest one: the object hides
    // what lies behind it, and a textured facade behind a plain car can outnumber the car's points
    let densest = windows.iter().copied().max().unwrap_or(0);
    let best =
        windows.iter().position(|&n| n >= MIN_OBJECT_POINTS && 2 * n >= densest).map_or((0, 0), |i| (windows[i], i));
    let kept = &cand[best.1..best.1 + best.0];
    let world: Vec<(Vector3<f64>, f64)> = kept
        .iter()
        .map(|p| ((world_from_camera * Point3::from(p.camera_point())).coords, p.camera_point().z))
        .collect();
    // a centroid needs a few points: one stray point of the background would fake a motion
    let centroid = (world.len() >= MIN_OBJECT_POINTS).then(|| {
        let m = |k: usize| median(&mut world.iter().map(|p| p.0[k]).collect::<Vec<_>>()).unwrap_or(f64::NAN);
        PointsCentroid {
            position: Vector3::new(m(0), m(1), m(2)),
            depth_sigma: sigma_z(median(&mut world.iter().map(|p| p.1).collect::<Vec<_>>()).unwrap_or(f64::NAN)),
        }
    });
    (kept.to_vec(), centroid)
}

/// The points inside the box's core at a depth its height allows for the class, nearest first (ties
/// in input order).
fn box_candidates<'a, P: BoxPoint>(points: &'a [P], d: &Detection, g: &PointGeometry) -> Vec<&'a P> {
    let (b, (near, far)) = (&d.bbox, box_depths(d, g));
    let mut cand: Vec<&P> = points
        .iter()
        .filter(|p| {
            let o = p.observation();
            g.noise.in_core(b, o[0], o[1])
        })
        .filter(|p| {
            let z = p.camera_point().z;
            z > 0.0 && (near..=far).contains(&z)
        })
        .collect();
    // stable sort: equal depths keep the input order (a keyframe's points come in id order)
    cand.sort_by(|a, b| a.camera_point().z.total_cmp(&b.camera_point().z));
    cand
}
