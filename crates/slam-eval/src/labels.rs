//! KITTI tracking labels seen from the run's camera.
//!
//! A label's 3-D box is given in **rectified camera-0** coordinates (`location` = bottom centre, `y`
//! down, `rotation_y` about `y`); its 2-D box belongs to the left **colour** camera (camera 2). A run on
//! the grey pair (raw drives' `image_00`/`image_01`, odometry `image_0`/`image_1`) sees the scene from
//! camera 0 itself, so its boxes are the 3-D boxes projected with camera 0's intrinsics; a run on the
//! colour pair sees it from camera 2, `t = K⁻¹ P2[:, 3]` (≈ +0.06 m in x) away. [`LabelGeometry`]
//! carries that offset.

use std::{collections::BTreeMap, path::Path};

use nalgebra::{Matrix3x4, Point3, Vector3};
use serde::{Deserialize, Serialize};
use slam_core::{
    geometry::{BBox, ImageSize, Intrinsics},
    Detection,
};
use slam_dataset::kitti::{
    calib::Calib,
    stereo::{Layout, StereoSequence},
    tracking::TrackingLabel,
};

use crate::EvalError;

/// The run's camera as the labels need it: intrinsics, image size, and where its centre lies in
/// rectified camera-0 coordinates (`label_offset`: a camera-0 point `X` is at `X + label_offset` in
/// the run's camera, rotations being the same after rectification). Written by `slam-app run` as
/// `camera.json` so that a run folder can be scored later.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LabelGeometry {
    /// Focal lengths and principal point, pixels.
    pub fx: f64,
    /// Vertical focal length, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: f64,
    /// Image height, pixels.
    pub height: f64,
    /// Camera-0 to run-camera translation, metres (zero for the grey pair).
    pub label_offset: [f64; 3],
    /// The run's boxes are the colour camera's, where the labels' own 2-D boxes apply.
    pub colour: bool,
}

impl LabelGeometry {
    /// The intrinsics.
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics::new(self.fx, self.fy, self.cx, self.cy)
    }

    /// The image size.
    pub fn image(&self) -> ImageSize {
        ImageSize::new(self.width, self.height)
    }

    /// The offset as a vector.
    pub fn offset(&self) -> Vector3<f64> {
        Vector3::from(self.label_offset)
    }

    /// The geometry of a stereo sequence's left camera (its calibration file is read for the colour
    /// pair's offset).
    pub fn of_sequence(seq: &StereoSequence, image: ImageSize) -> Result<Self, EvalError> {
        let [fx, fy, cx, cy] = seq.intrinsics;
        let first = seq.left.first().map(|p| p.to_string_lossy().into_owned()).unwrap_or_default();
        let colour = seq.layout == Layout::Tracking || (seq.layout == Layout::Raw && first.contains("image_02"));
        let offset = if !colour {
            Vector3::zeros()
        } else {
            let (path, key) = match seq.layout {
                Layout::Tracking => {
                    // training/image_02/NNNN → training/calib/NNNN.txt
                    let name = seq.dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
                    let training = seq.dir.parent().and_then(Path::parent).unwrap_or(&seq.dir);
                    (training.join("calib").join(format!("{name}.txt")), "P2")
                }
                _ => {
                    let date = seq.dir.parent().unwrap_or(&seq.dir);
                    (date.join("calib_cam_to_cam.txt"), "P_rect_02")
                }
            };
            let calib = Calib::read(&path)?;
            camera_offset(&calib.matrix3x4(key)?)
                .ok_or_else(|| EvalError::Invalid(format!("{}: {key} has a singular K", path.display())))?
        };
        Ok(Self {
            fx,
            fy,
            cx,
            cy,
            width: image.width,
            height: image.height,
            label_offset: [offset.x, offset.y, offset.z],
            colour,
        })
    }

    /// Read `camera.json`; a camera that cannot be one is an error naming the field
    /// ([`LabelGeometry::check`]).
    pub fn read(path: &Path) -> Result<Self, EvalError> {
        let text = slam_core::files::read_text(path, &slam_core::files::SMALL)?;
        let g: Self =
            serde_json::from_str(&text).map_err(|e| EvalError::Invalid(format!("{}: {e}", path.display())))?;
        g.check().map_err(|m| EvalError::Invalid(format!("{}: {m}", path.display())))?;
        Ok(g)
    }

    /// A camera that can be one: an image of at least one pixel each way (at most 100 000, no camera's
    /// sensor is wider), positive finite focal lengths, the principal point inside the image, a finite
    /// offset of at most 10 m (a stereo rig's cameras sit within its width).
    pub fn check(&self) -> Result<(), String> {
        use slam_core::check::{number, Range};
        let e = |v: slam_core::check::InvalidValue| v.to_string();
        number("width", self.width, Range::closed(1.0, 1e5), "px").map_err(e)?;
        number("height", self.height, Range::closed(1.0, 1e5), "px").map_err(e)?;
        number("fx", self.fx, Range::above(0.0, 1e7), "px").map_err(e)?;
        number("fy", self.fy, Range::above(0.0, 1e7), "px").map_err(e)?;
        number("cx", self.cx, Range::closed(0.0, self.width), "px (inside the image)").map_err(e)?;
        number("cy", self.cy, Range::closed(0.0, self.height), "px (inside the image)").map_err(e)?;
        for (k, v) in self.label_offset.iter().enumerate() {
            number(&format!("label_offset[{k}]"), *v, Range::closed(-10.0, 10.0), "m").map_err(e)?;
        }
        Ok(())
    }

    /// Write `camera.json`.
    pub fn write(&self, path: &Path) -> Result<(), EvalError> {
        let text = serde_json::to_string_pretty(self).map_err(|e| EvalError::Invalid(e.to_string()))?;
        Ok(slam_core::files::write_atomic(path, text.as_bytes())?)
    }

    /// A label's 3-D box centre in the run's camera.
    pub fn centre(&self, l: &TrackingLabel) -> Vector3<f64> {
        Vector3::new(l.location[0], l.location[1] - l.dimensions[0] / 2.0, l.location[2]) + self.offset()
    }

    /// The eight corners of a label's 3-D box in the run's camera.
    pub fn corners(&self, l: &TrackingLabel) -> [Vector3<f64>; 8] {
        let [h, w, len] = l.dimensions;
        let (s, c) = l.rotation_y.sin_cos();
        let base = Vector3::from(l.location) + self.offset();
        std::array::from_fn(|k| {
            let x = if k & 1 == 0 { -len / 2.0 } else { len / 2.0 };
            let y = if k & 2 == 0 { 0.0 } else { -h };
            let z = if k & 4 == 0 { -w / 2.0 } else { w / 2.0 };
            // rotation about y by rotation_y (KITTI's convention)
            base + Vector3::new(c * x + s * z, y, -s * x + c * z)
        })
    }

    /// The box of a label in the run's image: its 3-D box projected and clipped to the image; `None`
    /// when a corner lies behind the camera (0.1 m) or nothing is left after clipping.
    pub fn projected_box(&self, l: &TrackingLabel) -> Option<BBox> {
        let k = self.intrinsics();
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for p in self.corners(l) {
            if p.z < 0.1 {
                return None;
            }
            let (u, v) = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
            (x0, y0, x1, y1) = (x0.min(u), y0.min(v), x1.max(u), y1.max(v));
        }
        BBox::new(x0, y0, x1, y1).clipped(&self.image())
    }

    /// The box a label gives in the run's image: the annotated 2-D box on the colour camera, the
    /// projected 3-D box otherwise (DontCare regions have no 3-D box: their 2-D box either way).
    pub fn label_box(&self, l: &TrackingLabel) -> Option<BBox> {
        if self.colour || l.is_dont_care() {
            l.bbox.clipped(&self.image())
        } else {
            self.projected_box(l)
        }
    }

    /// Label boxes as detections per frame, for `--detector labels` on any layout (DontCare and Misc,
    /// which have no class, left out).
    pub fn detections(&self, labels: &[TrackingLabel]) -> BTreeMap<usize, Vec<Detection>> {
        let mut out: BTreeMap<usize, Vec<Detection>> = BTreeMap::new();
        for l in labels.iter().filter(|l| !l.is_dont_care()) {
            if let (Some(c), Some(b)) = (l.class, self.label_box(l)) {
                out.entry(l.frame).or_default().push(Detection::new(c, 1.0, b));
            }
        }
        out
    }

    /// World position of a camera point at a frame of the run.
    pub fn to_world(pose: &nalgebra::Isometry3<f64>, p: &Vector3<f64>) -> Vector3<f64> {
        (pose * Point3::from(*p)).coords
    }
}

/// `K⁻¹ P[:, 3]`: the camera centre offset of a rectified projection matrix from the reference camera's.
pub fn camera_offset(p: &Matrix3x4<f64>) -> Option<Vector3<f64>> {
    let kinv = p.fixed_view::<3, 3>(0, 0).into_owned().try_inverse()?;
    Some(kinv * p.column(3).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::ClassId;

    fn label(frame: usize, rotation_y: f64) -> TrackingLabel {
        TrackingLabel {
            frame,
            track_id: 3,
            kind: "Car".into(),
            class: Some(ClassId(2)),
            truncated: 0.0,
            occluded: 0,
            bbox: BBox::new(0.0, 0.0, 10.0, 10.0),
            dimensions: [1.5, 1.6, 4.0],
            location: [1.0, 1.7, 20.0],
            rotation_y,
            line: 0,
        }
    }

    fn grey() -> LabelGeometry {
        LabelGeometry {
            fx: 700.0,
            fy: 700.0,
            cx: 600.0,
            cy: 180.0,
            width: 1242.0,
            height: 375.0,
            label_offset: [0.0; 3],
            colour: false,
        }
    }

    #[test]
    fn box_corners_and_projection() {
        let g = grey();
        // heading along the camera x axis (rotation_y 0): length runs along x
        let c = g.corners(&label(0, 0.0));
        let span = |k: usize| {
            c.iter().map(|p| p[k]).fold(f64::MIN, f64::max) - c.iter().map(|p| p[k]).fold(f64::MAX, f64::min)
        };
        assert!((span(0) - 4.0).abs() < 1e-12 && (span(1) - 1.5).abs() < 1e-12 && (span(2) - 1.6).abs() < 1e-12);
        // turned 90°: length along z
        let c = g.corners(&label(0, std::f64::consts::FRAC_PI_2));
        let zs: Vec<f64> = c.iter().map(|p| p.z).collect();
        let zspan = zs.iter().cloned().fold(f64::MIN, f64::max) - zs.iter().cloned().fold(f64::MAX, f64::min);
        assert!((zspan - 4.0).abs() < 1e-9, "{zspan}");
        // centre: bottom centre lifted by half the height
        assert!((g.centre(&label(0, 0.0)) - Vector3::new(1.0, 0.95, 20.0)).norm() < 1e-12);
        // projected box: bottom edge at y = 1.7 m, front face at z = 19.2 m
        let b = g.projected_box(&label(0, 0.0)).expect("in view");
        assert!((b.ymax - (700.0 * 1.7 / 19.2 + 180.0)).abs() < 1e-9, "{b:?}");
        // behind the camera: no box
        let mut behind = label(0, 0.0);
        behind.location[2] = -5.0;
        assert!(g.projected_box(&behind).is_none());
        // the colour camera takes the annotated 2-D box
        let colour = LabelGeometry { colour: true, label_offset: [0.06, 0.0, 0.0], ..g };
        assert_eq!(colour.label_box(&label(0, 0.0)), Some(BBox::new(0.0, 0.0, 10.0, 10.0)));
        assert!((colour.centre(&label(0, 0.0)).x - 1.06).abs() < 1e-12);
    }

    #[test]
    fn offset_of_a_projection_matrix() {
        let p = Matrix3x4::new(700.0, 0.0, 600.0, 42.0, 0.0, 700.0, 180.0, 0.0, 0.0, 0.0, 1.0, 0.0);
        assert!((camera_offset(&p).expect("regular") - Vector3::new(0.06, 0.0, 0.0)).norm() < 1e-12);
    }
}
