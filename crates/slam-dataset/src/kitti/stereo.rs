//! One view of every KITTI stereo layout: odometry (`sequences/NN`), raw (`<date>/<drive>_sync`) and
//! tracking (`training/image_02/NNNN`). [`open_stereo`] recognises which one a path is.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3x4};

use crate::{
    kitti::{
        calib::Calib,
        odometry::{list_images, nominal_times, OdometrySequence},
        raw::read_timestamps,
        tracking::{read_tracking_labels, TrackingLabel},
    },
    DatasetError,
};

/// Which KITTI layout a sequence came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// Odometry benchmark: `sequences/NN/{calib.txt, image_0, image_1}` (+ `poses/NN.txt`).
    Odometry,
    /// Raw data: `<date>/<date>_drive_NNNN_sync/image_0{0,1,2,3}/data`, calibration in `<date>/`.
    Raw,
    /// Tracking benchmark: `training/{image_02,image_03}/NNNN`, `training/calib/NNNN.txt`.
    Tracking,
}

/// A rectified stereo sequence, images listed (not decoded).
#[derive(Debug, Clone)]
pub struct StereoSequence {
    /// Layout recognised.
    pub layout: Layout,
    /// The folder that was opened.
    pub dir: PathBuf,
    /// Left images, sorted.
    pub left: Vec<PathBuf>,
    /// Right images, sorted, as many as left.
    pub right: Vec<PathBuf>,
    /// Intrinsics `[fx, fy, cx, cy]` of the rectified pair.
    pub intrinsics: [f64; 4],
    /// Baseline, metres.
    pub baseline: f64,
    /// Frame times, seconds from the first.
    pub times: Vec<f64>,
    /// Ground-truth poses of the left camera (world = first frame), when the layout has them.
    pub ground_truth: Option<Vec<Isometry3<f64>>>,
    /// Object labels (tracking layout), when present.
    pub labels: Option<Vec<TrackingLabel>>,
}

fn pair_from(
    layout: Layout,
    dir: &Path,
    pl: &Matrix3x4<f64>,
    pr: &Matrix3x4<f64>,
    calib: &Path,
) -> Result<([f64; 4], f64), DatasetError> {
    let fx = pl[(0, 0)];
    let baseline = (pl[(0, 3)] - pr[(0, 3)]) / fx;
    if !(fx > 0.0 && baseline > 0.0 && baseline.is_finite()) {
        return Err(DatasetError::Invalid {
            path: calib.to_path_buf(),
            message: format!("{layout:?} stereo pair of {} has focal {fx} and baseline {baseline}", dir.display()),
        });
    }
    Ok(([fx, pl[(1, 1)], pl[(0, 2)], pl[(1, 2)]], baseline))
}

fn same_count(dir: &Path, left: &[PathBuf], right: &[PathBuf]) -> Result<(), DatasetError> {
    if left.len() != right.len() {
        return Err(DatasetError::Invalid {
            path: dir.to_path_buf(),
            message: format!("{} left images but {} right images", left.len(), right.len()),
        });
    }
    if left.is_empty() {
        return Err(DatasetError::Invalid { path: dir.to_path_buf(), message: "no PNG images".into() });
    }
    Ok(())
}

fn open_odometry(dir: &Path) -> Result<StereoSequence, DatasetError> {
    let seq = OdometrySequence::open(dir)?;
    let calib = dir.join("calib.txt");
    let (intrinsics, baseline) = pair_from(Layout::Odometry, dir, &seq.p0, &seq.p1, &calib)?;
    same_count(dir, &seq.left, &seq.right)?;
    Ok(StereoSequence {
        layout: Layout::Odometry,
        dir: dir.to_path_buf(),
        left: seq.left,
        right: seq.right,
        intrinsics,
        baseline,
        times: seq.times,
        ground_truth: seq.ground_truth,
        labels: None,
    })
}

fn open_raw(dir: &Path) -> Result<StereoSequence, DatasetError> {
    let date = dir.parent().unwrap_or(dir);
    let calib_path = date.join("calib_cam_to_cam.txt");
    let calib = Calib::read(&calib_path)?;
    // prefer the grey pair (00/01) when present: better stereo texture
    let (l, r, pl, pr) = if dir.join("image_00/data").is_dir() && dir.join("image_01/data").is_dir() {
        ("image_00", "image_01", "P_rect_00", "P_rect_01")
    } else {
        ("image_02", "image_03", "P_rect_02", "P_rect_03")
    };
    let (intrinsics, baseline) =
        pair_from(Layout::Raw, dir, &calib.matrix3x4(pl)?, &calib.matrix3x4(pr)?, &calib_path)?;
    let left = list_images(&dir.join(l).join("data"))?;
    let right = list_images(&dir.join(r).join("data"))?;
    same_count(dir, &left, &right)?;
    let ts = dir.join(l).join("timestamps.txt");
    let times = if ts.exists() { read_timestamps(&ts)? } else { nominal_times(left.len()) };
    Ok(StereoSequence {
        layout: Layout::Raw,
        dir: dir.to_path_buf(),
        left,
        right,
        intrinsics,
        baseline,
        times,
        ground_truth: None,
        labels: None,
    })
}

fn open_tracking(training: &Path, seq: &str) -> Result<StereoSequence, DatasetError> {
    let calib_path = training.join("calib").join(format!("{seq}.txt"));
    let calib = Calib::read(&calib_path)?;
    let (intrinsics, baseline) =
        pair_from(Layout::Tracking, training, &calib.matrix3x4("P2")?, &calib.matrix3x4("P3")?, &calib_path)?;
    let left = list_images(&training.join("image_02").join(seq))?;
    let right = list_images(&training.join("image_03").join(seq))?;
    let dir = training.join("image_02").join(seq);
    same_count(&dir, &left, &right)?;
    let label_path = training.join("label_02").join(format!("{seq}.txt"));
    let labels = if label_path.exists() { Some(read_tracking_labels(&label_path)?) } else { None };
    let times = nominal_times(left.len());
    Ok(StereoSequence {
        layout: Layout::Tracking,
        dir,
        left,
        right,
        intrinsics,
        baseline,
        times,
        ground_truth: None,
        labels,
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
    if p.join("calib.txt").is_file() && p.join("image_0").is_dir() {
        return open_odometry(p);
    }
    if let Some(seq) = first_subdir(&p.join("sequences"), |s| s.join("calib.txt").is_file()) {
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
        // mismatched counts and unknown folders are errors naming the folder
        touch_images(&odo.join("image_1"), 4);
        let e = open_stereo(&odo).expect_err("mismatch").to_string();
        assert!(e.contains("3 left images but 4 right images"), "{e}");
        let e =
            open_stereo(root.join("2011_09_26/2011_09_26_drive_0001_sync/image_02")).expect_err("unknown").to_string();
        assert!(e.contains("not a KITTI stereo sequence"), "{e}");
        std::fs::remove_dir_all(&root).ok();
    }
}
