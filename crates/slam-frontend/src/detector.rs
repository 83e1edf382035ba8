//! An object detector on OpenCV's dnn module (Darknet cfg + weights, or ONNX), for YOLO-style outputs.
//!
//! KITTI frames are 3.3 : 1. Squashing one into a square network input shrinks cars horizontally by a
//! factor of 3 and loses the small ones. [`InputMode`] offers letterboxing (keep the aspect ratio, pad)
//! and tiling (overlapping near-square crops across the width, each letterboxed, plus the whole frame),
//! with class-wise non-maximum suppression over all of them.

use std::path::Path;

use opencv::{core, dnn, imgproc, prelude::*};
use slam_core::{geometry::BBox, ClassId, DetectError, Detection, DetectionSource, Image};

use crate::image_io::{image_to_mat, FrontendError};

/// How a frame is fed to the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputMode {
    /// Resize to the square input, ignoring the aspect ratio.
    Squash,
    /// Resize keeping the aspect ratio, pad the rest.
    Letterbox,
    /// `n` overlapping crops across the width (each letterboxed) plus the letterboxed whole frame.
    Tiles(u32),
}

/// Detector settings.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorConfig {
    /// Square network input size, pixels (a multiple of 32).
    pub input_size: i32,
    /// Frame feeding.
    pub mode: InputMode,
    /// Smallest class confidence kept.
    pub score_threshold: f32,
    /// IoU above which a lower-scored box of the same class is suppressed.
    pub nms_iou: f32,
    /// Classes kept (empty = all).
    pub classes: Vec<u16>,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self { input_size: 320, mode: InputMode::Tiles(3), score_threshold: 0.2, nms_iou: 0.45, classes: Vec::new() }
    }
}

/// A YOLO-style detector running in OpenCV's dnn module on the CPU.
pub struct DnnDetector {
    net: dnn::Net,
    out_names: core::Vector<String>,
    /// Settings.
    pub config: DetectorConfig,
}

/// A model file OpenCV may open: a regular file (a pipe would block the loader, a device never end)
/// of at most the model limit ([`slam_core::files::MODEL`]).
fn model_file(p: &Path) -> Result<(), FrontendError> {
    slam_core::files::check_readable(p, &slam_core::files::MODEL).map_err(|e| FrontendError::Model {
        path: p.to_path_buf(),
        message: match &e {
            slam_core::files::ReadError::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
                "no such file".into()
            }
            other => other.reason(),
        },
    })
}

impl DnnDetector {
    /// Load a Darknet model (`.cfg` + `.weights`).
    pub fn from_darknet(
        cfg: impl AsRef<Path>,
        weights: impl AsRef<Path>,
        config: DetectorConfig,
    ) -> Result<Self, FrontendError> {
        let (cfg, weights) = (cfg.as_ref(), weights.as_ref());
        for p in [cfg, weights] {
            model_file(p)?;
        }
        let utf8 = |p: &Path| {
            p.to_str()
                .map(str::to_string)
                .ok_or(FrontendError::Model { path: p.to_path_buf(), message: "path is not UTF-8".into() })
        };
        // OpenCV's message does not say which of the two files it could not read: name both
        let net = dnn::read_net_from_darknet(&utf8(cfg)?, &utf8(weights)?).map_err(|e| FrontendError::Model {
            path: cfg.to_path_buf(),
            message: format!("this .cfg with the weights {} does not load: {e}", weights.display()),
        })?;
        Self::from_net(net, config, weights)
    }

    /// Load an ONNX model.
    pub fn from_onnx(model: impl AsRef<Path>, config: DetectorConfig) -> Result<Self, FrontendError> {
        let model = model.as_ref();
        model_file(model)?;
        let s = model
            .to_str()
            .ok_or(FrontendError::Model { path: model.to_path_buf(), message: "path is not UTF-8".into() })?;
        let net = dnn::read_net_from_onnx(s)
            .map_err(|e| FrontendError::Model { path: model.to_path_buf(), message: e.to_string() })?;
        Self::from_net(net, config, model)
    }

    fn from_net(mut net: dnn::Net, config: DetectorConfig, path: &Path) -> Result<Self, FrontendError> {
        if net.empty()? {
            return Err(FrontendError::Model { path: path.to_path_buf(), message: "empty network".into() });
        }
        net.set_preferable_backend(dnn::DNN_BACKEND_OPENCV)?;
        net.set_preferable_target(dnn::DNN_TARGET_CPU)?;
        let out_names = net.get_unconnected_out_layers_names()?;
        Ok(Self { net, out_names, config })
    }

    /// Run the network on one crop, letterboxed or squashed into the input; boxes in crop pixels.
    fn run_crop(&mut self, crop: &Mat, letterbox: bool) -> Result<Vec<Detection>, FrontendError> {
        let n = self.config.input_size;
        let (w, h) = (crop.cols() as f64, crop.rows() as f64);
        let (sx, sy, input) = if letterbox {
            let s = (n as f64 / w).min(n as f64 / h);
            let (nw, nh) = (((w * s).round() as i32).max(1), ((h * s).round() as i32).max(1));
            let mut resized = Mat::default();
            imgproc::resize(crop, &mut resized, core::Size::new(nw, nh), 0.0, 0.0, imgproc::INTER_LINEAR)?;
            let mut padded = Mat::default();
            core::copy_make_border(
                &resized,
                &mut padded,
                0,
                n - nh,
                0,
                n - nw,
                core::BORDER_CONSTANT,
                core::Scalar::all(114.0),
            )?;
            (s, s, padded)
        } else {
            let mut resized = Mat::default();
            imgproc::resize(crop, &mut resized, core::Size::new(n, n), 0.0, 0.0, imgproc::INTER_LINEAR)?;
            (n as f64 / w, n as f64 / h, resized)
        };
        let blob = dnn::blob_from_image(
            &input,
            1.0 / 255.0,
            core::Size::new(n, n),
            core::Scalar::default(),
            true,
            false,
            core::CV_32F,
        )?;
        self.net.set_input(&blob, "", 1.0, core::Scalar::default())?;
        let mut outs: core::Vector<Mat> = core::Vector::new();
        self.net.forward(&mut outs, &self.out_names)?;
        let mut dets = Vec::new();
        for out in outs.iter() {
            for r in 0..out.rows() {
                let row = out.at_row::<f32>(r)?;
                if row.len() < 6 {
                    continue;
                }
                let (best, score) =
                    row[5..].iter().enumerate().fold((0usize, 0f32), |b, (i, &s)| if s > b.1 { (i, s) } else { b });
                if score < self.config.score_threshold || !score.is_finite() {
                    continue;
                }
                if !self.config.classes.is_empty() && !self.config.classes.contains(&(best as u16)) {
                    continue;
                }
                let (cx, cy, bw, bh) = (
                    row[0] as f64 * n as f64,
                    row[1] as f64 * n as f64,
                    row[2] as f64 * n as f64,
                    row[3] as f64 * n as f64,
                );
                let b = BBox::new(
                    ((cx - bw / 2.0) / sx).clamp(0.0, w),
                    ((cy - bh / 2.0) / sy).clamp(0.0, h),
                    ((cx + bw / 2.0) / sx).clamp(0.0, w),
                    ((cy + bh / 2.0) / sy).clamp(0.0, h),
                );
                if b.validated().is_ok() {
                    dets.push(Detection::new(ClassId(best as u16), score as f64, b));
                }
            }
        }
        Ok(dets)
    }

    /// Detect objects in an image.
    pub fn detect_image(&mut self, image: &Image) -> Result<Vec<Detection>, FrontendError> {
        let mut mat = image_to_mat(image)?;
        if mat.channels() == 1 {
            // grey sequences (KITTI odometry image_0/1): the network wants three channels
            let mut bgr = Mat::default();
            opencv::imgproc::cvt_color_def(&mat, &mut bgr, opencv::imgproc::COLOR_GRAY2BGR)?;
            mat = bgr;
        }
        let (w, h) = (mat.cols(), mat.rows());
        let mut all = Vec::new();
        match self.config.mode {
            InputMode::Squash => all.extend(self.run_crop(&mat, false)?),
            InputMode::Letterbox => all.extend(self.run_crop(&mat, true)?),
            InputMode::Tiles(k) => {
                all.extend(self.run_crop(&mat, true)?);
                let k = k.max(1) as i32;
                // near-square tiles (4:3 at most) across the width, overlapping
                let tw = (h * 4 / 3).min(w).max(w / k);
                let step = if k > 1 { (w - tw) / (k - 1) } else { 0 };
                for i in 0..k {
                    let x0 = (i * step).min(w - tw);
                    let roi = Mat::roi(&mat, core::Rect::new(x0, 0, tw, h))?.try_clone()?;
                    for mut d in self.run_crop(&roi, true)? {
                        let b = d.bbox;
                        // a box cut by an inner tile edge is a partial object: the neighbouring tile or the
                        // whole-frame pass sees it whole
                        let cut_left = x0 > 0 && b.xmin <= 2.0;
                        let cut_right = x0 + tw < w && b.xmax >= tw as f64 - 2.0;
                        if cut_left || cut_right {
                            continue;
                        }
                        d.bbox = BBox::new(b.xmin + x0 as f64, b.ymin, b.xmax + x0 as f64, b.ymax);
                        all.push(d);
                    }
                }
            }
        }
        Ok(nms(all, self.config.nms_iou as f64))
    }
}

/// Class-wise non-maximum suppression, highest score first (ties by box), deterministic.
pub fn nms(mut dets: Vec<Detection>, iou: f64) -> Vec<Detection> {
    dets.sort_by(|a, b| {
        b.score
            .total_cmp(&a.score)
            .then(a.class.cmp(&b.class))
            .then(a.bbox.xmin.total_cmp(&b.bbox.xmin))
            .then(a.bbox.ymin.total_cmp(&b.bbox.ymin))
    });
    let mut keep: Vec<Detection> = Vec::new();
    for d in dets {
        if keep.iter().all(|k| k.class != d.class || k.bbox.iou(&d.bbox) <= iou) {
            keep.push(d);
        }
    }
    keep
}

impl DetectionSource for DnnDetector {
    fn name(&self) -> &str {
        "dnn"
    }

    fn needs_image(&self) -> bool {
        true
    }

    fn detect(&mut self, frame: usize, image: Option<&Image>) -> Result<Vec<Detection>, DetectError> {
        let image = image.ok_or(DetectError::NeedsImage(frame))?;
        self.detect_image(image).map_err(|e| DetectError::failed(frame, e))
    }
}
