//! A user's own stereo recording as a [`StereoSequence`], the same kind of source as a KITTI sequence:
//! a ROS 2 bag ([`crate::ros::bag`]) or a plain folder with `left/` and `right/` images and a
//! calibration file ([`crate::rig`]). [`open_sequence`] recognises what a path is and opens it; KITTI
//! folders go to [`open_stereo`].
//!
//! **A bag's two cameras.** Given `--left`/`--right`, those topics; else the topics a calibration file
//! names (Kalibr's `rostopic`); else found among the image topics (`sensor_msgs/msg/Image` or
//! `CompressedImage` in CDR): each camera is the namespace of its topics (`/ns/cam/image_raw`,
//! `/ns/cam/image_raw/compressed` → `/ns/cam`), with its `CameraInfo` at `/ns/cam/camera_info`;
//! without `--calib` only cameras with one count. A camera with a raw and a compressed topic uses the
//! raw one (nothing to decode, nothing lost). Two cameras are told apart by name (`left`, `right`),
//! else by the sign of their `CameraInfo`'s `P[0][3]` (`−fx·B` for the right camera, 0 for the
//! left); anything else asks for `--left`/`--right`. [`choose_topics`] also says why it chose so.
//!
//! **Pairs.** Left and right images are paired by their header stamps ([`pair_by_stamp`]); frames
//! are numbered by their left image's place among the left topic's images in stamp order, and timed
//! by its stamp (seconds since the first left image).

use std::{
    path::{Path, PathBuf},
    sync::Arc,
};

use crate::{
    kitti::{
        frames::IdRuns,
        stereo::{open_stereo, Layout, StereoSequence},
    },
    rig::{from_camera_infos, read_calibration, CalibrationFile},
    ros::{
        bag::{is_bag, Bag, IndexedImage},
        msgs::{CAMERA_INFO, COMPRESSED_IMAGE, IMAGE},
    },
    DatasetError,
};

mod frames;

pub use frames::{BagFrame, BagFrames, Recording};

/// How to read a recording that is not KITTI's (the command line's `--calib`, `--left`, `--right`,
/// `--rate`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SourceOptions {
    /// The rig's calibration file (Kalibr camchain or ORB-SLAM settings).
    pub calib: Option<PathBuf>,
    /// A bag's left image topic.
    pub left: Option<String>,
    /// A bag's right image topic.
    pub right: Option<String>,
    /// Frames a second of a folder without `times.txt`.
    pub rate_hz: Option<f64>,
}

impl SourceOptions {
    /// Whether any option is given.
    pub fn any(&self) -> bool {
        *self != SourceOptions::default()
    }
}

/// Open a stereo sequence: a ROS 2 bag (an `.mcap` file or a rosbag2 folder), a folder with `left/`
/// and `right/` images (with `opts.calib`), or any KITTI layout ([`open_stereo`]).
pub fn open_sequence(path: &Path, opts: &SourceOptions) -> Result<StereoSequence, DatasetError> {
    let refuse = |what: &str| DatasetError::Invalid { path: path.to_path_buf(), message: what.to_string() };
    if is_bag(path) {
        if opts.rate_hz.is_some() {
            return Err(refuse("--rate is for a folder of images without times.txt: a bag's frames have their stamps"));
        }
        return open_bag(path, opts);
    }
    if path.join("left").is_dir() && path.join("right").is_dir() {
        if opts.left.is_some() || opts.right.is_some() {
            return Err(refuse("--left and --right name a bag's topics: this is a folder of images"));
        }
        return open_folder(path, opts);
    }
    if opts.any() {
        return Err(refuse(
            "--calib, --left, --right and --rate are for a ROS 2 bag or a folder with left/ and right/ images; a KITTI sequence brings its own calibration and times",
        ));
    }
    open_stereo(path)
}

/// The camera a topic belongs to: its namespace without an image transport's suffix
/// (`/kitti/cam/image_raw/compressed` → `/kitti/cam`).
pub fn camera_namespace(topic: &str) -> &str {
    let base = topic.strip_suffix("/compressed").unwrap_or(topic);
    match base.rfind('/') {
        Some(i) => &base[..i],
        None => "",
    }
}

/// The `CameraInfo` topic beside an image topic.
pub fn camera_info_topic(topic: &str) -> String {
    format!("{}/camera_info", camera_namespace(topic))
}

/// The two image topics a run would read, and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicChoice {
    /// Left image topic.
    pub left: String,
    /// Right image topic.
    pub right: String,
    /// Why these, in a sentence.
    pub why: String,
}

/// Pixel encodings of raw images the front end decodes.
pub const ENCODINGS: [&str; 4] = ["mono8", "rgb8", "bgr8", "mono16"];

/// Whether a compressed image's format is one the front end decodes (PNG or JPEG; ROS writes e.g.
/// `png`, `jpeg`, `mono8; png compressed`, `bgr8; jpeg compressed bgr8`).
pub fn known_format(format: &str) -> bool {
    let f = format.to_ascii_lowercase();
    f.contains("png") || f.contains("jpeg") || f.contains("jpg")
}

/// Choose a bag's left and right image topics (module doc), or say why none can be chosen.
pub fn choose_topics(bag: &Bag, opts: &SourceOptions, calib: Option<&CalibrationFile>) -> Result<TopicChoice, String> {
    if let Some(given) = given_topics(bag, opts, calib)? {
        return Ok(given);
    }
    let images = image_topics(bag);
    if images.is_empty() {
        return Err(format!(
            "no image topic ({IMAGE} or {COMPRESSED_IMAGE}, CDR) in the bag; its topics: {}",
            bag.topics.iter().map(|t| format!("{} ({})", t.name, t.schema)).collect::<Vec<_>>().join(", ")
        ));
    }
    let (cameras, notes) = cameras_of(bag, &images, calib);
    let missing_info = || {
        let looked: Vec<String> = images.iter().map(|t| format!("{t} (looked for {})", camera_info_topic(t))).collect();
        format!(
            "no {CAMERA_INFO} beside the image topics {}: give the rig's calibration with --calib FILE (a Kalibr camchain or ORB-SLAM's stereo settings)",
            looked.join(", ")
        )
    };
    let (a, b) = match cameras.len() {
        0 => return Err(missing_info()),
        1 => {
            let extra =
                if calib.is_none() && images.len() > 1 { format!(" ({})", missing_info()) } else { String::new() };
            return Err(format!(
                "one camera only: {}; a stereo run needs a left and a right camera{extra}",
                cameras[0].1
            ));
        }
        2 => (cameras[0].1.clone(), cameras[1].1.clone()),
        _ => {
            return Err(format!(
                "{} cameras ({}): name the pair with --left TOPIC --right TOPIC",
                cameras.len(),
                cameras.iter().map(|c| c.1.as_str()).collect::<Vec<_>>().join(", ")
            ))
        }
    };
    let (a_left, why) = which_is_left(bag, &a, &b)?;
    let (left, right) = if a_left { (a, b) } else { (b, a) };
    let mut why = format!(
        "the only two cameras{}, left and right {why}",
        if calib.is_none() { " with a CameraInfo" } else { "" }
    );
    if !notes.is_empty() {
        why.push_str(&format!("; {}", notes.join("; ")));
    }
    Ok(TopicChoice { left, right, why })
}

/// The pair named by `--left`/`--right` or by the calibration file, when either names one.
fn given_topics(
    bag: &Bag,
    opts: &SourceOptions,
    calib: Option<&CalibrationFile>,
) -> Result<Option<TopicChoice>, String> {
    let image = |name: &str, flag: &str| -> Result<(), String> {
        match bag.topic(name) {
            Some(t) if t.is_image() => Ok(()),
            Some(t) => Err(format!("{flag} {name} is a topic of {} ({}), not of images", t.schema, t.encoding)),
            None => Err(format!(
                "{flag} {name}: no such topic in the bag (its image topics: {})",
                image_topics(bag).join(", ")
            )),
        }
    };
    match (&opts.left, &opts.right) {
        (Some(l), Some(r)) => {
            image(l, "--left")?;
            image(r, "--right")?;
            return Ok(Some(TopicChoice {
                left: l.clone(),
                right: r.clone(),
                why: "given with --left and --right".into(),
            }));
        }
        (Some(_), None) | (None, Some(_)) => {
            return Err("--left and --right go together: name both image topics".into())
        }
        (None, None) => {}
    }
    if let Some((l, r)) = calib.and_then(|c| c.topics.as_ref()) {
        if bag.topic(l).is_some_and(|t| t.is_image()) && bag.topic(r).is_some_and(|t| t.is_image()) {
            let file = calib.map(|c| c.path.display().to_string()).unwrap_or_default();
            return Ok(Some(TopicChoice {
                left: l.clone(),
                right: r.clone(),
                why: format!("the topics {file} names (rostopic)"),
            }));
        }
    }
    Ok(None)
}

/// One image topic per camera namespace (with a CameraInfo beside it unless a calibration file is
/// given; raw images preferred over compressed ones), and a note for each topic left out.
fn cameras_of(bag: &Bag, images: &[String], calib: Option<&CalibrationFile>) -> (Vec<(String, String)>, Vec<String>) {
    let mut cameras: Vec<(String, String)> = Vec::new();
    let mut notes = Vec::new();
    for t in images {
        let ns = camera_namespace(t).to_string();
        // a camera-info topic with a readable message (a channel without messages says nothing)
        let has_info = bag.camera_infos.contains_key(&camera_info_topic(t));
        if calib.is_none() && !has_info {
            continue;
        }
        match cameras.iter_mut().find(|(n, _)| *n == ns) {
            Some((_, chosen)) => {
                let raw = |n: &str| bag.topic(n).is_some_and(|t| t.schema == IMAGE);
                if raw(t) && !raw(chosen) {
                    notes.push(format!("{t} rather than {chosen} (raw images: nothing to decode)"));
                    *chosen = t.clone();
                } else {
                    notes.push(format!("{chosen} rather than {t}"));
                }
            }
            None => cameras.push((ns, t.clone())),
        }
    }
    (cameras, notes)
}

/// Whether camera `a` of the pair is the left one, and why: by the namespaces' names and by the sign of
/// each CameraInfo's P[0][3]; an error when neither says or they disagree.
fn which_is_left(bag: &Bag, a: &str, b: &str) -> Result<(bool, String), String> {
    let named = |t: &str, w: &str| camera_namespace(t).to_ascii_lowercase().contains(w);
    let tx = |t: &str| bag.camera_infos.get(&camera_info_topic(t)).map(|i| i.p[3]);
    let by_p = match (tx(a), tx(b)) {
        (Some(x), Some(y)) if x == 0.0 && y < 0.0 => Some(true),
        (Some(x), Some(y)) if y == 0.0 && x < 0.0 => Some(false),
        _ => None,
    };
    let by_name = match (named(a, "left") && named(b, "right"), named(b, "left") && named(a, "right")) {
        (true, false) => Some(true),
        (false, true) => Some(false),
        _ => None,
    };
    match (by_name, by_p) {
        (Some(n), Some(p)) if n != p => Err(format!(
            "{a} and {b}: their names and their CameraInfo P (the right camera has P[0][3] = −fx·B < 0) disagree on which is left; name the pair with --left and --right"
        )),
        (Some(n), _) => Ok((n, "by their names (left, right)".to_string())),
        (None, Some(p)) => Ok((p, "by their CameraInfo P: the right camera's P[0][3] = −fx·B is negative".to_string())),
        (None, None) => Err(format!(
            "two cameras, {a} and {b}, and neither their names nor a CameraInfo says which is left: name them with --left and --right"
        )),
    }
}

fn image_topics(bag: &Bag) -> Vec<String> {
    bag.topics.iter().filter(|t| t.is_image()).map(|t| t.name.clone()).collect()
}

/// How a bag's left and right images pair up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pairing {
    /// `(left, right)` positions of each pair, in left order.
    pub pairs: Vec<(usize, usize)>,
    /// The left camera's frame period: the median step between its stamps, ns (0 with fewer than two).
    pub period_ns: i64,
    /// The largest stamp difference of a pair, ns ([`pair_by_stamp`]).
    pub tolerance_ns: i64,
    /// Left images without a right one within the tolerance (positions).
    pub unpaired_left: Vec<usize>,
    /// Right images without a left one.
    pub unpaired_right: usize,
}

/// Pair left and right images (stamps in increasing order) by their stamps: each left image with the
/// right image nearest to it when that left image is also the nearest to it (so no image is used
/// twice), and the two are at most a quarter of the frame period apart. A synchronised rig stamps its
/// pairs alike (KITTI's grey pair within 3 ms at 10 Hz); free-running cameras at one rate are at most
/// half a period apart. A quarter period keeps a margin of another quarter before an image could be
/// nearer to its neighbour's partner, and a pair taken more than a quarter period apart sees the scene
/// move by a quarter of a frame's motion between its images, which no rectification can make up for.
pub fn pair_by_stamp(left: &[i64], right: &[i64]) -> Pairing {
    let steps = |s: &[i64]| -> Vec<i64> { s.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0).collect() };
    let mut d = steps(left);
    d.sort_unstable();
    let period_ns = d.get(d.len() / 2).copied().unwrap_or(0);
    let tolerance_ns = period_ns / 4;
    let nearest = |s: &[i64], t: i64| -> Option<usize> {
        let k = s.partition_point(|&x| x < t);
        [k.checked_sub(1), (k < s.len()).then_some(k)]
            .into_iter()
            .flatten()
            .min_by_key(|&j| ((s[j] - t).unsigned_abs(), j))
    };
    let mut pairs = Vec::new();
    let mut unpaired_left = Vec::new();
    let mut used = vec![false; right.len()];
    for (i, &t) in left.iter().enumerate() {
        let m = nearest(right, t)
            .filter(|&j| (right[j] - t).abs() <= tolerance_ns && nearest(left, right[j]) == Some(i) && !used[j]);
        match m {
            Some(j) => {
                used[j] = true;
                pairs.push((i, j));
            }
            None => unpaired_left.push(i),
        }
    }
    let unpaired_right = used.iter().filter(|u| !**u).count();
    Pairing { pairs, period_ns, tolerance_ns, unpaired_left, unpaired_right }
}

fn invalid(path: &Path, message: String) -> DatasetError {
    DatasetError::Invalid { path: path.to_path_buf(), message }
}

/// The checks of a chosen topic's images: a layout the front end decodes.
fn check_layouts(bag: &Bag, topic: &str) -> Result<(), String> {
    let Some(t) = bag.topic(topic) else { return Ok(()) };
    for l in &t.layouts {
        let known = if t.schema == IMAGE { ENCODINGS.contains(&l.as_str()) } else { known_format(l) };
        if !known {
            let kinds = if t.schema == IMAGE { ENCODINGS.join(", ") } else { "png, jpeg".to_string() };
            return Err(format!(
                "{topic}: images of encoding '{l}', which this program does not decode (it reads {kinds})"
            ));
        }
    }
    if t.count > 0 && bag.images.get(topic).is_none_or(Vec::is_empty) {
        return Err(format!("{topic}: none of its {} messages can be read (see the warnings)", t.count));
    }
    Ok(())
}

/// The sequence of a bag (module doc).
pub fn open_bag(path: &Path, opts: &SourceOptions) -> Result<StereoSequence, DatasetError> {
    let bag = Bag::open(path)?;
    let calib = opts.calib.as_deref().map(read_calibration).transpose()?;
    let choice = choose_topics(&bag, opts, calib.as_ref()).map_err(|m| invalid(path, m))?;
    for t in [&choice.left, &choice.right] {
        check_layouts(&bag, t).map_err(|m| invalid(path, m))?;
    }
    let (rig, calibration, calib_text) = bag_rig(path, &bag, &choice, calib.as_ref())?;
    let no_images = Vec::new();
    let l = bag.images.get(&choice.left).unwrap_or(&no_images);
    let r = bag.images.get(&choice.right).unwrap_or(&no_images);
    let mut warnings = bag.warnings.clone();
    let pairing = pair_images(path, &choice, l, r, &mut warnings)?;
    let t0 = l[0].stamp_ns;
    let ids: Vec<usize> = pairing.pairs.iter().map(|p| p.0).collect();
    let times: Vec<f64> = pairing.pairs.iter().map(|p| (l[p.0].stamp_ns - t0) as f64 * 1e-9).collect();
    let frames: Vec<BagFrame> = pairing.pairs.iter().map(|&(i, j)| BagFrame { left: l[i], right: r[j] }).collect();
    let file_of = |m: &IndexedImage| bag.files.get(m.at.file as usize).cloned().unwrap_or_default();
    let left: Vec<PathBuf> = frames.iter().map(|f| file_of(&f.left)).collect();
    let right: Vec<PathBuf> = frames.iter().map(|f| file_of(&f.right)).collect();
    let schema = |t: &str| bag.topic(t).map(|t| t.schema.clone()).unwrap_or_default();
    let (intrinsics, baseline, calibrated_size, rectify, rectified_here) = tracked_geometry(rig);
    let source = format!(
        "ROS 2 bag, left {} and right {} ({}), {calib_text}{rectified_here}",
        choice.left, choice.right, choice.why
    );
    let bag_frames = BagFrames {
        topics: (choice.left.clone(), choice.right.clone()),
        schemas: (schema(&choice.left), schema(&choice.right)),
        frames,
        bag: Arc::new(bag),
    };
    Ok(StereoSequence {
        layout: Layout::Bag,
        dir: path.to_path_buf(),
        gaps: IdRuns::default(),
        ids,
        left,
        right,
        intrinsics,
        baseline,
        times,
        ground_truth: None,
        truth_source: None,
        dead_reckoned: None,
        labels: None,
        one_camera: Vec::new(),
        warnings,
        recording: Some(Recording { bag: Some(bag_frames), rectify, calibration, calibrated_size, source }),
    })
}

/// A bag's rig, where it came from and the words saying so: the --calib file, else the topics' camera info.
fn bag_rig(
    path: &Path,
    bag: &Bag,
    choice: &TopicChoice,
    calib: Option<&CalibrationFile>,
) -> Result<(slam_core::rig::RigCalibration, PathBuf, String), DatasetError> {
    Ok(match calib {
        Some(c) => (c.rig.clone(), c.path.clone(), format!("calibration from {} ({})", c.path.display(), c.format)),
        None => {
            let (li, ri) = (camera_info_topic(&choice.left), camera_info_topic(&choice.right));
            let info = |t: &str| {
                bag.camera_infos.get(t).ok_or_else(|| {
                    invalid(
                        path,
                        format!("{t}: no readable {CAMERA_INFO}: give the rig's calibration with --calib FILE"),
                    )
                })
            };
            let rig = from_camera_infos(info(&li)?, info(&ri)?, (&li, &ri)).map_err(|m| invalid(path, m))?;
            (rig, path.to_path_buf(), format!("calibration from {li} and {ri}"))
        }
    })
}

/// Pair left and right images by stamp, warning of unpaired left ones and refusing a bag without a pair.
fn pair_images(
    path: &Path,
    choice: &TopicChoice,
    l: &[IndexedImage],
    r: &[IndexedImage],
    warnings: &mut Vec<String>,
) -> Result<Pairing, DatasetError> {
    let stamps = |v: &[IndexedImage]| v.iter().map(|m| m.stamp_ns).collect::<Vec<_>>();
    let pairing = pair_by_stamp(&stamps(l), &stamps(r));
    if !pairing.unpaired_left.is_empty() {
        let first: Vec<String> =
            pairing.unpaired_left.iter().take(3).map(|&i| format!("{} ns", l[i].stamp_ns)).collect();
        warnings.push(format!(
            "{} left image(s) have no right image within {:.1} ms (a quarter of the frame period {:.1} ms) and are skipped (first stamps: {}); {} right image(s) are left without a partner",
            pairing.unpaired_left.len(),
            pairing.tolerance_ns as f64 * 1e-6,
            pairing.period_ns as f64 * 1e-6,
            first.join(", "),
            pairing.unpaired_right
        ));
    }
    if pairing.pairs.is_empty() {
        return Err(invalid(
            path,
            format!(
                "no stereo pair: {} has {} images, {} has {}, and none are within {:.1} ms of each other",
                choice.left,
                l.len(),
                choice.right,
                r.len(),
                pairing.tolerance_ns as f64 * 1e-6
            ),
        ));
    }
    Ok(pairing)
}

/// What a run tracks on with rig `rig`: the rectified pair's intrinsics and baseline (the rig's own when
/// it is rectified already, else those its rectification gives), the size it was calibrated at, the rig
/// to rectify with (none when rectified already) and the words that say so in the source's description.
#[allow(clippy::type_complexity)]
fn tracked_geometry(
    rig: slam_core::rig::RigCalibration,
) -> ([f64; 4], f64, Option<(u32, u32)>, Option<slam_core::rig::RigCalibration>, &'static str) {
    let (intrinsics, baseline) = rig.rectified().unwrap_or_else(|| rig.raw());
    let calibrated_size = rig.size();
    let rectify = rig.rectified().is_none().then_some(rig);
    let words = if rectify.is_some() { ", rectified here (distortion or cameras not row-aligned)" } else { "" };
    (intrinsics, baseline, calibrated_size, rectify, words)
}

/// The image files of a folder, sorted by name.
fn images_in(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    let entries = std::fs::read_dir(dir).map_err(|source| DatasetError::Io { path: dir.to_path_buf(), source })?;
    let mut v: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|x| x.to_str())
                .is_some_and(|x| matches!(x.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
        })
        .collect();
    v.sort();
    Ok(v)
}

/// The sequence of a folder with `left/` and `right/` images (sorted by name; paired by name when the
/// two folders hold the same names, else by place when they hold as many), timed by `times.txt`
/// (one line per frame, seconds) or `opts.rate_hz`, calibrated by `opts.calib`.
pub fn open_folder(path: &Path, opts: &SourceOptions) -> Result<StereoSequence, DatasetError> {
    let Some(calib_path) = &opts.calib else {
        return Err(invalid(path, "a folder of left/ and right/ images needs the rig's calibration: --calib FILE (a Kalibr camchain or ORB-SLAM's stereo settings)".into()));
    };
    let calib = read_calibration(calib_path)?;
    let (left, right) = folder_images(path)?;
    let n = left.len();
    let times = folder_times(path, opts, n)?;
    let (intrinsics, baseline, calibrated_size, rectify, rectified_here) = tracked_geometry(calib.rig.clone());
    let source = format!(
        "left/ and right/ images, calibration from {} ({}){rectified_here}",
        calib.path.display(),
        calib.format
    );
    Ok(StereoSequence {
        layout: Layout::Folder,
        dir: path.to_path_buf(),
        ids: (0..n).collect(),
        left,
        right,
        intrinsics,
        baseline,
        times,
        ground_truth: None,
        truth_source: None,
        dead_reckoned: None,
        labels: None,
        gaps: IdRuns::default(),
        one_camera: Vec::new(),
        warnings: Vec::new(),
        recording: Some(Recording { bag: None, rectify, calibration: calib.path, calibrated_size, source }),
    })
}

/// The images of `left/` and `right/`, refused when none, or when paired neither by name nor by place.
fn folder_images(path: &Path) -> Result<(Vec<PathBuf>, Vec<PathBuf>), DatasetError> {
    let (left, right) = (images_in(&path.join("left"))?, images_in(&path.join("right"))?);
    let names = |v: &[PathBuf]| v.iter().map(|p| p.file_name().map(|n| n.to_os_string())).collect::<Vec<_>>();
    if names(&left) != names(&right) && left.len() != right.len() {
        return Err(invalid(
            path,
            format!("left/ holds {} images and right/ {}, under different names: images are paired by name, or by place when both hold as many", left.len(), right.len()),
        ));
    }
    if left.is_empty() {
        return Err(invalid(path, "left/ and right/ hold no PNG or JPEG image".into()));
    }
    Ok((left, right))
}

/// The times of a folder's `n` frames, seconds from the first: from its `times.txt` or at `--rate`.
fn folder_times(path: &Path, opts: &SourceOptions, n: usize) -> Result<Vec<f64>, DatasetError> {
    let times_path = path.join("times.txt");
    let times =
        match (times_path.exists(), opts.rate_hz) {
            (true, Some(_)) => return Err(invalid(&times_path, "--rate given beside times.txt: use one".into())),
            (true, None) => read_times(&times_path, n)?,
            (false, Some(hz)) => {
                if !(hz.is_finite() && hz > 0.0 && hz <= 1000.0) {
                    return Err(invalid(
                        path,
                        format!("--rate {hz}: frames a second in (0, 1000] (no camera of a moving rig records faster)"),
                    ));
                }
                (0..n).map(|k| k as f64 / hz).collect()
            }
            (false, None) => return Err(invalid(
                path,
                "the frames' times: a times.txt beside left/ and right/ (one line of seconds per frame) or --rate HZ"
                    .into(),
            )),
        };
    Ok(times)
}

/// The first `n` times of `times.txt` (one a line, each after the one before), counted from the first.
fn read_times(times_path: &Path, n: usize) -> Result<Vec<f64>, DatasetError> {
    let text = crate::read_text(times_path, &slam_core::files::TABLE)?;
    let lines = crate::frame_lines(times_path, &text)?;
    if lines.len() < n {
        return Err(invalid(times_path, format!("{} times for {n} frames", lines.len())));
    }
    let mut t = Vec::with_capacity(n);
    for (line, l) in lines.iter().take(n) {
        let v = crate::parse_exact(times_path, *line, &l.split_whitespace().collect::<Vec<_>>(), 1)?[0];
        if t.last().is_some_and(|&p: &f64| v <= p) {
            return Err(DatasetError::Parse {
                path: times_path.to_path_buf(),
                line: *line,
                message: format!("time {v} is not after the one before"),
            });
        }
        t.push(v);
    }
    let t0 = t[0];
    Ok(t.into_iter().map(|v| v - t0).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_pair_within_a_quarter_period_and_never_twice() {
        let ms = 1_000_000;
        // 10 Hz, the right camera 3 ms late, its frame 3 lost, one left image 40 ms off its partner
        let left: Vec<i64> = (0..6).map(|k| k * 100 * ms).collect();
        let right = vec![3 * ms, 103 * ms, 203 * ms, 440 * ms, 503 * ms];
        let p = pair_by_stamp(&left, &right);
        assert_eq!((p.period_ns, p.tolerance_ns), (100 * ms, 25 * ms));
        assert_eq!(p.pairs, vec![(0, 0), (1, 1), (2, 2), (5, 4)]);
        assert_eq!((p.unpaired_left, p.unpaired_right), (vec![3, 4], 1));
        // one right image nearest to two left ones goes to the nearer
        let p = pair_by_stamp(&[0, 10 * ms, 100 * ms], &[8 * ms, 100 * ms]);
        assert_eq!(p.pairs, vec![(1, 0), (2, 1)]);
    }

    #[test]
    fn camera_namespaces_follow_image_transport() {
        assert_eq!(camera_namespace("/kitti/camera_gray_left/image_raw"), "/kitti/camera_gray_left");
        assert_eq!(camera_namespace("/cam/image_raw/compressed"), "/cam");
        assert_eq!(camera_info_topic("/stereo/left/image_rect"), "/stereo/left/camera_info");
        assert!(known_format("bgr8; jpeg compressed bgr8") && known_format("png") && !known_format("theora"));
    }
}
