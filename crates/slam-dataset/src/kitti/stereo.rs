//! One view of every KITTI stereo layout: odometry (`sequences/NN`), raw (`<date>/<drive>_sync`) and
//! tracking (`training/image_02/NNNN`). [`open_stereo`] recognises which one a path is.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3x4};

use crate::{
    kitti::{
        calib::{rectified_pair, Calib},
        frames::{no_truth, nominal_times, nominal_times_note, pair_frames, values_of_ids, IdRuns},
        odometry::OdometrySequence,
        raw::{
            camera_poses_from_imu, camera_poses_from_oxts, check_oxts_steps, oxts_dead_reckoning, oxts_path_lengths,
            read_oxts_packet, read_timestamps, OxtsPath, RawCalib, OXTS_POS_ACCURACY,
        },
        tracking::{read_tracking_labels, TrackingLabel},
    },
    DatasetError,
};

pub use super::frames::is_no_truth_warning;

/// Which KITTI layout a sequence came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// Odometry benchmark: `sequences/NN/{calib.txt, image_0, image_1}` (+ `poses/NN.txt`).
    Odometry,
    /// Raw data: `<date>/<date>_drive_NNNN_sync/image_0{0,1,2,3}/data`, calibration in `<date>/`.
    Raw,
    /// Tracking benchmark: `training/{image_02,image_03}/NNNN`, `training/calib/NNNN.txt`.
    Tracking,
    /// A ROS 2 bag (`crate::recording`): an `.mcap` file or a rosbag2 folder.
    Bag,
    /// A folder of `left/` and `right/` images with a calibration file (`crate::recording`).
    Folder,
}

/// Where a sequence's ground-truth poses come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TruthSource {
    /// The odometry benchmark's `poses/NN.txt`.
    PosesFile,
    /// A raw drive's OXTS packets (GPS/IMU), converted as the KITTI devkit does.
    Oxts {
        /// Median of the packets' `pos_accuracy`, metres: the GPS position accuracy, below which
        /// position errors against this ground truth are not meaningful.
        median_pos_accuracy_m: f64,
        /// The path over the frames from the GPS positions and from the INS's velocities: where they
        /// disagree, so does the ground truth's scale ([`crate::kitti::raw::oxts_path_lengths`]).
        path: Option<OxtsPath>,
    },
}

impl TruthSource {
    /// The same source for a subset of the frames: without the OXTS path check, which covers the
    /// frames it was made from.
    pub fn for_a_subset(self) -> Self {
        match self {
            TruthSource::Oxts { median_pos_accuracy_m, .. } => TruthSource::Oxts { median_pos_accuracy_m, path: None },
            other => other,
        }
    }
}

/// A rectified stereo sequence, images listed (not decoded). Every per-frame vector has one entry per
/// frame, in frame-id order; `ids` says which frame each entry is (the number in the file names), so
/// ground truth, times, labels and detections stay aligned however frames are missing or selected.
#[derive(Debug, Clone)]
pub struct StereoSequence {
    /// Layout recognised.
    pub layout: Layout,
    /// The folder that was opened.
    pub dir: PathBuf,
    /// Frame id of each entry, increasing.
    pub ids: Vec<usize>,
    /// Left image of each entry (for a frame whose left image is missing: the path it should have, so
    /// reading it fails and the frame is played as unreadable).
    pub left: Vec<PathBuf>,
    /// Right image of each entry (same rule).
    pub right: Vec<PathBuf>,
    /// Intrinsics `[fx, fy, cx, cy]` of the rectified pair.
    pub intrinsics: [f64; 4],
    /// Baseline, metres.
    pub baseline: f64,
    /// Frame time of each entry, seconds (the time file's line `id`, else `0.1 · id`).
    pub times: Vec<f64>,
    /// Ground-truth pose of the left camera of each entry (camera-to-world, world = the sequence's
    /// frame 0 or first packet), when the layout has them and they cover every frame.
    pub ground_truth: Option<Vec<Isometry3<f64>>>,
    /// Where `ground_truth` came from.
    pub truth_source: Option<TruthSource>,
    /// A raw drive's second reference, from the INS alone ([`crate::kitti::raw::oxts_dead_reckoning`]:
    /// its velocities and orientation, no GPS position), in the frame of `ground_truth`; `None`
    /// elsewhere or when a packet's time is missing.
    pub dead_reckoned: Option<Vec<Isometry3<f64>>>,
    /// Object labels (tracking layout), when present; `frame` is the frame id.
    pub labels: Option<Vec<TrackingLabel>>,
    /// Frame ids missing in both cameras between the first and the last frame (skipped, ids kept), as runs.
    pub gaps: IdRuns,
    /// Frame ids with one image missing (kept, played as unreadable).
    pub one_camera: Vec<usize>,
    /// What was odd about the input and how it was handled, one sentence each (the caller logs them and
    /// prints their count).
    pub warnings: Vec<String>,
    /// A recording that is not KITTI's (a bag, a folder with a calibration file): where its frames are,
    /// the rig to rectify, the calibration's source; `None` for the KITTI layouts.
    pub recording: Option<crate::recording::Recording>,
}

/// Which frames to play: ids in `[first, end)` (either side open), every `stride`-th id from the
/// first. Ids come from the file names, so a selection keeps ground truth and output aligned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameSelection {
    /// First frame id (default: the sequence's first).
    pub first: Option<usize>,
    /// One past the last frame id (default: after the sequence's last).
    pub end: Option<usize>,
    /// Every `stride`-th frame id, counted from `first` (1 = every frame).
    pub stride: usize,
}

impl Default for FrameSelection {
    fn default() -> Self {
        Self { first: None, end: None, stride: 1 }
    }
}

impl FrameSelection {
    /// Parse a range of frame ids as Rust writes them: `A..B` (A to B − 1), `A..=B` (A to B), `A..`,
    /// `..B`, `..=B`, or a single id `A`.
    pub fn parse_range(text: &str) -> Result<(Option<usize>, Option<usize>), String> {
        let t = text.trim();
        let num = |s: &str| -> Result<Option<usize>, String> {
            let s = s.trim();
            if s.is_empty() {
                return Ok(None);
            }
            s.parse::<usize>().map(Some).map_err(|_| {
                format!("'{text}': '{s}' is not a frame id (a whole number ≥ 0); write A..B, A..=B, A.. or ..B")
            })
        };
        let (first, end) = if let Some((a, b)) = t.split_once("..=") {
            let b = num(b)?.ok_or_else(|| format!("'{text}': ..= needs a last frame id"))?;
            // the largest id has no id after it: up to it is up to the end
            (num(a)?, b.checked_add(1))
        } else if let Some((a, b)) = t.split_once("..") {
            (num(a)?, num(b)?)
        } else {
            let a = num(t)?.ok_or_else(|| format!("'{text}': empty frame range"))?;
            (Some(a), a.checked_add(1))
        };
        // without a start the range starts at frame 0: `..0` holds no frame, as `3..3` does not
        if let Some(b) = end {
            if b <= first.unwrap_or(0) {
                return Err(format!("'{text}' holds no frame: the end must be after the start"));
            }
        }
        Ok((first, end))
    }

    fn keeps(&self, first: usize, id: usize) -> bool {
        id >= first && self.end.is_none_or(|e| id < e) && (id - first) % self.stride.max(1) == 0
    }

    /// The positions in `ids` (frame ids in order) that the selection keeps; without a first id the
    /// stride counts from the first of `ids`.
    pub fn kept(&self, ids: &[usize]) -> Vec<usize> {
        let first = self.first.unwrap_or_else(|| ids.first().copied().unwrap_or(0));
        (0..ids.len()).filter(|&k| self.keeps(first, ids[k])).collect()
    }

    /// How this selection reads, e.g. `frames 0..=50, every 3rd`.
    pub fn describe(&self) -> String {
        let range = match (self.first, self.end) {
            (None, None) => "all frames".to_string(),
            (a, Some(e)) => format!("frames {}..={}", a.unwrap_or(0), e.saturating_sub(1)),
            (Some(a), None) => format!("frames {a}.."),
        };
        if self.stride > 1 {
            format!("{range}, every frame id {} apart", self.stride)
        } else {
            range
        }
    }
}

impl StereoSequence {
    /// Number of entries.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// True without entries (never for an opened sequence).
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// The entries a selection keeps (ids, times, images, ground truth and the gap lists alike); an
    /// error naming the folder when it keeps none.
    pub fn select(&self, sel: &FrameSelection) -> Result<StereoSequence, DatasetError> {
        let first = sel.first.unwrap_or_else(|| self.ids.first().copied().unwrap_or(0));
        let keep = sel.kept(&self.ids);
        if keep.is_empty() {
            let (a, b) = (self.ids.first().copied().unwrap_or(0), self.ids.last().copied().unwrap_or(0));
            return Err(DatasetError::Invalid {
                path: self.dir.clone(),
                message: format!("no frame in {} (this sequence has frames {a}..={b})", sel.describe()),
            });
        }
        let pick = |v: &[PathBuf]| keep.iter().map(|&k| v[k].clone()).collect::<Vec<_>>();
        let last = self.ids[keep[keep.len() - 1]];
        let within = |v: &[usize]| v.iter().copied().filter(|&id| id >= first && id <= last).collect::<Vec<_>>();
        Ok(StereoSequence {
            ids: keep.iter().map(|&k| self.ids[k]).collect(),
            left: pick(&self.left),
            right: pick(&self.right),
            times: keep.iter().map(|&k| self.times[k]).collect(),
            ground_truth: self.ground_truth.as_ref().map(|g| keep.iter().map(|&k| g[k]).collect()),
            dead_reckoned: self.dead_reckoned.as_ref().map(|g| keep.iter().map(|&k| g[k]).collect()),
            gaps: self.gaps.within(first, last),
            one_camera: within(&self.one_camera).into_iter().filter(|id| sel.keeps(first, *id)).collect(),
            // the path check covers the frames it was made from
            truth_source: if keep.len() == self.ids.len() {
                self.truth_source
            } else {
                self.truth_source.map(TruthSource::for_a_subset)
            },
            recording: self.recording.as_ref().map(|r| r.select(&keep)),
            ..self.clone()
        })
    }

    /// Keep the first `n` entries.
    pub fn truncate(&mut self, n: usize) {
        if n < self.ids.len() {
            self.truth_source = self.truth_source.map(TruthSource::for_a_subset);
        }
        self.ids.truncate(n);
        if let Some(r) = &mut self.recording {
            r.truncate(n);
        }
        self.left.truncate(n);
        self.right.truncate(n);
        self.times.truncate(n);
        if let Some(g) = &mut self.ground_truth {
            g.truncate(n);
        }
        if let Some(g) = &mut self.dead_reckoned {
            g.truncate(n);
        }
        if let Some(&last) = self.ids.last() {
            self.gaps = self.gaps.within(0, last);
            self.one_camera.retain(|&id| id <= last);
        }
    }

    /// Ground truth expressed in the first entry's camera frame (where a run's trajectory starts).
    pub fn truth_from_first(&self) -> Option<Vec<Isometry3<f64>>> {
        from_first(self.ground_truth.as_ref()?)
    }

    /// The INS's dead reckoning ([`StereoSequence::dead_reckoned`]) expressed in the first entry's
    /// camera frame.
    pub fn dead_reckoned_from_first(&self) -> Option<Vec<Isometry3<f64>>> {
        from_first(self.dead_reckoned.as_ref()?)
    }
}

/// Poses expressed in the frame of the first.
fn from_first(g: &[Isometry3<f64>]) -> Option<Vec<Isometry3<f64>>> {
    let origin = g.first()?.inverse();
    Some(g.iter().map(|p| origin * p).collect())
}

/// The intrinsics and baseline of a layout's stereo pair, its projection matrices checked to be a
/// rectified pair ([`crate::kitti::calib::rectified_pair`]); the error names the calibration file.
fn pair_from(
    (pl, pr): (&Matrix3x4<f64>, &Matrix3x4<f64>),
    keys: (&str, &str),
    calib: &Path,
) -> Result<([f64; 4], f64), DatasetError> {
    rectified_pair(pl, pr, keys).map_err(|message| DatasetError::Invalid { path: calib.to_path_buf(), message })
}

fn open_odometry(dir: &Path) -> Result<StereoSequence, DatasetError> {
    let seq = OdometrySequence::open(dir)?;
    let calib = dir.join("calib.txt");
    let (intrinsics, baseline) = pair_from((&seq.p0, &seq.p1), ("P0", "P1"), &calib)?;
    Ok(StereoSequence {
        layout: Layout::Odometry,
        dir: dir.to_path_buf(),
        ids: seq.ids,
        left: seq.left,
        right: seq.right,
        intrinsics,
        baseline,
        times: seq.times,
        truth_source: seq.ground_truth.as_ref().map(|_| TruthSource::PosesFile),
        dead_reckoned: None,
        ground_truth: seq.ground_truth,
        labels: None,
        gaps: seq.gaps,
        one_camera: seq.one_camera,
        warnings: seq.warnings,
        recording: None,
    })
}

/// Camera poses of every entry, the median GPS position accuracy (metres), the path check, and the
/// camera poses of the INS's dead reckoning.
type RawTruth = (Vec<Isometry3<f64>>, f64, Option<OxtsPath>, Option<Vec<Isometry3<f64>>>);

/// Camera-0 ground truth of a raw drive's frames from `oxts/data/<id>.txt` and the date's calibration;
/// `Ok(None)` (with a warning) when the drive has no `oxts/` or a packet or calibration file is missing.
fn raw_truth(
    drive: &Path,
    date: &Path,
    left: &[PathBuf],
    ids: &[usize],
    times: &[f64],
    warnings: &mut Vec<String>,
) -> Result<Option<RawTruth>, DatasetError> {
    let oxts = drive.join("oxts").join("data");
    if !oxts.is_dir() {
        warnings.push(no_truth(format_args!("{} not found (no ATE/RPE)", oxts.display())));
        return Ok(None);
    }
    for f in ["calib_imu_to_velo.txt", "calib_velo_to_cam.txt"] {
        if !date.join(f).is_file() {
            warnings.push(no_truth(format_args!("{} is missing (needed with oxts/)", date.join(f).display())));
            return Ok(None);
        }
    }
    let calib = RawCalib::read(date)?;
    let mut packets = Vec::with_capacity(ids.len());
    let mut names = Vec::with_capacity(ids.len());
    for (img, &id) in left.iter().zip(ids) {
        // the packet of a frame has the image's file stem (`0000000042.txt`)
        let name = img.file_stem().map(|s| s.to_string_lossy().to_string()).unwrap_or_default();
        let path = oxts.join(format!("{name}.txt"));
        // the reader's gate says what a packet that is no file is (a folder, a pipe, a device)
        match slam_core::files::regular_file(&path) {
            Ok(_) => {}
            Err(slam_core::files::ReadError::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
                warnings.push(no_truth(format_args!("the OXTS packet of frame {id} ({}) is missing", path.display())));
                return Ok(None);
            }
            Err(e) => {
                warnings.push(no_truth(format_args!("the OXTS packet of frame {id} cannot be read: {e}")));
                return Ok(None);
            }
        }
        packets.push(read_oxts_packet(&path)?);
        names.push(path);
    }
    // a packet no vehicle could have reached from the one before is an error naming it, here rather
    // than as a ground truth kilometres off (or a map too wide to draw) after the run
    let named: Vec<&Path> = names.iter().map(PathBuf::as_path).collect();
    check_oxts_steps(&packets, times, &named)?;
    let mut acc: Vec<f64> = packets.iter().map(|p| p.values[OXTS_POS_ACCURACY]).collect();
    acc.sort_by(|a, b| a.total_cmp(b));
    let median = acc[acc.len() / 2];
    let dead_reckoned = oxts_dead_reckoning(&packets, times).map(|imu| camera_poses_from_imu(imu, &calib));
    Ok(Some((camera_poses_from_oxts(&packets, &calib), median, oxts_path_lengths(&packets, times), dead_reckoned)))
}

fn open_raw(dir: &Path) -> Result<StereoSequence, DatasetError> {
    let date = dir.parent().unwrap_or(dir);
    let calib_path = date.join("calib_cam_to_cam.txt");
    let calib = Calib::read(&calib_path)?;
    // prefer the grey pair (00/01) when present: better stereo texture
    let grey = dir.join("image_00/data").is_dir() && dir.join("image_01/data").is_dir();
    let colour = dir.join("image_02/data").is_dir() && dir.join("image_03/data").is_dir();
    if !grey && !colour {
        let missing: Vec<String> = ["image_00", "image_01", "image_02", "image_03"]
            .iter()
            .filter(|c| !dir.join(c).join("data").is_dir())
            .map(|c| format!("{c}/data"))
            .collect();
        return Err(DatasetError::Invalid {
            path: dir.to_path_buf(),
            message: format!(
                "a raw drive needs a stereo pair: image_00/data with image_01/data (grey) or image_02/data with image_03/data (colour); missing: {}",
                missing.join(", ")
            ),
        });
    }
    let (l, r, pl, pr) = if grey {
        ("image_00", "image_01", "P_rect_00", "P_rect_01")
    } else {
        ("image_02", "image_03", "P_rect_02", "P_rect_03")
    };
    let (intrinsics, baseline) = pair_from((&calib.matrix3x4(pl)?, &calib.matrix3x4(pr)?), (pl, pr), &calib_path)?;
    let pairs = pair_frames(&dir.join(l).join("data"), &dir.join(r).join("data"))?;
    let mut warnings = pairs.warnings;
    let ts = dir.join(l).join("timestamps.txt");
    // a drive's timestamps.txt covers the whole drive: take the lines of the frames present
    let times = if ts.exists() {
        values_of_ids(&read_timestamps(&ts)?, &pairs.ids, &ts, "timestamps", "the images")?
    } else {
        warnings.push(nominal_times_note(&ts));
        nominal_times(&pairs.ids)
    };
    let truth = raw_truth(dir, date, &pairs.left, &pairs.ids, &times, &mut warnings)?;
    // the OXTS poses are of rectified camera 0; with the colour pair the left camera is camera 2, whose
    // rectified frame differs from camera 0's by a translation only
    let truth = match truth {
        Some((g, acc, path, dr)) if !grey => {
            // camera 2's centre in rectified camera 0: t = K⁻¹ · P_rect_02[:, 3]
            let p2 = calib.matrix3x4("P_rect_02")?;
            let k = p2.fixed_view::<3, 3>(0, 0).into_owned();
            let offset = k.try_inverse().map(|ki| ki * p2.column(3)).ok_or_else(|| DatasetError::Invalid {
                path: calib_path.clone(),
                message: "P_rect_02 has a singular K".into(),
            })?;
            let cam0_from_cam2 = Isometry3::translation(-offset.x, -offset.y, -offset.z);
            let to_cam2 = |g: Vec<Isometry3<f64>>| -> Vec<Isometry3<f64>> {
                g.iter().map(|p| cam0_from_cam2.inverse() * p * cam0_from_cam2).collect()
            };
            Some((to_cam2(g), acc, path, dr.map(to_cam2)))
        }
        other => other,
    };
    Ok(StereoSequence {
        layout: Layout::Raw,
        dir: dir.to_path_buf(),
        ids: pairs.ids,
        left: pairs.left,
        right: pairs.right,
        intrinsics,
        baseline,
        times,
        truth_source: truth.as_ref().map(|t| TruthSource::Oxts { median_pos_accuracy_m: t.1, path: t.2 }),
        dead_reckoned: truth.as_ref().and_then(|t| t.3.clone()),
        ground_truth: truth.map(|t| t.0),
        labels: None,
        gaps: pairs.gaps,
        one_camera: pairs.one_camera,
        warnings,
        recording: None,
    })
}

fn open_tracking(training: &Path, seq: &str) -> Result<StereoSequence, DatasetError> {
    let calib_path = training.join("calib").join(format!("{seq}.txt"));
    let calib = Calib::read(&calib_path)?;
    let (intrinsics, baseline) =
        pair_from((&calib.matrix3x4("P2")?, &calib.matrix3x4("P3")?), ("P2", "P3"), &calib_path)?;
    let dir = training.join("image_02").join(seq);
    let pairs = pair_frames(&dir, &training.join("image_03").join(seq))?;
    let label_path = training.join("label_02").join(format!("{seq}.txt"));
    let labels = if label_path.exists() { Some(read_tracking_labels(&label_path)?) } else { None };
    let times = nominal_times(&pairs.ids);
    Ok(StereoSequence {
        layout: Layout::Tracking,
        dir,
        ids: pairs.ids,
        left: pairs.left,
        right: pairs.right,
        intrinsics,
        baseline,
        times,
        ground_truth: None,
        truth_source: None,
        dead_reckoned: None,
        labels,
        gaps: pairs.gaps,
        one_camera: pairs.one_camera,
        // KITTI's tracking benchmark ships no poses
        warnings: [pairs.warnings, vec![no_truth("the tracking layout has no poses (no ATE/RPE)")]].concat(),
        recording: None,
    })
}

fn first_subdir(dir: &Path, keep: impl Fn(&Path) -> bool) -> Option<PathBuf> {
    let mut v: Vec<PathBuf> =
        std::fs::read_dir(dir).ok()?.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| keep(p)).collect();
    v.sort();
    v.into_iter().next()
}

/// Open a stereo sequence, recognising its layout:
/// - odometry: a folder with `calib.txt` and `image_0/`, or a root with `sequences/` (first sequence);
/// - raw: a drive folder with `image_00/data` + `image_01/data` or `image_02/data` + `image_03/data`
///   (calibration `calib_cam_to_cam.txt` one level up), or a date folder (first drive);
/// - tracking: `training/image_02/NNNN`, or a `training/` folder (first sequence).
pub fn open_stereo(path: impl AsRef<Path>) -> Result<StereoSequence, DatasetError> {
    let p = path.as_ref();
    if !p.is_dir() {
        return Err(DatasetError::Invalid { path: p.to_path_buf(), message: "not a folder".into() });
    }
    // a calibration that exists but is no file (a pipe, a folder) is the reader's to name
    if p.join("calib.txt").exists() && p.join("image_0").is_dir() {
        return open_odometry(p);
    }
    if let Some(seq) = first_subdir(&p.join("sequences"), |s| s.join("calib.txt").exists()) {
        return open_odometry(&seq);
    }
    let is_drive = |d: &Path| d.join("image_02/data").is_dir() || d.join("image_00/data").is_dir();
    if is_drive(p) {
        return open_raw(p);
    }
    if p.join("calib_cam_to_cam.txt").is_file() {
        if let Some(drive) = first_subdir(p, |d| is_drive(d)) {
            return open_raw(&drive);
        }
    }
    // training/image_02/NNNN
    if let (Some(parent), Some(name)) = (p.parent(), p.file_name()) {
        if parent.file_name().is_some_and(|n| n == "image_02") {
            if let Some(training) = parent.parent() {
                return open_tracking(training, &name.to_string_lossy());
            }
        }
    }
    if p.join("image_02").is_dir() && p.join("image_03").is_dir() && p.join("calib").is_dir() {
        if let Some(seq) = first_subdir(&p.join("image_02"), |d| d.is_dir()) {
            let name = seq.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
            return open_tracking(p, &name);
        }
    }
    Err(DatasetError::Invalid {
        path: p.to_path_buf(),
        message: "not a KITTI stereo sequence: expected an odometry sequence (calib.txt, image_0/, image_1/), a raw \
                  drive (image_02/data, image_03/data, calibration one level up) or a tracking sequence \
                  (training/image_02/NNNN)"
            .into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn touch_images(dir: &Path, n: usize) {
        std::fs::create_dir_all(dir).expect("dir");
        for i in 0..n {
            std::fs::write(dir.join(format!("{i:06}.png")), b"").expect("file");
        }
    }

    const P_ROW: &str = "700 0 600 {T} 0 700 180 0 0 0 1 0";

    fn p(t: f64) -> String {
        P_ROW.replace("{T}", &t.to_string())
    }

    #[test]
    fn frame_ranges_parse_as_rust_writes_them() {
        let p = FrameSelection::parse_range;
        assert_eq!(p("10..20"), Ok((Some(10), Some(20))));
        assert_eq!(p("10..=20"), Ok((Some(10), Some(21))));
        assert_eq!(p("5.."), Ok((Some(5), None)));
        assert_eq!(p("..=7"), Ok((None, Some(8))));
        assert_eq!(p("3"), Ok((Some(3), Some(4))));
        // the largest id: no overflow, up to the end
        assert_eq!(p(&format!("..={}", usize::MAX)), Ok((None, None)));
        assert_eq!(p(&format!("7..={}", usize::MAX)), Ok((Some(7), None)));
        assert_eq!(p(&usize::MAX.to_string()), Ok((Some(usize::MAX), None)));
        for bad in ["20..10", "5..5", "..0", "0..0", "a..3", "-1..4", "..=", "", "1.5..3"] {
            assert!(p(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_selection_keeps_ids_times_and_truth_together() {
        let root = std::env::temp_dir().join(format!("stereo-select-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let seq = root.join("sequences/00");
        touch_images(&seq.join("image_0"), 12);
        touch_images(&seq.join("image_1"), 12);
        std::fs::write(seq.join("calib.txt"), format!("P0: {}\nP1: {}\n", p(0.0), p(-378.0))).expect("calib");
        // frame 5 missing in both cameras: a gap, the others keep their ids
        for d in ["image_0", "image_1"] {
            std::fs::remove_file(seq.join(d).join("000005.png")).expect("rm");
        }
        let times: String = (0..20).map(|i| format!("{}\n", 0.25 * i as f64)).collect();
        std::fs::write(seq.join("times.txt"), times).expect("times");
        std::fs::create_dir_all(root.join("poses")).expect("dir");
        let poses: String = (0..12).map(|i| format!("1 0 0 0 0 1 0 0 0 0 1 {i}\n")).collect();
        std::fs::write(root.join("poses/00.txt"), poses).expect("poses");
        let s = open_stereo(&seq).expect("opens");
        assert_eq!(s.ids, vec![0, 1, 2, 3, 4, 6, 7, 8, 9, 10, 11]);
        assert_eq!(s.gaps.runs(), [(5, 5)]);
        assert!(s.warnings.iter().any(|w| w.contains("frame 5 missing in both cameras")), "{:?}", s.warnings);
        let z = |s: &StereoSequence| -> Vec<f64> {
            s.ground_truth.as_ref().expect("truth").iter().map(|g| g.translation.vector.z).collect()
        };
        // every entry's time and ground truth are those of its id, not of its position
        for (k, &id) in s.ids.iter().enumerate() {
            assert_eq!((s.times[k], z(&s)[k]), (0.25 * id as f64, id as f64));
            assert!(s.left[k].ends_with(format!("{id:06}.png")) && s.right[k].ends_with(format!("{id:06}.png")));
        }
        // 3..=10 every 2nd id: 3, (5 is a gap), 7, 9
        let (first, end) = FrameSelection::parse_range("3..=10").expect("range");
        let sub = s.select(&FrameSelection { first, end, stride: 2 }).expect("selects");
        assert_eq!(sub.ids, vec![3, 7, 9]);
        assert_eq!(z(&sub), vec![3.0, 7.0, 9.0]);
        assert_eq!(sub.times, vec![0.75, 1.75, 2.25]);
        assert_eq!(sub.gaps.runs(), [(5, 5)]);
        let rebased: Vec<f64> = sub.truth_from_first().expect("truth").iter().map(|g| g.translation.vector.z).collect();
        assert_eq!(rebased, vec![0.0, 4.0, 6.0]);
        let e = s.select(&FrameSelection { first: Some(40), end: None, stride: 1 }).expect_err("empty").to_string();
        assert!(e.contains("no frame in frames 40..") && e.contains("0..=11"), "{e}");
        // a time file shorter than the frames is an error naming it and both counts
        std::fs::write(seq.join("times.txt"), "0.0\n0.1\n0.2\n").expect("times");
        let e = open_stereo(&seq).expect_err("short times").to_string();
        assert!(e.contains("times.txt") && e.contains("3 times") && e.contains("frame 11"), "{e}");
        // a poses file shorter than the frames: no ground truth, with a warning naming the file
        std::fs::remove_file(seq.join("times.txt")).expect("rm");
        std::fs::write(root.join("poses/00.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n").expect("poses");
        let s = open_stereo(&seq).expect("opens");
        assert!(s.ground_truth.is_none() && s.truth_source.is_none());
        assert!(
            s.warnings.iter().any(|w| w.starts_with("no ground truth") && w.contains("00.txt")),
            "{:?}",
            s.warnings
        );
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn recognises_the_three_layouts() {
        let root = std::env::temp_dir().join(format!("stereo-layouts-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        // odometry
        let odo = root.join("odo/sequences/07");
        touch_images(&odo.join("image_0"), 3);
        touch_images(&odo.join("image_1"), 3);
        std::fs::write(odo.join("calib.txt"), format!("P0: {}\nP1: {}\n", p(0.0), p(-378.0))).expect("calib");
        let s = open_stereo(root.join("odo")).expect("odometry root");
        assert_eq!((s.layout, s.left.len()), (Layout::Odometry, 3));
        assert!((s.baseline - 0.54).abs() < 1e-12);
        // raw
        let date = root.join("2011_09_26");
        let drive = date.join("2011_09_26_drive_0001_sync");
        touch_images(&drive.join("image_02/data"), 4);
        touch_images(&drive.join("image_03/data"), 4);
        std::fs::write(
            date.join("calib_cam_to_cam.txt"),
            format!("P_rect_02: {}\nP_rect_03: {}\n", p(42.0), p(-336.0)),
        )
        .expect("calib");
        let s = open_stereo(&drive).expect("raw drive");
        assert_eq!((s.layout, s.left.len()), (Layout::Raw, 4));
        assert!((s.baseline - 0.54).abs() < 1e-12);
        assert_eq!(open_stereo(&date).expect("date folder").dir, drive);
        // tracking
        let tr = root.join("training");
        touch_images(&tr.join("image_02/0003"), 2);
        touch_images(&tr.join("image_03/0003"), 2);
        std::fs::create_dir_all(tr.join("calib")).expect("dir");
        std::fs::write(tr.join("calib/0003.txt"), format!("P2: {}\nP3: {}\n", p(42.0), p(-336.0))).expect("calib");
        let s = open_stereo(tr.join("image_02/0003")).expect("tracking");
        assert_eq!((s.layout, s.left.len(), s.labels.is_none()), (Layout::Tracking, 2, true));
        assert_eq!(open_stereo(&tr).expect("training root").layout, Layout::Tracking);
        // a frame with one image is kept (played as unreadable) and named in a warning
        touch_images(&odo.join("image_1"), 4);
        let s = open_stereo(&odo).expect("one-sided frame");
        assert_eq!((s.ids.clone(), s.one_camera.clone()), (vec![0, 1, 2, 3], vec![3]));
        assert_eq!(s.left[3], odo.join("image_0/000003.png"));
        assert!(
            s.warnings.iter().any(|w| w.contains("frame 3") && w.contains("image_0/000003.png")),
            "{:?}",
            s.warnings
        );
        // unknown folders are errors naming the folder
        let e =
            open_stereo(root.join("2011_09_26/2011_09_26_drive_0001_sync/image_02")).expect_err("unknown").to_string();
        assert!(e.contains("not a KITTI stereo sequence"), "{e}");
        std::fs::remove_dir_all(&root).ok();
    }
}
