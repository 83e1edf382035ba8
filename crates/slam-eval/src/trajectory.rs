//! A trajectory file against ground truth (`slam-app trajectory-eval`): KITTI or TUM files, matched by
//! time (two TUM files) or by line, both started at the identity at the first matched pair, then ATE,
//! drift and RPE ([`crate::trajectory_errors::trajectory_errors`]).

use std::{collections::BTreeMap, path::Path};

use crate::{
    trajectory_errors::{trajectory_errors, TrajectoryErrors},
    EvalError,
};
use nalgebra::Isometry3;

/// A pose file: KITTI poses, or TUM times and poses.
pub enum PoseFile {
    /// KITTI: 12 numbers per line (3×4 row-major, camera to world), no times.
    Kitti(Vec<Isometry3<f64>>),
    /// TUM: `time tx ty tz qx qy qz qw` per line, in time order (a file whose lines are not is sorted:
    /// a path, a drift and an RPE follow the poses in time, not in the file's line order).
    Tum(Vec<f64>, Vec<Isometry3<f64>>),
}

/// TUM times and poses in time order; whether the file's lines were not.
fn in_time_order(t: Vec<f64>, p: Vec<Isometry3<f64>>) -> (Vec<f64>, Vec<Isometry3<f64>>, bool) {
    if t.windows(2).all(|w| w[0] < w[1]) {
        return (t, p, false);
    }
    let mut order: Vec<usize> = (0..t.len()).collect();
    order.sort_by(|&a, &b| t[a].total_cmp(&t[b]));
    (order.iter().map(|&k| t[k]).collect(), order.iter().map(|&k| p[k]).collect(), true)
}

impl PoseFile {
    /// Read a KITTI or TUM file, told apart by the number of fields of the first data line.
    pub fn read(path: &Path) -> Result<Self, EvalError> {
        Self::read_noting(path).map(|(f, _)| f)
    }

    /// [`PoseFile::read`], and a note when a TUM file's lines were not in time order (they are sorted).
    pub fn read_noting(path: &Path) -> Result<(Self, Option<String>), EvalError> {
        let text = slam_core::files::read_text(path, &slam_core::files::TABLE)?;
        let first = text.lines().enumerate().find(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
        let fields = first.map_or(0, |(_, l)| l.split_whitespace().count());
        Ok(match fields {
            12 => (PoseFile::Kitti(slam_dataset::kitti::poses::parse_kitti_poses(path, &text)?), None),
            8 => {
                let (t, p) = slam_dataset::trajectory::parse_tum(path, &text)?;
                let (t, p, sorted) = in_time_order(t, p);
                let note = sorted.then(|| {
                    format!(
                        "note: the lines of {} are not in time order: its poses are taken in time order",
                        path.display()
                    )
                });
                (PoseFile::Tum(t, p), note)
            }
            n => {
                // a comma-separated first line is a table (e.g. a run's tracking.csv), not a trajectory
                let csv = first.is_some_and(|(_, l)| l.contains(','));
                return Err(EvalError::Invalid(format!(
                    "{}:{}: {n} whitespace-separated fields: a trajectory line has 12 (KITTI) or 8 (TUM){}",
                    path.display(),
                    first.map_or(1, |(k, _)| k + 1),
                    if csv {
                        " (this looks like a comma-separated table; a run writes trajectory.kitti.txt and trajectory.tum.txt)"
                    } else {
                        ""
                    }
                )));
            }
        })
    }

    /// The same file with only the poses at `keep` (positions, in order; out-of-range ones skipped).
    pub fn subset(&self, keep: &[usize]) -> PoseFile {
        let pick = |v: &[Isometry3<f64>]| keep.iter().filter_map(|&k| v.get(k).copied()).collect::<Vec<_>>();
        match self {
            PoseFile::Kitti(p) => PoseFile::Kitti(pick(p)),
            PoseFile::Tum(t, p) => PoseFile::Tum(keep.iter().filter_map(|&k| t.get(k).copied()).collect(), pick(p)),
        }
    }

    /// The poses.
    pub fn poses(&self) -> &[Isometry3<f64>] {
        match self {
            PoseFile::Kitti(p) | PoseFile::Tum(_, p) => p,
        }
    }
}

/// Pairs `(estimate index, ground-truth index)`: each estimated time to the nearest ground-truth time
/// within `max_diff` seconds (ground truth sorted by time first; each ground-truth pose used once, by the
/// estimate nearest to it).
pub fn match_by_time(est: &[f64], gt: &[f64], max_diff: f64) -> Vec<(usize, usize)> {
    let mut order: Vec<usize> = (0..gt.len()).collect();
    order.sort_by(|&a, &b| gt[a].total_cmp(&gt[b]));
    let mut best: BTreeMap<usize, (f64, usize)> = BTreeMap::new();
    for (i, &t) in est.iter().enumerate() {
        let k = order.partition_point(|&j| gt[j] < t);
        let near = [k.checked_sub(1), Some(k)]
            .into_iter()
            .flatten()
            .filter_map(|k| order.get(k).copied())
            .min_by(|&a, &b| (gt[a] - t).abs().total_cmp(&(gt[b] - t).abs()));
        if let Some(j) = near {
            let d = (gt[j] - t).abs();
            if d <= max_diff && best.get(&j).is_none_or(|b| d < b.0) {
                best.insert(j, (d, i));
            }
        }
    }
    let mut pairs: Vec<(usize, usize)> = best.into_iter().map(|(j, (_, i))| (i, j)).collect();
    pairs.sort();
    pairs
}

/// The matched poses of an estimate and its ground truth, and their errors.
pub struct Comparison {
    /// Pairs `(estimate index, ground-truth index)`.
    pub pairs: Vec<(usize, usize)>,
    /// How the poses were matched, for the report.
    pub how: String,
    /// ATE, drift and RPE over `lengths` (`None`: fewer than two matched poses).
    pub errors: Option<TrajectoryErrors>,
}

/// Match `est` to `gt` (by timestamp within `max_diff` seconds when both are TUM, else by line), start
/// both at the identity at the first matched pair, as KITTI's and our files do, and measure the errors
/// with RPE over segments of `lengths` metres.
pub fn compare(est: &PoseFile, gt: &PoseFile, max_diff: f64, lengths: &[f64]) -> Comparison {
    let (pairs, how) = match (est, gt) {
        (PoseFile::Tum(te, _), PoseFile::Tum(tg, _)) => {
            (match_by_time(te, tg, max_diff), format!("by timestamp (nearest within {max_diff} s)"))
        }
        _ => {
            let n = est.poses().len().min(gt.poses().len());
            let why = if matches!((est, gt), (PoseFile::Kitti(_), PoseFile::Kitti(_))) {
                "by line (KITTI files have no times)"
            } else {
                "by line (one file is KITTI, which has no times)"
            };
            ((0..n).map(|i| (i, i)).collect(), why.to_string())
        }
    };
    let pick = |v: &[Isometry3<f64>], first: bool| -> Vec<Isometry3<f64>> {
        let k = |&(i, j): &(usize, usize)| if first { i } else { j };
        let origin = pairs.first().map(|p| v[k(p)]).unwrap_or_else(Isometry3::identity).inverse();
        pairs.iter().map(|p| origin * v[k(p)]).collect()
    };
    let errors = trajectory_errors(&pick(est.poses(), true), &pick(gt.poses(), false), lengths);
    Comparison { pairs, how, errors }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    /// A run's tracking.csv given as a trajectory: the error names the line and says what the file is.
    #[test]
    fn a_csv_table_is_not_read_as_a_trajectory() {
        let dir = std::env::temp_dir().join(format!("traj-csv-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let path = dir.join("tracking.csv");
        std::fs::write(&path, "# note\nframe,state,inliers\n0,initialised,0\n").expect("write");
        let e = PoseFile::read(&path).err().expect("not a trajectory").to_string();
        assert!(e.contains("tracking.csv:2:") && e.contains("comma-separated table"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn times_match_nearest_within_the_limit_each_truth_once() {
        // estimates at 0.0, 0.1, 0.102, 0.5; truth (unsorted) at 0.1, 0.0, 0.3
        let pairs = match_by_time(&[0.0, 0.1, 0.102, 0.5], &[0.1, 0.0, 0.3], 0.01);
        // 0.1 and 0.102 both want truth 0.1: the nearer (0.1) wins; 0.5 has nothing within 0.01 s
        assert_eq!(pairs, [(0, 1), (1, 0)]);
        assert!(match_by_time(&[1.0], &[], 0.01).is_empty());
    }

    #[test]
    fn an_offset_copy_of_the_truth_has_no_error() {
        let truth: Vec<Isometry3<f64>> = (0..20)
            .map(|i| {
                let yaw = UnitQuaternion::from_euler_angles(0.0, 0.02 * i as f64, 0.0);
                Isometry3::from_parts(Translation3::new(0.1 * i as f64, 0.0, 1.0 * i as f64), yaw)
            })
            .collect();
        // the estimate starts elsewhere (another world frame): both are started at the identity first
        let shift = Isometry3::translation(5.0, 1.0, -3.0);
        let est: Vec<Isometry3<f64>> = truth.iter().map(|p| shift * p).collect();
        let times: Vec<f64> = (0..20).map(|i| 0.1 * i as f64).collect();
        let c = compare(&PoseFile::Tum(times.clone(), est.clone()), &PoseFile::Tum(times, truth.clone()), 0.01, &[5.0]);
        assert_eq!(c.pairs.len(), 20);
        assert!(c.how.starts_with("by timestamp"));
        let e = c.errors.expect("errors");
        assert!(e.ate_m < 1e-9 && e.end_drift_pct.abs() < 1e-9, "{} {}", e.ate_m, e.end_drift_pct);
        let c = compare(&PoseFile::Kitti(est), &PoseFile::Kitti(truth[..1].to_vec()), 0.01, &[]);
        assert_eq!(c.pairs.len(), 1);
        assert!(c.errors.is_none(), "one pair is too few");
    }
}
