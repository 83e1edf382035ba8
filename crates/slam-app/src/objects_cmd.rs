//! `slam-app objects` and `slam-app eval`: image-free object mapping on KITTI tracking labels + poses,
//! and the paper's object metrics.

use std::{
    collections::{BTreeMap, BTreeSet},
    path::PathBuf,
};

use anyhow::{bail, Context};
use clap::Args;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use slam_core::{geometry::BBox, rng::SimRng, Detection};
use slam_dataset::{
    classes,
    kitti::{calib::Calib, poses::read_kitti_poses, tracking::read_tracking_labels, tracking::TrackingLabel},
};
use slam_pipeline::objects::{write_object_map, FitMethod, MapperConfig, ObjectMapper};
use slam_quadric::{metrics, Camera, Ellipsoid, ImageSize, Intrinsics};

#[derive(Args, Debug, Clone)]
pub struct InputArgs {
    /// Box noise: σ of each coordinate as a fraction of the box width/height
    #[arg(long, default_value_t = 0.0)]
    noise: f64,
    /// Probability of dropping a label box
    #[arg(long, default_value_t = 0.0)]
    dropout: f64,
    /// Seed of the noise and dropout
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Ellipsoid method
    #[arg(long, value_enum, default_value_t = Method::Refine)]
    method: Method,
    /// Object associator
    #[arg(long, value_enum, default_value_t = crate::optimizer_choice::AssociatorKind::Oda)]
    associator: crate::optimizer_choice::AssociatorKind,
    /// Optimiser backend of the object fits
    #[arg(long, value_enum, default_value_t = crate::optimizer_choice::OptimizerKind::Lm)]
    optimizer: crate::optimizer_choice::OptimizerKind,
    /// Also fit objects seen without parallax (a standing camera) once they have this many boxes: depth
    /// from the class's size prior (off by default, as in the paper)
    #[arg(long)]
    without_parallax_after: Option<usize>,
    /// Least angle between an object's first and latest ray through its box centres before it is fitted,
    /// degrees
    #[arg(long, default_value_t = 3.0)]
    min_parallax_deg: f64,
    /// Flag an object dynamic when its fitted semi-axes lie this many prior σ from its class prior
    /// (Mahalanobis; 0: off)
    #[arg(long, default_value_t = 6.0)]
    dynamic_prior_sigmas: f64,
    /// What a box bounds in the object optimisation: the ellipsoid (the paper) or its circumscribed cuboid
    #[arg(long, value_enum, default_value_t = Shape::Ellipse)]
    box_shape: Shape,
    /// Remove an ellipsoid visible but not detected in this many frames in a row (0: never)
    #[arg(long, default_value_t = 5)]
    max_misses: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Shape {
    /// The ellipsoid's projected ellipse
    Ellipse,
    /// The ellipsoid's circumscribed cuboid
    Cuboid,
}

impl InputArgs {
    /// Range checks (before any file is read).
    fn check(&self) -> anyhow::Result<()> {
        use crate::validate::{count, number, Range};
        number("--noise", self.noise, Range::closed(0.0, 1.0), "(σ as a share of the box size)")?;
        number("--dropout", self.dropout, Range::closed(0.0, 1.0), "(a probability)")?;
        number("--min-parallax-deg", self.min_parallax_deg, Range::closed(0.0, 90.0), "degrees")?;
        number("--dynamic-prior-sigmas", self.dynamic_prior_sigmas, Range::closed(0.0, 1.0e6), "(0: off)")?;
        if let Some(n) = self.without_parallax_after {
            count("--without-parallax-after", n, 1, usize::MAX)?;
        }
        Ok(())
    }
}

impl Shape {
    pub(crate) fn shape(self) -> slam_optim::object::BoxShape {
        match self {
            Shape::Ellipse => slam_optim::object::BoxShape::Ellipse,
            Shape::Cuboid => slam_optim::object::BoxShape::Cuboid,
        }
    }
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Method {
    /// DQP + object optimisation (ours)
    Refine,
    /// QuadricSLAM's SVD
    Qslam,
    /// Rubino et al.'s conic method
    Conic,
    /// Triangulated centre + full 3×3 block
    Tri,
    /// DQP as printed
    TriYaw,
}

impl Method {
    pub(crate) fn fit(self) -> FitMethod {
        match self {
            Method::Refine => FitMethod::default(),
            Method::Qslam => FitMethod::qslam(),
            Method::Conic => FitMethod::conic(),
            Method::Tri => FitMethod::tri(),
            Method::TriYaw => FitMethod::tri_yaw(),
        }
    }
}

#[derive(Args, Debug)]
pub struct ObjectsArgs {
    /// Folder with label_02.txt, poses_orbslam3.txt and calib.txt
    dir: PathBuf,
    /// Labels file (default: DIR/label_02.txt)
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Poses file, camera-to-world of the left colour camera, one line per frame (default: DIR/poses_orbslam3.txt)
    #[arg(long)]
    poses: Option<PathBuf>,
    /// Calibration with P2 (default: DIR/calib.txt)
    #[arg(long)]
    calib: Option<PathBuf>,
    /// Output object-map JSON
    #[arg(long, default_value = "out/objects.json")]
    out: PathBuf,
    #[command(flatten)]
    input: InputArgs,
}

struct Sequence {
    labels: Vec<TrackingLabel>,
    poses: Vec<Isometry3<f64>>,
    k: Intrinsics,
    t2: Vector3<f64>,
}

fn load(labels: PathBuf, poses: PathBuf, calib: PathBuf) -> anyhow::Result<Sequence> {
    let labels = read_tracking_labels(&labels)?;
    let poses = read_kitti_poses(&poses)?;
    let calib = Calib::read(&calib)?;
    let p2 = calib.matrix3x4("P2")?;
    let k = Intrinsics { fx: p2[(0, 0)], fy: p2[(1, 1)], skew: p2[(0, 1)], cx: p2[(0, 2)], cy: p2[(1, 2)] };
    let kinv = p2.fixed_view::<3, 3>(0, 0).into_owned().try_inverse().context("P2 has a singular K")?;
    let t2 = kinv * p2.column(3).into_owned();
    let frames = labels.iter().map(|l| l.frame + 1).max().unwrap_or(0);
    if poses.len() < frames {
        bail!("{} poses for {frames} labelled frames", poses.len());
    }
    Ok(Sequence { labels, poses, k, t2 })
}

/// Run the mapper; returns it and, per (frame, detection index), the true track id of the detection.
fn run(seq: &Sequence, input: &InputArgs) -> (ObjectMapper, BTreeMap<(usize, usize), i64>) {
    let mut by_frame: BTreeMap<usize, Vec<&TrackingLabel>> = BTreeMap::new();
    for l in &seq.labels {
        if l.class.is_some() && l.track_id >= 0 {
            by_frame.entry(l.frame).or_default().push(l);
        }
    }
    let config = MapperConfig {
        min_views_without_parallax: input.without_parallax_after,
        box_shape: input.box_shape.shape(),
        min_parallax_deg: input.min_parallax_deg,
        dynamic_prior_sigmas: (input.dynamic_prior_sigmas > 0.0).then_some(input.dynamic_prior_sigmas),
        max_misses: (input.max_misses > 0).then_some(input.max_misses),
        ..MapperConfig::default()
    };
    let mut mapper = ObjectMapper::new(input.associator.build(None), config, input.optimizer.build())
        .with_method(input.method.fit());
    let mut truth = BTreeMap::new();
    for (frame, pose) in seq.poses.iter().enumerate() {
        let mut rng = SimRng::derive(input.seed, &[frame as u64]);
        let mut dets = Vec::new();
        for l in by_frame.get(&frame).map(|v| v.as_slice()).unwrap_or(&[]) {
            let draws = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
            if rng.unit() < input.dropout {
                continue;
            }
            let b = l.bbox;
            let (sx, sy) = (input.noise * b.width(), input.noise * b.height());
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

pub fn objects(a: &ObjectsArgs) -> anyhow::Result<()> {
    a.input.check()?;
    let out = crate::output::AtomicFile::new(&a.out)?;
    let seq = load(
        a.labels.clone().unwrap_or_else(|| a.dir.join("label_02.txt")),
        a.poses.clone().unwrap_or_else(|| a.dir.join("poses_orbslam3.txt")),
        a.calib.clone().unwrap_or_else(|| a.dir.join("calib.txt")),
    )?;
    let (mapper, _) = run(&seq, &a.input);
    let objs: Vec<_> = mapper.objects().collect();
    out.write_with(|tmp| write_object_map(tmp, &objs).map_err(anyhow::Error::from))?;
    let with = objs.iter().filter(|o| o.ellipsoid.is_some()).count();
    let dynamic = objs.iter().filter(|o| o.ellipsoid.is_some() && o.dynamic).count();
    println!(
        "{} frames, {} tracks, {with} objects with an ellipsoid ({dynamic} flagged dynamic), {} fits; wrote {}",
        seq.poses.len(),
        objs.len(),
        mapper.fits(),
        a.out.display()
    );
    Ok(())
}

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// One sequence folder (label_02.txt, poses_orbslam3.txt, calib.txt), a folder of them (default: the
    /// shipped fixtures/kitti_tracking), or the output folder of `slam-app run` (objects.json,
    /// trajectory.kitti.txt, camera.json) to score against --labels
    dir: Option<PathBuf>,
    /// With a run's output folder: the labels to score it against (label_02.txt format)
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Fewest labelled frames of a ground-truth vehicle
    #[arg(long, default_value_t = 10)]
    min_frames: usize,
    /// Largest spread (max distance from its mean) of a vehicle's world centre to count as static, metres
    #[arg(long, default_value_t = 1.0)]
    static_m: f64,
    /// Smallest spread of a vehicle's world centre to count as moving (the dynamic-object check), metres
    #[arg(long, default_value_t = 3.0)]
    moving_m: f64,
    /// Also write the table as CSV
    #[arg(long)]
    csv: Option<PathBuf>,
    #[command(flatten)]
    input: InputArgs,
}

/// A ground-truth static vehicle: its ellipsoid (inscribed in the mean labelled 3-D box) and its label
/// boxes per frame.
struct GtVehicle {
    ellipsoid: Ellipsoid,
    boxes: BTreeMap<usize, BBox>,
    /// Where the rays from each labelled frame's camera through the label's own 3-D centre meet (least
    /// squares), `None` when they do not (a standing camera).
    ray_centre: Option<Vector3<f64>>,
}

/// The label track that supplied most of an object's detections (ties: the lower id), with its count.
fn majority_track(
    o: &slam_pipeline::objects::MappedObject,
    truth: &BTreeMap<(usize, usize), i64>,
) -> Option<(i64, usize)> {
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
fn ray_intersection(rays: &[(Vector3<f64>, Vector3<f64>)]) -> Option<Vector3<f64>> {
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
struct VehicleTrack<'a> {
    id: i64,
    labels: Vec<&'a TrackingLabel>,
    centres: Vec<Vector3<f64>>,
    mean: Vector3<f64>,
    spread: f64,
}

/// The Car/Van label tracks of at least `min_frames` frames.
fn vehicle_tracks(seq: &Sequence, min_frames: usize) -> Vec<VehicleTrack<'_>> {
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

fn gt_vehicles(seq: &Sequence, min_frames: usize, static_m: f64) -> BTreeMap<i64, GtVehicle> {
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

#[derive(Default, Clone, Copy)]
struct Row {
    vehicles: usize,
    found: usize,
    iou: f64,
    e_trans: f64,
    e_axe: f64,
    /// Sum of the ray-triangulation errors over the found vehicles that have one, and their count.
    e_ray: f64,
    rays: usize,
    /// Sum over the found vehicles of the IoU2D of the ground-truth ellipsoid itself.
    iou_truth: f64,
    /// Sum of e_yaw (degrees) over the found vehicles, and how many were within 15 degrees.
    e_yaw: f64,
    yaw_within: usize,
}

/// `slam-app eval <run folder> --labels <label_02.txt>`: score a finished run's object map.
fn eval_run_folder(dir: &std::path::Path, a: &EvalArgs) -> anyhow::Result<()> {
    let labels_path = a.labels.as_ref().context("scoring a run folder needs --labels <label_02.txt>")?;
    let labels = read_tracking_labels(labels_path)?;
    let poses = read_kitti_poses(dir.join("trajectory.kitti.txt"))?;
    let geometry = slam_eval::LabelGeometry::read(&dir.join("camera.json"))?;
    let objects = slam_eval::read_object_map(&dir.join("objects.json"))?;
    let config =
        slam_eval::ScoreConfig { min_frames: a.min_frames, static_m: a.static_m, moving_m: a.moving_m, ..Default::default() };
    let score = slam_eval::score_run(&labels, &poses, &geometry, &objects, &config);
    print!("{}", score.report());
    let out = dir.join("objects_score.json");
    score.write_json(&out)?;
    println!("wrote {}", out.display());
    Ok(())
}

pub fn eval(a: &EvalArgs) -> anyhow::Result<()> {
    use crate::validate::{count, number, Range};
    a.input.check()?;
    count("--min-frames", a.min_frames, 1, usize::MAX)?;
    number("--static-m", a.static_m, Range::closed(0.0, 1000.0), "m")?;
    number("--moving-m", a.moving_m, Range::above(0.0, 1000.0), "m")?;
    if a.static_m > a.moving_m {
        bail!(
            "--static-m {} exceeds --moving-m {}: a vehicle would count as static and moving",
            a.static_m,
            a.moving_m
        );
    }
    let csv_out = a.csv.as_deref().map(crate::output::AtomicFile::new).transpose()?;
    let dir = a.dir.clone().unwrap_or_else(|| crate::fixture("kitti_tracking"));
    if dir.join("objects.json").is_file() && dir.join("trajectory.kitti.txt").is_file() {
        return eval_run_folder(&dir, a);
    }
    let seqs = crate::tracking_sequences(&dir)?;
    println!(
        "Object metrics, label boxes as detections (noise {} of box size, dropout {}), {} + {}",
        a.input.noise,
        a.input.dropout,
        a.input.associator.name(),
        a.input.method.fit().name()
    );
    println!(
        "GT: Car/Van tracks with >= {} frames whose world centre stays within {} m (static)",
        a.min_frames, a.static_m
    );
    println!(
        "{:<6} {:>8} {:>8} {:>8} {:>8} {:>9} {:>8} {:>8} {:>8} {:>7}",
        "seq", "vehicles", "found", "success", "IoU2D", "e_trans", "e_axe", "e_ray", "e_yaw", "<=15deg"
    );
    let mut csv = csv::Writer::from_writer(Vec::new());
    csv.write_record([
        "sequence",
        "vehicles",
        "found",
        "success",
        "iou2d",
        "e_trans",
        "e_axe",
        "e_ray",
        "e_yaw",
        "yaw_within_15",
    ])?;
    let (mut sum_yaw, mut sum_within) = (0.0, 0.0);
    let (mut tot, mut n_seq) = (Row::default(), 0usize);
    let (mut sum_success, mut sum_iou, mut sum_et, mut sum_ea, mut n_found_seq) = (0.0, 0.0, 0.0, 0.0, 0usize);
    let (mut sum_ray, mut n_ray_seq) = (0.0, 0usize);
    // moving vehicles: (count, mapped as a static ellipsoid, flagged dynamic only)
    let mut moving = (0usize, 0usize, 0usize);
    let image = ImageSize::new(1242.0, 375.0);
    let mut bar = crate::progress::Progress::new("eval", seqs.len() as u64, "sequences", false);
    for sdir in &seqs {
        let name = sdir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        bar.set_message(format!("sequence {name}"));
        let seq = load(sdir.join("label_02.txt"), sdir.join("poses_orbslam3.txt"), sdir.join("calib.txt"))?;
        let gts = gt_vehicles(&seq, a.min_frames, a.static_m);
        let movers: BTreeSet<i64> =
            vehicle_tracks(&seq, a.min_frames).into_iter().filter(|t| t.spread > a.moving_m).map(|t| t.id).collect();
        let (mapper, truth) = run(&seq, &a.input);
        // moving vehicles: what became of the objects built mostly from their boxes (flagged, mapped)
        let mut fate: BTreeMap<i64, (bool, bool)> = movers.iter().map(|&t| (t, (false, false))).collect();
        for o in mapper.objects() {
            let Some((t, _)) = majority_track(o, &truth) else { continue };
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
        // each object votes for the GT track that supplied most of its detections
        let mut best: BTreeMap<i64, (usize, Ellipsoid)> = BTreeMap::new();
        for o in mapper.objects() {
            let (Some(e), false) = (o.ellipsoid, o.dynamic) else { continue };
            if let Some((t, n)) = majority_track(o, &truth) {
                if gts.contains_key(&t) && best.get(&t).is_none_or(|b| n > b.0) {
                    best.insert(t, (n, e));
                }
            }
        }
        let mut row = Row { vehicles: gts.len(), ..Row::default() };
        for (id, gt) in &gts {
            let Some((_, e)) = best.get(id) else {
                // why: the objects that took this vehicle's boxes, and what became of them
                let mut took: Vec<String> = Vec::new();
                for o in mapper.objects() {
                    let n =
                        o.observations.iter().filter(|obs| truth.get(&(obs.frame, obs.detection)) == Some(id)).count();
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
                continue;
            };
            row.found += 1;
            let ious: Vec<f64> = gt
                .boxes
                .iter()
                .map(|(&f, b)| metrics::projected_iou(e, &Camera::new(seq.k, seq.poses[f]), &image, b))
                .collect();
            row.iou += ious.iter().sum::<f64>() / ious.len().max(1) as f64;
            let truth_ious: Vec<f64> = gt
                .boxes
                .iter()
                .map(|(&f, b)| metrics::projected_iou(&gt.ellipsoid, &Camera::new(seq.k, seq.poses[f]), &image, b))
                .collect();
            row.iou_truth += truth_ious.iter().sum::<f64>() / truth_ious.len().max(1) as f64;
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
                frames = gt.boxes.len(),
                first_depth = depth,
                travel,
                err = format!("{:.2} {:.2} {:.2}", err_cam.x, err_cam.y, err_cam.z),
                axes = format!("{:.2} {:.2} {:.2} vs {:.2} {:.2} {:.2}", e.semi_axes.x, e.semi_axes.y, e.semi_axes.z, gt.ellipsoid.semi_axes.x, gt.ellipsoid.semi_axes.y, gt.ellipsoid.semi_axes.z),
                "matched vehicle"
            );
        }
        let f = row.found.max(1) as f64;
        let success = if row.vehicles > 0 { row.found as f64 / row.vehicles as f64 } else { f64::NAN };
        let e_ray = if row.rays > 0 { row.e_ray / row.rays as f64 } else { f64::NAN };
        bar.println(&format!(
            "{:<6} {:>8} {:>8} {:>8.3} {:>8.3} {:>9.3} {:>8.3} {:>8.3} {:>8.1} {:>7.2}",
            name,
            row.vehicles,
            row.found,
            success,
            row.iou / f,
            row.e_trans / f,
            row.e_axe / f,
            e_ray,
            row.e_yaw / f,
            row.yaw_within as f64 / f
        ));
        csv.write_record([
            name.to_string(),
            row.vehicles.to_string(),
            row.found.to_string(),
            success.to_string(),
            (row.iou / f).to_string(),
            (row.e_trans / f).to_string(),
            (row.e_axe / f).to_string(),
            e_ray.to_string(),
            (row.e_yaw / f).to_string(),
            (row.yaw_within as f64 / f).to_string(),
        ])?;
        if row.vehicles > 0 {
            n_seq += 1;
            sum_success += success;
        }
        if row.rays > 0 {
            n_ray_seq += 1;
            sum_ray += e_ray;
        }
        if row.found > 0 {
            n_found_seq += 1;
            sum_iou += row.iou / f;
            sum_et += row.e_trans / f;
            sum_ea += row.e_axe / f;
            sum_yaw += row.e_yaw / f;
            sum_within += row.yaw_within as f64 / f;
        }
        tot.vehicles += row.vehicles;
        tot.found += row.found;
        tot.iou += row.iou;
        tot.e_trans += row.e_trans;
        tot.e_axe += row.e_axe;
        tot.e_ray += row.e_ray;
        tot.iou_truth += row.iou_truth;
        tot.e_yaw += row.e_yaw;
        tot.yaw_within += row.yaw_within;
        tot.rays += row.rays;
        bar.inc();
    }
    bar.finish();
    let f = tot.found.max(1) as f64;
    let m = n_found_seq.max(1) as f64;
    println!(
        "{:<6} {:>8} {:>8} {:>8.3} {:>8.3} {:>9.3} {:>8.3} {:>8.3} {:>8.1} {:>7.2}   (mean of sequences)",
        "avg",
        "",
        "",
        sum_success / n_seq.max(1) as f64,
        sum_iou / m,
        sum_et / m,
        sum_ea / m,
        sum_ray / n_ray_seq.max(1) as f64,
        sum_yaw / m,
        sum_within / m
    );
    println!(
        "{:<6} {:>8} {:>8} {:>8.3} {:>8.3} {:>9.3} {:>8.3} {:>8.3} {:>8.1} {:>7.2}   (pooled over vehicles)",
        "all",
        tot.vehicles,
        tot.found,
        tot.found as f64 / tot.vehicles.max(1) as f64,
        tot.iou / f,
        tot.e_trans / f,
        tot.e_axe / f,
        tot.e_ray / tot.rays.max(1) as f64,
        tot.e_yaw / f,
        tot.yaw_within as f64 / f
    );
    println!(
        "moving vehicles (world centre moves more than {} m): {}; mapped as a static ellipsoid: {}, flagged \
         dynamic: {}, never fitted: {}",
        a.moving_m,
        moving.0,
        moving.1,
        moving.2,
        moving.0 - moving.1 - moving.2
    );
    println!(
        "IoU2D of the ground-truth ellipsoids themselves over the same vehicles: {:.3} (an inscribed ellipsoid \
         projects to a box smaller than the labelled one)",
        tot.iou_truth / f
    );
    println!(
        "e_ray: e_trans of the point where rays from each labelled frame's camera (pose file) through the \
         label's own 3-D centre meet, over the same vehicles: what these poses allow a method that places \
         objects by bearings (docs/objects.md)"
    );
    println!("paper (its KITTI raw drives): success 0.602, IoU2D 0.730, e_trans 2.128 m, e_axe 0.642 m");
    if let Some(f) = csv_out {
        let bytes = csv.into_inner().map_err(|e| e.into_error())?;
        f.write_with(|tmp| std::fs::write(tmp, bytes).map_err(anyhow::Error::from))?;
    }
    Ok(())
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
}
