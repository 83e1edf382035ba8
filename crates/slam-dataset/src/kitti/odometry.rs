//! KITTI odometry sequences: `sequences/NN/{calib.txt, times.txt, image_0/, image_1/, image_2/,
//! image_3/}` and optional ground truth `poses/NN.txt` beside `sequences/`.

use std::{
    collections::{BTreeMap, BTreeSet},
    path::{Path, PathBuf},
};

use nalgebra::{Isometry3, Matrix3x4};

use crate::{
    kitti::{calib::Calib, poses::read_kitti_poses},
    read_text, DatasetError,
};

/// A sequence on disk (images are listed, not decoded).
#[derive(Debug, Clone)]
pub struct OdometrySequence {
    /// The sequence folder (`…/sequences/NN`).
    pub dir: PathBuf,
    /// Grey left / right projection matrices `P0`, `P1` (required).
    pub p0: Matrix3x4<f64>,
    /// Right grey camera.
    pub p1: Matrix3x4<f64>,
    /// Colour cameras `P2`, `P3`, when the calibration has them.
    pub p_colour: Option<[Matrix3x4<f64>; 2]>,
    /// Velodyne-to-camera `Tr`, when present.
    pub tr: Option<Matrix3x4<f64>>,
    /// Frame id of each entry (the number in the image file names), increasing.
    pub ids: Vec<usize>,
    /// Frame time of each entry, seconds (line `id` of `times.txt`, else `0.1 · id`).
    pub times: Vec<f64>,
    /// Left grey image of each entry (for a frame whose left image is missing: the path it should have).
    pub left: Vec<PathBuf>,
    /// Right grey image of each entry (same rule).
    pub right: Vec<PathBuf>,
    /// Ground-truth camera-0-to-world pose of each entry (line `id` of `poses/NN.txt`), when that file
    /// exists and covers every frame.
    pub ground_truth: Option<Vec<Isometry3<f64>>>,
    /// Frame ids missing in both cameras between the first and the last frame (skipped, ids kept).
    pub gaps: Vec<usize>,
    /// Frame ids with one image missing (played as unreadable frames).
    pub one_camera: Vec<usize>,
    /// What was odd about the input and how it was handled (gaps, one-sided frames, files that are not
    /// frames, ground truth dropped), one sentence each; the caller logs them.
    pub warnings: Vec<String>,
}

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
    /// One sentence per oddity (see [`OdometrySequence::warnings`]).
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

impl OdometrySequence {
    /// Open `sequences/NN` (the folder containing `calib.txt`).
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let dir = dir.as_ref().to_path_buf();
        let calib = Calib::read(dir.join("calib.txt"))?;
        let p_colour = if calib.has("P2") && calib.has("P3") {
            Some([calib.matrix3x4("P2")?, calib.matrix3x4("P3")?])
        } else {
            None
        };
        let tr = if calib.has("Tr") { Some(calib.matrix3x4("Tr")?) } else { None };
        let pairs = pair_frames(&dir.join("image_0"), &dir.join("image_1"))?;
        let mut warnings = pairs.warnings;
        let times_path = dir.join("times.txt");
        let times = if times_path.exists() {
            let text = read_text(&times_path)?;
            let mut t: Vec<f64> = Vec::new();
            for (n, l) in crate::frame_lines(&times_path, &text)? {
                let v = crate::parse_numbers(&times_path, n, &[l.trim()])?;
                if let (Some(&now), Some(&before)) = (v.first(), t.last()) {
                    if now <= before {
                        return Err(DatasetError::Parse {
                            path: times_path.clone(),
                            line: n,
                            message: format!(
                                "time {now} s is not after the line before ({before} s): frames are in time order"
                            ),
                        });
                    }
                }
                t.extend(v);
            }
            values_of_ids(&t, &pairs.ids, &times_path, "times")?
        } else {
            warnings.push(nominal_times_note(&times_path));
            nominal_times(&pairs.ids)
        };
        let gt_path = dir
            .parent()
            .and_then(|seqs| seqs.parent())
            .zip(dir.file_name())
            .map(|(root, name)| root.join("poses").join(format!("{}.txt", name.to_string_lossy())));
        let ground_truth = match gt_path {
            Some(p) if p.exists() => match values_of_ids(&read_kitti_poses(&p)?, &pairs.ids, &p, "poses") {
                Ok(g) => Some(g),
                Err(e) => {
                    warnings.push(super::stereo::no_truth(e));
                    None
                }
            },
            Some(p) => {
                warnings.push(super::stereo::no_truth(format_args!("{} not found (no ATE/RPE)", p.display())));
                None
            }
            None => None,
        };
        Ok(Self {
            p0: calib.matrix3x4("P0")?,
            p1: calib.matrix3x4("P1")?,
            p_colour,
            tr,
            ids: pairs.ids,
            times,
            left: pairs.left,
            right: pairs.right,
            ground_truth,
            gaps: pairs.gaps,
            one_camera: pairs.one_camera,
            warnings,
            dir,
        })
    }

    /// Stereo baseline of the grey pair, metres (`−P1[0,3] / P1[0,0]`).
    pub fn baseline(&self) -> f64 {
        -self.p1[(0, 3)] / self.p1[(0, 0)]
    }
}
