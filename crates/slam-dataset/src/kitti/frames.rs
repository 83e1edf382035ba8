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
    /// Ids between the first and the last one with no image in either camera.
    pub gaps: Vec<usize>,
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
    let (first, last) = (out.ids[0], out.ids[out.ids.len() - 1]);
    out.gaps = (first..=last).filter(|id| !ids.contains(id)).collect();
    for run in runs(&out.gaps) {
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

/// Consecutive runs `(first, last)` of sorted ids.
pub(crate) fn runs(ids: &[usize]) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for &id in ids {
        match out.last_mut() {
            Some((_, b)) if *b + 1 == id => *b = id,
            _ => out.push((id, id)),
        }
    }
    out
}

/// The values of the given frame ids from a per-frame file whose `k`-th value is frame `k` (KITTI's
/// `times.txt`, `timestamps.txt`, `poses/NN.txt`). A file with more lines than frames is fine (an
/// excerpt of a longer sequence); one that stops before the last frame id is an error naming the file
/// and both counts.
pub fn values_of_ids<T: Clone>(all: &[T], ids: &[usize], path: &Path, what: &str) -> Result<Vec<T>, DatasetError> {
    match ids.iter().max() {
        Some(&last) if last >= all.len() => Err(DatasetError::Invalid {
            path: path.to_path_buf(),
            message: format!(
                "{} {what} but the images go up to frame {last}: line k of this file is frame k, so it needs at \
                 least {} lines",
                all.len(),
                last + 1
            ),
        }),
        _ => Ok(ids.iter().map(|&i| all[i].clone()).collect()),
    }
}

/// Frame times of a sequence without a time file: KITTI's nominal 10 Hz, by frame id.
pub(crate) fn nominal_times(ids: &[usize]) -> Vec<f64> {
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
