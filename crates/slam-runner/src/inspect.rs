//! `map` (a saved map's counts and objects, and its exports) and `trajectory-eval` (ATE, drift and RPE of
//! a trajectory file against ground truth).

use std::path::{Path, PathBuf};

use slam_dataset::{
    output::{refuse_overwriting_inputs, AtomicFile, FilesInto, Written},
    trajectory::write_kitti_poses,
};
use slam_eval::trajectory::PoseFile;
use slam_pipeline::saved_map::SavedMap;

use crate::error::{Result, RunnerError};

/// RPE segment lengths of `trajectory-eval`, metres (KITTI's 100-800 m and shorter ones for excerpts).
pub const RPE_LENGTHS_M: [f64; 7] = [10.0, 20.0, 40.0, 100.0, 200.0, 400.0, 800.0];

/// The markdown table of `trajectory-eval`: poses compared, path, both ATEs, drift, scale and RPE.
fn error_table(e: &slam_eval::trajectory_errors::TrajectoryErrors) -> Vec<String> {
    let mut lines = vec!["| metric | value |\n|---|---:|".to_string()];
    lines.push(format!("| poses compared | {} |\n| path (ground truth) | {:.1} m |", e.frames, e.path_m));
    lines.push(format!(
        "| ATE (first poses aligned) | {:.3} m |\n| ATE (rigid alignment) | {:.3} m |",
        e.ate_m, e.ate_aligned_m
    ));
    // a ground truth that does not move has no path to divide by; without motion in both, no scale
    let scale = if e.scale.is_finite() { format!("{:.4}", e.scale) } else { "– (a trajectory does not move)".into() };
    lines.push(format!(
        "| end-point drift | {} |\n| scale (similarity fit) | {scale} |",
        crate::report::drift_text(e.end_drift_pct)
    ));
    for &(len, t, r, count) in &e.rpe {
        lines.push(format!("| RPE {len:.0} m ({count} segments) | {t:.2} % / {r:.2} deg/100 m |"));
    }
    lines
}

/// The `trajectory-eval` table of `estimate` against `truth` (TUM pairs matched within `max_diff` s):
/// a line on the matching, then a markdown table.
pub fn trajectory_eval(
    estimate: &Path,
    truth: &Path,
    max_diff: f64,
    selection: &slam_dataset::kitti::stereo::FrameSelection,
) -> Result<String> {
    let (est, est_note) = PoseFile::read_noting(estimate)?;
    let (all, truth_note) = PoseFile::read_noting(truth)?;
    // ground truth moves as a vehicle does: a step beyond its speed is a corrupt line, not a figure
    if let PoseFile::Kitti(p) = &all {
        slam_dataset::kitti::poses::check_pose_steps(truth, p).map_err(RunnerError::other)?;
    }
    // the ground truth's line k is frame id k: a run of a subset (`run --frames --stride`) is compared
    // with the same subset
    let whole = *selection == slam_dataset::kitti::stereo::FrameSelection::default();
    if !whole && matches!((&est, &all), (PoseFile::Tum(..), PoseFile::Tum(..))) {
        return Err(RunnerError::Invalid(
            "--frames/--stride pick ground-truth lines for matching by line; two TUM files are matched by \
             time and need none"
                .into(),
        ));
    }
    // the frame id of each ground-truth line kept (line k is frame k)
    let mut frame_ids: Vec<usize> = (0..all.poses().len()).collect();
    let gt = if whole {
        all
    } else {
        let ids: Vec<usize> = (0..all.poses().len()).collect();
        let keep = selection.kept(&ids);
        frame_ids = keep.clone();
        if keep.len() < 2 {
            return Err(RunnerError::Invalid(format!(
                "{} holds {} poses: {} keeps {} of them",
                truth.display(),
                ids.len(),
                selection.describe(),
                keep.len()
            )));
        }
        all.subset(&keep)
    };
    let mut lines: Vec<String> = est_note.into_iter().chain(truth_note).collect();
    // a TUM estimate carries times, a KITTI ground truth frame ids: give the ground truth its frames'
    // times and match by time (pairing by line ignores frames a run skipped or strode over)
    let gt = match (&est, gt) {
        (PoseFile::Tum(..), PoseFile::Kitti(poses)) => {
            let (times, source) = ground_truth_times(truth, &frame_ids)?;
            lines.push(format!(
                "ground truth {}: line k is frame id k, at {source}; matched to the TUM estimate by time",
                truth.display()
            ));
            PoseFile::Tum(times, poses)
        }
        (_, gt) => gt,
    };
    if !whole {
        lines.push(format!(
            "ground truth {}: {} only (its line k is frame id k)",
            truth.display(),
            selection.describe()
        ));
    }
    let c = slam_eval::trajectory::compare(&est, &gt, max_diff, &RPE_LENGTHS_M);
    lines.push(format!(
        "matched {} of {} estimated poses to the {} ground-truth poses {}",
        c.pairs.len(),
        est.poses().len(),
        gt.poses().len(),
        c.how
    ));
    let (ne, ng) = (est.poses().len(), gt.poses().len());
    if c.how.starts_with("by line") && ne != ng {
        lines.push(format!(
            "note: the estimate holds {ne} poses and the ground truth {ng}: the last {} of the {} have no partner. Matched by line, pose i is compared with pose i: check that both files are of the same sequence and start at the same frame",
            ne.abs_diff(ng),
            if ne > ng { "estimate" } else { "ground truth" }
        ));
    }
    let span = |f: &PoseFile, path: &Path| match f {
        PoseFile::Tum(t, _) if !t.is_empty() => {
            format!("{} spans times {} to {} s", path.display(), t[0], t[t.len() - 1])
        }
        _ => format!("{} holds {} poses", path.display(), f.poses().len()),
    };
    let e = c.errors.ok_or_else(|| {
        RunnerError::Invalid(format!(
            "fewer than two matched poses ({} matched {}): {}, {}{}",
            c.pairs.len(),
            c.how,
            span(&est, estimate),
            span(&gt, truth),
            if matches!((&est, &gt), (PoseFile::Tum(..), PoseFile::Tum(..))) {
                " (times in other units, e.g. nanoseconds against seconds, or of other clocks do not match)"
            } else {
                ""
            }
        ))
    })?;
    lines.extend(error_table(&e));
    let matched = |v: &[nalgebra::Isometry3<f64>], first: bool| -> Vec<nalgebra::Isometry3<f64>> {
        c.pairs.iter().map(|&(i, j)| v[if first { i } else { j }]).collect()
    };
    // the poses compared, named by frame id (a KITTI ground truth's line k is frame k) or by time (TUM)
    let (ids, times): (Vec<usize>, Vec<f64>) = c
        .pairs
        .iter()
        .map(|&(_, j)| {
            let time = if let PoseFile::Tum(t, _) = &gt { t.get(j).copied().unwrap_or(f64::NAN) } else { f64::NAN };
            (frame_ids.get(j).copied().unwrap_or(j), time)
        })
        .unzip();
    let names = match &gt {
        PoseFile::Tum(..) => crate::report::PoseNames::Times(&times),
        PoseFile::Kitti(_) => crate::report::PoseNames::Frames(&ids),
    };
    lines.extend(crate::report::interpolation_lines(&matched(est.poses(), true), &matched(gt.poses(), false), names));
    Ok(lines.join("\n"))
}

/// Times of the ground-truth frames `ids` of a KITTI pose file `truth`: the odometry layout's
/// `sequences/NN/times.txt` beside `poses/NN.txt` when there is one, else KITTI's nominal 0.1 s per
/// frame id; with a description of the source.
fn ground_truth_times(truth: &Path, ids: &[usize]) -> Result<(Vec<f64>, String)> {
    let times_file = truth
        .parent()
        .and_then(Path::parent)
        .zip(truth.file_stem())
        .map(|(root, stem)| root.join("sequences").join(stem).join("times.txt"))
        .filter(|p| p.is_file());
    match times_file {
        Some(p) => {
            let all = slam_dataset::kitti::frames::read_frame_times(&p).map_err(RunnerError::other)?;
            // the ground truth's lines ask for these frames, not images (none is read)
            let by = format!("the lines of the ground truth {}", truth.display());
            let times =
                slam_dataset::kitti::frames::values_of_ids(&all, ids, &p, "times", &by).map_err(RunnerError::other)?;
            Ok((times, format!("the times of {}", p.display())))
        }
        None => Ok((
            slam_dataset::kitti::frames::nominal_times(ids),
            "KITTI's nominal 0.1 s per frame id (no sequences/NN/times.txt beside it)".into(),
        )),
    }
}

/// A saved map's description: format, counts, and one line per object.
pub fn map_summary(map: &SavedMap, path: &Path) -> String {
    let s = map.stats();
    let mut lines = vec![
        format!("{} (format {} v{})", path.display(), map.format, map.version),
        format!(
            "frames {}, keyframes {} in {} segment(s), keyframe path {:.1} m, points {}, observations {} ({:.1} per point), objects {} ({} dynamic)",
            s.frames,
            s.keyframes,
            s.segments,
            s.keyframe_path_m,
            s.points,
            s.observations,
            s.observations as f64 / s.points.max(1) as f64,
            s.objects,
            s.dynamic_objects
        ),
    ];
    lines.push(match (&map.camera, &map.features) {
        (Some(c), Some(f)) => format!(
            "camera fx {:.4} fy {:.4} cx {:.4} cy {:.4} px, baseline {:.6} m, images {}×{}; keyframe features in {} ({:.2} MB, read and checked when `run --map` loads the map)",
            c.fx, c.fy, c.cx, c.cy, c.baseline, c.width, c.height, f.file, f.bytes as f64 / 1e6
        ),
        _ => format!("no keyframe features (format version {}; a map written before version 4, or without keyframes): inspected and exported, not tracked against", map.version),
    });
    for o in &map.objects {
        lines.push(format!(
            "object {:>3} class {:>2} {:<10} centre [{:7.2} {:6.2} {:7.2}] m, semi-axes [{:.2} {:.2} {:.2}] m, frames {:>3}{}{}",
            o.id,
            o.class,
            slam_core::ClassId(o.class).name(),
            o.center[0],
            o.center[1],
            o.center[2],
            o.semi_axes[0],
            o.semi_axes[1],
            o.semi_axes[2],
            o.frames.len(),
            if o.earlier_views > 0 { format!(" (+{} boxes of earlier runs)", o.earlier_views) } else { String::new() },
            match slam_viz::ObjectState::of(o.dynamic, o.moving) {
                slam_viz::ObjectState::Static => "",
                slam_viz::ObjectState::Dynamic => " dynamic",
                slam_viz::ObjectState::Moving => " moving (not mapped)",
            }
        ));
    }
    lines.join("\n")
}

/// What to export from a saved map (each optional).
#[derive(Debug, Clone, Default)]
pub struct MapExports {
    /// Map points as a PLY point cloud.
    pub ply: Option<PathBuf>,
    /// The 3-D scene as a PLY mesh.
    pub scene: Option<PathBuf>,
    /// The per-frame trajectory, KITTI format.
    pub trajectory: Option<PathBuf>,
    /// A folder for the top-down map picture (SVG + PNG).
    pub picture: Option<PathBuf>,
}

/// The exports of a map with every destination checked (files writable, the picture folder holding no
/// file of the picture's names that this program did not write), before the map is read.
pub struct PreparedExports {
    ply: Option<(PathBuf, AtomicFile)>,
    scene: Option<(PathBuf, AtomicFile)>,
    trajectory: Option<(PathBuf, AtomicFile)>,
    picture: Option<FilesInto>,
}

impl MapExports {
    /// Refuse destinations (these exports and a recording at `rerun`) that would overwrite the map at
    /// `map`, each named by its option.
    pub fn refuse_overwriting(&self, map: &Path, rerun: Option<&Path>) -> Result<()> {
        let pictures: Vec<PathBuf> =
            self.picture.iter().flat_map(|d| slam_viz::MAP_PICTURE_FILES.map(|n| d.join(n))).collect();
        let mut outputs: Vec<Written> =
            [("--ply", &self.ply), ("--scene", &self.scene), ("--trajectory", &self.trajectory)]
                .into_iter()
                .filter_map(|(option, p)| p.as_deref().map(|p| Written::File(option, p)))
                .collect();
        outputs.extend(pictures.iter().map(|p| Written::File("--picture", p)));
        outputs.extend(rerun.map(|p| Written::File("--rerun", p)));
        // the features file is read beside the file the path leads to or under the map's own name
        let features = slam_pipeline::saved_map::features_places(map, "map.features");
        let mut inputs = vec![("the map", map)];
        inputs.extend(features.iter().map(|f| ("the map's features", f.as_path())));
        Ok(refuse_overwriting_inputs(&inputs, &outputs)?)
    }

    /// Check every destination before any work (`map --ply/--scene/--trajectory/--picture`).
    pub fn prepare(&self) -> Result<PreparedExports> {
        let file = |p: &Option<PathBuf>| -> Result<Option<(PathBuf, AtomicFile)>> {
            p.as_ref().map(|p| Ok((p.clone(), AtomicFile::new(p)?))).transpose()
        };
        Ok(PreparedExports {
            ply: file(&self.ply)?,
            scene: file(&self.scene)?,
            trajectory: file(&self.trajectory)?,
            picture: self
                .picture
                .as_deref()
                .map(|d| FilesInto::new(d, &slam_viz::MAP_PICTURE_FILES, "--picture", "map"))
                .transpose()?,
        })
    }
}

/// Write the exports of `map` (loaded from `path`); `wrote` gets a line per file written, as it is.
pub fn export_map(map: &SavedMap, path: &Path, x: PreparedExports, wrote: &mut dyn FnMut(String)) -> Result<()> {
    if let Some((p, f)) = x.ply {
        f.write_with(|tmp| crate::map_export::export_points_ply(map, tmp))?;
        wrote(format!("wrote {}", p.display()));
    }
    if let Some((p, f)) = x.scene {
        let mut counts = None;
        f.write_with(|tmp| crate::map_export::export_scene_ply(map, tmp).map(|s| counts = Some(s)))?;
        if let Some(s) = counts {
            wrote(format!(
                "wrote {}: {} ellipsoids, {} camera frusta, {} trajectory vertices, {} points ({} vertices, {} faces, {} edges)",
                p.display(),
                s.ellipsoids,
                s.cameras,
                s.trajectory,
                s.points,
                s.vertices,
                s.faces,
                s.edges
            ));
        }
    }
    // frames not placed in a loaded map have no pose: left out, as the run's own trajectory files do
    let poses: Vec<nalgebra::Isometry3<f64>> = map.frame_poses().into_iter().flatten().collect();
    let placed = map.trajectory.iter().filter(|f| f.keyframe.is_some()).count();
    if let Some((p, f)) = x.trajectory {
        if poses.len() != placed {
            return Err(RunnerError::Invalid(format!(
                "{}: {} frames refer to missing keyframes",
                path.display(),
                placed - poses.len()
            )));
        }
        f.write_with(|tmp| write_kitti_poses(tmp, &poses))?;
        let unplaced = map.trajectory.len() - placed;
        let note = if unplaced > 0 { format!(" ({unplaced} frames without a pose left out)") } else { String::new() };
        wrote(format!("wrote {}{note}", p.display()));
    }
    if let Some(into) = x.picture {
        // each picture is written whole (beside its final name, then renamed): the folder may hold other files
        for f in into.write_with(|tmp| slam_viz::map_picture(map, &poses, None, tmp).map(|_| ()))? {
            wrote(format!("wrote {}", f.display()));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    use slam_dataset::kitti::stereo::FrameSelection;

    fn write_kitti(path: &Path, xs: &[f64]) {
        let text: String = xs.iter().map(|x| format!("1 0 0 {x} 0 1 0 0 0 0 1 0\n")).collect();
        std::fs::write(path, text).expect("write");
    }

    #[test]
    fn trajectory_eval_reports_a_scaled_estimate_and_refuses_one_pose() {
        let dir = std::env::temp_dir().join(format!("slam-runner-traj-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let (est, gt, one) = (dir.join("est.txt"), dir.join("gt.txt"), dir.join("one.txt"));
        let truth: Vec<f64> = (0..20).map(|i| i as f64).collect();
        // the estimate is 1 % short: scale 1.01 fits it, end-point drift 1 % of 19 m
        write_kitti(&est, &truth.iter().map(|x| 0.99 * x).collect::<Vec<_>>());
        write_kitti(&gt, &truth);
        write_kitti(&one, &[0.0]);
        let all = FrameSelection::default();
        let table = trajectory_eval(&est, &gt, 0.01, &all).expect("evaluates");
        assert!(table.starts_with("matched 20 of 20 estimated poses"), "{table}");
        assert!(table.contains("| path (ground truth) | 19.0 m |"), "{table}");
        assert!(table.contains("| end-point drift | 1.00 % |"), "{table}");
        let e = trajectory_eval(&one, &gt, 0.01, &all).expect_err("one pose").to_string();
        assert!(e.contains("fewer than two matched poses"), "{e}");
        // a run of every 3rd frame from frame 2 (ids 2, 5, ..., 17): compared with those ground-truth
        // lines, the exact estimate has no error; against the first six lines it would
        let strided = dir.join("strided.txt");
        write_kitti(&strided, &(2..20).step_by(3).map(|i| i as f64 - 2.0).collect::<Vec<_>>());
        let every_3rd = FrameSelection { first: Some(2), end: None, stride: 3 };
        let table = trajectory_eval(&strided, &gt, 0.01, &every_3rd).expect("evaluates");
        assert!(table.contains("| ATE (first poses aligned) | 0.000 m |"), "{table}");
        assert!(table.contains("| path (ground truth) | 15.0 m |"), "{table}");
        let by_line = trajectory_eval(&strided, &gt, 0.01, &all).expect("evaluates");
        assert!(!by_line.contains("| ATE (first poses aligned) | 0.000 m |"), "{by_line}");
        let none = FrameSelection { first: Some(30), end: None, stride: 1 };
        let e = trajectory_eval(&strided, &gt, 0.01, &none).expect_err("no lines").to_string();
        assert!(e.contains("keeps 0 of them"), "{e}");
        // two TUM files are matched by time: a selection of lines is refused
        let tum = dir.join("gt.tum");
        let text: String = (0..20).map(|i| format!("{:.1} {i} 0 0 0 0 0 1\n", 0.1 * i as f64)).collect();
        std::fs::write(&tum, text).expect("write");
        let e = trajectory_eval(&tum, &tum, 0.01, &every_3rd).expect_err("TUM with lines").to_string();
        assert!(e.contains("matched by time"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
