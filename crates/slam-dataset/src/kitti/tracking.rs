//! KITTI tracking labels (`label_02/NNNN.txt`): one object per line,
//! `frame track_id type truncated occluded alpha left top right bottom h w l x y z rotation_y`.
//!
//! `(x, y, z)` is the bottom centre of the 3-D box in rectified camera-0 coordinates (x right, y down,
//! z forward), metres; `rotation_y` is about the camera y axis; the 2-D box is in the left colour image.

use std::path::Path;

use slam_core::{geometry::BBox, ClassId};

use crate::{classes::kitti_class, parse_numbers, read_text, DatasetError};

/// One label line.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackingLabel {
    /// Frame index.
    pub frame: usize,
    /// Track id (−1 for DontCare).
    pub track_id: i64,
    /// KITTI type ("Car", "Van", "Pedestrian", …, "DontCare").
    pub kind: String,
    /// Our class, `None` for DontCare and Misc.
    pub class: Option<ClassId>,
    /// Truncation in `[0, 1]` (−1 for DontCare).
    pub truncated: f64,
    /// Occlusion state 0–3 (−1 for DontCare).
    pub occluded: i32,
    /// 2-D box in the left colour image, pixels.
    pub bbox: BBox,
    /// 3-D box size `(height, width, length)`, metres.
    pub dimensions: [f64; 3],
    /// Bottom centre of the 3-D box, rectified camera-0 frame, metres.
    pub location: [f64; 3],
    /// Yaw about the camera y axis, radians.
    pub rotation_y: f64,
    /// Line of the label file it was read from (1-based; 0 when made in code).
    pub line: usize,
}

impl TrackingLabel {
    /// True for DontCare regions.
    pub fn is_dont_care(&self) -> bool {
        self.kind == "DontCare"
    }
}

/// Read a tracking label file, in (frame, track) order whatever the order of its lines (a file out of
/// order is said in the log). Errors name the file and line.
pub fn read_tracking_labels(path: impl AsRef<Path>) -> Result<Vec<TrackingLabel>, DatasetError> {
    let path = path.as_ref();
    let text = read_text(path, &slam_core::files::TABLE)?;
    parse_tracking_labels(path, &text)
}

/// Parse the contents of such a file; `path` only names it in error messages.
pub fn parse_tracking_labels(path: &Path, text: &str) -> Result<Vec<TrackingLabel>, DatasetError> {
    let mut out = Vec::new();
    // (frame, track) → line: a track is one object, seen once per frame
    let mut seen: std::collections::HashMap<(usize, i64), usize> = std::collections::HashMap::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let label = parse_label_line(path, i, line)?;
        if !label.is_dont_care() {
            if let Some(first) = seen.insert((label.frame, label.track_id), i + 1) {
                let (track_id, frame) = (label.track_id, label.frame);
                return Err(DatasetError::Parse {
                    path: path.to_path_buf(),
                    line: i + 1,
                    message: format!(
                        "track {track_id} again in frame {frame} (first on line {first}): a track is one object, labelled once per frame"
                    ),
                });
            }
        }
        out.push(label);
    }
    if out.is_empty() {
        return Err(DatasetError::Invalid { path: path.to_path_buf(), message: "no labels in the file".into() });
    }
    in_frame_order(path, &mut out);
    Ok(out)
}

/// One label line (line `i + 1`) parsed and checked; the caller checks a track is labelled once a frame.
fn parse_label_line(path: &Path, i: usize, line: &str) -> Result<TrackingLabel, DatasetError> {
    let f: Vec<&str> = line.split_whitespace().collect();
    let err = |message: String| DatasetError::Parse { path: path.to_path_buf(), line: i + 1, message };
    if f.len() != 17 {
        return Err(err(format!("expected 17 fields, found {}", f.len())));
    }
    let frame = f[0].parse::<usize>().map_err(|_| err(format!("bad frame index '{}'", f[0])))?;
    let track_id = f[1].parse::<i64>().map_err(|_| err(format!("bad track id '{}'", f[1])))?;
    let occluded = f[4].parse::<i32>().map_err(|_| err(format!("bad occlusion '{}'", f[4])))?;
    let v = parse_numbers(path, i + 1, &[&f[3..4], &f[5..17]].concat())?;
    let bbox = BBox::new(v[2], v[3], v[4], v[5]);
    let kind = f[2].to_string();
    check_label_box(&kind, &bbox, &v).map_err(err)?;
    check_label_codes(&kind, occluded, track_id, &v).map_err(err)?;
    Ok(TrackingLabel {
        frame,
        track_id,
        class: kitti_class(&kind),
        kind,
        truncated: v[0],
        occluded,
        bbox,
        dimensions: [v[6], v[7], v[8]],
        location: [v[9], v[10], v[11]],
        rotation_y: v[12],
        line: i + 1,
    })
}

/// Check a label's type, 2-D box, truncation and 3-D size (`v`: its numbers); the first failure's message.
fn check_label_box(kind: &str, bbox: &BBox, v: &[f64]) -> Result<(), String> {
    if !KITTI_TYPES.contains(&kind) {
        return Err(format!("unknown type '{kind}' (KITTI's are {})", KITTI_TYPES.join(", ")));
    }
    if kind != "DontCare" && bbox.validated().is_err() {
        return Err(format!("empty box [{}, {}, {}, {}]", v[2], v[3], v[4], v[5]));
    }
    // truncation: 0–1 (object benchmark, a fraction) or 0, 1, 2 (tracking benchmark, levels)
    if kind != "DontCare" && !(0.0..=2.0).contains(&v[0]) {
        return Err(format!("truncated {} outside 0-2", v[0]));
    }
    if kind != "DontCare" && !(v[6] > 0.0 && v[7] > 0.0 && v[8] > 0.0) {
        return Err(format!(
            "3-D size {} × {} × {} m (height, width, length): each must be positive",
            v[6], v[7], v[8]
        ));
    }
    if kind != "DontCare" {
        let most = max_label_size_m(kind);
        if let Some(k) = (0..3).find(|&k| v[6 + k] > most[k]) {
            let name = ["height", "width", "length"][k];
            return Err(format!(
                "{name} {} m for a {kind}: at most {} m (a {kind} box is at most {} × {} × {} m, height × width × length; {})",
                v[6 + k],
                most[k],
                most[0],
                most[1],
                most[2],
                LABEL_SIZE_REASON
            ));
        }
    }
    Ok(())
}

/// Check a label's occlusion level, angles, track id and location; the first failure's message.
fn check_label_codes(kind: &str, occluded: i32, track_id: i64, v: &[f64]) -> Result<(), String> {
    // occlusion is a level 0-3 (3: unknown) and alpha an angle of the circle, for every object
    if kind != "DontCare" && !(0..=3).contains(&occluded) {
        return Err(format!(
            "occluded {occluded}: KITTI's occlusion levels are 0 (visible), 1 (partly), 2 (largely) and 3 (unknown)"
        ));
    }
    for (name, a) in [("alpha", v[1]), ("rotation_y", v[12])] {
        // written with 6 decimals: π rounds up by at most 5e-7
        if kind != "DontCare" && a.abs() > std::f64::consts::PI + 1e-6 {
            return Err(format!("{name} {a} rad: an angle in [-π, π] (KITTI's range)"));
        }
    }
    // KITTI numbers tracks from 0 and gives DontCare regions -1
    let valid_id = if kind == "DontCare" { track_id == -1 } else { track_id >= 0 };
    if !valid_id {
        return Err(format!(
            "track id {track_id} for a {kind}: tracks are numbered from 0, and -1 marks a DontCare region"
        ));
    }
    if kind != "DontCare" {
        if let Some(a) = v[9..12].iter().find(|a| a.abs() > MAX_LABEL_DISTANCE_M) {
            return Err(format!(
                "location coordinate {a:.3e} m: a labelled object lies within {MAX_LABEL_DISTANCE_M} m of the camera (at 1 km a car is 3 px wide at KITTI's focal length; its labels reach 150 m)"
            ));
        }
    }
    Ok(())
}

/// Put the labels in (frame, track) order when the file's lines are not, saying so in the log.
fn in_frame_order(path: &Path, out: &mut [TrackingLabel]) {
    // every consumer walks labels by frame, and takes a track's first label as its reference: the file's
    // line order must not matter
    if let Some(k) = out.windows(2).position(|w| (w[1].frame, w[1].track_id) < (w[0].frame, w[0].track_id)) {
        tracing::warn!(
            "{}: labels are not in frame order (line {}: frame {} after frame {} on line {}): read in frame order",
            path.display(),
            out[k + 1].line,
            out[k + 1].frame,
            out[k].frame,
            out[k].line
        );
        out.sort_by_key(|l| (l.frame, l.track_id));
    }
}

/// Refuse a label whose frame is not one of the sequence's `frames` (frames `0..frames`, counted from
/// `source`, e.g. "the 270 poses of poses_orbslam3.txt"), naming the label file's line. Everything that
/// then walks the labelled frames costs in proportion to the sequence, never to the largest id a label
/// names (an id of 10^8 or 2^64 - 1 would otherwise mean a loop or a table that long).
pub fn check_label_frames(
    path: &Path,
    labels: &[TrackingLabel],
    frames: usize,
    source: &str,
) -> Result<(), DatasetError> {
    match labels.iter().find(|l| l.frame >= frames) {
        Some(l) => Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line: l.line,
            message: format!(
                "frame {} is not a frame of the sequence: it has {frames} frame(s) (0-{}), from {source}",
                l.frame,
                frames.saturating_sub(1)
            ),
        }),
        None => Ok(()),
    }
}

/// Largest 3-D box a label of `kind` may have, metres (height, width, length). Road vehicles are at most
/// 4 m high and 2.55 m wide and a road train 25.25 m long (EU Directive 96/53/EC); coupled city trams
/// reach about 75 m; a person or a cyclist fits in 3 m. The bounds leave room for labelling slack
/// (KITTI's own labels reach a 4.05 m truck and a 35 m tram) and refuse only boxes no object has.
pub fn max_label_size_m(kind: &str) -> [f64; 3] {
    match kind {
        "Pedestrian" | "Person" | "Person_sitting" | "Cyclist" => [3.0, 3.0, 3.0],
        "Tram" => [5.0, 4.0, 80.0],
        _ => [5.0, 4.0, 30.0],
    }
}

const LABEL_SIZE_REASON: &str =
    "road vehicles are at most 4 m high, 2.55 m wide, 25.25 m long (EU 96/53/EC), coupled trams about 75 m";

/// Farthest a labelled object's 3-D box may lie from the camera, metres, on each axis.
pub const MAX_LABEL_DISTANCE_M: f64 = 1000.0;

/// The object types of KITTI's label files (object and tracking benchmarks; the tracking labels write
/// `Person` for a sitting person).
pub const KITTI_TYPES: [&str; 10] =
    ["Car", "Van", "Truck", "Pedestrian", "Person", "Person_sitting", "Cyclist", "Tram", "Misc", "DontCare"];

/// A KITTI tracking sequence in either layout:
///
/// * **official**: `training/{image_02/NNNN/*.png, label_02/NNNN.txt, calib/NNNN.txt, oxts/NNNN.txt}`;
/// * **image-free** (this repository's `fixtures/kitti_tracking/NNNN/`): `label_02.txt`, `calib.txt` and
///   `poses_orbslam3.txt` (camera-to-world poses of the left colour camera, one per frame).
#[derive(Debug, Clone)]
pub struct TrackingSequence {
    /// Labels, all frames.
    pub labels: Vec<TrackingLabel>,
    /// Calibration (`P0..P3`, `R0_rect` / `R_rect`, `Tr_velo_to_cam` / `Tr_velo_cam`, …).
    pub calib: crate::kitti::calib::Calib,
    /// Left colour images, sorted (empty in the image-free layout).
    pub images: Vec<std::path::PathBuf>,
    /// Camera-to-world poses when known (image-free: `poses_orbslam3.txt`).
    pub poses: Option<Vec<nalgebra::Isometry3<f64>>>,
    /// IMU poses from the OXTS file (official layout), relative to the first frame.
    pub imu_poses: Option<Vec<nalgebra::Isometry3<f64>>>,
}

impl TrackingSequence {
    /// Open sequence `seq` (e.g. `"0000"`) under an official `training/` folder.
    pub fn open_official(training: impl AsRef<Path>, seq: &str) -> Result<Self, DatasetError> {
        let t = training.as_ref();
        let labels = read_tracking_labels(t.join("label_02").join(format!("{seq}.txt")))?;
        let calib = crate::kitti::calib::Calib::read(t.join("calib").join(format!("{seq}.txt")))?;
        let img_dir = t.join("image_02").join(seq);
        let mut images: Vec<std::path::PathBuf> = std::fs::read_dir(&img_dir)
            .map_err(|source| DatasetError::Io { path: img_dir.clone(), source })?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
            .collect();
        images.sort();
        let oxts_path = t.join("oxts").join(format!("{seq}.txt"));
        let imu_poses = if oxts_path.exists() {
            let text = read_text(&oxts_path, &slam_core::files::TABLE)?;
            let mut packets = Vec::new();
            for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
                let p = crate::kitti::raw::parse_oxts_packet(&oxts_path, line).map_err(|e| match e {
                    DatasetError::Parse { path, message, .. } => DatasetError::Parse { path, line: i + 1, message },
                    other => other,
                })?;
                packets.push(p);
            }
            Some(crate::kitti::raw::oxts_poses(&packets))
        } else {
            None
        };
        Ok(Self { labels, calib, images, poses: None, imu_poses })
    }

    /// Open an image-free sequence folder (`label_02.txt`, `calib.txt`, `poses_orbslam3.txt`).
    pub fn open_image_free(dir: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let d = dir.as_ref();
        let labels = read_tracking_labels(d.join("label_02.txt"))?;
        let calib = crate::kitti::calib::Calib::read(d.join("calib.txt"))?;
        let poses = crate::kitti::poses::read_ground_truth_poses(d.join("poses_orbslam3.txt"))?;
        let source =
            format!("the {} poses of {} (line k is frame k)", poses.len(), d.join("poses_orbslam3.txt").display());
        check_label_frames(&d.join("label_02.txt"), &labels, poses.len(), &source)?;
        Ok(Self { labels, calib, images: Vec::new(), poses: Some(poses), imu_poses: None })
    }

    /// Translation from the rectified camera-0 frame (labels) to the left colour camera (cam2):
    /// `t2 = K⁻¹ · P2[:, 3]` (about +0.06 m in x on KITTI).
    pub fn cam2_offset(&self) -> Result<nalgebra::Vector3<f64>, DatasetError> {
        let p2 = self.calib.matrix3x4("P2")?;
        let k = p2.fixed_view::<3, 3>(0, 0).into_owned();
        let col: nalgebra::Vector3<f64> = p2.column(3).into_owned();
        k.try_inverse().map(|ki| ki * col).ok_or_else(|| DatasetError::Invalid {
            path: self.calib.path().to_path_buf(),
            message: "the camera matrix of P2 is singular".into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CAR: &str = "0 0 Car 0 0 -1.5 100 150 200 190 1.5 1.6 3.9 2.0 1.7 20.0 -1.6";

    #[test]
    fn a_label_beyond_the_sequence_is_named_by_its_line() {
        let p = Path::new("label_02.txt");
        for frame in ["5", "100000000", "18446744073709551615"] {
            let text = format!("{CAR}\n\n{}\n", CAR.replacen("0 0 Car", &format!("{frame} 1 Car"), 1));
            let labels = parse_tracking_labels(p, &text).expect("parses");
            let e = check_label_frames(p, &labels, 5, "the 5 poses").expect_err("beyond").to_string();
            assert!(e.contains("label_02.txt:3:") && e.contains(frame), "{e}");
            assert!(e.contains("5 frame(s) (0-4)"), "{e}");
        }
        let labels = parse_tracking_labels(p, &format!("{CAR}\n")).expect("parses");
        check_label_frames(p, &labels, 1, "one pose").expect("frame 0 of 1");
    }

    #[test]
    fn a_box_no_object_has_is_refused_by_class() {
        let p = Path::new("label_02.txt");
        let tall = CAR.replacen("1.5 1.6 3.9", "500 1.6 3.9", 1);
        let e = parse_tracking_labels(p, &tall).expect_err("500 m high").to_string();
        assert!(
            e.contains("label_02.txt:1:") && e.contains("height 500 m for a Car") && e.contains("at most 5 m"),
            "{e}"
        );
        let long_person = CAR.replacen("Car", "Pedestrian", 1);
        let e = parse_tracking_labels(p, &long_person).expect_err("3.9 m person").to_string();
        assert!(e.contains("length 3.9 m for a Pedestrian"), "{e}");
        let tram = CAR.replacen("Car", "Tram", 1).replacen("1.5 1.6 3.9", "3.7 2.8 35.2", 1);
        parse_tracking_labels(p, &tram).expect("a long tram");
    }

    /// R04/R15: the same labels in any line order are read alike (frame order, tracks within a frame
    /// in id order); an occlusion level or an angle outside KITTI's ranges is refused by line.
    #[test]
    fn line_order_does_not_matter_and_levels_and_angles_are_checked() {
        let p = Path::new("label_02.txt");
        let lines = [
            "0 -1 DontCare -1 -1 -10 10 10 40 40 -1000 -1000 -1000 -10 -1 -1 -1".to_string(),
            CAR.to_string(),
            CAR.replacen("0 0 Car", "0 3 Car", 1),
            CAR.replacen("0 0 Car", "1 0 Car", 1),
            CAR.replacen("0 0 Car", "2 3 Car", 1),
        ];
        let forward = parse_tracking_labels(p, &(lines.join("\n") + "\n")).expect("forward");
        let mut reversed = lines.to_vec();
        reversed.reverse();
        let back = parse_tracking_labels(p, &(reversed.join("\n") + "\n")).expect("reversed");
        let key = |v: &[TrackingLabel]| v.iter().map(|l| (l.frame, l.track_id, l.kind.clone())).collect::<Vec<_>>();
        assert_eq!(key(&forward), key(&back));
        assert_eq!(back[1].line, 4, "each label keeps its own line for messages");
        for (field, value, want) in
            [(4, "9", "occluded 9"), (5, "100", "alpha 100 rad"), (16, "-7", "rotation_y -7 rad")]
        {
            let mut f: Vec<&str> = CAR.split_whitespace().collect();
            f[field] = value;
            let e = parse_tracking_labels(p, &f.join(" ")).expect_err(want).to_string();
            assert!(e.contains("label_02.txt:1:") && e.contains(want), "{e}");
        }
    }
}
