//! Detections: class, confidence, box and optional instance mask.

use std::fmt;

use slam_quadric::BBox;

/// An object class. Detectors and datasets map their own labels to these ids (see the dataset crate's
/// class tables); association only compares them for equality.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ClassId(pub u16);

/// The 80 class names of COCO, by index: the ids the shipped detector, the detection files and the
/// dataset readers use (docs/system.md, "Conventions").
pub const COCO_NAMES: [&str; 80] = [
    "person",
    "bicycle",
    "car",
    "motorcycle",
    "airplane",
    "bus",
    "train",
    "truck",
    "boat",
    "traffic light",
    "fire hydrant",
    "stop sign",
    "parking meter",
    "bench",
    "bird",
    "cat",
    "dog",
    "horse",
    "sheep",
    "cow",
    "elephant",
    "bear",
    "zebra",
    "giraffe",
    "backpack",
    "umbrella",
    "handbag",
    "tie",
    "suitcase",
    "frisbee",
    "skis",
    "snowboard",
    "sports ball",
    "kite",
    "baseball bat",
    "baseball glove",
    "skateboard",
    "surfboard",
    "tennis racket",
    "bottle",
    "wine glass",
    "cup",
    "fork",
    "knife",
    "spoon",
    "bowl",
    "banana",
    "apple",
    "sandwich",
    "orange",
    "broccoli",
    "carrot",
    "hot dog",
    "pizza",
    "donut",
    "cake",
    "chair",
    "couch",
    "potted plant",
    "bed",
    "dining table",
    "toilet",
    "tv",
    "laptop",
    "mouse",
    "remote",
    "keyboard",
    "cell phone",
    "microwave",
    "oven",
    "toaster",
    "sink",
    "refrigerator",
    "book",
    "clock",
    "vase",
    "scissors",
    "teddy bear",
    "hair drier",
    "toothbrush",
];

impl ClassId {
    /// The COCO name of this id (`"unknown"` beyond the 80 COCO classes).
    pub fn name(self) -> &'static str {
        COCO_NAMES.get(self.0 as usize).copied().unwrap_or("unknown")
    }

    /// The group of classes a detector confuses on one object, named by its lowest member: vehicles
    /// (car 2, bus 5, truck 7) are 2, two-wheelers (bicycle 1, motorcycle 3) are 1; any other class is
    /// its own group.
    pub fn group(self) -> u16 {
        match self.0 {
            2 | 5 | 7 => 2,
            1 | 3 => 1,
            other => other,
        }
    }
}

impl fmt::Display for ClassId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "class {} ({})", self.0, self.name())
    }
}

/// Identity of an object track / object landmark, unique over a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct TrackId(pub u64);

impl fmt::Display for TrackId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "#{}", self.0)
    }
}

/// A binary instance mask stored over its own bounding rectangle of whole pixels.
///
/// Pixel `(u, v)` (column, row, integer image coordinates) is set when
/// `bits[(v − y0) · width + (u − x0)]` is true. A point `(x, y)` in continuous pixel coordinates belongs
/// to pixel `(floor(x), floor(y))`.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Mask {
    /// Column of the first stored pixel.
    pub x0: i32,
    /// Row of the first stored pixel.
    pub y0: i32,
    /// Stored width in pixels.
    pub width: u32,
    /// Stored height in pixels.
    pub height: u32,
    /// Row-major bits, `width · height` of them.
    pub bits: Vec<bool>,
}

impl Mask {
    /// A mask; `None` when `bits` does not hold `width · height` entries.
    pub fn new(x0: i32, y0: i32, width: u32, height: u32, bits: Vec<bool>) -> Option<Self> {
        (bits.len() == width as usize * height as usize).then_some(Self { x0, y0, width, height, bits })
    }

    /// A mask filling a box (pixels whose centres lie inside it).
    pub fn from_box(b: &BBox) -> Self {
        let x0 = (b.xmin - 0.5).ceil() as i32;
        let y0 = (b.ymin - 0.5).ceil() as i32;
        let x1 = (b.xmax - 0.5).floor() as i32;
        let y1 = (b.ymax - 0.5).floor() as i32;
        let width = (x1 - x0 + 1).max(0) as u32;
        let height = (y1 - y0 + 1).max(0) as u32;
        Self { x0, y0, width, height, bits: vec![true; width as usize * height as usize] }
    }

    /// True when the point lies on a set pixel.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        if !(x.is_finite() && y.is_finite()) {
            return false;
        }
        let u = x.floor() as i64 - self.x0 as i64;
        let v = y.floor() as i64 - self.y0 as i64;
        if u < 0 || v < 0 || u >= self.width as i64 || v >= self.height as i64 {
            return false;
        }
        self.bits[v as usize * self.width as usize + u as usize]
    }

    /// Number of set pixels.
    pub fn area(&self) -> usize {
        self.bits.iter().filter(|b| **b).count()
    }
}

/// Where an object is in an image: its box, or its instance mask when one exists.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Region<'a> {
    /// Axis-aligned box.
    Box(BBox),
    /// Instance mask.
    Mask(&'a Mask),
}

impl Region<'_> {
    /// True when the point is inside the region.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        match self {
            Region::Box(b) => x >= b.xmin && x <= b.xmax && y >= b.ymin && y <= b.ymax,
            Region::Mask(m) => m.contains(x, y),
        }
    }
}

/// One detection in the left image.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Detection {
    /// Object class.
    pub class: ClassId,
    /// Detector confidence in `[0, 1]` (1 for ground truth).
    pub score: f64,
    /// Box, pixels.
    pub bbox: BBox,
    /// Instance mask, when the detector gives one.
    pub mask: Option<Mask>,
}

impl Detection {
    /// A detection without mask.
    pub fn new(class: ClassId, score: f64, bbox: BBox) -> Self {
        Self { class, score, bbox, mask: None }
    }

    /// The mask if present, else the box.
    pub fn region(&self) -> Region<'_> {
        match &self.mask {
            Some(m) => Region::Mask(m),
            None => Region::Box(self.bbox),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_contains_and_from_box() {
        let m = Mask::from_box(&BBox::new(10.0, 20.0, 14.0, 22.0));
        assert_eq!((m.x0, m.y0, m.width, m.height), (10, 20, 4, 2));
        assert!(m.contains(10.2, 20.5) && m.contains(13.9, 21.9));
        assert!(!m.contains(14.1, 21.0) && !m.contains(f64::NAN, 21.0));
        assert_eq!(m.area(), 8);
        assert!(Mask::new(0, 0, 2, 2, vec![true; 3]).is_none());
        let r = Region::Mask(&m);
        assert!(r.contains(11.0, 21.0));
    }

    #[test]
    fn class_groups_join_the_classes_a_detector_confuses() {
        let g = |c: u16| ClassId(c).group();
        assert_eq!((g(2), g(5), g(7)), (2, 2, 2), "car, bus, truck");
        assert_eq!((g(1), g(3)), (1, 1), "bicycle, motorcycle");
        assert_eq!((g(0), g(6), g(9)), (0, 6, 9), "person, train, traffic light alone");
    }
}
