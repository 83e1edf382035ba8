//! `objects-bench`: the object map of every dev case in one table, the guard of the object half (issue
//! 45). Drive 0005 (frames 0-90, the shipped detector, our own poses) scored against its labels at
//! several strides (the same drive at lower frame rates): the census of the static map objects, how
//! the association followed the labelled objects, and each static labelled vehicle's errors (on that
//! drive, the parked van); the image-free study on the 17 tracking sequences (label boxes, ORB-SLAM3
//! poses); and the main job's objects (odometry 06, a straight street) against the street. Every figure
//! is deterministic but the times.

use std::path::{Path, PathBuf};

use slam_core::figure::{cell, median, DASH};
use slam_eval::{
    labelled::{Figures, LabelNoise, VehicleCriteria},
    street::against_street,
    trajectory_errors::trajectory_errors,
    RunScore,
};
use slam_pipeline::objects::{MapperConfig, ObjectMapper};
use slam_quadric::ImageSize;

use crate::{
    error::{Context, Result},
    run::{prepare, RunSettings},
    run_summary::median_fps,
};

/// Where the bench's cases live.
#[derive(Debug, Clone)]
pub struct ObjectsBenchCases {
    /// The labelled drive (raw drive 0005).
    pub drive: PathBuf,
    /// Its KITTI tracking labels (tracking sequence 0000).
    pub labels: PathBuf,
    /// Strides the drive is played at.
    pub strides: Vec<usize>,
    /// The folder of image-free tracking sequences (`None`: left out).
    pub tracking: Option<PathBuf>,
    /// The main job's sequence (odometry 06, frames 0-50: one straight street).
    pub street: PathBuf,
}

impl ObjectsBenchCases {
    /// The shipped cases under `fixtures`: raw drive 0005 with the labels of tracking sequence 0000 at
    /// `strides`, the 17 tracking sequences (unless `image_free` is false), odometry 06.
    pub fn shipped(fixtures: &Path, strides: Vec<usize>, image_free: bool) -> Self {
        Self {
            drive: fixtures.join("kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync"),
            labels: fixtures.join("kitti_tracking/0000/label_02.txt"),
            strides,
            tracking: image_free.then(|| fixtures.join("kitti_tracking")),
            street: fixtures.join("kitti_odom_06/sequences/06"),
        }
    }
}

/// A car along the street is one whose centre lies within this distance of the camera's path, metres:
/// the driving lane (3.5 m) the camera is in, half of it to the camera (1.75 m), the parking lane
/// beside it (2.5 m) and the car's half-width less its clearance: a car parked at the kerb of either
/// side is within about 6 m of a camera in the lane next to the parking lane (issue 45).
pub const STREET_SIDE_M: f64 = 6.0;

/// One stride of the labelled drive: the score and the run's own figures.
#[derive(Debug, Clone)]
pub struct DriveRow {
    /// Stride.
    pub stride: usize,
    /// The objects scored against the labels.
    pub score: RunScore,
    /// Aligned ATE against the drive's ground truth, metres.
    pub ate_aligned_m: Option<f64>,
    /// Median time of the object stage at the keyframes that ran a fit (mapping thread), ms, and how
    /// many keyframes did.
    pub object_ms: (Option<f64>, usize),
    /// Median frames per second.
    pub fps: Option<f64>,
}

/// The main job's objects against its street.
#[derive(Debug, Clone)]
pub struct StreetRow {
    /// Static objects with an ellipsoid.
    pub static_objects: usize,
    /// Objects flagged dynamic (with an ellipsoid).
    pub dynamic: usize,
    /// Each static object of a vehicle class: id, class name, lateral distance (m), angle to the street
    /// (degrees), along the street (m).
    pub cars: Vec<(u64, &'static str, f64, Option<f64>, f64)>,
    /// Object stage median at the keyframes that ran a fit, ms, and how many did.
    pub object_ms: (Option<f64>, usize),
    /// Median frames per second.
    pub fps: Option<f64>,
}

/// The whole bench.
#[derive(Debug, Clone)]
pub struct ObjectsBench {
    /// The labelled drive at each stride.
    pub drive: Vec<DriveRow>,
    /// The image-free study (`None` when left out).
    pub image_free: Option<slam_eval::labelled::StudyFigures>,
    /// The main job's objects.
    pub street: StreetRow,
}

/// A keyframe whose object stage took less than this ran no fit (a fit of the smallest object is a few
/// optimiser iterations over its views: well above a tenth of a millisecond), ms.
const NO_FIT_MS: f64 = 0.1;

/// The median object-stage time of a run's keyframes that ran a fit, ms, and how many did.
fn object_ms(out: &slam_pipeline::system::RunOutput) -> (Option<f64>, usize) {
    let mut t: Vec<f64> =
        out.frames.iter().filter(|r| r.keyframe && r.times.objects >= NO_FIT_MS).map(|r| r.times.objects).collect();
    let n = t.len();
    (median(&mut t), n)
}

/// Run the labelled drive at `stride` with `base`'s settings and score it.
pub fn drive_row(base: &RunSettings, cases: &ObjectsBenchCases, stride: usize) -> Result<DriveRow> {
    let mut s = base.clone();
    s.path = cases.drive.clone();
    s.selection.stride = stride;
    s.labels = Some(cases.labels.clone());
    let o = prepare(&s)?.run(&s, &mut |_| {}, || false).context_with(|| format!("drive at stride {stride}"))?;
    let score = o.run_score().ok_or_else(|| crate::RunnerError::Invalid("the drive's labels were not read".into()))?;
    let truth = o.seq.truth_from_first();
    let scored = truth.as_ref().map(|g| crate::report::Scored::of(&o.out, g, &o.seq.ids));
    let ate_aligned_m = scored.as_ref().and_then(|s| trajectory_errors(&s.est, &s.truth, &[])).map(|e| e.ate_aligned_m);
    Ok(DriveRow { stride, score, ate_aligned_m, object_ms: object_ms(&o.out), fps: median_fps(&o.out) })
}

/// Run the main job's sequence with `base`'s settings and measure its objects against the street.
pub fn street_row(base: &RunSettings, cases: &ObjectsBenchCases) -> Result<StreetRow> {
    let mut s = base.clone();
    s.path = cases.street.clone();
    s.labels = None;
    let o = prepare(&s)?.run(&s, &mut |_| {}, || false).context_with(|| "the main job's sequence".to_string())?;
    let out = &o.out;
    let with = |dynamic: bool| out.objects.iter().filter(move |x| x.ellipsoid.is_some() && x.dynamic == dynamic);
    let statics: Vec<(u64, slam_core::geometry::Ellipsoid)> = with(false)
        .filter(|x| x.class.group() == slam_core::ClassId(2).group())
        .filter_map(|x| Some((x.id.0, x.ellipsoid?)))
        .collect();
    let placed: Vec<nalgebra::Isometry3<f64>> =
        out.poses.iter().zip(&out.placed).filter(|(_, p)| **p).map(|(x, _)| *x).collect();
    let street = against_street(&placed, &statics).unwrap_or_default();
    let name = |id: u64| out.objects.iter().find(|x| x.id.0 == id).map_or("?", |x| x.class.name());
    let cars = street.iter().map(|c| (c.id, name(c.id), c.lateral_m, c.angle_deg, c.along_m)).collect();
    Ok(StreetRow {
        static_objects: with(false).count(),
        dynamic: with(true).count(),
        cars,
        object_ms: object_ms(out),
        fps: median_fps(out),
    })
}

/// The image-free study over `tracking`'s sequences with the default image-free mapper, its box model
/// taken from `objects` (the settings file's `[objects] box_shape`).
pub fn image_free(base: &RunSettings, tracking: &Path) -> Result<slam_eval::labelled::StudyFigures> {
    let seqs = slam_dataset::folders::tracking_sequences(tracking)?;
    let config = MapperConfig { box_shape: base.system.objects.box_shape, ..MapperConfig::default() };
    let mapper =
        || ObjectMapper::new((base.associator)(None), config, (base.optimizer)()).with_method(base.method.clone());
    let criteria = VehicleCriteria::default();
    let image = ImageSize::new(1242.0, 375.0);
    let (study, _) =
        slam_eval::study::eval_study(&seqs, &mapper, &LabelNoise::default(), &criteria, &image, &mut |_, _| {})?;
    Ok(study.figures())
}

/// Every case of the bench; `progress` hears of each as it starts.
pub fn objects_bench(
    base: &RunSettings,
    cases: &ObjectsBenchCases,
    progress: &mut dyn FnMut(&str),
) -> Result<ObjectsBench> {
    let mut drive = Vec::new();
    for &stride in &cases.strides {
        progress(&format!("drive {} at stride {stride}", cases.drive.display()));
        drive.push(drive_row(base, cases, stride)?);
    }
    let image_free = match &cases.tracking {
        Some(dir) => {
            progress(&format!("image-free study on {}", dir.display()));
            Some(image_free(base, dir)?)
        }
        None => None,
    };
    progress(&format!("main job on {}", cases.street.display()));
    let street = street_row(base, cases)?;
    Ok(ObjectsBench { drive, image_free, street })
}

impl ObjectsBench {
    /// The bench's tables (markdown) and notes, line by line.
    pub fn lines(&self) -> Vec<String> {
        let mut out = Vec::new();
        self.drive_lines(&mut out);
        if let Some(f) = &self.image_free {
            out.push(String::new());
            image_free_lines(f, &mut out);
        }
        out.push(String::new());
        street_lines(&self.street, &mut out);
        out
    }

    /// A row of the drive's table: its name and a cell a stride, `f` giving the cell.
    fn row(&self, name: &str, f: &dyn Fn(&DriveRow) -> String) -> String {
        format!("| {name} | {} |", self.drive.iter().map(f).collect::<Vec<_>>().join(" | "))
    }

    /// The drive's table, a column a stride: census, flags, association, vehicles, ATE and speed.
    fn drive_lines(&self, out: &mut Vec<String>) {
        let strides: Vec<String> = self.drive.iter().map(|r| format!("stride {}", r.stride)).collect();
        out.push(format!("| drive 0005 against its labels | {} |", strides.join(" | ")));
        out.push(format!("|---|{}", "---:|".repeat(self.drive.len())));
        out.push(self.row(
            "static map objects: matched / duplicate / moving as static / DontCare / nothing (of which parked bicycles or motorcycles, which KITTI does not label)",
            &|r| {
                let c = &r.score.census;
                format!(
                    "{}: {} / {} / {} / {} / {} ({})",
                    c.static_objects, c.matched, c.duplicate, c.moving, c.dont_care, c.nothing, c.nothing_unlabelled_class
                )
            },
        ));
        out.push(self.row("flagged dynamic (on moving labels)", &|r| {
            format!("{} ({})", r.score.census.dynamic_objects, r.score.census.dynamic_on_moving)
        }));
        out.push(self.row("tracks per labelled object / switches / mixed", &|r| match &r.score.association {
            Some(a) => format!("{:.2} / {} / {}", a.tracks_per_label, a.switches, a.mixed_tracks),
            None => DASH.to_string(),
        }));
        self.vehicle_lines(out);
        out.push(self.row("ATE aligned m (vs OXTS)", &|r| cell(r.ate_aligned_m, 3)));
        out.push(self.row("object stage median ms a keyframe that ran a fit (keyframes)", &|r| {
            format!("{} ({})", cell(r.object_ms.0, 1), r.object_ms.1)
        }));
        out.push(self.row("median frames/s", &|r| cell(r.fps, 1)));
    }

    /// Two rows of the drive's table for every static labelled vehicle: its errors, and its IoUs.
    fn vehicle_lines(&self, out: &mut Vec<String>) {
        // on drive 0005: the parked van, label 3
        let vehicles: Vec<i64> = self
            .drive
            .iter()
            .flat_map(|r| r.score.tracks.iter().filter(|t| t.vehicle).map(|t| t.track))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        for id in vehicles {
            let track = |r: &DriveRow| r.score.tracks.iter().find(|t| t.track == id && t.vehicle).cloned();
            let kind = self.drive.iter().find_map(|r| track(r).map(|t| t.kind)).unwrap_or_default();
            out.push(self.row(
                &format!("static {kind} (label {id}): e_trans m / e_yaw deg / e_axe m"),
                &|r| match track(r) {
                    Some(t) if t.object.is_some() => {
                        format!("{} / {} / {}", cell(t.e_trans, 2), cell(t.e_yaw, 1), cell(t.e_axe, 2))
                    }
                    Some(_) => "not mapped".to_string(),
                    None => "not static here".to_string(),
                },
            ));
            out.push(self.row(&format!("label {id}: IoU2D / box IoU2D (the ground truth's)"), &|r| match track(r) {
                Some(t) if t.object.is_some() => format!(
                    "{} / {} ({} / {})",
                    cell(t.iou2d, 2),
                    cell(t.box_iou2d, 2),
                    cell(Some(r.score.vehicles.iou2d_truth), 2),
                    cell(Some(r.score.vehicles.box_iou2d_truth), 2)
                ),
                _ => DASH.to_string(),
            }));
        }
    }
}

/// The image-free study's table (means of sequences, pooled, the ground truth's) and its moving vehicles.
fn image_free_lines(f: &slam_eval::labelled::StudyFigures, out: &mut Vec<String>) {
    out.push("| image-free, 17 tracks (label boxes) | success | IoU2D | box IoU2D | e_trans m | e_axe m | e_yaw deg | within 15 deg |".into());
    out.push("|---|---:|---:|---:|---:|---:|---:|---:|".into());
    let line = |name: &str, x: &Figures| {
        format!(
            "| {name} | {} | {} | {} | {} | {} | {} | {} |",
            cell(x.success, 3),
            cell(x.iou2d, 3),
            cell(x.box_iou2d, 3),
            cell(x.e_trans, 3),
            cell(x.e_axe, 3),
            cell(x.e_yaw, 1),
            cell(x.yaw_within.map(|w| 100.0 * w), 0)
        )
    };
    out.push(line("mean of sequences", &f.means));
    out.push(line("pooled over vehicles", &f.pooled));
    out.push(format!(
        "| the ground-truth ellipsoids themselves (found vehicles) | | {} | {} | | | | |",
        cell(f.truth.0, 3),
        cell(f.truth.1, 3)
    ));
    out.push(format!(
        "| the rays through the labels' own centres (e_ray: what these poses allow placing by bearings), mean of sequences / pooled | | | | {} / {} | | | |",
        cell(f.e_ray.0, 3),
        cell(f.e_ray.1, 3)
    ));
    out.push(format!(
        "moving vehicles: {}; mapped as a static ellipsoid {}, flagged dynamic {}",
        f.moving.0, f.moving.1, f.moving.2
    ));
}

/// The main job's summary line and its table of vehicles against the street, with the street-side count.
fn street_lines(s: &StreetRow, out: &mut Vec<String>) {
    out.push(format!(
        "main job (odometry 06, frames 0-50): {} static objects with an ellipsoid, {} dynamic; object stage {} ms a keyframe that ran a fit (median of {}), {} frames/s",
        s.static_objects,
        s.dynamic,
        cell(s.object_ms.0, 1),
        s.object_ms.1,
        cell(s.fps, 1)
    ));
    out.push("| vehicle | along the street m | from the path m | angle to the street deg |".into());
    out.push("|---|---:|---:|---:|".into());
    for (id, name, lateral, angle, along) in &s.cars {
        let tag = if *lateral <= STREET_SIDE_M { "street side" } else { "off the street" };
        out.push(format!("| #{id} {name} ({tag}) | {along:.1} | {lateral:.1} | {} |", cell(*angle, 1)));
    }
    let side: Vec<f64> = s.cars.iter().filter(|c| c.2 <= STREET_SIDE_M).filter_map(|c| c.3).collect();
    out.push(format!(
        "street-side cars (within {STREET_SIDE_M} m of the path): {}, largest angle to the street {} deg",
        side.len(),
        cell(side.iter().copied().reduce(f64::max), 1)
    ));
}
