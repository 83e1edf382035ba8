//! Checks of values before any work starts: numbers against their valid range ([`number`], [`count`],
//! with messages that name the value, what was given and the range), and a stereo sequence's calibration
//! against the images it describes ([`calibration`], [`declared_size`], [`first_pair`], and the file it
//! came from, [`calibration_file`]). Used by `slam-app` for command-line options, settings files and the
//! sequences it opens.

use std::path::{Path, PathBuf};

use crate::{
    kitti::stereo::{Layout, StereoSequence},
    DatasetError,
};

/// A value outside its valid range, or a calibration that does not fit its images.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The message names the value (option, settings key or file), what was given and what is valid.
    #[error("{0}")]
    Invalid(String),
    /// A value outside its range (the message names it).
    #[error(transparent)]
    Value(#[from] slam_core::check::InvalidValue),
    /// The calibration file could not be read.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
}

macro_rules! bail {
    ($($arg:tt)*) => {
        return Err(CheckError::Invalid(format!($($arg)*)))
    };
}

pub use slam_core::check::Range;

/// `what` (e.g. `--noise`) must be a finite number in `range`; `unit` is appended to the range.
pub fn number(what: &str, v: f64, range: Range, unit: &str) -> Result<(), CheckError> {
    slam_core::check::number(what, v, range, unit).map_err(CheckError::from)
}

/// A count `what` must lie in `[lo, hi]`.
pub fn count(what: &str, v: usize, lo: usize, hi: usize) -> Result<(), CheckError> {
    slam_core::check::count(what, v, lo, hi).map_err(CheckError::from)
}

/// Calibration sanity against the image it describes: focal lengths that give a field of view between
/// 1° and 170° (a rectified pinhole image cannot show more; less is a telescope), pixels no more than
/// twice as tall as wide, the principal point inside the image and near its centre
/// ([`PRINCIPAL_POINT_OFF_CENTRE`]: images of another size than the calibration's), a baseline in
/// (0, 10] m.
pub fn calibration(
    calib: &Path,
    intrinsics: [f64; 4],
    baseline: f64,
    image: &Path,
    size: (u32, u32),
) -> Result<(), CheckError> {
    let [fx, fy, cx, cy] = intrinsics;
    let (w, h) = (size.0 as f64, size.1 as f64);
    let at = |what: &str| format!("{}: {what}", calib.display());
    let img = format!("{} is {}×{}", image.display(), size.0, size.1);
    let fov = |f: f64, side: f64| 2.0 * (side / (2.0 * f)).atan().to_degrees();
    let f_lo = w / (2.0 * 85f64.to_radians().tan());
    let f_hi = w / (2.0 * 0.5f64.to_radians().tan());
    number(
        &at("focal length fx"),
        fx,
        Range::closed(f_lo, f_hi),
        &format!("px (a field of view of 1°–170° over {img}; given: {:.1}°)", fov(fx, w)),
    )?;
    number(&at("focal length fy"), fy, Range::closed(fx / 2.0, fx * 2.0), "px (within a factor 2 of fx)")?;
    number(&at("principal point cx"), cx, Range::open(0.0, w), &format!("px (inside the image: {img})"))?;
    number(&at("principal point cy"), cy, Range::open(0.0, h), &format!("px (inside the image: {img})"))?;
    principal_point_near_centre(calib, [cx, cy], &img, (w, h))?;
    number(&at("baseline"), baseline, Range::above(0.0, 10.0), "m")?;
    Ok(())
}

pub use slam_core::check::PRINCIPAL_POINT_OFF_CENTRE;

/// The principal point must lie near the middle of the image ([`PRINCIPAL_POINT_OFF_CENTRE`]): a
/// calibration of another image size, or of another camera, is refused naming both.
fn principal_point_near_centre(
    calib: &Path,
    [cx, cy]: [f64; 2],
    img: &str,
    (w, h): (f64, f64),
) -> Result<(), CheckError> {
    let off = [(cx - w / 2.0).abs() / w, (cy - h / 2.0).abs() / h];
    if off.iter().all(|&o| o <= PRINCIPAL_POINT_OFF_CENTRE) {
        return Ok(());
    }
    bail!(
        "{}: the principal point ({cx:.1}, {cy:.1}) px lies {:.0} % of the width and {:.0} % of the height from \
         the centre of the image ({img}); a camera's principal point lies near the middle of its image (at \
         most {:.0} % off): the images do not have the size this calibration was made for (it implies about \
         {:.0}×{:.0}: half or twice the size?), or the calibration is another camera's",
        calib.display(),
        100.0 * off[0],
        100.0 * off[1],
        100.0 * PRINCIPAL_POINT_OFF_CENTRE,
        2.0 * cx,
        2.0 * cy
    );
}

/// A raw drive's calibration declares each camera's rectified image size (`S_rect_0N`): the image must
/// have it. Files without the key (other layouts) are not checked.
pub fn declared_size(calib: &Path, image: &Path, size: (u32, u32)) -> Result<(), CheckError> {
    let Some(cam) = image
        .components()
        .filter_map(|c| c.as_os_str().to_str())
        .find_map(|c| c.strip_prefix("image_").filter(|n| n.len() == 2))
    else {
        return Ok(());
    };
    let Ok(c) = crate::kitti::calib::Calib::read(calib) else { return Ok(()) };
    let key = format!("S_rect_{cam}");
    if !c.has(&key) {
        return Ok(());
    }
    let v = c.numbers(&key, Some(2))?;
    if (v[0], v[1]) != (size.0 as f64, size.1 as f64) {
        bail!(
            "{}: {key} declares {}×{} images, but {} is {}×{}",
            calib.display(),
            v[0],
            v[1],
            image.display(),
            size.0,
            size.1
        );
    }
    Ok(())
}

/// The first frame with both images on disk (a frame missing in one camera is played as unreadable, so
/// sizes are checked on the first complete pair).
pub fn first_pair<'a>(
    left: &'a [std::path::PathBuf],
    right: &'a [std::path::PathBuf],
) -> Result<(&'a Path, &'a Path), CheckError> {
    left.iter()
        .zip(right)
        .find(|(l, r)| l.is_file() && r.is_file())
        .map(|(l, r)| (l.as_path(), r.as_path()))
        .ok_or_else(|| {
            let dir = left.first().and_then(|p| p.parent()).map(|p| p.display().to_string()).unwrap_or_default();
            CheckError::Invalid(format!("{dir}: no frame has both its left and its right image"))
        })
}

/// The calibration file a sequence's intrinsics came from (for messages).
pub fn calibration_file(seq: &StereoSequence) -> PathBuf {
    match seq.layout {
        Layout::Odometry => seq.dir.join("calib.txt"),
        Layout::Raw => seq.dir.parent().unwrap_or(&seq.dir).join("calib_cam_to_cam.txt"),
        Layout::Tracking => {
            let name = seq.dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            seq.dir.parent().and_then(|p| p.parent()).unwrap_or(&seq.dir).join("calib").join(format!("{name}.txt"))
        }
        Layout::Bag | Layout::Folder => {
            seq.recording.as_ref().map_or_else(|| seq.dir.clone(), |r| r.calibration.clone())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_print_and_reject_non_finite_values() {
        let e = number("--noise", f64::NAN, Range::closed(0.0, 1.0), "").expect_err("nan").to_string();
        assert_eq!(e, "--noise NaN: must be a finite number in [0, 1]");
        let e = number("x", f64::INFINITY, Range::above(0.0, f64::INFINITY), "m").expect_err("inf").to_string();
        assert_eq!(e, "x inf: must be a finite number in (0, ∞) m");
        assert!(number("x", 0.0, Range::above(0.0, 1.0), "").is_err());
        assert!(number("x", 1.0, Range::open(0.0, 1.0), "").is_err());
        assert!(number("x", 1.0, Range::closed(0.0, 1.0), "").is_ok());
        assert_eq!(count("n", 0, 1, usize::MAX).expect_err("0").to_string(), "n 0: must be at least 1");
        assert_eq!(count("n", 9, 1, 5).expect_err("9").to_string(), "n 9: must be an integer in [1, 5]");
    }

    #[test]
    fn calibration_checks_focal_length_principal_point_and_baseline() {
        let (c, i) = (Path::new("calib.txt"), Path::new("000000.png"));
        let size = (1241, 376);
        calibration(c, [718.856, 718.856, 607.19, 185.22], 0.537, i, size).expect("KITTI 06");
        let e = calibration(c, [0.001, 0.001, 607.0, 185.0], 0.5, i, size).expect_err("fx").to_string();
        assert!(e.contains("focal length fx 0.001") && e.contains("field of view"), "{e}");
        let e = calibration(c, [718.0, 718.0, 1500.0, 185.0], 0.5, i, size).expect_err("cx").to_string();
        assert!(e.contains("principal point cx 1500") && e.contains("(0, 1241)"), "{e}");
        let e = calibration(c, [718.0, 718.0, 600.0, 185.0], 0.0, i, size).expect_err("baseline").to_string();
        assert!(e.contains("baseline 0"), "{e}");
        let e = calibration(c, [718.0, 100.0, 600.0, 185.0], 0.5, i, size).expect_err("fy").to_string();
        assert!(e.contains("focal length fy 100"), "{e}");
        // odometry 06's calibration with images half and twice its size (R01): the principal point sits
        // in the corner, or in the first quarter; the image size of a crop of 100 px on the right passes
        let k06 = [707.0912, 707.0912, 601.8873, 183.1104];
        let e = calibration(c, k06, 0.537, i, (613, 185)).expect_err("half").to_string();
        assert!(e.contains("principal point (601.9, 183.1) px lies 48 % of the width and 49 % of the height"), "{e}");
        assert!(e.contains("000000.png is 613×185") && e.contains("implies about 1204×366"), "{e}");
        let e = calibration(c, k06, 0.537, i, (2452, 740)).expect_err("double").to_string();
        assert!(e.contains("25 % of the width"), "{e}");
        calibration(c, k06, 0.537, i, (1126, 370)).expect("cropped on the right");
    }

    #[test]
    fn the_first_complete_pair_is_found_and_none_is_an_error() {
        let dir = std::env::temp_dir().join(format!("slam-dataset-check-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let [l0, l1, r1] = ["l0.png", "l1.png", "r1.png"].map(|n| dir.join(n));
        for p in [&l0, &l1, &r1] {
            std::fs::write(p, b"x").expect("write");
        }
        let left = vec![l0.clone(), l1.clone()];
        let right = vec![dir.join("r0.png"), r1.clone()];
        let (l, r) = first_pair(&left, &right).expect("frame 1 is complete");
        assert_eq!((l, r), (l1.as_path(), r1.as_path()));
        let e = first_pair(&left[..1], &right[..1]).expect_err("no complete frame").to_string();
        assert!(e.contains("no frame has both its left and its right image"), "{e}");
        // a raw drive's declared image size must match; a calibration without the key is not checked
        let calib = dir.join("calib_cam_to_cam.txt");
        std::fs::write(&calib, "S_rect_02: 1.242000e+03 3.750000e+02\n").expect("calib");
        let image = dir.join("image_02/data/0000000000.png");
        declared_size(&calib, &image, (1242, 375)).expect("matches");
        let e = declared_size(&calib, &image, (1241, 376)).expect_err("differs").to_string();
        assert!(e.contains("S_rect_02 declares 1242×375 images") && e.contains("1241×376"), "{e}");
        declared_size(&calib, &dir.join("image_03/data/0000000000.png"), (1, 1)).expect("no S_rect_03: unchecked");
        std::fs::remove_dir_all(&dir).ok();
    }
}
