//! Detection files and ground-truth detection sources.
//!
//! ## The JSON schema (version 1)
//!
//! ```json
//! {
//!   "version": 1,
//!   "image_size": [1242, 375],
//!   "frames": [
//!     { "frame": 0,
//!       "detections": [
//!         { "class": 2, "class_name": "car", "score": 0.91, "box": [296.7, 161.8, 455.2, 292.4],
//!           "mask": { "rle": { "size": [375, 1242], "counts": [12345, 20, 355, 21] } } },
//!         { "class": 0, "score": 0.55, "box": [10, 20, 60, 140],
//!           "mask": { "polygon": [[12, 22], [58, 22], [58, 138], [12, 138]] } }
//!       ] } ] }
//! ```
//!
//! * `class`: COCO-80 index (see [`crate::classes`]); `class_name` is informative, but one that names
//!   another COCO class (COCO's name or Darknet's spelling of it) contradicts the index and is refused.
//! * `box`: `[xmin, ymin, xmax, ymax]` in pixels of the left image; `score` in `[0, 1]`.
//! * `mask` (optional): COCO-style uncompressed RLE over the whole image (`size` = `[height, width]`,
//!   run lengths in column-major order starting with a run of 0s), or a polygon of pixel coordinates.
//! * Frames missing from the file have no detections. Invalid detections (NaN or empty box, score
//!   outside `[0, 1]`, a mask whose RLE does not sum to `height · width`) are errors naming the frame
//!   and detection, never silently dropped.

use std::{collections::BTreeMap, path::Path};

use serde::{Deserialize, Serialize};
use slam_core::{geometry::BBox, rng::SimRng, ClassId, DetectError, Detection, DetectionSource, Image, Mask};

use crate::{classes, read_text, DatasetError};

/// Current schema version.
pub const SCHEMA_VERSION: u32 = 1;

/// Whether `name` names COCO class `class`: COCO's own name or Darknet's `coco.names` spelling of it
/// (`motorbike`, `aeroplane`, `sofa`, `pottedplant`, `diningtable`, `tvmonitor`), in any case, with
/// spaces, underscores or hyphens alike.
fn names_class(name: &str, class: u16) -> bool {
    let norm = |s: &str| s.to_lowercase().replace(['_', '-'], " ");
    let darknet = match class {
        3 => "motorbike",
        4 => "aeroplane",
        57 => "sofa",
        58 => "pottedplant",
        60 => "diningtable",
        62 => "tvmonitor",
        _ => "",
    };
    let n = norm(name.trim());
    n == norm(ClassId(class).name()) || (!darknet.is_empty() && n == darknet)
}

/// Number of COCO-80 class indices (`class` runs from 0 to 79).
pub const COCO_CLASSES: usize = 80;

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileJson {
    version: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    image_size: Option<[u32; 2]>,
    frames: Vec<FrameJson>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameJson {
    frame: usize,
    detections: Vec<DetJson>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct DetJson {
    class: u16,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    class_name: Option<String>,
    score: f64,
    #[serde(rename = "box")]
    bbox: [f64; 4],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    mask: Option<MaskJson>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
enum MaskJson {
    Rle { size: [u32; 2], counts: Vec<u32> },
    Polygon(Vec<[f64; 2]>),
}

/// Decode an uncompressed column-major RLE over an image of `height × width` into a mask cropped to
/// its set pixels.
fn mask_from_rle(height: u32, width: u32, counts: &[u32]) -> Result<Mask, String> {
    if height as u64 * width as u64 > 100_000_000 {
        return Err(format!("mask size {height}×{width} is larger than 100 megapixels"));
    }
    let total: u64 = counts.iter().map(|&c| c as u64).sum();
    if total != height as u64 * width as u64 {
        return Err(format!("RLE counts sum to {total}, image has {} pixels", height as u64 * width as u64));
    }
    let mut set = Vec::new();
    let mut pos = 0u64;
    for (i, &c) in counts.iter().enumerate() {
        if i % 2 == 1 {
            for p in pos..pos + c as u64 {
                let (x, y) = ((p / height as u64) as i32, (p % height as u64) as i32);
                set.push((x, y));
            }
        }
        pos += c as u64;
    }
    Ok(mask_from_pixels(&set))
}

fn mask_from_pixels(set: &[(i32, i32)]) -> Mask {
    if set.is_empty() {
        return Mask { x0: 0, y0: 0, width: 0, height: 0, bits: Vec::new() };
    }
    let x0 = set.iter().map(|p| p.0).min().unwrap_or(0);
    let y0 = set.iter().map(|p| p.1).min().unwrap_or(0);
    let x1 = set.iter().map(|p| p.0).max().unwrap_or(0);
    let y1 = set.iter().map(|p| p.1).max().unwrap_or(0);
    let (w, h) = ((x1 - x0 + 1) as u32, (y1 - y0 + 1) as u32);
    let mut bits = vec![false; w as usize * h as usize];
    for &(x, y) in set {
        bits[(y - y0) as usize * w as usize + (x - x0) as usize] = true;
    }
    Mask { x0, y0, width: w, height: h, bits }
}

/// Rasterise a polygon (even-odd rule, pixel centres).
fn mask_from_polygon(poly: &[[f64; 2]]) -> Result<Mask, String> {
    if poly.len() < 3 || !poly.iter().flatten().all(|v| v.is_finite()) {
        return Err("polygon needs at least 3 finite points".into());
    }
    let (xmin, xmax) = poly.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p[0]), b.max(p[0])));
    let (ymin, ymax) = poly.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p[1]), b.max(p[1])));
    if (xmax - xmin) * (ymax - ymin) > 4.0e7 {
        return Err("polygon too large".into());
    }
    let mut set = Vec::new();
    for y in (ymin.floor() as i32)..=(ymax.ceil() as i32) {
        for x in (xmin.floor() as i32)..=(xmax.ceil() as i32) {
            let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
            let mut inside = false;
            let n = poly.len();
            for i in 0..n {
                let (a, b) = (poly[i], poly[(i + n - 1) % n]);
                if (a[1] > py) != (b[1] > py) && px < (b[0] - a[0]) * (py - a[1]) / (b[1] - a[1]) + a[0] {
                    inside = !inside;
                }
            }
            if inside {
                set.push((x, y));
            }
        }
    }
    Ok(mask_from_pixels(&set))
}

fn rle_of(mask: &Mask, height: u32, width: u32) -> Vec<u32> {
    let mut counts = Vec::new();
    let (mut current, mut run) = (false, 0u32);
    for x in 0..width as i32 {
        for y in 0..height as i32 {
            let v = mask.contains(x as f64 + 0.5, y as f64 + 0.5);
            if v != current {
                counts.push(run);
                run = 0;
                current = v;
            }
            run += 1;
        }
    }
    counts.push(run);
    counts
}

/// Detections of a whole sequence, by frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DetectionFile {
    /// Image size `[width, height]`, needed to write masks as RLE.
    pub image_size: Option<[u32; 2]>,
    /// Detections per frame (frames without detections may be absent).
    pub frames: BTreeMap<usize, Vec<Detection>>,
}

impl DetectionFile {
    /// Read and validate a detection file.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let text = read_text(path, &slam_core::files::DOCUMENT)?;
        Self::parse(path, &text)
    }

    /// Parse the contents of such a file; `path` only names it in error messages.
    pub fn parse(path: &Path, text: &str) -> Result<Self, DatasetError> {
        // serde would read an array as the object's fields in order ("invalid type: map, expected u32"):
        // say what the file is instead
        if let Some((k, c)) = text.char_indices().find(|(_, c)| !c.is_whitespace()).filter(|&(_, c)| c != '{') {
            let line = 1 + text[..k].matches('\n').count();
            let what = if c == '[' { "an array" } else { "not a JSON object" };
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line,
                message: format!(
                    "the file is {what}: a detection file is one object, {{\"version\": {SCHEMA_VERSION}, \"frames\": [...]}} (docs/detections.md)"
                ),
            });
        }
        let parsed: FileJson = serde_json::from_str(text).map_err(|e| {
            let at = slam_core::files::json_path_at(text, e.line(), e.column());
            DatasetError::Parse {
                path: path.to_path_buf(),
                line: e.line(),
                message: if at.is_empty() { e.to_string() } else { format!("{at}: {e}") },
            }
        })?;
        let invalid = |m: String| DatasetError::Invalid { path: path.to_path_buf(), message: m };
        if parsed.version != SCHEMA_VERSION {
            return Err(invalid(format!("schema version {} (this reader knows {SCHEMA_VERSION})", parsed.version)));
        }
        let mut frames = BTreeMap::new();
        // an RLE mask covers the whole image: its size is the image size, the file's or the first mask's
        let mut image_size = parsed.image_size;
        for f in parsed.frames {
            let mut dets = Vec::with_capacity(f.detections.len());
            for (k, d) in f.detections.into_iter().enumerate() {
                let where_ = format!("frame {} detection {k}", f.frame);
                let bbox = BBox::from_array(d.bbox).validated().map_err(|e| invalid(format!("{where_}: {e}")))?;
                if !(0.0..=1.0).contains(&d.score) {
                    return Err(invalid(format!("{where_}: score {} outside [0, 1]", d.score)));
                }
                if usize::from(d.class) >= COCO_CLASSES {
                    return Err(invalid(format!(
                        "{where_}: class {} is not a COCO class index (0-{})",
                        d.class,
                        COCO_CLASSES - 1
                    )));
                }
                // a name of another COCO class contradicts the index; a name of none ("other") is a note
                let other = d.class_name.as_deref().and_then(|n| {
                    (0..COCO_CLASSES as u16).find(|&c| c != d.class && names_class(n, c)).map(|c| (n, c))
                });
                if let Some((name, c)) = other {
                    return Err(invalid(format!(
                        "{where_}: class {} is COCO's \"{}\" but class_name \"{name}\" names class {c}: the two \
                         contradict each other (the class index is what is used; correct or drop class_name)",
                        d.class,
                        ClassId(d.class).name()
                    )));
                }
                let mask = match d.mask {
                    None => None,
                    Some(MaskJson::Rle { size, counts }) => {
                        let [w, h] = *image_size.get_or_insert([size[1], size[0]]);
                        if size != [h, w] {
                            return Err(invalid(format!(
                                "{where_}: mask size {}×{} (height × width) is not the image's {h}×{w}: an RLE mask covers the whole image",
                                size[0], size[1]
                            )));
                        }
                        Some(mask_from_rle(size[0], size[1], &counts).map_err(|e| invalid(format!("{where_}: {e}")))?)
                    }
                    Some(MaskJson::Polygon(p)) => {
                        Some(mask_from_polygon(&p).map_err(|e| invalid(format!("{where_}: {e}")))?)
                    }
                };
                dets.push(Detection { class: ClassId(d.class), score: d.score, bbox, mask });
            }
            if frames.insert(f.frame, dets).is_some() {
                return Err(invalid(format!("frame {} appears twice", f.frame)));
            }
        }
        Ok(Self { image_size, frames })
    }

    /// Write the file atomically. Masks are written as RLE when the image size is known, else dropped
    /// with a warning.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), DatasetError> {
        let path = path.as_ref();
        Ok(slam_core::files::write_atomic(path, self.to_json(path)?.as_bytes())?)
    }

    /// The file's JSON text ([`DetectionFile::write`]); `path` names the file in messages.
    pub fn to_json(&self, path: &Path) -> Result<String, DatasetError> {
        let mut dropped = 0usize;
        let frames = self
            .frames
            .iter()
            .map(|(&frame, dets)| FrameJson {
                frame,
                detections: dets
                    .iter()
                    .map(|d| DetJson {
                        class: d.class.0,
                        class_name: Some(classes::name(d.class).to_string()),
                        score: d.score,
                        bbox: d.bbox.to_array(),
                        mask: d.mask.as_ref().and_then(|m| match self.image_size {
                            Some([w, h]) => Some(MaskJson::Rle { size: [h, w], counts: rle_of(m, h, w) }),
                            None => {
                                dropped += 1;
                                None
                            }
                        }),
                    })
                    .collect(),
            })
            .collect();
        if dropped > 0 {
            tracing::warn!(dropped, path = %path.display(), "masks not written: image size unknown");
        }
        let json = FileJson { version: SCHEMA_VERSION, image_size: self.image_size, frames };
        serde_json::to_string(&json)
            .map_err(|e| DatasetError::Invalid { path: path.to_path_buf(), message: e.to_string() })
    }
}

impl DetectionSource for DetectionFile {
    fn name(&self) -> &str {
        "file"
    }

    fn needs_image(&self) -> bool {
        false
    }

    fn detect(&mut self, frame: usize, _image: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
        Ok(self.frames.get(&frame).cloned().unwrap_or_default())
    }
}

/// Noise applied to ground-truth boxes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundTruthNoise {
    /// σ of each box coordinate as a fraction of the box width (x) or height (y).
    pub box_sigma: f64,
    /// Probability that a true detection is dropped.
    pub dropout: f64,
    /// Expected number of false boxes per frame (Poisson-like: rounded uniform).
    pub false_positives: f64,
    /// Seed.
    pub seed: u64,
}

impl Default for GroundTruthNoise {
    fn default() -> Self {
        Self { box_sigma: 0.0, dropout: 0.0, false_positives: 0.0, seed: 1 }
    }
}

/// Ground-truth boxes (e.g. KITTI labels) as a detection source, with seeded noise, dropout and false
/// positives. The noise of frame `f` depends only on the seed and `f`, not on the order of calls.
#[derive(Debug, Clone)]
pub struct GroundTruthDetections {
    truth: BTreeMap<usize, Vec<Detection>>,
    noise: GroundTruthNoise,
    image: [f64; 2],
}

impl GroundTruthDetections {
    /// From per-frame true detections, for an image of `image = [width, height]`.
    pub fn new(truth: BTreeMap<usize, Vec<Detection>>, noise: GroundTruthNoise, image: [f64; 2]) -> Self {
        Self { truth, noise, image }
    }

    /// From raw-data tracklets, projected into the left colour camera (`P_rect_02`) with the drive's
    /// calibration: each box's 8 corners, clipped to the image; boxes with a corner behind the camera or
    /// nothing inside the image are left out.
    pub fn from_tracklets(
        tracklets: &[crate::kitti::tracklets::Tracklet],
        calib: &crate::kitti::raw::RawCalib,
        noise: GroundTruthNoise,
    ) -> Self {
        let [w, h] = calib.image_size;
        let rect_from_velo = calib.rect_from_velo();
        let p2 = calib.p_rect[2];
        let mut truth: BTreeMap<usize, Vec<Detection>> = BTreeMap::new();
        for t in tracklets {
            let Some(class) = classes::kitti_class(&t.object_type) else { continue };
            for frame in t.frames() {
                let Some(pose) = t.pose_at(frame) else { continue };
                let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
                let mut behind = false;
                for c in crate::kitti::tracklets::box_corners(t.hwl, pose) {
                    let pc = rect_from_velo * nalgebra::Point3::from(c);
                    let x = p2 * pc.to_homogeneous();
                    if x.z <= 0.1 {
                        behind = true;
                        break;
                    }
                    let (u, v) = (x.x / x.z, x.y / x.z);
                    b = [b[0].min(u), b[1].min(v), b[2].max(u), b[3].max(v)];
                }
                let bbox = BBox::new(b[0].max(0.0), b[1].max(0.0), b[2].min(w), b[3].min(h));
                if !behind && bbox.validated().is_ok() {
                    truth.entry(frame).or_default().push(Detection::new(class, 1.0, bbox));
                }
            }
        }
        Self::new(truth, noise, [w, h])
    }

    /// From KITTI tracking labels (DontCare and Misc dropped).
    pub fn from_tracking_labels(
        labels: &[crate::kitti::tracking::TrackingLabel],
        noise: GroundTruthNoise,
        image: [f64; 2],
    ) -> Self {
        let mut truth: BTreeMap<usize, Vec<Detection>> = BTreeMap::new();
        for l in labels {
            if let Some(class) = l.class {
                truth.entry(l.frame).or_default().push(Detection::new(class, 1.0, l.bbox));
            }
        }
        Self::new(truth, noise, image)
    }
}

impl DetectionSource for GroundTruthDetections {
    fn name(&self) -> &str {
        "ground-truth"
    }

    fn needs_image(&self) -> bool {
        false
    }

    fn detect(&mut self, frame: usize, _image: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
        let n = &self.noise;
        let mut rng = SimRng::derive(n.seed, &[frame as u64]);
        let [w, h] = self.image;
        let mut out = Vec::new();
        for d in self.truth.get(&frame).map(|v| v.as_slice()).unwrap_or(&[]) {
            let (dw, dh) = (d.bbox.width(), d.bbox.height());
            let draws = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
            if rng.unit() < n.dropout {
                continue;
            }
            let b = BBox::new(
                (d.bbox.xmin + n.box_sigma * dw * draws[0]).clamp(0.0, w),
                (d.bbox.ymin + n.box_sigma * dh * draws[1]).clamp(0.0, h),
                (d.bbox.xmax + n.box_sigma * dw * draws[2]).clamp(0.0, w),
                (d.bbox.ymax + n.box_sigma * dh * draws[3]).clamp(0.0, h),
            );
            if b.validated().is_ok() {
                out.push(Detection { bbox: b, ..d.clone() });
            }
        }
        let fp = (n.false_positives + rng.uniform(-0.5, 0.5)).round().max(0.0) as usize;
        for _ in 0..fp {
            let bw = rng.uniform(20.0, 150.0).min(w);
            let bh = bw * rng.uniform(0.5, 1.2);
            let x = rng.uniform(0.0, (w - bw).max(0.0));
            let y = rng.uniform(0.0, (h - bh).max(0.0));
            out.push(Detection::new(classes::CAR, rng.uniform(0.3, 0.7), BBox::new(x, y, x + bw, (y + bh).min(h))));
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rle_and_polygon() {
        // 4×3 image, pixels (1,0),(1,1) set → column-major: col 0 = 3 zeros, col 1 = [1,1,0]
        let m = mask_from_rle(3, 4, &[3, 2, 7]).expect("valid");
        assert!(m.contains(1.5, 0.5) && m.contains(1.5, 1.5) && !m.contains(1.5, 2.5) && !m.contains(0.5, 0.5));
        assert_eq!(rle_of(&m, 3, 4), vec![3, 2, 7]);
        assert!(mask_from_rle(3, 4, &[3, 2]).is_err());
        let p = mask_from_polygon(&[[10.0, 10.0], [20.0, 10.0], [20.0, 20.0], [10.0, 20.0]]).expect("square");
        assert_eq!(p.area(), 100);
        assert!(mask_from_polygon(&[[0.0, 0.0], [1.0, f64::NAN], [2.0, 2.0]]).is_err());
    }

    /// R15: a class name that names another COCO class contradicts the index; COCO's or Darknet's name of
    /// the same class, in any case, and a name of no class ("other", as older files wrote) are accepted.
    #[test]
    fn a_class_name_may_not_name_another_class() {
        let file = |name: &str| {
            format!(
                r#"{{"version":1,"frames":[{{"frame":0,"detections":[{{"class":3,"class_name":"{name}","score":0.9,"box":[1,1,9,9]}}]}}]}}"#
            )
        };
        let p = Path::new("d.json");
        for ok in ["motorcycle", "Motorbike", "other"] {
            DetectionFile::parse(p, &file(ok)).expect(ok);
        }
        let e = DetectionFile::parse(p, &file("banana")).expect_err("banana").to_string();
        assert!(e.contains("d.json: frame 0 detection 0: class 3 is COCO's \"motorcycle\" but class_name \"banana\" names class 46"), "{e}");
        assert!(names_class("dining_table", 60) && names_class("diningtable", 60) && !names_class("car", 60));
    }
}
