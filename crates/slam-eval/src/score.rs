//! A run's object map scored against KITTI tracking labels.
//!
//! * **Label tracks** are carried into the run's world with the run's own poses (box centre in the run's
//!   camera, then `world_from_camera` of that frame). A track whose world centre stays within
//!   `static_m` of its mean is **static** (a parked car moves by the poses' drift and the labels' noise
//!   only: a few decimetres); one that leaves it by more than `moving_m` is **moving**; in between it
//!   is neither (a car creeping, or labels too noisy to tell) and is not held against the map either way.
//! * **Census of the static map objects** (an ellipsoid, not flagged dynamic): each object is projected
//!   with the run's pose in every frame of its own detections and its image-clipped box compared with
//!   that frame's label boxes. A frame votes for the label track with the highest IoU (at least
//!   `match_iou`), else for "DontCare" when at least `dont_care_cover` of the box lies in a DontCare
//!   region, else for "nothing". The object's fate is its majority vote: a label track → **matched**
//!   (the object with the most votes for that track), **duplicate** (another object of the same track),
//!   **moving** (the track is moving: traffic mapped as static); or **dont_care**, or **nothing**.
//! * **Vehicles**: static Car/Van tracks with at least `min_frames` labelled frames in the run. Found =
//!   matched by an object. Over the found ones: IoU2D (mean over the labelled frames of the IoU of the
//!   estimate's clipped projected box with the label's box; beside it what the ground-truth ellipsoid,
//!   inscribed in the label's 3-D box, scores), box IoU2D (the same with the bounds of the estimate's own
//!   3-D box projected, `slam_quadric::metrics::box_iou`, and the ground truth's), e_trans (centre distance to the label
//!   box's mean world centre), e_axe (semi-axes in the best order vs half the label's l, h, w), e_yaw
//!   (the estimate's longest horizontal axis vs the labelled heading, modulo 180°) and the share with
//!   e_yaw within `yaw_within_deg`.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;
use slam_core::geometry::{metrics, project, BBox, Camera, Ellipsoid, ImageSize};
use slam_dataset::kitti::tracking::TrackingLabel;

use crate::labels::LabelGeometry;

/// Settings of the scoring.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScoreConfig {
    /// Least IoU of an object's projected box with a label box for the frame to vote for that label.
    /// Default 0.3: an ellipsoid inscribed in a car's box projects to a box about 0.7 of the label's in
    /// each direction, so a good estimate reaches about 0.5 and 0.3 leaves room for a metre of error at
    /// 15 m.
    pub match_iou: f64,
    /// Least share of an object's projected box inside one DontCare region for the frame to vote
    /// "DontCare". Default 0.5.
    pub dont_care_cover: f64,
    /// Largest spread of a label track's world centre for a static track, metres. Default 1.0 (the
    /// labels' own depth noise plus a run's drift over a few tens of metres).
    pub static_m: f64,
    /// Least spread of a label track's world centre for a moving track, metres. Default 3.0.
    pub moving_m: f64,
    /// Fewest labelled frames (inside the run) of a vehicle counted for success. Default 10.
    pub min_frames: usize,
    /// e_yaw threshold of the "within" share, degrees. Default 15.
    pub yaw_within_deg: f64,
}

impl Default for ScoreConfig {
    fn default() -> Self {
        Self {
            match_iou: 0.3,
            dont_care_cover: 0.5,
            static_m: 1.0,
            moving_m: 3.0,
            min_frames: 10,
            yaw_within_deg: 15.0,
        }
    }
}

impl From<crate::labelled::VehicleCriteria> for ScoreConfig {
    /// The default scoring with the vehicles' criteria (frames, static and moving spreads).
    fn from(c: crate::labelled::VehicleCriteria) -> Self {
        Self { min_frames: c.min_frames, static_m: c.static_m, moving_m: c.moving_m, ..Self::default() }
    }
}

/// A map object to score.
#[derive(Debug, Clone, PartialEq)]
pub struct ScoredInput {
    /// Its id.
    pub id: u64,
    /// COCO class.
    pub class: u16,
    /// Its ellipsoid, world frame of the run.
    pub ellipsoid: Ellipsoid,
    /// Frames of its detections.
    pub frames: Vec<usize>,
    /// Flagged dynamic by the run.
    pub dynamic: bool,
}

/// What a map object turned out to be.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Fate {
    /// The best object of a static (or not clearly moving) label track.
    Matched,
    /// Another object of a label track that already has one.
    Duplicate,
    /// An object of a moving label track.
    Moving,
    /// Mostly inside DontCare regions.
    DontCare,
    /// Matches no label.
    Nothing,
    /// Never in view in its own frames (projection failed everywhere): not scored.
    Unscored,
}

/// One object's score.
#[derive(Debug, Clone, Serialize)]
pub struct ObjectScore {
    /// Object id.
    pub id: u64,
    /// COCO class.
    pub class: u16,
    /// Flagged dynamic by the run (those are not in the census).
    pub dynamic: bool,
    /// Its fate.
    pub fate: Fate,
    /// The label track it voted for, if any.
    pub track: Option<i64>,
    /// Frames that voted for its fate, of `frames`.
    pub votes: usize,
    /// Frames scored.
    pub frames: usize,
}

/// One label track as the run saw it.
#[derive(Debug, Clone, Serialize)]
pub struct TrackScore {
    /// Track id.
    pub track: i64,
    /// KITTI type.
    pub kind: String,
    /// Labelled frames inside the run.
    pub frames: usize,
    /// Largest distance of its world centre from the mean, metres.
    pub spread_m: f64,
    /// Static, moving or neither (see the module).
    pub motion: &'static str,
    /// Counted as a static vehicle for success.
    pub vehicle: bool,
    /// The static map object matched to it.
    pub object: Option<u64>,
    /// Dynamic-flagged objects that voted for it.
    pub flagged: Vec<u64>,
    /// Figures of the match (vehicles that were found).
    pub iou2d: Option<f64>,
    /// Box IoU2D of the match (its own 3-D box projected).
    pub box_iou2d: Option<f64>,
    /// Centre error, metres.
    pub e_trans: Option<f64>,
    /// Semi-axis error, metres.
    pub e_axe: Option<f64>,
    /// Yaw error, degrees.
    pub e_yaw: Option<f64>,
}

/// The census of the static map objects.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Census {
    /// Static map objects scored.
    pub static_objects: usize,
    /// Matched a label track.
    pub matched: usize,
    /// A second (third…) object of one label track.
    pub duplicate: usize,
    /// A moving label track mapped as static.
    pub moving: usize,
    /// In a DontCare region.
    pub dont_care: usize,
    /// Matching nothing.
    pub nothing: usize,
    /// Of those, objects of a class the labels never annotate standing alone: bicycles and motorcycles
    /// (KITTI labels one only with its rider, as a Cyclist), so a parked one can match nothing.
    pub nothing_unlabelled_class: usize,
    /// Not in view in its own frames.
    pub unscored: usize,
    /// Objects flagged dynamic by the run (not in the counts above).
    pub dynamic_objects: usize,
    /// Of those, the ones whose majority is a moving label track (rightly flagged).
    pub dynamic_on_moving: usize,
}

/// Summary figures over the static vehicles.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct VehicleFigures {
    /// Static labelled vehicles (Car/Van, `min_frames` frames or more).
    pub vehicles: usize,
    /// Found (matched by a static map object).
    pub found: usize,
    /// found / vehicles (NaN without vehicles).
    pub success: f64,
    /// Mean IoU2D over the found ones.
    pub iou2d: f64,
    /// The same for the ground-truth ellipsoids (inscribed in the labels' 3-D boxes) of all the static
    /// vehicles, found or not: what the metric gives the truth.
    pub iou2d_truth: f64,
    /// Mean box IoU2D over the found ones (each estimate's own 3-D box projected).
    pub box_iou2d: f64,
    /// The same for the ground-truth ellipsoids of all the static vehicles.
    pub box_iou2d_truth: f64,
    /// Mean centre error, metres.
    pub e_trans: f64,
    /// Mean semi-axis error, metres.
    pub e_axe: f64,
    /// Mean yaw error, degrees.
    pub e_yaw: f64,
    /// Share of the found ones with e_yaw within `yaw_within_deg`.
    pub yaw_within: f64,
}

/// The whole score of a run.
#[derive(Debug, Clone, Serialize)]
pub struct RunScore {
    /// Format version of the JSON.
    pub version: u32,
    /// Settings used.
    pub config: ScoreConfig,
    /// Frames of the run (labels of later frames are ignored).
    pub frames: usize,
    /// The census.
    pub census: Census,
    /// Vehicle figures.
    pub vehicles: VehicleFigures,
    /// Per object.
    pub objects: Vec<ObjectScore>,
    /// Per label track (DontCare excluded).
    pub tracks: Vec<TrackScore>,
    /// How the run's association followed the label tracks, when its per-frame boxes and their
    /// tracks are known ([`association_score`]; a run folder scored again has no boxes).
    pub association: Option<AssociationScore>,
}

/// Least IoU of a detection box with a label box for the box to be that label's (the usual detection
/// threshold).
pub const ASSOCIATION_IOU: f64 = 0.5;

/// How the association followed the labelled objects: the detection boxes that match a label box
/// (IoU ≥ [`ASSOCIATION_IOU`], one to one, best first) and the track each box was given. One physical
/// object should be one track: a label's boxes on several tracks are fragments (the track was lost and
/// restarted, or its boxes went elsewhere), and a track holding boxes of two labels mixes objects.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct AssociationScore {
    /// Detection boxes matched to a label box.
    pub boxes: usize,
    /// Label tracks with at least one matched box.
    pub label_tracks: usize,
    /// Mean number of tracks per label track (1 is one track per object).
    pub tracks_per_label: f64,
    /// Changes of track between consecutive matched boxes of one label track.
    pub switches: usize,
    /// Tracks holding matched boxes of two or more label tracks.
    pub mixed_tracks: usize,
    /// Per label track: its id and the tracks of its boxes (ascending).
    pub per_label: Vec<(i64, Vec<u64>)>,
}

/// One played frame's association: its frame id, and each detection box with the track the association
/// gave it (`None`: none).
pub type FrameBoxes = (usize, Vec<(BBox, Option<u64>)>);

/// [`AssociationScore`] of a run from its frames' boxes ([`FrameBoxes`]).
pub fn association_score(labels: &[TrackingLabel], geometry: &LabelGeometry, boxes: &[FrameBoxes]) -> AssociationScore {
    let mut by_frame: BTreeMap<usize, Vec<(i64, BBox)>> = BTreeMap::new();
    for l in labels.iter().filter(|l| !l.is_dont_care() && l.track_id >= 0) {
        if let Some(b) = geometry.label_box(l) {
            by_frame.entry(l.frame).or_default().push((l.track_id, b));
        }
    }
    // per label track, its matched boxes' tracks in frame order
    let mut seen: BTreeMap<i64, Vec<u64>> = BTreeMap::new();
    let mut matched = 0;
    for (frame, dets) in boxes {
        let Some(truth) = by_frame.get(frame) else { continue };
        let label_boxes: Vec<BBox> = truth.iter().map(|t| t.1).collect();
        let det_boxes: Vec<BBox> = dets.iter().map(|d| d.0).collect();
        for (j, i) in crate::recall::matched_pairs(&label_boxes, &det_boxes, |iou| iou >= ASSOCIATION_IOU) {
            matched += 1;
            if let Some(track) = dets[i].1 {
                seen.entry(truth[j].0).or_default().push(track);
            }
        }
    }
    let switches = seen.values().map(|v| v.windows(2).filter(|w| w[0] != w[1]).count()).sum();
    let mut holders: BTreeMap<u64, std::collections::BTreeSet<i64>> = BTreeMap::new();
    let per_label: Vec<(i64, Vec<u64>)> = seen
        .iter()
        .map(|(&label, v)| {
            let mut tracks = v.clone();
            tracks.sort_unstable();
            tracks.dedup();
            for &t in &tracks {
                holders.entry(t).or_default().insert(label);
            }
            (label, tracks)
        })
        .collect();
    let n = per_label.len();
    AssociationScore {
        boxes: matched,
        label_tracks: n,
        tracks_per_label: per_label.iter().map(|(_, t)| t.len()).sum::<usize>() as f64 / n.max(1) as f64,
        switches,
        mixed_tracks: holders.values().filter(|l| l.len() >= 2).count(),
        per_label,
    }
}

/// The label tracks inside the run, with their world centres.
struct Track<'a> {
    labels: Vec<&'a TrackingLabel>,
    spread: f64,
    mean: Vector3<f64>,
}

/// The rotation of a label box in the run's world at the frame of `l`.
fn label_ellipsoid(l: &TrackingLabel, pose: &Isometry3<f64>, centre: Vector3<f64>) -> Ellipsoid {
    let [h, w, len] = l.dimensions;
    let rot = pose.rotation * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), l.rotation_y);
    Ellipsoid::new(Isometry3::from_parts(Translation3::from(centre), rot), Vector3::new(len / 2.0, h / 2.0, w / 2.0))
}

/// The labels inside the run: each played frame's pose, the label tracks with their world centres, the
/// label boxes and the DontCare regions of each frame.
struct LabelScene<'a> {
    pose_of: BTreeMap<usize, Isometry3<f64>>,
    tracks: BTreeMap<i64, Track<'a>>,
    dont_care: BTreeMap<usize, Vec<BBox>>,
    boxes: BTreeMap<usize, Vec<(i64, BBox)>>,
}

impl<'a> LabelScene<'a> {
    fn new(
        labels: &'a [TrackingLabel],
        poses: &[Isometry3<f64>],
        frame_ids: &[usize],
        geometry: &LabelGeometry,
    ) -> Self {
        let pose_of: BTreeMap<usize, Isometry3<f64>> = frame_ids.iter().copied().zip(poses.iter().copied()).collect();
        let mut by_track: BTreeMap<i64, Vec<&TrackingLabel>> = BTreeMap::new();
        let mut dont_care: BTreeMap<usize, Vec<BBox>> = BTreeMap::new();
        let mut boxes: BTreeMap<usize, Vec<(i64, BBox)>> = BTreeMap::new();
        for l in labels.iter().filter(|l| pose_of.contains_key(&l.frame)) {
            if l.is_dont_care() {
                if let Some(b) = geometry.label_box(l) {
                    dont_care.entry(l.frame).or_default().push(b);
                }
                continue;
            }
            if l.track_id < 0 {
                continue;
            }
            by_track.entry(l.track_id).or_default().push(l);
            if let Some(b) = geometry.label_box(l) {
                boxes.entry(l.frame).or_default().push((l.track_id, b));
            }
        }
        let tracks: BTreeMap<i64, Track> = by_track
            .into_iter()
            .map(|(id, labels)| {
                let centres: Vec<Vector3<f64>> =
                    labels.iter().map(|l| LabelGeometry::to_world(&pose_of[&l.frame], &geometry.centre(l))).collect();
                let mean = centres.iter().sum::<Vector3<f64>>() / centres.len() as f64;
                let spread = centres.iter().map(|c| (c - mean).norm()).fold(0.0, f64::max);
                (id, Track { labels, spread, mean })
            })
            .collect();
        Self { pose_of, tracks, dont_care, boxes }
    }

    fn is_moving(&self, track: i64, config: &ScoreConfig) -> bool {
        self.tracks.get(&track).is_some_and(|t| t.spread > config.moving_m)
    }
}

/// What the frames of an object's detections say it is.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Vote {
    Track(i64),
    DontCare,
    Nothing,
}

/// (object index, majority vote with its count, frames scored)
type Voted = (usize, Option<(Vote, usize)>, usize);

/// The best static object of each track: its (votes, reversed id, object index); the most votes win,
/// then the lower id.
type BestOf = BTreeMap<i64, (usize, std::cmp::Reverse<u64>, usize)>;

/// Each object projected into the frames of its detections votes there for the label box it overlaps
/// most, else DontCare, else nothing; the majority decides (ties: a label track, the lower id, then
/// DontCare).
fn vote_objects(
    scene: &LabelScene,
    objects: &[ScoredInput],
    geometry: &LabelGeometry,
    config: &ScoreConfig,
) -> Vec<Voted> {
    let (k, image) = (geometry.intrinsics(), geometry.image());
    let mut voted: Vec<Voted> = Vec::new();
    for (oi, o) in objects.iter().enumerate() {
        let mut votes: BTreeMap<Vote, usize> = BTreeMap::new();
        let mut scored = 0;
        for (&f, pose) in o.frames.iter().filter_map(|f| Some((f, scene.pose_of.get(f)?))) {
            let cam = Camera::new(k, *pose);
            let Some(b) = project(&o.ellipsoid, &cam).ok().and_then(|c| c.clipped_bounds(&image).ok()) else {
                continue;
            };
            scored += 1;
            let best = scene
                .boxes
                .get(&f)
                .into_iter()
                .flatten()
                .map(|(t, lb)| (b.iou(lb), *t))
                .filter(|(iou, _)| *iou >= config.match_iou)
                .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
            let vote = if let Some((_, t)) = best {
                Vote::Track(t)
            } else if scene
                .dont_care
                .get(&f)
                .into_iter()
                .flatten()
                .any(|d| b.intersection(d).map_or(0.0, |i| i.area()) >= config.dont_care_cover * b.area().max(1e-9))
            {
                Vote::DontCare
            } else {
                Vote::Nothing
            };
            *votes.entry(vote).or_default() += 1;
        }
        // majority; ties go to a label track (the lower id), then DontCare (the enum's order)
        let majority = votes.into_iter().max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)));
        voted.push((oi, majority, scored));
    }
    voted
}

fn best_static_of(voted: &[Voted], objects: &[ScoredInput]) -> BestOf {
    let mut best_of = BestOf::new();
    for &(oi, m, _) in voted {
        let o = &objects[oi];
        if let (false, Some((Vote::Track(t), v))) = (o.dynamic, m) {
            let key = (v, std::cmp::Reverse(o.id), oi);
            if best_of.get(&t).is_none_or(|b| key > *b) {
                best_of.insert(t, key);
            }
        }
    }
    best_of
}

/// Each object's fate and the census of the map's objects; the dynamic objects on each label track.
fn census_of(
    scene: &LabelScene,
    voted: &[Voted],
    objects: &[ScoredInput],
    best_of: &BestOf,
    config: &ScoreConfig,
) -> (Census, Vec<ObjectScore>, BTreeMap<i64, Vec<u64>>) {
    let mut census = Census::default();
    let mut scores = Vec::new();
    let mut flagged: BTreeMap<i64, Vec<u64>> = BTreeMap::new();
    for &(oi, m, scored) in voted {
        let o = &objects[oi];
        let (fate, track, votes) = match m {
            None => (Fate::Unscored, None, 0),
            Some((Vote::Track(t), v)) if scene.is_moving(t, config) => (Fate::Moving, Some(t), v),
            Some((Vote::Track(t), v)) if !o.dynamic && best_of.get(&t).is_some_and(|b| b.2 != oi) => {
                (Fate::Duplicate, Some(t), v)
            }
            Some((Vote::Track(t), v)) => (Fate::Matched, Some(t), v),
            Some((Vote::DontCare, v)) => (Fate::DontCare, None, v),
            Some((Vote::Nothing, v)) => (Fate::Nothing, None, v),
        };
        if o.dynamic {
            census.dynamic_objects += 1;
            if fate == Fate::Moving {
                census.dynamic_on_moving += 1;
            }
            if let Some(t) = track {
                flagged.entry(t).or_default().push(o.id);
            }
        } else {
            census.static_objects += 1;
            match fate {
                Fate::Matched => census.matched += 1,
                Fate::Duplicate => census.duplicate += 1,
                Fate::Moving => census.moving += 1,
                Fate::DontCare => census.dont_care += 1,
                Fate::Nothing => {
                    census.nothing += 1;
                    // COCO bicycle (1) and motorcycle (3)
                    if matches!(o.class, 1 | 3) {
                        census.nothing_unlabelled_class += 1;
                    }
                }
                Fate::Unscored => census.unscored += 1,
            }
        }
        scores.push(ObjectScore { id: o.id, class: o.class, dynamic: o.dynamic, fate, track, votes, frames: scored });
    }
    (census, scores, flagged)
}

/// The static labelled vehicles: found or not, and the figures of the best object of each found one
/// beside what the ground-truth ellipsoids score.
fn vehicle_scores(
    scene: &LabelScene,
    objects: &[ScoredInput],
    best_of: &BestOf,
    mut flagged: BTreeMap<i64, Vec<u64>>,
    geometry: &LabelGeometry,
    config: &ScoreConfig,
) -> (VehicleFigures, Vec<TrackScore>) {
    let mut figures = VehicleFigures::default();
    let mut sums = VehicleSums::default();
    let mut track_scores = Vec::new();
    for (&id, t) in &scene.tracks {
        let mut ts = track_score(scene, objects, best_of, &mut flagged, config, id, t);
        if ts.vehicle {
            figures.vehicles += 1;
            let found = best_of.get(&id).map(|b| &objects[b.2].ellipsoid);
            let (iou_truth, box_truth, matched) = vehicle_figures(scene, t, found, geometry);
            // what the metrics give the truth itself, found or not
            sums.iou_truth += iou_truth;
            sums.box_truth += box_truth;
            if let Some(m) = matched {
                sums.box_iou += m.box_iou;
                figures.found += 1;
                sums.iou += m.iou;
                sums.e_trans += m.e_trans;
                sums.e_axe += m.e_axe;
                sums.e_yaw += m.e_yaw;
                sums.within += usize::from(m.e_yaw <= config.yaw_within_deg);
                (ts.iou2d, ts.box_iou2d, ts.e_trans, ts.e_axe, ts.e_yaw) =
                    (Some(m.iou), Some(m.box_iou), Some(m.e_trans), Some(m.e_axe), Some(m.e_yaw));
            }
        }
        track_scores.push(ts);
    }
    mean_figures(&mut figures, &sums);
    (figures, track_scores)
}

/// Running sums over the static vehicles: the found ones' figures, and the ground truth's IoUs over all.
#[derive(Default)]
struct VehicleSums {
    iou: f64,
    box_iou: f64,
    e_trans: f64,
    e_axe: f64,
    e_yaw: f64,
    within: usize,
    iou_truth: f64,
    box_truth: f64,
}

/// The figures of a found vehicle's best object.
struct Matched {
    iou: f64,
    box_iou: f64,
    e_trans: f64,
    e_axe: f64,
    e_yaw: f64,
}

/// A label track's score without a match's figures: kind, motion, vehicle or not, its objects.
fn track_score(
    scene: &LabelScene,
    objects: &[ScoredInput],
    best_of: &BestOf,
    flagged: &mut BTreeMap<i64, Vec<u64>>,
    config: &ScoreConfig,
    id: i64,
    t: &Track,
) -> TrackScore {
    let kind = t.labels[0].kind.clone();
    let motion = if t.spread <= config.static_m {
        "static"
    } else if t.spread > config.moving_m {
        "moving"
    } else {
        "unclear"
    };
    let vehicle = (kind == "Car" || kind == "Van") && motion == "static" && t.labels.len() >= config.min_frames;
    let object = best_of.get(&id).filter(|_| !scene.is_moving(id, config)).map(|b| objects[b.2].id);
    TrackScore {
        track: id,
        kind,
        frames: t.labels.len(),
        spread_m: t.spread,
        motion,
        vehicle,
        object,
        flagged: flagged.remove(&id).unwrap_or_default(),
        iou2d: None,
        box_iou2d: None,
        e_trans: None,
        e_axe: None,
        e_yaw: None,
    }
}

/// A static vehicle's figures: its ground truth's two IoUs, and the found object's IoUs and errors.
fn vehicle_figures(
    scene: &LabelScene,
    t: &Track,
    found: Option<&Ellipsoid>,
    geometry: &LabelGeometry,
) -> (f64, f64, Option<Matched>) {
    let (k, image) = (geometry.intrinsics(), geometry.image());
    let pose_of = &scene.pose_of;
    let l0 = t.labels[0];
    let truth = label_ellipsoid(l0, &pose_of[&l0.frame], t.mean);
    // the mean over the labelled frames of an IoU of `of`'s box with the label box
    let mean_iou = |of: &Ellipsoid, iou: fn(&Ellipsoid, &Camera, &ImageSize, &BBox) -> f64| {
        let v: Vec<f64> = t
            .labels
            .iter()
            .filter_map(|l| Some(iou(of, &Camera::new(k, pose_of[&l.frame]), &image, &geometry.label_box(l)?)))
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    let iou_truth = mean_iou(&truth, metrics::projected_iou);
    let box_truth = mean_iou(&truth, metrics::box_iou);
    let matched = found.map(|e| {
        let iou = mean_iou(e, metrics::projected_iou);
        let box_iou = mean_iou(e, metrics::box_iou);
        let up = pose_of[&l0.frame].rotation * Vector3::y();
        let (e_trans, e_axe, e_yaw) =
            (metrics::e_trans(e, &truth), metrics::e_axe(e, &truth), metrics::e_yaw(e, &truth, &up));
        Matched { iou, box_iou, e_trans, e_axe, e_yaw }
    });
    (iou_truth, box_truth, matched)
}

/// The vehicle figures from the sums: success and the means (NaN where there is nothing to average).
fn mean_figures(figures: &mut VehicleFigures, sums: &VehicleSums) {
    let f = figures.found.max(1) as f64;
    figures.success = if figures.vehicles > 0 { figures.found as f64 / figures.vehicles as f64 } else { f64::NAN };
    if figures.found > 0 {
        (figures.iou2d, figures.e_trans, figures.e_axe, figures.e_yaw, figures.yaw_within) =
            (sums.iou / f, sums.e_trans / f, sums.e_axe / f, sums.e_yaw / f, sums.within as f64 / f);
        figures.box_iou2d = sums.box_iou / f;
    } else {
        (figures.iou2d, figures.e_trans, figures.e_axe, figures.e_yaw, figures.yaw_within) =
            (f64::NAN, f64::NAN, f64::NAN, f64::NAN, f64::NAN);
        figures.box_iou2d = f64::NAN;
    }
    if figures.vehicles > 0 {
        let n = figures.vehicles as f64;
        (figures.iou2d_truth, figures.box_iou2d_truth) = (sums.iou_truth / n, sums.box_truth / n);
    } else {
        (figures.iou2d_truth, figures.box_iou2d_truth) = (f64::NAN, f64::NAN);
    }
}

/// Score a run's objects. `poses`: world from the run's camera, one per played frame; `frame_ids`: the
/// sequence's frame id of each (a run with `--frames 20..60` starts at id 20), the ids that labels and
/// the objects' `frames` use. Labels of frames the run did not play are ignored.
pub fn score_run(
    labels: &[TrackingLabel],
    poses: &[Isometry3<f64>],
    frame_ids: &[usize],
    geometry: &LabelGeometry,
    objects: &[ScoredInput],
    config: &ScoreConfig,
) -> RunScore {
    let scene = LabelScene::new(labels, poses, frame_ids, geometry);
    let voted = vote_objects(&scene, objects, geometry, config);
    let best_of = best_static_of(&voted, objects);
    let (census, scores, flagged) = census_of(&scene, &voted, objects, &best_of, config);
    let (vehicles, tracks) = vehicle_scores(&scene, objects, &best_of, flagged, geometry, config);
    RunScore {
        version: 1,
        config: *config,
        frames: poses.len(),
        census,
        vehicles,
        objects: scores,
        tracks,
        association: None,
    }
}

/// A figure with `digits` decimals and its unit, or "–" when it is not finite.
fn fig(x: f64, digits: usize, unit: &str) -> String {
    // a figure over no vehicle is no figure: "–", not NaN (its unit goes with the number)
    if x.is_finite() {
        format!("{x:.digits$}{unit}")
    } else {
        "–".to_string()
    }
}

/// The report's census line: what the static map objects matched, and the objects flagged dynamic.
fn census_line(c: &Census) -> String {
    format!(
        "static map objects {}: matched {}, duplicate {}, moving object mapped as static {}, in a DontCare \
         region {}, matching nothing {}{}{}; objects flagged dynamic (with an ellipsoid) {}, {} of them on a \
         moving label (an object found moving before its first fit has no ellipsoid and is not counted)\n",
        c.static_objects,
        c.matched,
        c.duplicate,
        c.moving,
        c.dont_care,
        c.nothing,
        if c.nothing_unlabelled_class > 0 {
            format!(
                " ({} of them bicycles or motorcycles, which KITTI labels only with a rider)",
                c.nothing_unlabelled_class
            )
        } else {
            String::new()
        },
        if c.unscored > 0 { format!(", never in view {}", c.unscored) } else { String::new() },
        c.dynamic_objects,
        c.dynamic_on_moving
    )
}

/// The report's line of a label track (a static vehicle or a moving track): what it was mapped as.
fn track_line(t: &TrackScore) -> String {
    format!(
        "  label {:>3} {:<10} {:>3} frames, spread {:5.2} m ({}): {}\n",
        t.track,
        t.kind,
        t.frames,
        t.spread_m,
        t.motion,
        match (t.object, t.e_trans) {
            (Some(o), Some(e)) => format!(
                "object {o}, e_trans {e:.2} m, e_axe {:.2} m, e_yaw {:.1} deg, IoU2D {:.2}, box IoU2D {:.2}",
                t.e_axe.unwrap_or(f64::NAN),
                t.e_yaw.unwrap_or(f64::NAN),
                t.iou2d.unwrap_or(f64::NAN),
                t.box_iou2d.unwrap_or(f64::NAN)
            ),
            (Some(o), None) => format!("mapped as static object {o}"),
            (None, _) if !t.flagged.is_empty() => format!("flagged dynamic {:?}", t.flagged),
            (None, _) => "not mapped".into(),
        }
    )
}

impl RunScore {
    /// The figures as text (several lines).
    pub fn report(&self) -> String {
        let mut s = self.vehicles_line();
        s.push_str(&census_line(&self.census));
        if let Some(a) = &self.association {
            s.push_str(&format!(
                "association vs labels: {} detection boxes on {} label tracks (IoU ≥ {ASSOCIATION_IOU}); {:.2} tracks \
                 per label track (1: one track per object), {} track switches, {} tracks holding two or more \
                 label tracks\n",
                a.boxes, a.label_tracks, a.tracks_per_label, a.switches, a.mixed_tracks
            ));
        }
        let tracks_of = |label: i64| {
            self.association
                .as_ref()
                .and_then(|a| a.per_label.iter().find(|(l, _)| *l == label))
                .map_or(String::new(), |(_, t)| format!("; its boxes on tracks {t:?}"))
        };
        for t in self.tracks.iter().filter(|t| t.vehicle || t.motion == "moving") {
            s.push_str(&track_line(t));
            // the track list goes on the line just written
            if s.ends_with('\n') {
                s.pop();
                s.push_str(&tracks_of(t.track));
                s.push('\n');
            }
        }
        s
    }

    /// The report's first line: the static labelled vehicles, how many were found and their figures.
    fn vehicles_line(&self) -> String {
        let v = &self.vehicles;
        if v.vehicles == 0 {
            format!(
                "objects vs labels ({} frames): static labelled vehicles 0 (no Car or Van track of at least {} \
                 labelled frames stays within {} m under this run's poses), so no success, IoU2D or errors; \
                 labels of another sequence also look like this\n",
                self.frames, self.config.min_frames, self.config.static_m
            )
        } else {
            format!(
                "objects vs labels ({} frames): static labelled vehicles {}, found {} (success {}); IoU2D {} (the \
                 ground truth's {}), box IoU2D {} (the ground truth's {}), e_trans {}, e_axe {}, e_yaw {}, within \
                 {:.0} deg {}\n",
                self.frames,
                v.vehicles,
                v.found,
                fig(v.success, 3, ""),
                fig(v.iou2d, 3, ""),
                fig(v.iou2d_truth, 3, ""),
                fig(v.box_iou2d, 3, ""),
                fig(v.box_iou2d_truth, 3, ""),
                fig(v.e_trans, 3, " m"),
                fig(v.e_axe, 3, " m"),
                fig(v.e_yaw, 1, " deg"),
                self.config.yaw_within_deg,
                fig(100.0 * v.yaw_within, 0, " %")
            )
        }
    }

    /// Write as JSON.
    pub fn write_json(&self, path: &std::path::Path) -> Result<(), crate::EvalError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| crate::EvalError::Invalid(e.to_string()))?;
        Ok(slam_core::files::write_atomic(path, text.as_bytes())?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::{geometry::BBox, ClassId};

    const G: LabelGeometry = LabelGeometry {
        fx: 720.0,
        fy: 720.0,
        cx: 620.0,
        cy: 180.0,
        width: 1242.0,
        height: 375.0,
        label_offset: [0.0; 3],
        colour: false,
    };

    /// A label of a 4 × 1.5 × 1.6 m car whose bottom centre is at `p` in the camera of `frame`, heading
    /// along the camera's z axis.
    fn car(frame: usize, track: i64, p: Vector3<f64>) -> TrackingLabel {
        TrackingLabel {
            frame,
            track_id: track,
            kind: "Car".into(),
            class: Some(ClassId(2)),
            truncated: 0.0,
            occluded: 0,
            bbox: BBox::new(0.0, 0.0, 1.0, 1.0),
            dimensions: [1.5, 1.6, 4.0],
            location: [p.x, p.y, p.z],
            rotation_y: -std::f64::consts::FRAC_PI_2,
            line: 0,
        }
    }

    fn ellipsoid(centre: Vector3<f64>, yaw: f64) -> Ellipsoid {
        Ellipsoid::new(
            Isometry3::from_parts(Translation3::from(centre), UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw)),
            Vector3::new(2.0, 0.75, 0.8),
        )
    }

    #[test]
    fn census_and_vehicle_figures_of_a_scripted_scene() {
        scripted_scene(0);
    }

    /// A run that starts at frame id 20 (`--frames 20..32`): poses are matched to labels and
    /// detections by frame id, not by position, so the figures are those of the run from 0.
    #[test]
    fn a_run_not_starting_at_frame_0_is_scored_by_frame_id() {
        scripted_scene(20);
    }

    /// Two cars over 6 frames. Car 1's boxes go to track 10, then (frames 3-5) to track 11: 2 tracks,
    /// 1 switch. Car 2's boxes go to track 11 in frames 0-2: track 11 holds both cars (mixed). A box
    /// that overlaps no label (a false detection) and one below the IoU threshold count nowhere.
    #[test]
    fn association_score_counts_fragments_switches_and_mixed_tracks() {
        let mut labels = Vec::new();
        let mut boxes = Vec::new();
        for f in 0..6 {
            let (a, b) = (car(f, 1, Vector3::new(4.0, 1.6, 20.0)), car(f, 2, Vector3::new(-4.0, 1.6, 25.0)));
            let (ba, bb) = (G.label_box(&a).expect("in view"), G.label_box(&b).expect("in view"));
            let mut dets = vec![(ba, Some(if f < 3 { 10 } else { 11 })), (BBox::new(0.0, 0.0, 30.0, 30.0), Some(99))];
            if f < 3 {
                dets.push((bb, Some(11)));
            } else {
                // a box of car 2 shifted by its own width: IoU 0 with the label
                dets.push((BBox::new(bb.xmax, bb.ymin, 2.0 * bb.xmax - bb.xmin, bb.ymax), Some(12)));
            }
            boxes.push((f, dets));
            labels.extend([a, b]);
        }
        let a = association_score(&labels, &G, &boxes);
        assert_eq!((a.boxes, a.label_tracks, a.switches, a.mixed_tracks), (9, 2, 1, 1), "{a:?}");
        assert_eq!(a.per_label, vec![(1, vec![10, 11]), (2, vec![11])]);
        assert!((a.tracks_per_label - 1.5).abs() < 1e-12);
    }

    /// Labels with no static vehicle (one car driving ahead at the camera's speed: what labels of
    /// another drive also look like under a run's poses): the report says so, and prints no NaN.
    #[test]
    fn a_run_without_a_static_labelled_vehicle_says_so() {
        let poses: Vec<Isometry3<f64>> = (0..12).map(|i| Isometry3::translation(0.0, 0.0, i as f64)).collect();
        let ids: Vec<usize> = (0..12).collect();
        let labels: Vec<TrackingLabel> = ids.iter().map(|&f| car(f, 2, Vector3::new(-3.0, 1.6, 15.0))).collect();
        let score = score_run(&labels, &poses, &ids, &G, &[], &ScoreConfig::default());
        assert_eq!(score.vehicles.vehicles, 0);
        let text = score.report();
        assert!(text.contains("static labelled vehicles 0 (no Car or Van track of at least 10"), "{text}");
        assert!(!text.contains("NaN"), "{text}");
    }

    /// The scripted scene with every frame id shifted by `first`, plus labels of frames before and
    /// after the run (which must be ignored).
    fn scripted_scene(first: usize) {
        // the camera drives 1 m per frame along z for 12 frames
        let poses: Vec<Isometry3<f64>> = (0..12).map(|i| Isometry3::translation(0.0, 0.0, i as f64)).collect();
        let ids: Vec<usize> = (first..first + 12).collect();
        let mut labels = Vec::new();
        if first > 0 {
            // a car that the run never saw, labelled before its first frame
            labels.push(car(first - 1, 8, Vector3::new(0.0, 1.6, 10.0)));
        }
        labels.push(car(first + 12, 8, Vector3::new(0.0, 1.6, 10.0)));
        for f in 0..12 {
            let z = f as f64;
            let f = f + first;
            labels.push(car(f, 1, Vector3::new(4.0, 1.6, 25.0 - z))); // parked at world (4, 0.85, 25)
            labels.push(car(f, 2, Vector3::new(-3.0, 1.6, 15.0))); // driving ahead at the camera's speed
            let mut dc = car(f, -1, Vector3::zeros());
            dc.kind = "DontCare".into();
            dc.class = None;
            dc.bbox = BBox::new(100.0, 150.0, 300.0, 250.0);
            labels.push(dc);
        }
        let frames: Vec<usize> = ids.clone();
        let heading = -std::f64::consts::FRAC_PI_2;
        let parked = Vector3::new(4.0, 0.85, 25.0);
        // the DontCare region's ray at 30 m: pixel (200, 200)
        let in_dont_care = Vector3::new((200.0 - 620.0) / 720.0 * 30.0, (200.0 - 180.0) / 720.0 * 30.0, 30.0);
        let objects = vec![
            // the parked car, 0.5 m off and turned by 10°
            ScoredInput {
                id: 7,
                class: 2,
                ellipsoid: ellipsoid(parked + Vector3::new(0.5, 0.0, 0.0), heading + 10f64.to_radians()),
                frames: frames.clone(),
                dynamic: false,
            },
            // the same car again, 0.8 m off: a duplicate
            ScoredInput {
                id: 9,
                class: 2,
                ellipsoid: ellipsoid(parked + Vector3::new(0.0, 0.0, 0.8), heading),
                frames: frames[..6].to_vec(),
                dynamic: false,
            },
            // the car ahead mapped as static where it was in the middle of the drive
            ScoredInput {
                id: 3,
                class: 2,
                ellipsoid: ellipsoid(Vector3::new(-3.0, 0.85, 21.0), heading),
                frames: (first + 4..first + 8).collect(),
                dynamic: false,
            },
            // the car ahead, flagged dynamic
            ScoredInput {
                id: 4,
                class: 2,
                ellipsoid: ellipsoid(Vector3::new(-3.0, 0.85, 18.0), heading),
                frames: (first + 2..first + 5).collect(),
                dynamic: true,
            },
            ScoredInput {
                id: 5,
                class: 2,
                ellipsoid: Ellipsoid::new(
                    Isometry3::translation(in_dont_care.x, in_dont_care.y, in_dont_care.z),
                    Vector3::new(1.0, 0.8, 1.0),
                ),
                frames: vec![first],
                dynamic: false,
            },
            // junk on the road, far from any label
            ScoredInput {
                id: 6,
                class: 2,
                ellipsoid: ellipsoid(Vector3::new(0.0, 1.0, 40.0), 0.0),
                frames: vec![first, first + 1],
                dynamic: false,
            },
            // a parked bicycle: no label can match it (KITTI labels a bicycle only with its rider)
            ScoredInput {
                id: 10,
                class: 1,
                ellipsoid: Ellipsoid::new(Isometry3::translation(-3.0, 1.2, 30.0), Vector3::new(0.9, 0.5, 0.3)),
                frames: vec![first, first + 1],
                dynamic: false,
            },
        ];
        let s = score_run(&labels, &poses, &ids, &G, &objects, &ScoreConfig::default());
        assert!(s.tracks.iter().all(|t| t.track != 8), "a track outside the run's frames was scored");
        let c = s.census;
        assert_eq!(
            (c.static_objects, c.matched, c.duplicate, c.moving, c.dont_care, c.nothing, c.nothing_unlabelled_class),
            (6, 1, 1, 1, 1, 2, 1),
            "{}",
            s.report()
        );
        assert!(s.report().contains("matching nothing 2 (1 of them bicycles or motorcycles"), "{}", s.report());
        assert_eq!((c.dynamic_objects, c.dynamic_on_moving), (1, 1));
        let fate = |id: u64| s.objects.iter().find(|o| o.id == id).map(|o| o.fate);
        assert_eq!(fate(7), Some(Fate::Matched));
        assert_eq!(fate(9), Some(Fate::Duplicate));
        assert_eq!(fate(3), Some(Fate::Moving));
        assert_eq!(fate(5), Some(Fate::DontCare));
        assert_eq!(fate(6), Some(Fate::Nothing));
        // one static vehicle (track 1), found by object 7
        let v = s.vehicles;
        assert_eq!((v.vehicles, v.found), (1, 1));
        assert!((v.e_trans - 0.5).abs() < 1e-9, "{}", v.e_trans);
        assert!((v.e_yaw - 10.0).abs() < 1e-6, "{}", v.e_yaw);
        assert_eq!(v.yaw_within, 1.0);
        assert!(v.e_axe < 0.1 && v.iou2d > 0.3, "{v:?}");
        // on the grey camera a label's box is its 3-D box projected: the ground truth's own 3-D box scores 1
        // on the box IoU2D, its ellipse less on the paper's; the estimate (0.5 m off, turned 10°) less on both
        assert!((v.box_iou2d_truth - 1.0).abs() < 1e-9 && v.iou2d_truth < 0.9, "{v:?}");
        assert!(v.box_iou2d < v.box_iou2d_truth && v.box_iou2d > 0.3, "{v:?}");
        assert!(s.report().contains("IoU2D ") && s.report().contains("(the ground truth's 1.000)"), "{}", s.report());
        let moving = s.tracks.iter().find(|t| t.track == 2).expect("track 2");
        assert_eq!((moving.motion, moving.flagged.as_slice()), ("moving", &[4u64][..]));
        // the JSON carries the same figures
        let json = serde_json::to_value(&s).expect("serialises");
        assert_eq!(json["census"]["duplicate"], 1);
        assert_eq!(json["objects"][0]["fate"], "matched");
    }
}
