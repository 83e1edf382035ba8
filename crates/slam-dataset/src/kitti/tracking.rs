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
}

impl TrackingLabel {
    /// True for DontCare regions.
    pub fn is_dont_care(&self) -> bool {
        self.kind == "DontCare"
    }
}

/// Read a tracking label file. Errors name the file and line.
pub fn read_tracking_labels(path: impl AsRef<Path>) -> Result<Vec<TrackingLabel>, DatasetError> {
    let path = path.as_ref();
    let text = read_text(path)?;
    parse_tracking_labels(path, &text)
}

/// Parse the contents of such a file; `path` only names it in error messages.
pub fn parse_tracking_labels(path: &Path, text: &str) -> Result<Vec<TrackingLabel>, DatasetError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
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
        if kind != "DontCare" && bbox.validated().is_err() {
            return Err(err(format!("empty box [{}, {}, {}, {}]", v[2], v[3], v[4], v[5])));
        }
        out.push(TrackingLabel {
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
        });
    }
    Ok(out)
}
