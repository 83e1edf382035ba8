//! Axis-aligned image boxes, their lines, and the planes they back-project to.

use std::fmt;

use nalgebra::{Matrix3x4, Vector3, Vector4};

/// An image size in pixels. The image covers `[0, width] × [0, height]`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ImageSize {
    /// Width in pixels.
    pub width: f64,
    /// Height in pixels.
    pub height: f64,
}

impl ImageSize {
    /// A new image size.
    pub const fn new(width: f64, height: f64) -> Self {
        Self { width, height }
    }

    /// The whole image as a box.
    pub fn as_box(&self) -> BBox {
        BBox::new(0.0, 0.0, self.width, self.height)
    }
}

/// An axis-aligned box `[xmin, ymin, xmax, ymax]` in pixels ("tlbr", as gtsam-quadrics' `AlignedBox2`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BBox {
    /// Left edge.
    pub xmin: f64,
    /// Top edge (image y grows downwards).
    pub ymin: f64,
    /// Right edge.
    pub xmax: f64,
    /// Bottom edge.
    pub ymax: f64,
}

/// Why a box is not usable as a measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BoxError {
    /// A coordinate is NaN or infinite.
    NotFinite,
    /// `xmax <= xmin` or `ymax <= ymin`.
    Empty,
}

impl fmt::Display for BoxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BoxError::NotFinite => write!(f, "box has a NaN or infinite coordinate"),
            BoxError::Empty => write!(f, "box is empty (max <= min)"),
        }
    }
}

impl std::error::Error for BoxError {}

impl BBox {
    /// A box from its corners; no check (see [`BBox::validated`]).
    pub const fn new(xmin: f64, ymin: f64, xmax: f64, ymax: f64) -> Self {
        Self { xmin, ymin, xmax, ymax }
    }

    /// A box from `[xmin, ymin, xmax, ymax]`.
    pub const fn from_array(a: [f64; 4]) -> Self {
        Self::new(a[0], a[1], a[2], a[3])
    }

    /// `[xmin, ymin, xmax, ymax]`.
    pub const fn to_array(&self) -> [f64; 4] {
        [self.xmin, self.ymin, self.xmax, self.ymax]
    }

    /// `[xmin, ymin, xmax, ymax]` as a vector.
    pub fn to_vector(&self) -> Vector4<f64> {
        Vector4::new(self.xmin, self.ymin, self.xmax, self.ymax)
    }

    /// The box itself if all coordinates are finite and it has positive width and height.
    pub fn validated(self) -> Result<Self, BoxError> {
        if !self.to_array().iter().all(|v| v.is_finite()) {
            return Err(BoxError::NotFinite);
        }
        if self.xmax <= self.xmin || self.ymax <= self.ymin {
            return Err(BoxError::Empty);
        }
        Ok(self)
    }

    /// Width (`xmax - xmin`).
    pub fn width(&self) -> f64 {
        self.xmax - self.xmin
    }

    /// Height (`ymax - ymin`).
    pub fn height(&self) -> f64 {
        self.ymax - self.ymin
    }

    /// Area, zero for an empty or inverted box.
    pub fn area(&self) -> f64 {
        self.width().max(0.0) * self.height().max(0.0)
    }

    /// Centre `[(xmin + xmax)/2, (ymin + ymax)/2]`.
    pub fn centre(&self) -> [f64; 2] {
        [0.5 * (self.xmin + self.xmax), 0.5 * (self.ymin + self.ymax)]
    }

    /// Intersection box, or `None` when the boxes do not overlap with positive area.
    pub fn intersection(&self, other: &BBox) -> Option<BBox> {
        let b = BBox::new(
            self.xmin.max(other.xmin),
            self.ymin.max(other.ymin),
            self.xmax.min(other.xmax),
            self.ymax.min(other.ymax),
        );
        (b.xmax > b.xmin && b.ymax > b.ymin).then_some(b)
    }

    /// Intersection over union in `[0, 1]`; 0 when either box is empty.
    pub fn iou(&self, other: &BBox) -> f64 {
        let Some(inter) = self.intersection(other) else {
            return 0.0;
        };
        let i = inter.area();
        let u = self.area() + other.area() - i;
        if u > 0.0 {
            i / u
        } else {
            0.0
        }
    }

    /// True when `other` lies inside `self` (edges included).
    pub fn contains(&self, other: &BBox) -> bool {
        self.xmin <= other.xmin && self.ymin <= other.ymin && self.xmax >= other.xmax && self.ymax >= other.ymax
    }

    /// True when the point `(x, y)` lies inside (edges included).
    pub fn contains_point(&self, x: f64, y: f64) -> bool {
        self.xmin <= x && x <= self.xmax && self.ymin <= y && y <= self.ymax
    }

    /// True when the boxes share at least one point: they overlap, touch, or one contains the other.
    ///
    /// This is set intersection (`self ∩ other ≠ ∅`), so `a.iou(b) > 0` implies `a.intersects(b)`, and
    /// containment counts. gtsam-quadrics' `AlignedBox2::intersects` differs: it returns false when one
    /// box contains the other (its "edges cross" test); we keep the set meaning, which is what gating
    /// and overlap checks want (a small box inside a large one does overlap it).
    pub fn intersects(&self, other: &BBox) -> bool {
        self.xmin <= other.xmax && other.xmin <= self.xmax && self.ymin <= other.ymax && other.ymin <= self.ymax
    }

    /// True when any edge lies within `margin` pixels of the image border (or outside the image).
    /// Object optimisation uses this to skip boxes that are probably truncated.
    pub fn touches_border(&self, image: &ImageSize, margin: f64) -> bool {
        self.xmin <= margin
            || self.ymin <= margin
            || self.xmax >= image.width - margin
            || self.ymax >= image.height - margin
    }

    /// The box clipped to the image; `None` when nothing is left.
    pub fn clipped(&self, image: &ImageSize) -> Option<BBox> {
        self.intersection(&image.as_box())
    }

    /// The four image lines of the box edges, `l·[u, v, 1] = 0`, in the order
    /// `[1, 0, -xmin], [0, 1, -ymin], [1, 0, -xmax], [0, 1, -ymax]` (the oracle's order).
    pub fn lines(&self) -> [Vector3<f64>; 4] {
        [
            Vector3::new(1.0, 0.0, -self.xmin),
            Vector3::new(0.0, 1.0, -self.ymin),
            Vector3::new(1.0, 0.0, -self.xmax),
            Vector3::new(0.0, 1.0, -self.ymax),
        ]
    }

    /// The four world planes `π = Pᵀ l` through the camera centre and each box edge, for the
    /// projection matrix `P` (world to image). A point `X` (homogeneous) lies on a plane when `πᵀX = 0`.
    pub fn planes(&self, p: &Matrix3x4<f64>) -> [Vector4<f64>; 4] {
        self.lines().map(|l| p.transpose() * l)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_basic() {
        let a = BBox::new(0.0, 0.0, 2.0, 2.0);
        let b = BBox::new(1.0, 1.0, 3.0, 3.0);
        assert!((a.iou(&b) - 1.0 / 7.0).abs() < 1e-15);
        assert_eq!(a.iou(&BBox::new(5.0, 5.0, 6.0, 6.0)), 0.0);
        assert!((a.iou(&a) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn validation() {
        assert_eq!(BBox::new(0.0, 0.0, f64::NAN, 1.0).validated(), Err(BoxError::NotFinite));
        assert_eq!(BBox::new(2.0, 0.0, 1.0, 1.0).validated(), Err(BoxError::Empty));
        assert!(BBox::new(0.0, 0.0, 1.0, 1.0).validated().is_ok());
    }

    #[test]
    fn border() {
        let img = ImageSize::new(100.0, 50.0);
        assert!(BBox::new(0.5, 10.0, 20.0, 20.0).touches_border(&img, 1.0));
        assert!(!BBox::new(5.0, 10.0, 20.0, 20.0).touches_border(&img, 1.0));
        assert!(BBox::new(5.0, 10.0, 20.0, 49.5).touches_border(&img, 1.0));
    }

    #[test]
    fn planes_contain_edge_points() {
        // Camera at origin looking along +z, K = identity-like: the plane through the edge x = xmin
        // must contain the back-projected ray of any pixel on that edge.
        let p = Matrix3x4::new(500.0, 0.0, 320.0, 0.0, 0.0, 500.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0);
        let b = BBox::new(100.0, 50.0, 200.0, 150.0);
        let planes = b.planes(&p);
        // Pixel (100, 77) at depth 3: X = 3 * K^-1 [u v 1]
        let x = Vector4::new(3.0 * (100.0 - 320.0) / 500.0, 3.0 * (77.0 - 240.0) / 500.0, 3.0, 1.0);
        assert!(planes[0].dot(&x).abs() < 1e-9);
        assert!(planes[2].dot(&x).abs() > 1.0);
    }
}
