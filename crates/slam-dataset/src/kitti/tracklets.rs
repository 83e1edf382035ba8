//! KITTI raw `tracklet_labels.xml` (boost-serialisation XML) turned into per-frame 3-D boxes.
//!
//! The XML is parsed by `roxmltree` (attributes are ignored; the file's `<!DOCTYPE>` is allowed);
//! errors give the file and line.

use std::path::Path;

use crate::{read_text, DatasetError};

/// One pose of a tracklet (Velodyne frame): the box's bottom centre and its rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackletPose {
    /// Bottom-centre position, metres (Velodyne frame: x forward, y left, z up).
    pub t: [f64; 3],
    /// Rotation angles, radians (`rz` is the yaw).
    pub r: [f64; 3],
    /// Annotation state (0 unknown, 1 interpolated, 2 labelled).
    pub state: i32,
    /// Occlusion level.
    pub occlusion: i32,
    /// Truncation level.
    pub truncation: i32,
}

/// One tracked object.
#[derive(Debug, Clone, PartialEq)]
pub struct Tracklet {
    /// KITTI type ("Car", "Cyclist", "Tram", …).
    pub object_type: String,
    /// Box height, width, length, metres.
    pub hwl: [f64; 3],
    /// Frame of the first pose.
    pub first_frame: usize,
    /// One pose per frame from `first_frame`.
    pub poses: Vec<TrackletPose>,
}

impl Tracklet {
    /// Frames covered.
    pub fn frames(&self) -> std::ops::Range<usize> {
        self.first_frame..self.first_frame + self.poses.len()
    }

    /// The pose at a frame, if the tracklet covers it.
    pub fn pose_at(&self, frame: usize) -> Option<&TrackletPose> {
        frame.checked_sub(self.first_frame).and_then(|i| self.poses.get(i))
    }
}

#[derive(Debug)]
struct Element {
    name: String,
    line: usize,
    text: String,
    children: Vec<Element>,
}

impl Element {
    fn child(&self, name: &str) -> Option<&Element> {
        self.children.iter().find(|c| c.name == name)
    }
}

/// Parse the document into the element tree below; the returned element is a nameless root whose one
/// child is the document's root element.
fn parse_xml(path: &Path, text: &str) -> Result<Element, DatasetError> {
    let options = roxmltree::ParsingOptions { allow_dtd: true, ..roxmltree::ParsingOptions::default() };
    let doc = roxmltree::Document::parse_with_options(text, options).map_err(|e| DatasetError::Parse {
        path: path.to_path_buf(),
        line: e.pos().row as usize,
        message: e.to_string(),
    })?;
    // elements are visited in document order, so line numbers are counted incrementally (the files
    // have tens of thousands of tags; a count from the start for each would be quadratic)
    let mut lines = LineCounter { text, line: 1, counted: 0 };
    let root = convert(doc.root_element(), &mut lines, 0).map_err(|(line, message)| DatasetError::Parse {
        path: path.to_path_buf(),
        line,
        message,
    })?;
    Ok(Element { name: String::new(), line: 0, text: String::new(), children: vec![root] })
}

/// Line numbers of increasing byte positions.
struct LineCounter<'a> {
    text: &'a str,
    line: usize,
    counted: usize,
}

impl LineCounter<'_> {
    fn line_of(&mut self, pos: usize) -> usize {
        let pos = pos.max(self.counted);
        self.line += self.text.as_bytes()[self.counted..pos].iter().filter(|&&b| b == b'\n').count();
        self.counted = pos;
        self.line
    }
}

/// Deepest element nesting accepted. A tracklet file nests six deep (document, tracklets, item,
/// poses, item, value); the limit only keeps a hostile file from exhausting the stack.
const MAX_DEPTH: usize = 64;

/// An element and its descendants; its text is the trimmed text of its own text nodes, joined.
/// Fails with (line, message) past [`MAX_DEPTH`].
fn convert(
    node: roxmltree::Node<'_, '_>,
    lines: &mut LineCounter<'_>,
    depth: usize,
) -> Result<Element, (usize, String)> {
    let line = lines.line_of(node.range().start);
    if depth >= MAX_DEPTH {
        return Err((line, format!("elements nest deeper than {MAX_DEPTH}")));
    }
    let mut el = Element { name: node.tag_name().name().to_string(), line, text: String::new(), children: Vec::new() };
    for child in node.children() {
        if child.is_element() {
            el.children.push(convert(child, lines, depth + 1)?);
        } else if let Some(t) = child.text().filter(|_| child.is_text()) {
            el.text.push_str(t.trim());
        }
    }
    Ok(el)
}

/// Read a tracklet file. Checks the declared counts against the items found.
pub fn read_tracklets(path: impl AsRef<Path>) -> Result<Vec<Tracklet>, DatasetError> {
    let path = path.as_ref();
    let text = read_text(path, &slam_core::files::DOCUMENT)?;
    parse_tracklets(path, &text)
}

/// Parse the contents of such a file; `path` only names it in error messages.
pub fn parse_tracklets(path: &Path, text: &str) -> Result<Vec<Tracklet>, DatasetError> {
    let root = parse_xml(path, text)?;
    let err = |line: usize, m: String| DatasetError::Parse { path: path.to_path_buf(), line, message: m };
    let boost = root.child("boost_serialization").ok_or_else(|| err(1, "no <boost_serialization> element".into()))?;
    let tracklets = boost.child("tracklets").ok_or_else(|| err(boost.line, "no <tracklets> element".into()))?;
    let num = |e: &Element, name: &str| -> Result<f64, DatasetError> {
        let c = e.child(name).ok_or_else(|| err(e.line, format!("<{}> lacks <{name}>", e.name)))?;
        match c.text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(err(c.line, format!("<{name}> is not a finite number: '{}'", c.text))),
        }
    };
    let int = |e: &Element, name: &str| -> Result<i64, DatasetError> {
        let c = e.child(name).ok_or_else(|| err(e.line, format!("<{}> lacks <{name}>", e.name)))?;
        c.text.parse::<i64>().map_err(|_| err(c.line, format!("<{name}> is not an integer: '{}'", c.text)))
    };
    let count = int(tracklets, "count")?;
    let mut out = Vec::new();
    for item in tracklets.children.iter().filter(|c| c.name == "item") {
        let object_type =
            item.child("objectType").ok_or_else(|| err(item.line, "tracklet lacks <objectType>".into()))?.text.clone();
        let first = int(item, "first_frame")?;
        if first < 0 {
            return Err(err(item.line, format!("negative first_frame {first}")));
        }
        let poses_el = item.child("poses").ok_or_else(|| err(item.line, "tracklet lacks <poses>".into()))?;
        let n_poses = int(poses_el, "count")?;
        let mut poses = Vec::new();
        for p in poses_el.children.iter().filter(|c| c.name == "item") {
            poses.push(TrackletPose {
                t: [num(p, "tx")?, num(p, "ty")?, num(p, "tz")?],
                r: [num(p, "rx")?, num(p, "ry")?, num(p, "rz")?],
                state: int(p, "state")? as i32,
                occlusion: int(p, "occlusion")? as i32,
                truncation: int(p, "truncation")? as i32,
            });
        }
        if poses.len() as i64 != n_poses {
            return Err(err(poses_el.line, format!("declares {n_poses} poses, has {}", poses.len())));
        }
        out.push(Tracklet {
            object_type,
            hwl: [num(item, "h")?, num(item, "w")?, num(item, "l")?],
            first_frame: first as usize,
            poses,
        });
    }
    if out.len() as i64 != count {
        return Err(err(tracklets.line, format!("declares {count} tracklets, has {}", out.len())));
    }
    Ok(out)
}

/// The eight corners of a tracklet box at a pose, in the Velodyne frame (bottom face first).
pub fn box_corners(hwl: [f64; 3], pose: &TrackletPose) -> [nalgebra::Vector3<f64>; 8] {
    let [h, w, l] = hwl;
    let (s, c) = pose.r[2].sin_cos();
    let mut out = [nalgebra::Vector3::zeros(); 8];
    for (k, (dx, dy, dz)) in [
        (0.5, 0.5, 0.0),
        (0.5, -0.5, 0.0),
        (-0.5, -0.5, 0.0),
        (-0.5, 0.5, 0.0),
        (0.5, 0.5, 1.0),
        (0.5, -0.5, 1.0),
        (-0.5, -0.5, 1.0),
        (-0.5, 0.5, 1.0),
    ]
    .iter()
    .enumerate()
    {
        let (x, y, z) = (dx * l, dy * w, dz * h);
        out[k] = nalgebra::Vector3::new(c * x - s * y + pose.t[0], s * x + c * y + pose.t[1], z + pose.t[2]);
    }
    out
}
