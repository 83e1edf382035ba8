//! What the frames of every KITTI layout share: the two cameras' images paired by the frame id in their
//! names ([`pair_frames`]), values of per-frame files taken by frame id ([`values_of_ids`], nominal times
//! without a time file), and the wording of the sequence warnings that say there is no ground truth
//! ([`no_truth`]). The odometry, raw and tracking readers ([`super::odometry`], [`super::stereo`]) use it;
//! it uses none of them.

use std::{
    collections::{BTreeMap, BTreeSet},
    path::{Path, PathBuf},
};

use crate::DatasetError;

/// The frame id a KITTI image (or OXTS packet) file name carries: its stem as a decimal number
/// (`000042.png` → 42); `None` when the stem is not a number.
pub fn frame_id(path: &Path) -> Option<usize> {
    let stem = path.file_stem()?.to_str()?;
    if stem.is_empty() || !stem.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    stem.parse().ok()
}

/// The stereo frames of two camera folders, paired by frame id.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FramePairs {
    /// Frame ids, increasing: every id with at least one image.
    pub ids: Vec<usize>,
    /// Left image of each id (the expected path when only the right one exists).
    pub left: Vec<PathBuf>,
    /// Right image of each id (the expected path when only the left one exists).
    pub right: Vec<PathBuf>,
    /// Ids between the first and the last one with no image in either camera, as runs.
    pub gaps: IdRuns,
    /// Ids with an image in one camera only.
    pub one_camera: Vec<usize>,
    /// One sentence per oddity (see [`super::odometry::OdometrySequence::warnings`]).
    pub warnings: Vec<String>,
}

fn images_by_id(dir: &Path, warnings: &mut Vec<String>) -> Result<BTreeMap<usize, PathBuf>, DatasetError> {
    let mut out = BTreeMap::new();
    for p in list_images(dir)? {
        match frame_id(&p) {
            Some(id) => {
                if let Some(old) = out.insert(id, p.clone()) {
                    return Err(DatasetError::Invalid {
                        path: dir.to_path_buf(),
                        message: format!("{} and {} are both frame {id}", old.display(), p.display()),
                    });
                }
            }
            None => warnings.push(format!("{}: the file name is not a frame number; ignored", p.display())),
        }
    }
    Ok(out)
}

/// Pair the PNG images of a left and a right camera folder by the frame id in their names (never by
/// position). A frame missing in both cameras is a gap: it is skipped and the others keep their ids. A
/// frame missing in one camera is kept, with the path its missing image should have, so that reading it
/// fails and the frame is played as unreadable. Both cases are listed in the warnings. Errors: no
/// image at all, no frame with both images, two files of one frame.
pub fn pair_frames(left_dir: &Path, right_dir: &Path) -> Result<FramePairs, DatasetError> {
    let mut warnings = Vec::new();
    let l = images_by_id(left_dir, &mut warnings)?;
    let r = images_by_id(right_dir, &mut warnings)?;
    let ids: BTreeSet<usize> = l.keys().chain(r.keys()).copied().collect();
    if ids.is_empty() {
        return Err(DatasetError::Invalid { path: left_dir.to_path_buf(), message: "no PNG images".into() });
    }
    if !l.keys().any(|id| r.contains_key(id)) {
        return Err(DatasetError::Invalid {
            path: left_dir.to_path_buf(),
            message: format!(
                "no frame has both a left and a right image ({} left images, {} right images in {})",
                l.len(),
                r.len(),
                right_dir.display()
            ),
        });
    }
    let mut out = FramePairs::default();
    let expected =
        |dir: &Path, other: &Path| other.file_name().map(|n| dir.join(n)).unwrap_or_else(|| dir.to_path_buf());
    for &id in &ids {
        let (lp, rp) = match (l.get(&id), r.get(&id)) {
            (Some(a), Some(b)) => (a.clone(), b.clone()),
            (Some(a), None) => (a.clone(), expected(right_dir, a)),
            (None, Some(b)) => (expected(left_dir, b), b.clone()),
            (None, None) => continue,
        };
        if !(l.contains_key(&id) && r.contains_key(&id)) {
            let missing = if l.contains_key(&id) { &rp } else { &lp };
            warnings.push(format!(
                "frame {id}: {} is missing; the frame is played as unreadable (it keeps the previous pose)",
                missing.display()
            ));
            out.one_camera.push(id);
        }
        out.ids.push(id);
        out.left.push(lp);
        out.right.push(rp);
    }
    // the missing ids as runs between neighbours: memory in proportion to the frames that exist, however
    // far apart their ids are (one image named 4294967296.png among frames 0-3 is one run)
    out.gaps = IdRuns::between(&out.ids);
    for &run in out.gaps.runs() {
        warnings.push(format!(
            "frame{} missing in both cameras: skipped; the other frames keep their ids (ground truth, labels and \
             detections stay aligned)",
            match run {
                (a, b) if a == b => format!(" {a}"),
                (a, b) => format!("s {a}..={b}"),
            }
        ));
    }
    out.warnings = warnings;
    Ok(out)
}

/// Frame ids as inclusive runs `(first, last)`, increasing and apart (two runs never touch): the
/// memory is in proportion to the runs, not to the ids they hold.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct IdRuns(Vec<(usize, usize)>);

impl IdRuns {
    /// The ids missing between neighbours of `ids` (increasing): a run `(a + 1, b − 1)` for each pair
    /// of neighbours `a`, `b` more than one apart.
    pub fn between(ids: &[usize]) -> Self {
        Self(ids.windows(2).filter(|w| w[1] > w[0] + 1).map(|w| (w[0] + 1, w[1] - 1)).collect())
    }

    /// The runs, increasing.
    pub fn runs(&self) -> &[(usize, usize)] {
        &self.0
    }

    /// Whether there is no id.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// How many ids the runs hold (at most `u64::MAX`).
    pub fn count(&self) -> u64 {
        self.0.iter().fold(0u64, |n, &(a, b)| n.saturating_add((b - a) as u64).saturating_add(1))
    }

    /// Whether `id` lies in a run.
    pub fn contains(&self, id: usize) -> bool {
        let k = self.0.partition_point(|&(_, b)| b < id);
        self.0.get(k).is_some_and(|&(a, _)| a <= id)
    }

    /// The ids in `first..=last` (runs cut at both ends).
    pub fn within(&self, first: usize, last: usize) -> Self {
        Self(
            self.0
                .iter()
                .filter(|&&(a, b)| b >= first && a <= last)
                .map(|&(a, b)| (a.max(first), b.min(last)))
                .collect(),
        )
    }
}

/// The values of the given frame ids from a per-frame file whose `k`-th value is frame `k` (KITTI's
/// `times.txt`, `timestamps.txt`, `poses/NN.txt`). A file with more lines than frames is fine (an
/// excerpt of a longer sequence); one that stops before the last frame id is an error naming the file,
/// both counts and what asks for the frames (`by`: "the images", or a ground-truth file).
pub fn values_of_ids<T: Clone>(
    all: &[T],
    ids: &[usize],
    path: &Path,
    what: &str,
    by: &str,
) -> Result<Vec<T>, DatasetError> {
    match ids.iter().max() {
        Some(&last) if last >= all.len() => Err(DatasetError::Invalid {
            path: path.to_path_buf(),
            message: format!(
                "{} {what} but {by} go up to frame {last}: line k of this file is frame k, so it needs at \
                 least {} lines",
                all.len(),
                // the largest id has no usize after it
                last as u128 + 1
            ),
        }),
        _ => Ok(ids.iter().map(|&i| all[i].clone()).collect()),
    }
}

/// Shortest time between two frames of a time file's consecutive lines, seconds: no stereo camera on a
/// vehicle records a thousand frames a second (KITTI's record ten); closer times are not times (other
/// units, a corrupt line), and a tracker whose motion limits scale with them would accept no motion.
pub const MIN_FRAME_INTERVAL_S: f64 = 1e-3;

/// The message of two frame times closer than [`MIN_FRAME_INTERVAL_S`].
pub(crate) fn too_close(dt: f64) -> String {
    format!(
        "{dt:.3e} s after the line before: frames of a camera are at least {MIN_FRAME_INTERVAL_S} s apart (a thousand a second; KITTI records ten)"
    )
}

/// Longest time between two consecutive frames of one recording, seconds: a camera that stopped for
/// more than an hour made two recordings, and a time file saying so holds another clock's times or a
/// corrupt line (`1e300`; a date a year on).
pub const MAX_FRAME_GAP_S: f64 = 3600.0;

/// Largest time a `times.txt` line may hold, seconds: 1e10 s is 317 years, past any clock a recording
/// counts from (a Unix time is 1.8e9 s now; KITTI's count from the sequence's start).
pub const MAX_FRAME_TIME_S: f64 = 1e10;

/// Why frame time `now` (seconds) cannot follow `before` on the line before in a time file: not after
/// it, closer than [`MIN_FRAME_INTERVAL_S`], or further than [`MAX_FRAME_GAP_S`]; `None` when it can.
pub(crate) fn next_time_error(before: f64, now: f64) -> Option<String> {
    if now <= before {
        Some(format!("time {now} s is not after the line before ({before} s): frames are in time order"))
    } else if now - before < MIN_FRAME_INTERVAL_S {
        Some(too_close(now - before))
    } else if now - before > MAX_FRAME_GAP_S {
        Some(format!(
            "{:.3e} s after the line before: consecutive frames of one recording are at most {MAX_FRAME_GAP_S} s (an hour) apart",
            now - before
        ))
    } else {
        None
    }
}

/// Read a KITTI odometry `times.txt` (one time in seconds per line, line k being frame k), each line
/// checked: finite, at most [`MAX_FRAME_TIME_S`], after the line before by [`next_time_error`]'s rules.
pub fn read_frame_times(path: &Path) -> Result<Vec<f64>, DatasetError> {
    let text = crate::read_text(path, &slam_core::files::TABLE)?;
    let mut t: Vec<f64> = Vec::new();
    for (n, l) in crate::frame_lines(path, &text)? {
        let err = |message: String| DatasetError::Parse { path: path.to_path_buf(), line: n, message };
        let v = crate::parse_numbers(path, n, &[l.trim()])?;
        for &now in &v {
            if now.abs() > MAX_FRAME_TIME_S {
                return Err(err(format!(
                    "time {now:e} s: a frame time is at most {MAX_FRAME_TIME_S:e} s (317 years) from its clock's origin"
                )));
            }
            if let Some(m) = t.last().and_then(|&before| next_time_error(before, now)) {
                return Err(err(m));
            }
            t.push(now);
        }
    }
    Ok(t)
}

/// Frame times of a sequence without a time file: KITTI's nominal 10 Hz, by frame id.
pub fn nominal_times(ids: &[usize]) -> Vec<f64> {
    ids.iter().map(|&i| 0.1 * i as f64).collect()
}

/// The warning of a sequence whose time file `missing` is absent.
pub(crate) fn nominal_times_note(missing: &Path) -> String {
    format!("{} is missing: frame times are KITTI's nominal 0.1 s per frame id", missing.display())
}

pub(crate) fn list_images(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    let rd = std::fs::read_dir(dir).map_err(|source| DatasetError::Io { path: dir.to_path_buf(), source })?;
    let mut v: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
        .collect();
    v.sort();
    Ok(v)
}

/// How every warning that a sequence has no ground truth starts ([`no_truth`]).
const NO_TRUTH: &str = "no ground truth:";

/// The warning that a sequence has no ground truth, and why.
pub(crate) fn no_truth(why: impl std::fmt::Display) -> String {
    format!("{NO_TRUTH} {why}")
}

/// Whether a sequence warning is one that says there is no ground truth ([`no_truth`]): commands that
/// compute no ATE leave it out.
pub fn is_no_truth_warning(w: &str) -> bool {
    w.starts_with(NO_TRUTH)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn touch(dir: &Path, ids: &[usize]) {
        std::fs::create_dir_all(dir).expect("dir");
        for i in ids {
            std::fs::write(dir.join(format!("{i:06}.png")), b"").expect("file");
        }
    }

    #[test]
    fn a_per_frame_file_shorter_than_the_largest_id_says_how_many_lines_without_overflow() {
        let e =
            values_of_ids(&[1.0, 2.0], &[0, usize::MAX], Path::new("t.txt"), "times", "the images").expect_err("short");
        assert!(e.to_string().contains("at least 18446744073709551616 lines"), "{e}");
        assert_eq!(values_of_ids(&[1.0, 2.0], &[1], Path::new("t.txt"), "times", "the images").expect("fits"), [2.0]);
    }

    #[test]
    fn pairs_by_id_with_gaps_as_runs_whatever_the_ids() {
        let root = std::env::temp_dir().join(format!("frames-pairs-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let (l, r) = (root.join("l"), root.join("r"));
        // frames 0-3, 6 and one named 4294967296 (2³²); frame 2 only on the left
        touch(&l, &[0, 1, 2, 3, 6, 1 << 32]);
        touch(&r, &[0, 1, 3, 6, 1 << 32]);
        let p = pair_frames(&l, &r).expect("pairs");
        assert_eq!(p.ids, [0, 1, 2, 3, 6, 1 << 32]);
        assert_eq!(p.one_camera, [2]);
        assert_eq!(p.right[2], r.join("000002.png"), "the missing image's path");
        // two runs, not four billion ids
        assert_eq!(p.gaps.runs(), [(4, 5), (7, (1 << 32) - 1)]);
        assert_eq!(p.gaps.count(), 2 + (1 << 32) - 7);
        assert!(
            p.warnings.iter().any(|w| w.contains("frames 7..=4294967295 missing in both cameras")),
            "{:?}",
            p.warnings
        );
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn runs_count_clip_and_find_ids() {
        let g = IdRuns::between(&[0, 3, 4, 10, usize::MAX]);
        assert_eq!(g.runs(), [(1, 2), (5, 9), (11, usize::MAX - 1)]);
        assert_eq!(g.count(), u64::MAX - 11 + 7, "no overflow");
        assert!(g.contains(1) && g.contains(9) && g.contains(12) && !g.contains(3) && !g.contains(10));
        assert_eq!(g.within(2, 6).runs(), [(2, 2), (5, 6)]);
        assert!(g.within(3, 4).is_empty());
        assert!(IdRuns::between(&[4, 5, 6]).is_empty());
    }
}
