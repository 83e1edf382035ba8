//! The image-free object study on KITTI tracking sequences (`slam-app objects` and `slam-app eval` on a
//! folder of sequences): label boxes, optionally perturbed, play the detector; the given poses play the
//! tracker; the object mapper associates (track ids are not used), initialises and optimises ellipsoids;
//! the result is scored with the paper's metrics against the static Car/Van label tracks.
//!
//! Ground truth: a Car/Van track of at least `min_frames` labelled frames whose world centre stays within
//! `static_m` of its mean is a static vehicle; its ellipsoid is inscribed in the mean labelled 3-D box. A
//! track whose centre moves more than `moving_m` is a moving vehicle (the dynamic-object check).

use std::{
    collections::{BTreeMap, BTreeSet},
    path::Path,
};

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use slam_core::{
    figure::{cell, csv, mean, share},
    geometry::BBox,
    rng::SimRng,
    Detection,
};
use slam_dataset::{
    classes,
    kitti::{calib::Calib, tracking::read_tracking_labels, tracking::TrackingLabel},
};
use slam_pipeline::objects::{MappedObject, ObjectMapper};
use slam_quadric::{metrics, Camera, Ellipsoid, ImageSize, Intrinsics};

use crate::EvalError;

/// A KITTI tracking sequence without images: its labels, the left colour camera's poses (camera to
/// world, one per frame), its intrinsics and the offset from the rectified camera 0 to camera 2.
pub struct LabelledSequence {
    /// The label lines.
    pub labels: Vec<TrackingLabel>,
    /// Camera-to-world poses of the left colour camera, one per frame.
    pub poses: Vec<Isometry3<f64>>,
    /// The colour camera's intrinsics (from P2).
    pub k: Intrinsics,
    /// Camera 2's centre in rectified camera 0 coordinates, negated: `K⁻¹ · P2[:, 3]`.
    pub t2: Vector3<f64>,
}

/// The files of an image-free sequence folder: labels, poses, calibration.
pub const SEQUENCE_FILES: [&str; 3] = ["label_02.txt", "poses_orbslam3.txt", "calib.txt"];

impl LabelledSequence {
    /// Read the labels (`label_02.txt` format), the poses (KITTI format) and the calibration (with P2);
    /// refuses fewer poses than labelled frames.
    pub fn load(labels: &Path, poses: &Path, calib: &Path) -> Result<Self, EvalError> {
        let (label_path, pose_path, calib_path) = (labels, poses, calib);
        let labels = read_tracking_labels(label_path)?;
        let poses = slam_dataset::kitti::poses::read_ground_truth_poses(pose_path)?;
        let calib = Calib::read(calib_path)?;
        let p2 = calib.matrix3x4("P2")?;
        let k = Intrinsics { fx: p2[(0, 0)], fy: p2[(1, 1)], skew: p2[(0, 1)], cx: p2[(0, 2)], cy: p2[(1, 2)] };
        if !(k.fx > 0.0 && k.fy > 0.0) {
            return Err(EvalError::Invalid(format!(
                "{}: P2's focal lengths are {} and {} px: both must be positive",
                calib_path.display(),
                k.fx,
                k.fy
            )));
        }
        check_tracking_calibration(calib_path, &calib, &p2)?;
        let kinv = p2.fixed_view::<3, 3>(0, 0).into_owned().try_inverse().ok_or_else(|| {
            EvalError::Invalid(format!("{}: the camera matrix of P2 is singular", calib_path.display()))
        })?;
        let t2 = kinv * p2.column(3).into_owned();
        let source = format!("the {} poses of {} (line k is frame k)", poses.len(), pose_path.display());
        slam_dataset::kitti::tracking::check_label_frames(label_path, &labels, poses.len(), &source)?;
        Ok(Self { labels, poses, k, t2 })
    }

    /// [`LabelledSequence::load`] of a sequence folder's `label_02.txt`, `poses_orbslam3.txt` and
    /// `calib.txt`.
    pub fn load_dir(dir: &Path) -> Result<Self, EvalError> {
        let [labels, poses, calib] = SEQUENCE_FILES.map(|f| dir.join(f));
        Self::load(&labels, &poses, &calib)
    }
}

/// Size of KITTI tracking's colour images (1242 × 375 px; a few sequences are a little smaller), which
/// the image-free layout's calibration describes.
pub const TRACKING_IMAGE_SIZE: (u32, u32) = (1242, 375);

/// The rules the odometry layout's calibration is held to, on the image-free tracking layout's: P2 a
/// rectified camera, with P3 a rectified pair, and the intrinsics and baseline plausible for KITTI's
/// colour image ([`slam_dataset::check::calibration`]).
fn check_tracking_calibration(path: &Path, calib: &Calib, p2: &nalgebra::Matrix3x4<f64>) -> Result<(), EvalError> {
    use slam_dataset::kitti::calib::{rectified_camera, rectified_pair};
    let invalid = |m: String| EvalError::Invalid(format!("{}: {m}", path.display()));
    rectified_camera(p2, "P2").map_err(invalid)?;
    let (intrinsics, baseline) = if calib.has("P3") {
        rectified_pair(p2, &calib.matrix3x4("P3")?, ("P2", "P3")).map_err(invalid)?
    } else {
        // one camera: no baseline to check
        ([p2[(0, 0)], p2[(1, 1)], p2[(0, 2)], p2[(1, 2)]], 0.5)
    };
    let image = Path::new("KITTI tracking's colour image");
    slam_dataset::check::calibration(path, intrinsics, baseline, image, TRACKING_IMAGE_SIZE)
        .map_err(|e| EvalError::Invalid(e.to_string()))
}

/// How label boxes are perturbed before they play the detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabelNoise {
    /// σ of each box coordinate as a fraction of the box width / height.
    pub noise: f64,
    /// Probability of dropping a box.
    pub dropout: f64,
    /// Seed of the noise and the dropout (each frame draws from its own stream).
    pub seed: u64,
}

impl Default for LabelNoise {
    /// The label boxes as they are (`slam-app eval`'s defaults: no noise, no dropout, seed 1).
    fn default() -> Self {
        Self { noise: 0.0, dropout: 0.0, seed: 1 }
    }
}

/// Per (frame, detection index), the label track id the detection came from.
pub type DetectionTruth = BTreeMap<(usize, usize), i64>;

/// Feed `mapper` the sequence's (perturbed) label boxes of classified, tracked labels as detections,
/// frame by frame with the given poses; returns it and which track each detection came from.
pub fn run_mapper(
    seq: &LabelledSequence,
    noise: &LabelNoise,
    mut mapper: ObjectMapper,
) -> (ObjectMapper, DetectionTruth) {
    let mut by_frame: BTreeMap<usize, Vec<&TrackingLabel>> = BTreeMap::new();
    for l in &seq.labels {
        if l.class.is_some() && l.track_id >= 0 {
            by_frame.entry(l.frame).or_default().push(l);
        }
    }
    let mut truth = BTreeMap::new();
    for (frame, pose) in seq.poses.iter().enumerate() {
        let mut rng = SimRng::derive(noise.seed, &[frame as u64]);
        let mut dets = Vec::new();
        for l in by_frame.get(&frame).map(|v| v.as_slice()).unwrap_or(&[]) {
            let draws = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
            if rng.unit() < noise.dropout {
                continue;
            }
            let b = l.bbox;
            let (sx, sy) = (noise.noise * b.width(), noise.noise * b.height());
            let nb = BBox::new(
                b.xmin + sx * draws[0],
                b.ymin + sy * draws[1],
                b.xmax + sx * draws[2],
                b.ymax + sy * draws[3],
            );
            let nb = if nb.validated().is_ok() { nb } else { b };
            truth.insert((frame, dets.len()), l.track_id);
            dets.push(Detection::new(l.class.unwrap_or(classes::CAR), 1.0, nb));
        }
        mapper.step(frame, &Camera::new(seq.k, *pose), &dets);
    }
    (mapper, truth)
}

/// Which label tracks count as static and as moving vehicles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleCriteria {
    /// Fewest labelled frames of a ground-truth vehicle.
    pub min_frames: usize,
    /// Largest spread (max distance from its mean) of a static vehicle's world centre, metres.
    pub static_m: f64,
    /// Smallest spread of a moving vehicle's world centre, metres.
    pub moving_m: f64,
}

impl Default for VehicleCriteria {
    /// `slam-app eval`'s defaults: 10 labelled frames; static within 1 m (parked cars move by the poses'
    /// drift only, 0.25-0.4 m RMS per the fixtures' SOURCE.md), moving beyond 3 m.
    fn default() -> Self {
        Self { min_frames: 10, static_m: 1.0, moving_m: 3.0 }
    }
}

/// A ground-truth static vehicle: its ellipsoid (inscribed in the mean labelled 3-D box) and its label
/// boxes per frame.
pub struct GtVehicle {
    /// The ellipsoid inscribed in the mean labelled 3-D box.
    pub ellipsoid: Ellipsoid,
    /// The label boxes per frame.
    pub boxes: BTreeMap<usize, BBox>,
    /// Where the rays from each labelled frame's camera through the label's own 3-D centre meet (least
    /// squares), `None` when they do not (a standing camera).
    pub ray_centre: Option<Vector3<f64>>,
}

/// The label track that supplied most of an object's detections (ties: the lower id), with its count.
pub fn majority_track(o: &MappedObject, truth: &DetectionTruth) -> Option<(i64, usize)> {
    let mut votes: BTreeMap<i64, usize> = BTreeMap::new();
    for obs in &o.observations {
        if let Some(&t) = truth.get(&(obs.frame, obs.detection)) {
            *votes.entry(t).or_default() += 1;
        }
    }
    votes.into_iter().max_by_key(|&(t, n)| (n, -t))
}

/// Least-squares intersection of rays `(origin, direction)`: the point nearest to all of them; `None`
/// when they are (nearly) parallel.
pub fn ray_intersection(rays: &[(Vector3<f64>, Vector3<f64>)]) -> Option<Vector3<f64>> {
    let mut a = nalgebra::Matrix3::zeros();
    let mut b = Vector3::zeros();
    for (o, d) in rays {
        let d = d.try_normalize(1e-12)?;
        let m = nalgebra::Matrix3::identity() - d * d.transpose();
        a += m;
        b += m * o;
    }
    let eig = nalgebra::SymmetricEigen::new(a);
    let (lo, hi) = (eig.eigenvalues.min(), eig.eigenvalues.max());
    (lo > 1e-9 * hi.max(1e-12)).then(|| a.try_inverse().map(|inv| inv * b)).flatten()
}

/// A Car/Van label track: its labels and world centres (bottom-centre origin in rect cam0 → box centre
/// → cam2 → world), their mean and spread (largest distance from the mean).
pub struct VehicleTrack<'a> {
    /// Track id.
    pub id: i64,
    /// Its labels, in frame order.
    pub labels: Vec<&'a TrackingLabel>,
    /// World centre per label.
    pub centres: Vec<Vector3<f64>>,
    /// Mean world centre.
    pub mean: Vector3<f64>,
    /// Largest distance of a centre from the mean, metres.
    pub spread: f64,
}

/// The Car/Van label tracks of at least `min_frames` frames.
pub fn vehicle_tracks(seq: &LabelledSequence, min_frames: usize) -> Vec<VehicleTrack<'_>> {
    let mut tracks: BTreeMap<i64, Vec<&TrackingLabel>> = BTreeMap::new();
    for l in &seq.labels {
        if (l.kind == "Car" || l.kind == "Van") && l.track_id >= 0 {
            tracks.entry(l.track_id).or_default().push(l);
        }
    }
    tracks
        .into_iter()
        .filter(|(_, ls)| ls.len() >= min_frames)
        .map(|(id, labels)| {
            let centres: Vec<Vector3<f64>> = labels
                .iter()
                .map(|l| {
                    let c = Vector3::new(l.location[0], l.location[1] - l.dimensions[0] / 2.0, l.location[2]) + seq.t2;
                    (seq.poses[l.frame] * Point3::from(c)).coords
                })
                .collect();
            let mean = centres.iter().sum::<Vector3<f64>>() / centres.len() as f64;
            let spread = centres.iter().map(|c| (c - mean).norm()).fold(0.0, f64::max);
            VehicleTrack { id, labels, centres, mean, spread }
        })
        .collect()
}

/// The static vehicles (spread at most `static_m`) among the Car/Van tracks of at least `min_frames`
/// frames, by track id.
pub fn gt_vehicles(seq: &LabelledSequence, min_frames: usize, static_m: f64) -> BTreeMap<i64, GtVehicle> {
    let mut out = BTreeMap::new();
    for VehicleTrack { id, labels: ls, centres, mean, spread } in vehicle_tracks(seq, min_frames) {
        if spread > static_m {
            continue;
        }
        let l0 = ls[0];
        let [h, w, len] = l0.dimensions;
        let rot = seq.poses[l0.frame].rotation * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), l0.rotation_y);
        let ellipsoid = Ellipsoid::new(
            Isometry3::from_parts(Translation3::from(mean), rot),
            Vector3::new(len / 2.0, h / 2.0, w / 2.0),
        );
        let rays: Vec<(Vector3<f64>, Vector3<f64>)> = ls
            .iter()
            .zip(&centres)
            .map(|(l, c)| {
                let origin = seq.poses[l.frame].translation.vector;
                (origin, c - origin)
            })
            .collect();
        out.insert(
            id,
            GtVehicle {
                ellipsoid,
                boxes: ls.iter().map(|l| (l.frame, l.bbox)).collect(),
                ray_centre: ray_intersection(&rays),
            },
        );
    }
    out
}

/// The object figures of a sequence (sums over its found vehicles; divide by `found` for means).
#[derive(Debug, Default, Clone, Copy)]
pub struct Row {
    /// Static ground-truth vehicles.
    pub vehicles: usize,
    /// Those an object was matched to.
    pub found: usize,
    /// Sum of the mean IoU2D over each found vehicle's labelled frames.
    pub iou: f64,
    /// Sum of the mean box IoU2D (the estimate's own 3-D box projected, [`metrics::box_iou`]) over each
    /// found vehicle's labelled frames.
    pub box_iou: f64,
    /// Sum of e_trans, metres.
    pub e_trans: f64,
    /// Sum of e_axe, metres.
    pub e_axe: f64,
    /// Sum of the ray-triangulation errors over the found vehicles that have one, and their count.
    pub e_ray: f64,
    /// How many found vehicles have a ray centre.
    pub rays: usize,
    /// Sum over the found vehicles of the IoU2D of the ground-truth ellipsoid itself.
    pub iou_truth: f64,
    /// Sum over the found vehicles of the box IoU2D of the ground-truth ellipsoid itself.
    pub box_iou_truth: f64,
    /// Sum of e_yaw (degrees) over the found vehicles, and how many were within 15 degrees.
    pub e_yaw: f64,
    /// How many found vehicles have e_yaw within 15 degrees.
    pub yaw_within: usize,
}

/// A sequence's result: its figures and what became of its moving vehicles.
#[derive(Debug, Default, Clone, Copy)]
pub struct SequenceScore {
    /// The object figures over its static vehicles.
    pub row: Row,
    /// Moving vehicles: (count, mapped as a static ellipsoid, flagged dynamic only).
    pub moving: (usize, usize, usize),
}

/// Score a finished mapper against the sequence's vehicles: each object votes for the label track that
/// supplied most of its detections; a static vehicle is found when a static object voted for it (the
/// object with most of its boxes wins). `name` labels the debug log lines; `image` is the image size the
/// IoU2D is measured in.
pub fn score_sequence(
    name: &str,
    seq: &LabelledSequence,
    mapper: &ObjectMapper,
    truth: &DetectionTruth,
    criteria: &VehicleCriteria,
    image: &ImageSize,
) -> SequenceScore {
    let gts = gt_vehicles(seq, criteria.min_frames, criteria.static_m);
    let moving = moving_outcomes(name, seq, mapper, truth, criteria);
    let best = static_votes(mapper, truth, &gts);
    let mut row = Row { vehicles: gts.len(), ..Row::default() };
    for (id, gt) in &gts {
        let Some((_, e)) = best.get(id) else {
            log_unfound_vehicle(name, seq, mapper, truth, id, gt);
            continue;
        };
        row.found += 1;
        let yaw = add_found_vehicle(&mut row, seq, image, gt, e);
        log_matched_vehicle(name, seq, id, gt, e, yaw);
    }
    SequenceScore { row, moving }
}

/// What became of the moving vehicles: (count, mapped as a static ellipsoid, flagged dynamic only).
fn moving_outcomes(
    name: &str,
    seq: &LabelledSequence,
    mapper: &ObjectMapper,
    truth: &DetectionTruth,
    criteria: &VehicleCriteria,
) -> (usize, usize, usize) {
    let mut moving = (0usize, 0usize, 0usize);
    let movers: BTreeSet<i64> = vehicle_tracks(seq, criteria.min_frames)
        .into_iter()
        .filter(|t| t.spread > criteria.moving_m)
        .map(|t| t.id)
        .collect();
    // each mover: (flagged dynamic, mapped as static)
    let mut fate: BTreeMap<i64, (bool, bool)> = movers.iter().map(|&t| (t, (false, false))).collect();
    for o in mapper.objects() {
        let Some((t, _)) = majority_track(o, truth) else { continue };
        if let (Some(f), Some(_)) = (fate.get_mut(&t), o.ellipsoid) {
            if o.dynamic {
                f.0 = true;
            } else {
                f.1 = true;
                tracing::debug!(sequence = %name, vehicle = t, object = %o.id, "moving vehicle mapped as static");
            }
        }
    }
    moving.0 += fate.len();
    moving.1 += fate.values().filter(|f| f.1).count();
    moving.2 += fate.values().filter(|f| f.0 && !f.1).count();
    moving
}

/// The best static object (most boxes) of each static vehicle, by each object's majority label track.
fn static_votes(
    mapper: &ObjectMapper,
    truth: &DetectionTruth,
    gts: &BTreeMap<i64, GtVehicle>,
) -> BTreeMap<i64, (usize, Ellipsoid)> {
    let mut best: BTreeMap<i64, (usize, Ellipsoid)> = BTreeMap::new();
    for o in mapper.objects() {
        let (Some(e), false) = (o.ellipsoid, o.dynamic) else { continue };
        if let Some((t, n)) = majority_track(o, truth) {
            if gts.contains_key(&t) && best.get(&t).is_none_or(|b| n > b.0) {
                best.insert(t, (n, e));
            }
        }
    }
    best
}

/// Log why a static vehicle was not found: the objects that took its boxes, and what became of them.
fn log_unfound_vehicle(
    name: &str,
    seq: &LabelledSequence,
    mapper: &ObjectMapper,
    truth: &DetectionTruth,
    id: &i64,
    gt: &GtVehicle,
) {
    let mut took: Vec<String> = Vec::new();
    for o in mapper.objects() {
        let n = o.observations.iter().filter(|obs| truth.get(&(obs.frame, obs.detection)) == Some(id)).count();
        if n > 0 {
            took.push(format!(
                "object {} ({n} of its {} boxes, ellipsoid {}, dynamic {})",
                o.id,
                o.observations.len(),
                o.ellipsoid.is_some(),
                o.dynamic
            ));
        }
    }
    let first = gt.boxes.keys().next().copied().unwrap_or(0);
    let last = gt.boxes.keys().last().copied().unwrap_or(0);
    tracing::debug!(
        sequence = %name,
        vehicle = id,
        frames = gt.boxes.len(),
        travel = (seq.poses[last].translation.vector - seq.poses[first].translation.vector).norm(),
        first_depth = (seq.poses[first].inverse() * Point3::from(gt.ellipsoid.centre())).z,
        "vehicle not found; its boxes went to: {}",
        if took.is_empty() { "no object".to_string() } else { took.join("; ") }
    );
}

/// Add a found vehicle's figures (estimate `e` against its ground truth) to `row`; returns its e_yaw.
fn add_found_vehicle(row: &mut Row, seq: &LabelledSequence, image: &ImageSize, gt: &GtVehicle, e: &Ellipsoid) -> f64 {
    let ious: Vec<f64> =
        gt.boxes.iter().map(|(&f, b)| metrics::projected_iou(e, &Camera::new(seq.k, seq.poses[f]), image, b)).collect();
    row.iou += ious.iter().sum::<f64>() / ious.len().max(1) as f64;
    // the mean over the vehicle's labelled frames of an IoU of `of`'s box with the label box
    let mean_over_frames = |of: &Ellipsoid, iou: fn(&Ellipsoid, &Camera, &ImageSize, &BBox) -> f64| {
        let v: Vec<f64> = gt.boxes.iter().map(|(&f, b)| iou(of, &Camera::new(seq.k, seq.poses[f]), image, b)).collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    row.box_iou += mean_over_frames(e, metrics::box_iou);
    row.iou_truth += mean_over_frames(&gt.ellipsoid, metrics::projected_iou);
    row.box_iou_truth += mean_over_frames(&gt.ellipsoid, metrics::box_iou);
    row.e_trans += metrics::e_trans(e, &gt.ellipsoid);
    row.e_axe += metrics::e_axe(e, &gt.ellipsoid);
    let up = seq.poses[gt.boxes.keys().next().copied().unwrap_or(0)].rotation * Vector3::y();
    let yaw = metrics::e_yaw(e, &gt.ellipsoid, &up);
    row.e_yaw += yaw;
    row.yaw_within += usize::from(yaw <= 15.0);
    if let Some(c) = gt.ray_centre {
        row.e_ray += (c - gt.ellipsoid.centre()).norm();
        row.rays += 1;
    }
    yaw
}

/// Log a matched vehicle: its errors, its first depth, how far the camera travelled and the axes.
fn log_matched_vehicle(name: &str, seq: &LabelledSequence, id: &i64, gt: &GtVehicle, e: &Ellipsoid, yaw: f64) {
    let first = gt.boxes.keys().next().copied().unwrap_or(0);
    let depth = (seq.poses[first].inverse() * nalgebra::Point3::from(gt.ellipsoid.centre())).z;
    let err_cam = seq.poses[first].inverse().rotation * (e.centre() - gt.ellipsoid.centre());
    let last = gt.boxes.keys().last().copied().unwrap_or(0);
    let travel = (seq.poses[last].translation.vector - seq.poses[first].translation.vector).norm();
    tracing::debug!(
        sequence = %name,
        vehicle = id,
        e_trans = metrics::e_trans(e, &gt.ellipsoid),
        e_axe = metrics::e_axe(e, &gt.ellipsoid),
        e_yaw = yaw,
        frames = gt.boxes.len(),
        first_depth = depth,
        travel,
        err = format!("{:.2} {:.2} {:.2}", err_cam.x, err_cam.y, err_cam.z),
        e_ray = ?gt.ray_centre.map(|c| (c - gt.ellipsoid.centre()).norm()),
        axes = format!("{:.2} {:.2} {:.2} vs {:.2} {:.2} {:.2}", e.semi_axes.x, e.semi_axes.y, e.semi_axes.z, gt.ellipsoid.semi_axes.x, gt.ellipsoid.semi_axes.y, gt.ellipsoid.semi_axes.z),
        "matched vehicle"
    );
}

impl Row {
    /// Share of the vehicles found (`None` without vehicles).
    pub fn success(&self) -> Option<f64> {
        share(self.found, self.vehicles)
    }

    /// Mean ray-triangulation error (`None` without rays).
    pub fn e_ray_mean(&self) -> Option<f64> {
        mean(self.e_ray, self.rays)
    }

    /// The means over the found vehicles, in the table's order (IoU2D, box IoU2D, e_trans, e_axe,
    /// e_yaw, share within 15°); `None` each when no vehicle was found (a mean of nothing is no figure).
    fn found_means(&self) -> [Option<f64>; 6] {
        let n = self.found;
        [
            mean(self.iou, n),
            mean(self.box_iou, n),
            mean(self.e_trans, n),
            mean(self.e_axe, n),
            mean(self.e_yaw, n),
            share(self.yaw_within, n),
        ]
    }

    /// The sequence's line of the table ([`table_header`]'s columns); a figure of no vehicle is a dash.
    pub fn table_line(&self, name: &str) -> String {
        let [iou, box_iou, e_trans, e_axe, e_yaw, within] = self.found_means();
        format!(
            "{:<6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8} {:>8} {:>8} {:>7}",
            name,
            self.vehicles,
            self.found,
            cell(self.success(), 3),
            cell(iou, 3),
            cell(box_iou, 3),
            cell(e_trans, 3),
            cell(e_axe, 3),
            cell(self.e_ray_mean(), 3),
            cell(e_yaw, 1),
            cell(within, 2)
        )
    }

    /// The sequence's CSV record ([`CSV_COLUMNS`]' fields), for a `csv` writer; a figure of no vehicle is
    /// an empty field.
    pub fn csv_record(&self, name: &str) -> [String; 11] {
        let [iou, box_iou, e_trans, e_axe, e_yaw, within] = self.found_means();
        [
            name.to_string(),
            self.vehicles.to_string(),
            self.found.to_string(),
            csv(self.success()),
            csv(iou),
            csv(box_iou),
            csv(e_trans),
            csv(e_axe),
            csv(self.e_ray_mean()),
            csv(e_yaw),
            csv(within),
        ]
    }
}

/// The study's title: the detections (label boxes with `noise`), the associator and method named, and
/// which vehicles count as ground truth.
pub fn study_title(noise: &LabelNoise, associator: &str, method: &str, criteria: &VehicleCriteria) -> String {
    format!(
        "Object metrics, label boxes as detections (noise {} of box size, dropout {}), {associator} + {method}\n\
         GT: Car/Van tracks with >= {} frames whose world centre stays within {} m (static)",
        noise.noise, noise.dropout, criteria.min_frames, criteria.static_m
    )
}

/// Column names of [`Row::table_line`], aligned alike.
pub fn table_header() -> String {
    format!(
        "{:<6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8} {:>8} {:>8} {:>7}",
        "seq", "vehicles", "found", "success", "IoU2D", "boxIoU", "e_trans", "e_axe", "e_ray", "e_yaw", "<=15deg"
    )
}

/// Column names of [`Row::csv_record`].
pub const CSV_COLUMNS: [&str; 11] = [
    "sequence",
    "vehicles",
    "found",
    "success",
    "iou2d",
    "box_iou2d",
    "e_trans",
    "e_axe",
    "e_ray",
    "e_yaw",
    "yaw_within_15",
];

/// One line of a study's figures ([`Study::figures`]): success, IoU2D, box IoU2D, e_trans and e_axe
/// (metres), e_yaw (degrees) and the share within 15°; `None` where there is nothing to average.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Figures {
    /// Found / static vehicles.
    pub success: Option<f64>,
    /// The paper's IoU2D.
    pub iou2d: Option<f64>,
    /// Box IoU2D (the estimate's own 3-D box projected).
    pub box_iou2d: Option<f64>,
    /// Centre error, metres.
    pub e_trans: Option<f64>,
    /// Semi-axis error, metres.
    pub e_axe: Option<f64>,
    /// Yaw error, degrees.
    pub e_yaw: Option<f64>,
    /// Share of the found vehicles with e_yaw within 15°.
    pub yaw_within: Option<f64>,
}

/// A study's summary ([`Study::figures`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StudyFigures {
    /// Means of the sequences' figures.
    pub means: Figures,
    /// Pooled over vehicles.
    pub pooled: Figures,
    /// What the ground-truth ellipsoids score on the found vehicles: IoU2D and box IoU2D.
    pub truth: (Option<f64>, Option<f64>),
    /// `e_ray` (the centre error of the point where the rays through the labels' own 3-D centres
    /// meet, under the sequences' poses: what these poses allow a method that places objects by
    /// bearings), mean of sequences and pooled over vehicles.
    pub e_ray: (Option<f64>, Option<f64>),
    /// Moving vehicles: (count, mapped as a static ellipsoid, flagged dynamic only).
    pub moving: (usize, usize, usize),
}

/// The study over several sequences: means of the sequences' means and figures pooled over vehicles.
#[derive(Debug, Default, Clone)]
pub struct Study {
    tot: Row,
    n_seq: usize,
    sum_success: f64,
    n_found_seq: usize,
    sum_iou: f64,
    sum_box_iou: f64,
    sum_et: f64,
    sum_ea: f64,
    sum_yaw: f64,
    sum_within: f64,
    n_ray_seq: usize,
    sum_ray: f64,
    moving: (usize, usize, usize),
}

impl Study {
    /// Add a sequence.
    pub fn add(&mut self, s: &SequenceScore) {
        let row = &s.row;
        if let Some(success) = row.success() {
            self.n_seq += 1;
            self.sum_success += success;
        }
        if let Some(e) = row.e_ray_mean() {
            self.n_ray_seq += 1;
            self.sum_ray += e;
        }
        if let [Some(iou), Some(box_iou), Some(et), Some(ea), Some(yaw), Some(within)] = row.found_means() {
            self.n_found_seq += 1;
            self.sum_iou += iou;
            self.sum_box_iou += box_iou;
            self.sum_et += et;
            self.sum_ea += ea;
            self.sum_yaw += yaw;
            self.sum_within += within;
        }
        let tot = &mut self.tot;
        tot.vehicles += row.vehicles;
        tot.found += row.found;
        tot.iou += row.iou;
        tot.box_iou += row.box_iou;
        tot.box_iou_truth += row.box_iou_truth;
        tot.e_trans += row.e_trans;
        tot.e_axe += row.e_axe;
        tot.e_ray += row.e_ray;
        tot.iou_truth += row.iou_truth;
        tot.e_yaw += row.e_yaw;
        tot.yaw_within += row.yaw_within;
        tot.rays += row.rays;
        self.moving.0 += s.moving.0;
        self.moving.1 += s.moving.1;
        self.moving.2 += s.moving.2;
    }

    /// The figures pooled over all vehicles of the added sequences.
    pub fn pooled(&self) -> Row {
        self.tot
    }

    /// The summary figures: the means of the sequences' figures and the figures pooled over vehicles
    /// (a mean of nothing is `None`), and what the ground-truth ellipsoids score on the found vehicles.
    pub fn figures(&self) -> StudyFigures {
        let m = self.n_found_seq;
        let means = Figures {
            success: mean(self.sum_success, self.n_seq),
            iou2d: mean(self.sum_iou, m),
            box_iou2d: mean(self.sum_box_iou, m),
            e_trans: mean(self.sum_et, m),
            e_axe: mean(self.sum_ea, m),
            e_yaw: mean(self.sum_yaw, m),
            yaw_within: mean(self.sum_within, m),
        };
        let tot = &self.tot;
        let [iou2d, box_iou2d, e_trans, e_axe, e_yaw, yaw_within] = tot.found_means();
        let pooled = Figures { success: tot.success(), iou2d, box_iou2d, e_trans, e_axe, e_yaw, yaw_within };
        StudyFigures {
            means,
            pooled,
            truth: (mean(tot.iou_truth, tot.found), mean(tot.box_iou_truth, tot.found)),
            e_ray: (mean(self.sum_ray, self.n_ray_seq), tot.e_ray_mean()),
            moving: self.moving,
        }
    }

    /// The study's closing lines (the mean of the sequences, the pooled figures, the moving vehicles and
    /// notes), each with a line end; `moving_m` is the criteria's, for the text. A mean over no sequence
    /// or no vehicle is a dash.
    pub fn report(&self, moving_m: f64) -> String {
        let tot = &self.tot;
        let m = self.n_found_seq;
        let moving = self.moving;
        let mut s = format!(
            "{:<6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8} {:>8} {:>8} {:>7}   (mean of sequences)\n",
            "avg",
            "",
            "",
            cell(mean(self.sum_success, self.n_seq), 3),
            cell(mean(self.sum_iou, m), 3),
            cell(mean(self.sum_box_iou, m), 3),
            cell(mean(self.sum_et, m), 3),
            cell(mean(self.sum_ea, m), 3),
            cell(mean(self.sum_ray, self.n_ray_seq), 3),
            cell(mean(self.sum_yaw, m), 1),
            cell(mean(self.sum_within, m), 2)
        );
        let pooled = tot.table_line("all");
        s += &format!("{pooled}   (pooled over vehicles)\n");
        s += &format!(
            "moving vehicles (world centre moves more than {} m): {}; mapped as a static ellipsoid: {}, flagged \
             dynamic: {}, never fitted: {}\n",
            moving_m,
            moving.0,
            moving.1,
            moving.2,
            moving.0 - moving.1 - moving.2
        );
        s += &format!(
            "what the ground-truth ellipsoids (inscribed in the labels' 3-D boxes) score themselves over the same \
             vehicles: IoU2D {} (an inscribed ellipsoid projects to a box smaller than the labelled one), box \
             IoU2D {} (boxIoU: the ellipsoid's own 3-D box projected; the labels' 2-D boxes are drawn on the \
             image, not projected from their 3-D boxes)\n",
            cell(mean(tot.iou_truth, tot.found), 3),
            cell(mean(tot.box_iou_truth, tot.found), 3)
        );
        s += "e_ray: e_trans of the point where rays from each labelled frame's camera (pose file) through the \
         label's own 3-D centre meet, over the same vehicles: what these poses allow a method that places \
         objects by bearings (docs/objects.md)\n";
        s += "paper (its KITTI raw drives): success 0.602, IoU2D 0.730, e_trans 2.128 m, e_axe 0.642 m\n";
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_meet_at_their_common_point_and_parallel_rays_do_not() {
        let p = Vector3::new(-3.0, 1.0, 25.0);
        let rays: Vec<(Vector3<f64>, Vector3<f64>)> =
            (0..5).map(|i| Vector3::new(0.1 * i as f64, 0.0, 1.5 * i as f64)).map(|o| (o, p - o)).collect();
        let x = ray_intersection(&rays).expect("meet");
        assert!((x - p).norm() < 1e-9, "{x}");
        // a standing camera: every ray from one point along one direction
        let standing = vec![(Vector3::zeros(), p); 4];
        assert!(ray_intersection(&standing).is_none());
        assert!(ray_intersection(&[(Vector3::zeros(), Vector3::zeros())]).is_none());
    }

    #[test]
    fn the_study_averages_sequences_and_pools_vehicles() {
        // sequence a: 1 of 2 vehicles found (IoU 0.8); b: 3 of 3 (IoU sums 1.5: mean 0.5); c: no vehicles
        let a = Row { vehicles: 2, found: 1, iou: 0.8, e_trans: 1.0, ..Row::default() };
        let b = Row { vehicles: 3, found: 3, iou: 1.5, e_trans: 6.0, ..Row::default() };
        let mut study = Study::default();
        for row in [a, b, Row::default()] {
            study.add(&SequenceScore { row, moving: (1, 0, 1) });
        }
        assert!(Row::default().success().is_none() && Row::default().e_ray_mean().is_none());
        assert_eq!(a.success(), Some(0.5));
        let pooled = study.pooled();
        assert_eq!((pooled.vehicles, pooled.found), (5, 4));
        let report = study.report(3.0);
        let line = |tag: &str| report.lines().find(|l| l.starts_with(tag)).expect("line").to_string();
        // mean of sequences with vehicles: success (0.5 + 1) / 2, IoU2D (0.8 + 0.5) / 2, e_trans (1 + 2) / 2
        let avg: Vec<String> = line("avg").split_whitespace().map(str::to_string).collect();
        assert_eq!(&avg[1..3], ["0.750", "0.650"], "{report}");
        assert_eq!(avg[4], "1.500", "{report}");
        // pooled: 4 of 5 found, IoU2D 2.3 / 4, e_trans 7 / 4
        let all: Vec<String> = line("all").split_whitespace().map(str::to_string).collect();
        assert_eq!(&all[1..6], ["5", "4", "0.800", "0.575", "0.000"], "{report}");
        assert_eq!(all[6], "1.750", "{report}");
        assert!(report.contains("moving vehicles (world centre moves more than 3 m): 3; mapped as a static ellipsoid: 0, flagged dynamic: 3, never fitted: 0"), "{report}");
        // the same figures as numbers
        let f = study.figures();
        assert_eq!((f.means.success, f.means.e_trans), (Some(0.75), Some(1.5)));
        assert!((f.means.iou2d.unwrap() - 0.65).abs() < 1e-12);
        assert_eq!((f.pooled.success, f.pooled.e_trans), (Some(0.8), Some(1.75)));
        assert_eq!(f.moving, (3, 0, 3));
        assert_eq!(a.csv_record("0001").len(), CSV_COLUMNS.len());
        assert_eq!(a.table_line("0001").split_whitespace().count(), table_header().split_whitespace().count());
        // R05: no vehicle, or none found: dashes and empty CSV fields, never 0.000 or NaN
        let none = Row { vehicles: 2, ..Row::default() };
        let line = none.table_line("0009");
        assert_eq!(
            line.split_whitespace().collect::<Vec<_>>(),
            ["0009", "2", "0", "0.000", "–", "–", "–", "–", "–", "–", "–"]
        );
        assert_eq!(Row::default().csv_record("0009")[3..], [""; 8].map(String::from));
        let mut empty = Study::default();
        empty.add(&SequenceScore { row: Row::default(), moving: (0, 0, 0) });
        let report = empty.report(3.0);
        assert!(!report.contains("NaN") && !report.contains("0.000"), "{report}");
    }
}
