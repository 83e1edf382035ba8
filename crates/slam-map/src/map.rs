//! The map: keyframes, map points and the covisibility graph, changed only through the primitives
//! here, each of which keeps the three consistent (a keyframe's keypoint observes a point exactly when
//! the point lists that observation; the graph's weights count the shared points). A snapshot of part
//! of the map ([`Map::window`]) records every change made to it as an [`Edit`]; the live map replays
//! those edits ([`Map::apply`]) with the same primitives, so work done on a snapshot on another thread
//! reaches the live map at a moment the caller chooses.

use std::collections::{BTreeMap, BTreeSet};

use nalgebra::{Isometry3, Point3, Vector3};

use crate::{
    camera::{ScalePyramid, StereoCamera},
    covisibility::Covisibility,
    descriptor::{representative, Descriptor},
    edit::Edit,
    keyframe::Keyframe,
    point::{MapPoint, Observation},
    KeyframeId, PointId,
};

/// Why a keyframe cannot be inserted.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum MapError {
    /// The id is taken (or was used before).
    #[error("keyframe {0} exists already or its id was used before")]
    DuplicateKeyframe(KeyframeId),
    /// Its features and its point list differ in length.
    #[error("keyframe {id}: {keypoints} keypoints but {descriptors} descriptors or point slots")]
    Features {
        /// The keyframe.
        id: KeyframeId,
        /// Keypoints.
        keypoints: usize,
        /// Descriptors or point slots.
        descriptors: usize,
    },
    /// Its pose has a non-finite number.
    #[error("keyframe {0}: its pose is not finite")]
    Pose(KeyframeId),
}

/// A keyframe culled from the map, kept as an anchor: the frames that were tracked against it keep
/// their pose relative to it, and it keeps its pose relative to its parent at the moment it was culled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Retired {
    /// The input frame it was made from.
    pub frame: usize,
    /// Its parent when it was culled.
    pub parent: KeyframeId,
    /// Its pose in the parent's frame when it was culled.
    pub parent_from_this: Isometry3<f64>,
}

/// Keyframes, map points and their covisibility.
#[derive(Debug, Clone)]
pub struct Map {
    camera: StereoCamera,
    pyramid: ScalePyramid,
    keyframes: BTreeMap<KeyframeId, Keyframe>,
    points: BTreeMap<PointId, MapPoint>,
    covisibility: Covisibility,
    retired: BTreeMap<KeyframeId, Retired>,
    next_keyframe: KeyframeId,
    next_point: PointId,
    /// Keyframes inserted so far (culled ones included).
    inserted: u64,
    /// Edits recorded since the snapshot was taken (`None`: not recording).
    log: Option<Vec<Edit>>,
}

impl Map {
    /// An empty map measured with `camera`, its keypoints from `pyramid`.
    pub fn new(camera: StereoCamera, pyramid: ScalePyramid) -> Self {
        Self {
            camera,
            pyramid,
            keyframes: BTreeMap::new(),
            points: BTreeMap::new(),
            covisibility: Covisibility::default(),
            retired: BTreeMap::new(),
            next_keyframe: 0,
            next_point: 0,
            inserted: 0,
            log: None,
        }
    }

    /// The camera.
    pub fn camera(&self) -> &StereoCamera {
        &self.camera
    }

    /// The scale pyramid of its keypoints.
    pub fn pyramid(&self) -> &ScalePyramid {
        &self.pyramid
    }

    /// A keyframe.
    pub fn keyframe(&self, id: KeyframeId) -> Option<&Keyframe> {
        self.keyframes.get(&id)
    }

    /// Every keyframe, by id.
    pub fn keyframes(&self) -> impl Iterator<Item = &Keyframe> {
        self.keyframes.values()
    }

    /// Number of keyframes (culled ones not counted).
    pub fn keyframe_count(&self) -> usize {
        self.keyframes.len()
    }

    /// A map point.
    pub fn point(&self, id: PointId) -> Option<&MapPoint> {
        self.points.get(&id)
    }

    /// Every map point, by id.
    pub fn points(&self) -> impl Iterator<Item = (PointId, &MapPoint)> {
        self.points.iter().map(|(&id, p)| (id, p))
    }

    /// Number of map points.
    pub fn point_count(&self) -> usize {
        self.points.len()
    }

    /// The covisibility graph.
    pub fn covisibility(&self) -> &Covisibility {
        &self.covisibility
    }

    /// The culled keyframes kept as anchors.
    pub fn retired(&self) -> &BTreeMap<KeyframeId, Retired> {
        &self.retired
    }

    /// The id the next keyframe inserted must have.
    pub fn next_keyframe_id(&self) -> KeyframeId {
        self.next_keyframe
    }

    /// Keyframes inserted so far, culled ones included.
    pub fn inserted(&self) -> u64 {
        self.inserted
    }

    /// The pose of keyframe `id` (world from camera), a culled one's through its anchor.
    pub fn keyframe_pose(&self, id: KeyframeId) -> Option<Isometry3<f64>> {
        let mut rel = Isometry3::identity();
        let mut at = id;
        // an anchor chain is at most as long as the keyframes culled
        for _ in 0..=self.retired.len() {
            if let Some(k) = self.keyframes.get(&at) {
                return Some(k.pose * rel);
            }
            let r = self.retired.get(&at)?;
            rel = r.parent_from_this * rel;
            at = r.parent;
        }
        None
    }

    /// The world position of map point `id`.
    pub fn position(&self, id: PointId) -> Option<Vector3<f64>> {
        self.points.get(&id).map(|p| p.position)
    }

    // ---- insertion (live map only) ----

    /// Add a keyframe that observes no point yet (its `points` all `None`); its id must be
    /// [`Map::next_keyframe_id`].
    pub(crate) fn add_keyframe(&mut self, kf: Keyframe) -> Result<(), MapError> {
        if kf.id != self.next_keyframe || self.keyframes.contains_key(&kf.id) {
            return Err(MapError::DuplicateKeyframe(kf.id));
        }
        let (n, d) = (kf.features.keypoints.len(), kf.features.descriptors.len());
        if n != d || kf.points.len() != n {
            return Err(MapError::Features { id: kf.id, keypoints: n, descriptors: d.min(kf.points.len()) });
        }
        if !(kf.pose.translation.vector.iter().all(|v| v.is_finite())
            && kf.pose.rotation.coords.iter().all(|v| v.is_finite()))
        {
            return Err(MapError::Pose(kf.id));
        }
        let mut kf = kf;
        kf.points.iter_mut().for_each(|p| *p = None);
        self.next_keyframe = kf.id + 1;
        self.inserted += 1;
        self.keyframes.insert(kf.id, kf);
        Ok(())
    }

    /// Ids below `next` are not given to new keyframes (those of a saved map's culled keyframes, say).
    pub fn reserve_keyframe_ids(&mut self, next: KeyframeId) {
        self.next_keyframe = self.next_keyframe.max(next);
    }

    /// Restoring a map: the next keyframe inserted takes id `id` (never lower than the next one).
    pub(crate) fn set_next_keyframe(&mut self, id: KeyframeId) {
        self.next_keyframe = self.next_keyframe.max(id);
    }

    /// Restoring a map: point `id` as saved, observed by nobody yet.
    pub(crate) fn insert_point(&mut self, id: PointId, point: MapPoint) {
        self.next_point = self.next_point.max(id + 1);
        self.points.insert(id, point);
    }

    /// Restoring a map: a point nobody observes left out.
    pub(crate) fn drop_point(&mut self, id: PointId) {
        self.points.remove(&id);
    }

    /// Join the map segment that starts at keyframe `root` to the rest of the map (live map only): the
    /// segment was tracked in a frame of its own (a run that started beside a loaded map it had not been
    /// placed in), and `map_from_segment` takes its poses into the map's. Every keyframe from `root` on
    /// (the keyframes made since the segment started: ids are handed out in order) and every point
    /// they alone observe is moved by it (a point's viewing direction turns with it; its distance range
    /// and descriptor stay), and `root` gets `anchor` (a keyframe of the map the segment was placed
    /// against) as its parent: one segment, in one frame. Culled keyframes follow through their anchors.
    /// Returns the keyframes and points moved.
    pub fn join_segment(
        &mut self,
        root: KeyframeId,
        map_from_segment: &Isometry3<f64>,
        anchor: KeyframeId,
    ) -> (usize, usize) {
        if !self.keyframes.contains_key(&root) || !self.keyframes.contains_key(&anchor) || anchor >= root {
            return (0, 0);
        }
        let mut moved = (0, 0);
        for k in self.keyframes.range_mut(root..).map(|(_, k)| k) {
            k.pose = map_from_segment * k.pose;
            moved.0 += 1;
        }
        for p in self.points.values_mut() {
            let ours = !p.observations.is_empty() && p.observations.iter().all(|o| o.keyframe >= root);
            if ours {
                p.position = (map_from_segment * Point3::from(p.position)).coords;
                p.normal = map_from_segment.rotation * p.normal;
                moved.1 += 1;
            }
        }
        if let Some(k) = self.keyframes.get_mut(&root) {
            k.parent = Some(anchor);
        }
        moved
    }

    // ---- the primitives (recorded in a snapshot) ----

    fn record(&mut self, e: Edit) {
        if let Some(log) = &mut self.log {
            log.push(e);
        }
    }

    /// A new point at `position` (world), made by `keyframe`, observed by nobody yet; its id.
    pub fn add_point(&mut self, position: Vector3<f64>, keyframe: KeyframeId) -> PointId {
        let id = self.next_point;
        self.add_point_with_id(id, position, keyframe);
        id
    }

    fn add_point_with_id(&mut self, id: PointId, position: Vector3<f64>, keyframe: KeyframeId) {
        self.next_point = self.next_point.max(id + 1);
        self.points.insert(id, MapPoint::new(position, keyframe, self.inserted));
        self.record(Edit::AddPoint { point: id, position, keyframe });
    }

    /// Keypoint `keypoint` of `keyframe` observes `point`. Refused (false) when the point or the
    /// keyframe is not here, the keyframe already observes the point, or the keypoint observes another
    /// point already.
    pub fn observe(&mut self, point: PointId, keyframe: KeyframeId, keypoint: usize) -> bool {
        let Some(p) = self.points.get(&point) else { return false };
        if p.observation(keyframe).is_some() {
            return false;
        }
        let Some(k) = self.keyframes.get(&keyframe) else { return false };
        if k.points.get(keypoint).is_none_or(|slot| slot.is_some()) {
            return false;
        }
        let level = k.features.keypoints[keypoint].level;
        for o in &p.observations {
            self.covisibility.link(keyframe, o.keyframe);
        }
        let p = self.points.get_mut(&point).expect("checked above");
        let at = p.observations.partition_point(|o| o.keyframe < keyframe);
        p.observations.insert(at, Observation { keyframe, keypoint: keypoint as u32, level });
        if let Some(k) = self.keyframes.get_mut(&keyframe) {
            k.points[keypoint] = Some(point);
        }
        self.record(Edit::Observe { point, keyframe, keypoint: keypoint as u32 });
        true
    }

    /// `keyframe` no longer observes `point`; a point nobody observes any more is removed. False when
    /// there was no such observation.
    pub fn unobserve(&mut self, point: PointId, keyframe: KeyframeId) -> bool {
        if !self.unobserve_quietly(point, keyframe) {
            return false;
        }
        self.record(Edit::Unobserve { point, keyframe });
        true
    }

    fn unobserve_quietly(&mut self, point: PointId, keyframe: KeyframeId) -> bool {
        let Some(p) = self.points.get_mut(&point) else { return false };
        let Ok(at) = p.observations.binary_search_by_key(&keyframe, |o| o.keyframe) else { return false };
        let o = p.observations.remove(at);
        let others: Vec<KeyframeId> = p.observations.iter().map(|o| o.keyframe).collect();
        let empty = p.observations.is_empty();
        for k in others {
            self.covisibility.unlink(keyframe, k);
        }
        if let Some(k) = self.keyframes.get_mut(&keyframe) {
            if k.points.get(o.keypoint as usize).copied().flatten() == Some(point) {
                k.points[o.keypoint as usize] = None;
            }
        }
        if empty {
            self.points.remove(&point);
        }
        true
    }

    /// Remove a point and all its observations.
    pub fn remove_point(&mut self, point: PointId) {
        let Some(p) = self.points.get(&point) else { return };
        let observers: Vec<KeyframeId> = p.observations.iter().map(|o| o.keyframe).collect();
        for k in observers {
            self.unobserve_quietly(point, k);
        }
        self.points.remove(&point);
        self.record(Edit::RemovePoint { point });
    }

    /// `from` and `into` are the same place: `from`'s observations move to `into` (an observation in a
    /// keyframe that already observes `into` is dropped), its counts are added, and `from` is removed.
    pub fn merge(&mut self, from: PointId, into: PointId) {
        if from == into || !self.points.contains_key(&into) {
            return;
        }
        let Some(p) = self.points.get(&from) else { return };
        let moved: Vec<Observation> = p.observations.clone();
        let (visible, found) = (p.visible, p.found);
        let logging = self.log.take();
        for o in &moved {
            self.unobserve_quietly(from, o.keyframe);
            if self.keyframes.contains_key(&o.keyframe) {
                self.observe(into, o.keyframe, o.keypoint as usize);
            } else if let Some(q) = self.points.get(&into) {
                // a keyframe outside a snapshot: the point keeps the observation it will have
                if q.observation(o.keyframe).is_none() {
                    for other in q.observations.iter().map(|x| x.keyframe).collect::<Vec<_>>() {
                        self.covisibility.link(o.keyframe, other);
                    }
                    let q = self.points.get_mut(&into).expect("exists");
                    let at = q.observations.partition_point(|x| x.keyframe < o.keyframe);
                    q.observations.insert(at, *o);
                }
            }
        }
        self.points.remove(&from);
        if let Some(q) = self.points.get_mut(&into) {
            q.visible += visible;
            q.found += found;
        }
        self.log = logging;
        self.record(Edit::Merge { from, into });
    }

    /// Move keyframe `keyframe`.
    pub fn set_pose(&mut self, keyframe: KeyframeId, pose: Isometry3<f64>) {
        if let Some(k) = self.keyframes.get_mut(&keyframe) {
            k.pose = pose;
            self.record(Edit::SetPose { keyframe, pose });
        }
    }

    /// Move point `point`.
    pub fn set_position(&mut self, point: PointId, position: Vector3<f64>) {
        if let Some(p) = self.points.get_mut(&point) {
            p.position = position;
            self.record(Edit::SetPosition { point, position });
        }
    }

    /// Cull keyframe `keyframe`: its observations are removed (points nobody sees any more with
    /// them), its children take its parent, and it stays as an anchor relative to that parent. A
    /// keyframe without a parent (the start of a map segment) is never culled (false).
    pub fn remove_keyframe(&mut self, keyframe: KeyframeId) -> bool {
        let Some(k) = self.keyframes.get(&keyframe) else { return false };
        let Some(parent) = k.parent else { return false };
        let Some(parent_pose) = self.keyframe_pose(parent) else { return false };
        let anchor = Retired { frame: k.frame, parent, parent_from_this: parent_pose.inverse() * k.pose };
        let observed: Vec<PointId> = k.observations().map(|(_, p)| p).collect();
        let logging = self.log.take();
        for p in observed {
            self.unobserve_quietly(p, keyframe);
        }
        self.log = logging;
        self.covisibility.remove(keyframe);
        self.keyframes.remove(&keyframe);
        for c in self.keyframes.values_mut() {
            if c.parent == Some(keyframe) {
                c.parent = Some(parent);
            }
        }
        self.retired.insert(keyframe, anchor);
        self.record(Edit::RemoveKeyframe { keyframe });
        true
    }

    /// Count a tracked frame's sightings: `visible` points lay in its view, `found` were matched and
    /// kept. Not recorded (the live map's own bookkeeping).
    pub fn count_sightings(&mut self, visible: &[PointId], found: &[PointId]) {
        for id in visible {
            if let Some(p) = self.points.get_mut(id) {
                p.visible += 1;
            }
        }
        for id in found {
            if let Some(p) = self.points.get_mut(id) {
                p.found += 1;
            }
        }
    }

    // ---- derived values ----

    /// Recompute a point's representative descriptor, mean viewing direction and detectable distance
    /// range from its observations in the keyframes present (the range from the observation nearest
    /// the point's first keyframe, ORB's reference view).
    pub fn refresh(&mut self, point: PointId) {
        let Some(p) = self.points.get(&point) else { return };
        let mut descriptors: Vec<Descriptor> = Vec::with_capacity(p.observations.len());
        let mut normal = Vector3::zeros();
        let mut n = 0;
        let mut reference: Option<(KeyframeId, f64, u8)> = None;
        for o in &p.observations {
            let Some(k) = self.keyframes.get(&o.keyframe) else { continue };
            descriptors.push(k.features.descriptors[o.keypoint as usize]);
            let ray = p.position - k.centre();
            let d = ray.norm();
            if d > 0.0 {
                normal += ray / d;
                n += 1;
            }
            // the first keyframe's view if present, else the earliest present
            if reference.is_none() || o.keyframe == p.first_keyframe {
                reference = Some((o.keyframe, d, o.level));
            }
        }
        let Some(descriptor) = representative(&descriptors) else { return };
        let range = reference.map(|(_, d, level)| self.pyramid.distance_range(d, level));
        let p = self.points.get_mut(&point).expect("exists");
        p.descriptor = descriptor;
        if n > 0 {
            p.normal = normal / n as f64;
            let norm = p.normal.norm();
            if norm > 0.0 {
                p.normal /= norm;
            }
        }
        if let Some(range) = range {
            p.distance = range;
        }
    }

    // ---- snapshots ----

    /// A snapshot holding `keyframes` (those present), every point they observe (with all its
    /// observations, in keyframes outside the snapshot too), and the links among them; it records the
    /// edits made to it ([`Map::take_edits`]).
    pub fn window(&self, keyframes: &BTreeSet<KeyframeId>) -> Map {
        let kfs: BTreeMap<KeyframeId, Keyframe> =
            keyframes.iter().filter_map(|id| self.keyframes.get(id).map(|k| (*id, k.clone()))).collect();
        let mut points = BTreeMap::new();
        for k in kfs.values() {
            for (_, p) in k.observations() {
                if let Some(mp) = self.points.get(&p) {
                    points.entry(p).or_insert_with(|| mp.clone());
                }
            }
        }
        let mut covisibility = Covisibility::default();
        for &a in kfs.keys() {
            for (b, w) in self.covisibility.neighbours(a, 1) {
                if a < b {
                    for _ in 0..w {
                        covisibility.link(a, b);
                    }
                }
            }
        }
        Map {
            camera: self.camera,
            pyramid: self.pyramid,
            keyframes: kfs,
            points,
            covisibility,
            retired: BTreeMap::new(),
            next_keyframe: self.next_keyframe,
            next_point: self.next_point,
            inserted: self.inserted,
            log: Some(Vec::new()),
        }
    }

    /// Whether this map is a snapshot recording its edits.
    pub fn is_snapshot(&self) -> bool {
        self.log.is_some()
    }

    /// The edits recorded so far (the log is emptied).
    pub fn take_edits(&mut self) -> Vec<Edit> {
        self.log.as_mut().map(std::mem::take).unwrap_or_default()
    }

    /// Replay a snapshot's edits on this map with the same primitives, then refresh the points they
    /// touched. Edits naming what is not (or no longer) here are skipped.
    pub fn apply(&mut self, edits: &[Edit]) {
        let mut touched = BTreeSet::new();
        for e in edits {
            match *e {
                Edit::AddPoint { point, position, keyframe } => {
                    if !self.points.contains_key(&point) {
                        self.add_point_with_id(point, position, keyframe);
                    }
                    touched.insert(point);
                }
                Edit::Observe { point, keyframe, keypoint } => {
                    self.observe(point, keyframe, keypoint as usize);
                    touched.insert(point);
                }
                Edit::Unobserve { point, keyframe } => {
                    self.unobserve(point, keyframe);
                    touched.insert(point);
                }
                Edit::RemovePoint { point } => self.remove_point(point),
                Edit::Merge { from, into } => {
                    self.merge(from, into);
                    touched.insert(into);
                }
                Edit::SetPose { keyframe, pose } => self.set_pose(keyframe, pose),
                Edit::SetPosition { point, position } => {
                    self.set_position(point, position);
                    touched.insert(point);
                }
                Edit::RemoveKeyframe { keyframe } => {
                    if let Some(k) = self.keyframes.get(&keyframe) {
                        touched.extend(k.observations().map(|(_, p)| p));
                    }
                    self.remove_keyframe(keyframe);
                }
            }
        }
        // a point left without observations (its keyframes are no longer here) is dropped
        for p in touched {
            if self.points.get(&p).is_some_and(|x| x.observations.is_empty()) {
                self.points.remove(&p);
            } else {
                self.refresh(p);
            }
        }
    }

    /// The point `point` seen from keyframe `keyframe`'s camera, in its camera frame.
    pub fn in_camera(&self, keyframe: KeyframeId, point: &Vector3<f64>) -> Option<Vector3<f64>> {
        self.keyframes.get(&keyframe).map(|k| (k.pose.inverse() * Point3::from(*point)).coords)
    }

    /// Check the invariants (tests and debugging): every observation is listed on both sides and the
    /// covisibility weights equal the shared points among present keyframes. The first broken one.
    pub fn check(&self) -> Result<(), String> {
        for (&id, p) in &self.points {
            if p.observations.is_empty() {
                return Err(format!("point {id} has no observation"));
            }
            if p.observations.windows(2).any(|w| w[0].keyframe >= w[1].keyframe) {
                return Err(format!("point {id}: observations out of order"));
            }
            for o in &p.observations {
                if let Some(k) = self.keyframes.get(&o.keyframe) {
                    if k.points.get(o.keypoint as usize).copied().flatten() != Some(id) {
                        return Err(format!(
                            "point {id}: keyframe {} keypoint {} does not observe it",
                            o.keyframe, o.keypoint
                        ));
                    }
                }
            }
        }
        let mut shared: BTreeMap<(KeyframeId, KeyframeId), u32> = BTreeMap::new();
        for k in self.keyframes.values() {
            for (i, p) in k.observations() {
                let Some(mp) = self.points.get(&p) else {
                    return Err(format!("keyframe {} keypoint {i}: point {p} does not exist", k.id));
                };
                if mp.observation(k.id).map(|o| o.keypoint as usize) != Some(i) {
                    return Err(format!("keyframe {} keypoint {i}: point {p} does not list it", k.id));
                }
            }
        }
        for p in self.points.values() {
            let present: Vec<KeyframeId> =
                p.observations.iter().map(|o| o.keyframe).filter(|k| self.keyframes.contains_key(k)).collect();
            for (i, &a) in present.iter().enumerate() {
                for &b in &present[i + 1..] {
                    *shared.entry((a, b)).or_default() += 1;
                }
            }
        }
        for (&(a, b), &w) in &shared {
            if self.covisibility.weight(a, b) != w {
                return Err(format!("link {a}-{b}: weight {} but {w} shared points", self.covisibility.weight(a, b)));
            }
        }
        for (a, b, w) in self.covisibility.iter() {
            if self.keyframes.contains_key(&a) && self.keyframes.contains_key(&b) && shared.get(&(a, b)) != Some(&w) {
                return Err(format!("link {a}-{b} of weight {w} without as many shared points"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        fusion::Fusion, insert::CreationPolicy, point_culling::PointCulling, synthetic, triangulation::Triangulation,
    };

    /// A segment tracked in a frame of its own (keyframes 2 and 3, made beside keyframes 0 and 1 of the
    /// same street with their poses in a frame turned by 0.3 rad and moved 5 m) joined to the map by
    /// the transform between the two frames: its keyframes and the points it made are where the street
    /// is, its first keyframe's parent is the keyframe it was placed against, the map stays consistent,
    /// and fusion then finds the two segments' points of one corner to be one point.
    #[test]
    fn a_segment_joined_to_the_map_lands_in_the_map_frame() {
        let mut street = synthetic::Street::new(8, 500);
        let mut live = synthetic::map();
        let policy = CreationPolicy::default();
        let mut first = BTreeMap::new();
        for (n, z) in [0.0, 2.0].into_iter().enumerate() {
            street.insert(&mut live, (n, z), &policy, &mut first);
        }
        let segment_from_map = Isometry3::new(Vector3::new(5.0, 0.0, -3.0), Vector3::new(0.0, 0.3, 0.0));
        let mut second: BTreeMap<usize, PointId> = BTreeMap::new();
        let mut index_of = BTreeMap::new();
        for (n, z) in [(2usize, 3.0), (3, 5.0)] {
            let (mut kf, index) = street.keyframe(&live, n, z, &|i| second.get(&i).copied());
            kf.pose = segment_from_map * kf.pose;
            kf.parent = (n == 3).then_some(2);
            let id = kf.id;
            live.insert_keyframe(kf, &policy).expect("insert");
            for (kp, p) in live.keyframe(id).expect("kf").observations() {
                second.entry(index[kp]).or_insert(p);
                index_of.insert(p, index[kp]);
            }
        }
        let ours: Vec<PointId> = second.values().copied().collect();
        assert!(ours.iter().all(|p| (live.position(*p).expect("p") - street.points[index_of[p]]).norm() > 1.0));
        let moved = live.join_segment(2, &segment_from_map.inverse(), 1);
        assert_eq!(moved, (2, ours.len()));
        for (id, z) in [(2, 3.0), (3, 5.0)] {
            let k = live.keyframe_pose(id).expect("kf");
            assert!((k.translation.vector - Vector3::new(0.0, 0.0, z)).norm() < 1e-9 && k.rotation.angle() < 1e-9);
        }
        for p in &ours {
            let err = (live.position(*p).expect("point") - street.points[index_of[p]]).norm();
            assert!(err < 1e-9, "point {p}: {err} m from the street");
        }
        assert_eq!(live.keyframe(2).expect("kf").parent, Some(1), "one segment");
        live.check().expect("consistent");
        let fused = live.fuse(2, &[1, 0], &Fusion::default());
        assert!(fused.merged > 50, "the two segments' points of one corner are one: {fused:?}");
        live.check().expect("consistent after fusion");
        // a root that is not after its anchor, or unknown keyframes, join nothing
        assert_eq!(live.join_segment(1, &Isometry3::identity(), 2), (0, 0));
    }

    /// Work done on a snapshot and replayed on the live map gives what the same work done on the live
    /// map itself gives: points, observations, positions and poses.
    #[test]
    fn edits_recorded_on_a_snapshot_replay_on_the_live_map() {
        let mut street = synthetic::Street::new(6, 500);
        let mut live = synthetic::map();
        let policy = CreationPolicy::default();
        let mut of = BTreeMap::new();
        for (n, z) in [0.0, 2.0, 4.0, 6.0].into_iter().enumerate() {
            street.insert(&mut live, (n, z), &policy, &mut of);
        }
        let work = |m: &mut Map| {
            m.triangulate_new_points(3, &[2, 1], &Triangulation::default());
            m.fuse(3, &[2, 1], &Fusion::default());
            m.cull_young_points(&PointCulling::default());
            let moved: Vec<PointId> = m.keyframe(3).expect("kf").observations().map(|(_, p)| p).take(5).collect();
            for p in moved {
                let x = m.position(p).expect("point") + Vector3::new(0.01, 0.0, 0.0);
                m.set_position(p, x);
            }
            m.set_pose(2, Isometry3::translation(0.0, 0.01, 4.0));
        };
        let summary = |m: &Map| -> Vec<(PointId, Vec<Observation>, [i64; 3])> {
            m.points()
                .map(|(id, p)| (id, p.observations.clone(), [0, 1, 2].map(|i| (p.position[i] * 1e9).round() as i64)))
                .collect()
        };
        let first_difference = |a: &Map, b: &Map| {
            let (x, y) = (summary(a), summary(b));
            x.iter()
                .zip(&y)
                .find(|(p, q)| p != q)
                .map(|(p, q)| format!("{p:?} vs {q:?}"))
                .or_else(|| (x.len() != y.len()).then(|| format!("{} vs {} points", x.len(), y.len())))
        };
        let mut direct = live.clone();
        work(&mut direct);
        // a snapshot of the whole map: the replay gives exactly the same map
        let mut whole = live.clone();
        let mut snapshot = whole.window(&[0, 1, 2, 3].into_iter().collect());
        work(&mut snapshot);
        let edits = snapshot.take_edits();
        assert!(edits.len() > 20, "{} edits", edits.len());
        whole.apply(&edits);
        whole.check().expect("consistent");
        assert_eq!(first_difference(&whole, &direct), None);
        assert_eq!(whole.covisibility(), direct.covisibility());
        // a snapshot of the last three keyframes: the points it holds end the same (culling there sees
        // only them, so it is left out of this comparison)
        let partial = |m: &mut Map| {
            m.triangulate_new_points(3, &[2, 1], &Triangulation::default());
            m.fuse(3, &[2, 1], &Fusion::default());
            let moved: Vec<PointId> = m.keyframe(3).expect("kf").observations().map(|(_, p)| p).take(5).collect();
            for p in moved {
                let x = m.position(p).expect("point") + Vector3::new(0.01, 0.0, 0.0);
                m.set_position(p, x);
            }
            m.set_pose(2, Isometry3::translation(0.0, 0.01, 4.0));
        };
        let mut direct = live.clone();
        partial(&mut direct);
        let keyframes: BTreeSet<KeyframeId> = [1, 2, 3].into_iter().collect();
        let mut snapshot = live.window(&keyframes);
        partial(&mut snapshot);
        live.apply(&snapshot.take_edits());
        live.check().expect("consistent");
        direct.check().expect("consistent");
        assert_eq!(first_difference(&live, &direct), None);
        assert_eq!(live.keyframe_pose(2), direct.keyframe_pose(2));
        assert_eq!(live.covisibility(), direct.covisibility());
    }
}
