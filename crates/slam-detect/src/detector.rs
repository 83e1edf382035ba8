//! An object detector for two output layouts ([`ModelFamily`]): YOLOX's grid cells (the shipped
//! YOLOX-nano, the default) and the normalised rows of Darknet's YOLO layers (the shipped Yolo-Fastest
//! 1.1). ONNX models run on ONNX Runtime ([`crate::onnx`]); Darknet models (cfg + weights) on OpenCV's dnn
//! module, which is the only one of the two that reads them. Both share the frame feeding below and the
//! decoding, and both time their forward passes ([`DnnDetector::forward_ms`]).
//!
//! KITTI frames are 3.3 : 1. A network that takes any input whose sides are multiples of 32 (YOLOX) is
//! fed the whole frame letterboxed into a wide input (736 × 224 keeps the aspect ratio). A square-input
//! network loses small cars when the frame is squashed or letterboxed into its square; [`InputMode`]
//! offers tiling for it (overlapping near-square crops across the width, each letterboxed, plus the
//! whole frame), with non-maximum suppression over all of them.

use std::{path::Path, time::Instant};

use opencv::{core, dnn, imgproc, prelude::*};
use slam_core::{geometry::BBox, ClassId, DetectError, Detection, DetectionSource, Image};
use slam_frontend::image_io::image_to_mat;

use crate::{
    onnx::{OnnxError, OnnxNet, RuntimeOptions},
    DetectorError,
};

/// How frames are fed to the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputMode {
    /// Resize to the input, ignoring the aspect ratio.
    Squash,
    /// Resize keeping the aspect ratio, pad the rest (right and bottom, grey 114).
    Letterbox,
    /// `n` overlapping crops across the width (each letterboxed) plus the letterboxed whole frame.
    Tiles(u32),
}

/// A network's input scaling and output layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelFamily {
    /// YOLOX (Ge et al. 2021) as exported to ONNX: input BGR 0–255; output `1 × N × (5 + classes)`, one
    /// row per grid cell of strides 8, 16 and 32 in turn (row-major within a stride), each row
    /// `(dx, dy, log w, log h, objectness, class scores)` with the sigmoids applied ([`decode_yolox`]).
    Yolox,
    /// Darknet's YOLO rows (as OpenCV's region layer gives them): input RGB 0–1; rows
    /// `(cx, cy, w, h, objectness, class scores)`, box normalised to the input, class scores already
    /// multiplied by the objectness.
    Rows,
}

impl ModelFamily {
    /// Lower-case name, as on a command line.
    pub fn name(self) -> &'static str {
        match self {
            ModelFamily::Yolox => "yolox",
            ModelFamily::Rows => "rows",
        }
    }
}

/// Detector settings.
#[derive(Debug, Clone, PartialEq)]
pub struct DetectorConfig {
    /// The network's input scaling and output layout.
    pub family: ModelFamily,
    /// Network input `[width, height]`, pixels (multiples of 32).
    pub input: [i32; 2],
    /// Frame feeding.
    pub mode: InputMode,
    /// Smallest detection score kept.
    pub score_threshold: f32,
    /// IoU above which a lower-scored box is suppressed (within its class, or its class group for
    /// [`DetectorConfig::group_nms`]).
    pub nms_iou: f32,
    /// Suppress overlapping boxes across the classes a detector confuses on one object (car, bus,
    /// truck; bicycle, motorcycle: [`ClassId::group`]) instead of within each class.
    pub group_nms: bool,
    /// Classes kept (empty = all).
    pub classes: Vec<u16>,
}

impl DetectorConfig {
    /// The shipped YOLOX-nano's settings: the whole frame letterboxed into 736 × 224 (a KITTI frame,
    /// 1242 × 375, keeps its aspect ratio: 736 × 222 and two rows of padding), score ≥ 0.4, one box per
    /// object across car / bus / truck (NMS at IoU 0.45 by class group). docs/detections.md has the
    /// measurements behind the input and the score threshold.
    pub fn yolox() -> Self {
        Self {
            family: ModelFamily::Yolox,
            input: [736, 224],
            mode: InputMode::Letterbox,
            score_threshold: 0.4,
            nms_iou: 0.45,
            group_nms: true,
            classes: Vec::new(),
        }
    }

    /// The shipped Yolo-Fastest 1.1's settings: 320 × 320, the whole frame and 3 tiles, score ≥ 0.2,
    /// class-wise NMS at IoU 0.45.
    pub fn yolo_fastest() -> Self {
        Self {
            family: ModelFamily::Rows,
            input: [320, 320],
            mode: InputMode::Tiles(3),
            score_threshold: 0.2,
            nms_iou: 0.45,
            group_nms: false,
            classes: Vec::new(),
        }
    }
}

impl Default for DetectorConfig {
    /// [`DetectorConfig::yolox`], the default detector's.
    fn default() -> Self {
        Self::yolox()
    }
}

/// The strides of YOLOX's three output grids, in the order of its output rows.
pub const YOLOX_STRIDES: [i32; 3] = [8, 16, 32];

/// Decode YOLOX's output for an input of `width × height` pixels: `out` holds one row of `row_len`
/// values (`5 + classes`) per grid cell, cells of stride 8, then 16, then 32 ([`YOLOX_STRIDES`]),
/// row-major within each stride. A cell `(gx, gy)` of stride `s` gives a box centred at
/// `((dx + gx) s, (dy + gy) s)` of size `(e^{log w} s, e^{log h} s)`; its score is the objectness times
/// the best class score, its class that class. Boxes scoring below `score_threshold`, of classes not in
/// `classes` (when not empty) or not finite are left out. Boxes are in input pixels, not clipped. An
/// output whose length does not match the input's grids is an error that says both.
pub fn decode_yolox(
    out: &[f32],
    row_len: usize,
    [width, height]: [i32; 2],
    score_threshold: f32,
    classes: &[u16],
) -> Result<Vec<Detection>, String> {
    if row_len < 6 {
        return Err(format!("YOLOX rows have 5 box values and at least one class score, got rows of {row_len}"));
    }
    let cells: usize = YOLOX_STRIDES.iter().map(|s| ((width / s) * (height / s)) as usize).sum();
    if out.len() != cells * row_len {
        return Err(format!(
            "a {width}x{height} input has {cells} YOLOX grid cells (strides 8, 16, 32) of {row_len} values, \
             {} values in all; the output has {}",
            cells * row_len,
            out.len()
        ));
    }
    let mut dets = Vec::new();
    let mut rows = out.chunks_exact(row_len);
    for s in YOLOX_STRIDES {
        let (gw, gh) = (width / s, height / s);
        for gy in 0..gh {
            for gx in 0..gw {
                let Some(row) = rows.next() else { return Err("YOLOX output shorter than its grids".into()) };
                let (best, class_score) = row[5..]
                    .iter()
                    .enumerate()
                    .fold((0usize, f32::NEG_INFINITY), |b, (i, &c)| if c > b.1 { (i, c) } else { b });
                let score = row[4] * class_score;
                if !(score >= score_threshold && score.is_finite()) {
                    continue;
                }
                if !classes.is_empty() && !classes.contains(&(best as u16)) {
                    continue;
                }
                let s = s as f64;
                let (cx, cy) = ((row[0] as f64 + gx as f64) * s, (row[1] as f64 + gy as f64) * s);
                let (w, h) = ((row[2] as f64).exp() * s, (row[3] as f64).exp() * s);
                let b = BBox::new(cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0);
                if b.to_array().iter().all(|v| v.is_finite()) && b.validated().is_ok() {
                    dets.push(Detection::new(ClassId(best as u16), score as f64, b));
                }
            }
        }
    }
    Ok(dets)
}

/// Decode Darknet YOLO rows (see [`ModelFamily::Rows`]) for an input of `width × height` pixels: `out`
/// holds rows of `row_len` values; one detection per row whose best class score reaches `score_threshold`
/// (and whose class is in `classes`, when not empty), box in input pixels.
fn decode_rows(
    out: &[f32],
    row_len: usize,
    [width, height]: [i32; 2],
    score_threshold: f32,
    classes: &[u16],
) -> Vec<Detection> {
    let mut dets = Vec::new();
    if row_len < 6 {
        return dets;
    }
    for row in out.chunks_exact(row_len) {
        let (best, score) =
            row[5..].iter().enumerate().fold((0usize, 0f32), |b, (i, &s)| if s > b.1 { (i, s) } else { b });
        if score < score_threshold || !score.is_finite() {
            continue;
        }
        if !classes.is_empty() && !classes.contains(&(best as u16)) {
            continue;
        }
        let (w, h) = (width as f64, height as f64);
        let (cx, cy, bw, bh) = (row[0] as f64 * w, row[1] as f64 * h, row[2] as f64 * w, row[3] as f64 * h);
        let b = BBox::new(cx - bw / 2.0, cy - bh / 2.0, cx + bw / 2.0, cy + bh / 2.0);
        if b.to_array().iter().all(|v| v.is_finite()) {
            dets.push(Detection::new(ClassId(best as u16), score as f64, b));
        }
    }
    dets
}

/// The outputs of a network (their shapes, one per output) against what the decode of `config`'s family
/// reads: YOLOX one `1 × cells × 85` output, `cells` the grid cells of strides 8, 16 and 32 of the
/// input; rows 2-D outputs of 85 columns. 85 is 4 box values, the objectness and COCO's 80 class scores
/// (a class index is a COCO class id). The message says both shapes.
pub fn check_output_shapes(shapes: &[Vec<i32>], config: &DetectorConfig) -> Result<(), String> {
    let row = 5 + crate::darknet::COCO_CLASSES as i32;
    let text = |s: &[i32]| s.iter().map(i32::to_string).collect::<Vec<_>>().join("×");
    let all = shapes.iter().map(|s| text(s)).collect::<Vec<_>>().join(", ");
    let [w, h] = config.input;
    match config.family {
        ModelFamily::Yolox => {
            let cells: i32 = YOLOX_STRIDES.iter().map(|s| (w / s) * (h / s)).sum();
            let want = [1, cells, row];
            if shapes.len() != 1
                || shapes[0].iter().product::<i32>() != want.iter().product::<i32>()
                || shapes[0].last() != Some(&row)
            {
                return Err(format!(
                    "its output is {all}, but the YOLOX decode (--family yolox) of a {w}x{h} input reads one output of \
                     {} (a row per grid cell of strides 8, 16 and 32: 4 box values, objectness, 80 COCO class \
                     scores): not a YOLOX model of COCO's classes, or another --family",
                    text(&want)
                ));
            }
        }
        ModelFamily::Rows => {
            if shapes.is_empty() || shapes.iter().any(|s| s.len() != 2 || s[1] != row) {
                return Err(format!(
                    "its output is {all}, but the rows decode (Darknet's YOLO layers, --family rows) reads 2-D \
                     outputs of {row} columns (4 box values, objectness, 80 COCO class scores): not a model of \
                     YOLO rows over COCO's classes, or another --family"
                ));
            }
        }
    }
    Ok(())
}

/// Decode one output tensor of `family` (its values row-major, rows of its last dimension's length).
fn decode(
    family: ModelFamily,
    shape: &[i64],
    values: &[f32],
    config: &DetectorConfig,
) -> Result<Vec<Detection>, DetectorError> {
    let row_len = shape.last().copied().unwrap_or(0).max(0) as usize;
    // a network computes finite numbers from a finite image: NaN or infinity in its output is a model
    // whose weights or arithmetic broke, and no box of that pass can be trusted (it is not a frame
    // without objects)
    let broken = values.iter().filter(|v| !v.is_finite()).count();
    if broken > 0 {
        return Err(DetectorError::Network(format!(
            "{broken} of the network's {} output values are not finite numbers (NaN or infinite): a model whose \
             weights or arithmetic are broken; none of this pass's boxes is used",
            values.len()
        )));
    }
    let (threshold, classes) = (config.score_threshold, &config.classes);
    match family {
        ModelFamily::Rows => Ok(decode_rows(values, row_len, config.input, threshold, classes)),
        ModelFamily::Yolox => decode_yolox(values, row_len, config.input, threshold, classes)
            .map_err(|m| DetectorError::Network(format!("the network's output is not YOLOX's (--family yolox): {m}"))),
    }
}

/// The network's input, `1 × 3 × height × width` floats row-major, from an 8-bit grey or BGR image
/// already resized to fit (`image`, placed at the top left; the rest is the letterbox's grey 114):
/// Darknet's rows family wants RGB in 0–1, YOLOX BGR (OpenCV's order) in 0–255; a grey image gives three
/// equal channels. (What `cv::dnn::blobFromImage` gives for the padded 3-channel
/// image, without making that image.)
fn input_blob(image: &Mat, [width, height]: [usize; 2], family: ModelFamily) -> Result<Vec<f32>, DetectorError> {
    let (scale, order) = match family {
        ModelFamily::Rows => (1.0 / 255.0, [2, 1, 0]),
        ModelFamily::Yolox => (1.0, [0, 1, 2]),
    };
    let (cols, rows, channels) = (image.cols() as usize, image.rows() as usize, image.channels() as usize);
    if cols > width || rows > height || !matches!(channels, 1 | 3) || image.depth() != core::CV_8U {
        return Err(DetectorError::Network(format!(
            "a {cols}x{rows} image of {channels} channels (depth {}) does not fit a {width}x{height} input",
            image.depth()
        )));
    }
    let mut blob = vec![114.0 * scale; 3 * width * height];
    let pixels = image.data_bytes()?;
    for (plane, &source) in order.iter().enumerate() {
        let source = if channels == 1 { 0 } else { source };
        for y in 0..rows {
            let row = &pixels[y * cols * channels..(y + 1) * cols * channels];
            let out = &mut blob[(plane * height + y) * width..][..cols];
            for (o, px) in out.iter_mut().zip(row.chunks_exact(channels)) {
                *o = f32::from(px[source]) * scale;
            }
        }
    }
    Ok(blob)
}

/// What runs the network.
enum Backend {
    /// OpenCV's dnn module (Darknet models), on the CPU.
    OpenCv { net: dnn::Net, out_names: core::Vector<String> },
    /// ONNX Runtime (ONNX models).
    Onnx(OnnxNet),
}

/// A YOLO-style detector: an ONNX model on ONNX Runtime, or a Darknet model on OpenCV's dnn module.
pub struct DnnDetector {
    backend: Backend,
    /// Milliseconds of forward passes in the last [`DnnDetector::detect_image`] (its tiles' passes summed).
    last_forward_ms: Option<f64>,
    /// Boxes of the last [`DnnDetector::detect_image`] that reached past the image and were clipped to it.
    last_clipped: usize,
    /// Settings.
    pub config: DetectorConfig,
}

/// Share of OpenCV's estimate of the layers' outputs (`Net::getMemoryConsumption`) that a forward pass
/// takes: the estimate counts every layer's output as if all were held at once, while OpenCV reuses
/// their buffers. Measured on the shipped YOLOX-nano at a 2048 × 2048 input: 3.2 GB estimated, the
/// process grew by 0.6 GB (peak resident 0.70 GB against 0.10 GB at 736 × 224); a quarter keeps a
/// margin above that.
const BLOB_REUSE: f64 = 0.25;

/// A model file OpenCV may open: a regular file (a pipe would block the loader, a device never end)
/// of at most the model limit ([`slam_core::files::MODEL`]).
fn model_file(p: &Path) -> Result<(), DetectorError> {
    slam_core::files::check_readable(p, &slam_core::files::MODEL).map_err(|e| DetectorError::Model {
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
    ) -> Result<Self, DetectorError> {
        let (cfg, weights) = (cfg.as_ref(), weights.as_ref());
        for p in [cfg, weights] {
            model_file(p)?;
        }
        // OpenCV reads as many numbers as the cfg's layers ask for, whatever the file holds
        crate::darknet::check_weights(cfg, weights)
            .map_err(|(path, message)| DetectorError::Model { path, message })?;
        let utf8 = |p: &Path| {
            p.to_str()
                .map(str::to_string)
                .ok_or(DetectorError::Model { path: p.to_path_buf(), message: "path is not UTF-8".into() })
        };
        // OpenCV's message does not say which of the two files it could not read: name both
        let net = dnn::read_net_from_darknet(&utf8(cfg)?, &utf8(weights)?).map_err(|e| DetectorError::Model {
            path: cfg.to_path_buf(),
            message: format!("this .cfg with the weights {} does not load: {e}", weights.display()),
        })?;
        Self::from_net(net, config, weights)
    }

    /// Load an ONNX model on ONNX Runtime (`runtime`: where its library is, the device, the threads).
    pub fn from_onnx(
        model: impl AsRef<Path>,
        config: DetectorConfig,
        runtime: &RuntimeOptions,
    ) -> Result<Self, DetectorError> {
        let model = model.as_ref();
        model_file(model)?;
        let net = OnnxNet::load(model, runtime).map_err(|e| match e {
            OnnxError::Model { path, message } => DetectorError::Model { path, message },
            other => DetectorError::Onnx(other),
        })?;
        tracing::debug!(model = %model.display(), device = runtime.device.name(), threads = runtime.threads, "detector on ONNX Runtime");
        let mut net = net;
        // one pass on a blank input: the output must have the shape the decode reads
        let [w, h] = config.input;
        let err = |message: String| DetectorError::Model { path: model.to_path_buf(), message };
        let blank = vec![0f32; 3 * w as usize * h as usize];
        let shape = net
            .forward(&blank, [w as usize, h as usize], |shape, _| shape.iter().map(|&d| d as i32).collect::<Vec<i32>>())
            .map_err(|e| err(format!("does not run on an input of {w}x{h} (see --input-size): {e}")))?;
        net.take_forward_ms();
        check_output_shapes(&[shape], &config).map_err(err)?;
        Ok(Self { backend: Backend::Onnx(net), last_forward_ms: None, last_clipped: 0, config })
    }

    fn from_net(mut net: dnn::Net, config: DetectorConfig, path: &Path) -> Result<Self, DetectorError> {
        let err = |message: String| DetectorError::Model { path: path.to_path_buf(), message };
        if net.empty()? {
            return Err(err("empty network".into()));
        }
        net.set_preferable_backend(dnn::DNN_BACKEND_OPENCV)?;
        net.set_preferable_target(dnn::DNN_TARGET_CPU)?;
        let out_names = net.get_unconnected_out_layers_names()?;
        let [w, h] = config.input;
        // the memory a forward pass at this input size takes, against what this process can have; a
        // model OpenCV cannot estimate is run as before
        let shape = core::Vector::<i32>::from_slice(&[1, 3, h, w]);
        let (mut weights, mut blobs) = (0, 0);
        if net.get_memory_consumption_1(&shape, &mut weights, &mut blobs).is_ok() {
            let need = weights as f64 + BLOB_REUSE * blobs as f64;
            slam_core::memory::check_fits(&format!("the network at an input of {w}x{h}"), need)
                .map_err(|m| err(format!("{m}: choose a smaller --input-size")))?;
        }
        // one pass on a blank input: the outputs must have the shape the decode reads
        let blank = Mat::new_nd_with_default(&[1, 3, h, w], core::CV_32F, core::Scalar::all(0.0))?;
        net.set_input(&blank, "", 1.0, core::Scalar::default())?;
        let mut outs: core::Vector<Mat> = core::Vector::new();
        net.forward(&mut outs, &out_names).map_err(|e| {
            err(format!("does not run on an input of {w}x{h} (its input size may be fixed; see --input-size): {e}"))
        })?;
        let shapes: Vec<Vec<i32>> = outs.iter().map(|o| o.mat_size().iter().copied().collect()).collect();
        check_output_shapes(&shapes, &config).map_err(err)?;
        Ok(Self { backend: Backend::OpenCv { net, out_names }, last_forward_ms: None, last_clipped: 0, config })
    }

    /// Whether the network runs on ONNX Runtime (else on OpenCV's dnn module).
    pub fn on_onnx_runtime(&self) -> bool {
        matches!(self.backend, Backend::Onnx(_))
    }

    /// Milliseconds the network's forward passes took in the last [`DnnDetector::detect_image`] (all of its
    /// passes: one per tile in mode tiles); the rest of that call is pre- and post-processing.
    pub fn forward_ms(&self) -> Option<f64> {
        self.last_forward_ms
    }

    /// Run the network on one crop (grey or BGR), letterboxed or squashed into the input; boxes in crop
    /// pixels, clipped to the crop, each with whether it was.
    fn run_crop(&mut self, crop: &Mat, letterbox: bool) -> Result<Vec<(Detection, bool)>, DetectorError> {
        let [nw_in, nh_in] = self.config.input;
        let (w, h) = (crop.cols() as f64, crop.rows() as f64);
        let (sx, sy, size) = if letterbox {
            let s = (nw_in as f64 / w).min(nh_in as f64 / h);
            let (nw, nh) = (((w * s).round() as i32).clamp(1, nw_in), ((h * s).round() as i32).clamp(1, nh_in));
            (s, s, core::Size::new(nw, nh))
        } else {
            (nw_in as f64 / w, nh_in as f64 / h, core::Size::new(nw_in, nh_in))
        };
        let mut resized = Mat::default();
        imgproc::resize(crop, &mut resized, size, 0.0, 0.0, imgproc::INTER_LINEAR)?;
        let blob = input_blob(&resized, [nw_in as usize, nh_in as usize], self.config.family)?;
        let config = &self.config;
        let (family, [nw, nh]) = (config.family, [nw_in as usize, nh_in as usize]);
        let mut dets = Vec::new();
        match &mut self.backend {
            Backend::OpenCv { net, out_names } => {
                let start = Instant::now();
                let flat = Mat::from_slice(&blob)?;
                let blob = flat.reshape_nd(1, &[1, 3, nh_in, nw_in])?;
                net.set_input(&blob, "", 1.0, core::Scalar::default())?;
                let mut outs: core::Vector<Mat> = core::Vector::new();
                net.forward(&mut outs, out_names)?;
                *self.last_forward_ms.get_or_insert(0.0) += start.elapsed().as_secs_f64() * 1e3;
                for out in outs.iter() {
                    let shape: Vec<i64> = out.mat_size().iter().map(|&d| d as i64).collect();
                    dets.extend(decode(family, &shape, out.data_typed::<f32>()?, config)?);
                }
            }
            Backend::Onnx(net) => {
                let found = net
                    .forward(&blob, [nw, nh], |shape, values| decode(family, shape, values, config))
                    .map_err(DetectorError::Onnx)??;
                *self.last_forward_ms.get_or_insert(0.0) += net.take_forward_ms();
                dets.extend(found);
            }
        }
        // input pixels → crop pixels
        Ok(dets
            .into_iter()
            .filter_map(|mut d| {
                let b = d.bbox;
                let unclipped = [b.xmin / sx, b.ymin / sy, b.xmax / sx, b.ymax / sy];
                d.bbox = BBox::new(
                    unclipped[0].clamp(0.0, w),
                    unclipped[1].clamp(0.0, h),
                    unclipped[2].clamp(0.0, w),
                    unclipped[3].clamp(0.0, h),
                );
                let clipped = d.bbox.to_array() != unclipped;
                d.bbox.validated().is_ok().then_some((d, clipped))
            })
            .collect())
    }

    /// Detect objects in an image.
    pub fn detect_image(&mut self, image: &Image) -> Result<Vec<Detection>, DetectorError> {
        (self.last_forward_ms, self.last_clipped) = (None, 0);
        // a grey frame (KITTI's cameras 0 and 1) stays grey until the input blob, which repeats it in
        // all three channels: resizing one channel instead of three equal ones gives the same values
        let mat = image_to_mat(image)?;
        let (w, h) = (mat.cols(), mat.rows());
        let mut all = Vec::new();
        // the boxes clipped to the image (a tile's clipped at an inner edge are dropped as cut below)
        let mut clipped = Vec::new();
        let mut keep = |found: Vec<(Detection, bool)>, all: &mut Vec<Detection>| {
            for (d, c) in found {
                if c {
                    clipped.push(d.bbox);
                }
                all.push(d);
            }
        };
        match self.config.mode {
            InputMode::Squash => keep(self.run_crop(&mat, false)?, &mut all),
            InputMode::Letterbox => keep(self.run_crop(&mat, true)?, &mut all),
            InputMode::Tiles(k) => {
                keep(self.run_crop(&mat, true)?, &mut all);
                let k = k.max(1) as i32;
                // near-square tiles (4:3 at most) across the width, overlapping
                let tw = (h * 4 / 3).min(w).max(w / k);
                let step = if k > 1 { (w - tw) / (k - 1) } else { 0 };
                for i in 0..k {
                    let x0 = (i * step).min(w - tw);
                    let roi = Mat::roi(&mat, core::Rect::new(x0, 0, tw, h))?.try_clone()?;
                    for (mut d, c) in self.run_crop(&roi, true)? {
                        let b = d.bbox;
                        // a box cut by an inner tile edge is a partial object: the neighbouring tile or the
                        // whole-frame pass sees it whole
                        let cut_left = x0 > 0 && b.xmin <= 2.0;
                        let cut_right = x0 + tw < w && b.xmax >= tw as f64 - 2.0;
                        if cut_left || cut_right {
                            continue;
                        }
                        d.bbox = BBox::new(b.xmin + x0 as f64, b.ymin, b.xmax + x0 as f64, b.ymax);
                        keep(vec![(d, c)], &mut all);
                    }
                }
            }
        }
        let iou = self.config.nms_iou as f64;
        let kept = if self.config.group_nms { nms_by_group(all, iou) } else { nms(all, iou) };
        self.last_clipped = kept.iter().filter(|d| clipped.contains(&d.bbox)).count();
        Ok(kept)
    }

    /// Boxes of the last [`DnnDetector::detect_image`] that reached past the image and were clipped to it.
    pub fn clipped(&self) -> usize {
        self.last_clipped
    }
}

/// Class-wise non-maximum suppression, highest score first (ties by box), deterministic.
pub fn nms(dets: Vec<Detection>, iou: f64) -> Vec<Detection> {
    suppress(dets, iou, |c| c.0)
}

/// Non-maximum suppression within class groups ([`ClassId::group`]: a box called car and another
/// called truck on one vehicle are one object), highest score first (ties by box), deterministic.
pub fn nms_by_group(dets: Vec<Detection>, iou: f64) -> Vec<Detection> {
    suppress(dets, iou, ClassId::group)
}

fn suppress(mut dets: Vec<Detection>, iou: f64, key: impl Fn(ClassId) -> u16) -> Vec<Detection> {
    dets.sort_by(|a, b| {
        b.score
            .total_cmp(&a.score)
            .then(a.class.cmp(&b.class))
            .then(a.bbox.xmin.total_cmp(&b.bbox.xmin))
            .then(a.bbox.ymin.total_cmp(&b.bbox.ymin))
    });
    let mut keep: Vec<Detection> = Vec::new();
    for d in dets {
        if keep.iter().all(|k| key(k.class) != key(d.class) || k.bbox.iou(&d.bbox) <= iou) {
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

    fn forward_ms(&self) -> Option<f64> {
        self.last_forward_ms
    }

    fn clipped(&self) -> usize {
        self.last_clipped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-built YOLOX output for a 64 × 32 input (grids 8 × 4, 4 × 2, 2 × 1: 42 cells) with three
    /// classes: every cell empty but two.
    fn output(cells: &[(usize, [f32; 8])]) -> Vec<f32> {
        let mut out = vec![0.0f32; 42 * 8];
        for (i, row) in out.chunks_exact_mut(8).enumerate() {
            row[2] = 0.3; // log w, log h of an empty cell: anything
            row[4] = 0.01; // objectness
            row[5 + i % 3] = 0.5;
        }
        for (cell, values) in cells {
            out[cell * 8..cell * 8 + 8].copy_from_slice(values);
        }
        out
    }

    #[test]
    fn yolox_decode_gives_back_known_boxes() {
        // stride 16, cell (gx 2, gy 1): after the 32 cells of stride 8, row-major: cell 32 + 4 + 2
        // centre ((0.25 + 2) 16, (0.5 + 1) 16) = (36, 24), size e^0 16 = 16 by e^0 16: [28, 16, 44, 32]
        let a = (38, [0.25, 0.5, 0.0, 0.0, 0.9, 0.1, 0.8, 0.3]);
        // stride 32, cell (1, 0): cell 32 + 8 + 1; centre (48, 16), size 32 e^ln2 = 64 by 32 e^ln0.5 = 16
        let b = (41, [0.5, 0.5, 2f32.ln(), 0.5f32.ln(), 1.0, 0.0, 0.0, 0.6]);
        // stride 8, cell (3, 1): cell 11; scores 0.9 × 0.4 = 0.36, under the threshold
        let c = (11, [0.0, 0.0, 0.0, 0.0, 0.9, 0.4, 0.0, 0.0]);
        let out = output(&[a, b, c]);
        let d = decode_yolox(&out, 8, [64, 32], 0.4, &[]).expect("decodes");
        assert_eq!(d.len(), 2, "{d:?}");
        assert_eq!((d[0].class, d[0].bbox), (ClassId(1), BBox::new(28.0, 16.0, 44.0, 32.0)));
        assert!((d[0].score - 0.72).abs() < 1e-6, "objectness × the best class score: {}", d[0].score);
        assert_eq!(d[1].class, ClassId(2));
        let want = [16.0, 8.0, 80.0, 24.0];
        assert!(d[1].bbox.to_array().iter().zip(want).all(|(g, w)| (g - w).abs() < 1e-5), "{:?}", d[1].bbox);
        // a lower threshold lets the third through; a class filter keeps only class 2
        assert_eq!(decode_yolox(&out, 8, [64, 32], 0.3, &[]).expect("decodes").len(), 3);
        let only = decode_yolox(&out, 8, [64, 32], 0.3, &[2]).expect("decodes");
        assert!(only.len() == 1 && only[0].class == ClassId(2));
    }

    #[test]
    fn the_input_blob_has_the_family_s_channel_order_and_scale_and_grey_padding() {
        // a 2 x 1 BGR image into a 3 x 2 input: pixel (0, 0) = B 10, G 20, R 30; (1, 0) = 40, 50, 60
        let bgr = Mat::from_slice(&[10u8, 20, 30, 40, 50, 60]).expect("mat");
        let bgr = bgr.reshape(3, 1).expect("3 channels").try_clone().expect("owned");
        let yolox = input_blob(&bgr, [3, 2], ModelFamily::Yolox).expect("fits");
        let p = 114.0;
        assert_eq!(yolox, [10.0, 40.0, p, p, p, p, 20.0, 50.0, p, p, p, p, 30.0, 60.0, p, p, p, p]);
        let rows = input_blob(&bgr, [3, 2], ModelFamily::Rows).expect("fits");
        assert_eq!(rows.len(), 18);
        assert!((rows[0] - 30.0 / 255.0).abs() < 1e-7 && (rows[6] - 20.0 / 255.0).abs() < 1e-7, "RGB, 0-1");
        assert!((rows[2] - 114.0 / 255.0).abs() < 1e-7);
        // grey: the same value in all three planes
        let grey = Mat::from_slice(&[7u8, 9]).expect("mat").try_clone().expect("owned");
        let g = input_blob(&grey, [2, 1], ModelFamily::Yolox).expect("fits");
        assert_eq!(g, [7.0, 9.0, 7.0, 9.0, 7.0, 9.0]);
        assert!(input_blob(&bgr, [1, 1], ModelFamily::Yolox).is_err(), "larger than the input");
    }

    #[test]
    fn yolox_decode_refuses_an_output_of_another_input_or_layout() {
        let out = output(&[]);
        let e = decode_yolox(&out, 8, [64, 64], 0.4, &[]).expect_err("a 64 x 64 input has 84 cells");
        assert!(e.contains("84 YOLOX grid cells") && e.contains("the output has 336"), "{e}");
        assert!(decode_yolox(&out, 5, [64, 32], 0.4, &[]).is_err(), "rows without class scores");
        // NaN scores and boxes are left out, not kept
        let nan = (5, [0.0, 0.0, f32::NAN, 0.0, 1.0, 0.9, 0.0, 0.0]);
        let nan_score = (6, [0.0, 0.0, 0.0, 0.0, f32::NAN, 0.9, 0.0, 0.0]);
        assert!(decode_yolox(&output(&[nan, nan_score]), 8, [64, 32], 0.4, &[]).expect("decodes").is_empty());
        // a forward pass whose output holds NaN is a broken model, not a frame without objects
        let config = DetectorConfig { input: [64, 32], ..DetectorConfig::yolox() };
        let values = output(&[nan, (7, [0.0, 0.0, 0.0, 0.0, 1.0, 0.9, 0.0, 0.0])]);
        let e = decode(ModelFamily::Yolox, &[1, 42, 8], &values, &config).expect_err("NaN").to_string();
        assert!(e.contains("1 of the network's 336 output values are not finite"), "{e}");
        let all_nan = vec![f32::NAN; 42 * 85];
        let rows = decode(ModelFamily::Rows, &[42, 85], &all_nan, &config).expect_err("all NaN").to_string();
        assert!(rows.contains("3570 of the network's 3570"), "{rows}");
    }

    /// A network's outputs against its decode: YOLOX's one output of a row per grid cell, Darknet's
    /// 2-D rows, each of 85 values; another count of cells (another input), another row length (other
    /// classes) or a 3-D rows output is refused, naming both shapes.
    #[test]
    fn output_shapes_are_checked_against_the_decode() {
        let yolox = DetectorConfig::yolox();
        // 736 x 224: 92 x 28 + 46 x 14 + 23 x 7 = 3381 cells
        check_output_shapes(&[vec![1, 3381, 85]], &yolox).expect("YOLOX-nano at 736x224");
        let e = check_output_shapes(&[vec![1, 2100, 85]], &yolox).expect_err("another input").to_string();
        assert!(e.contains("its output is 1×2100×85") && e.contains("reads one output of 1×3381×85"), "{e}");
        assert!(check_output_shapes(&[vec![1, 3381, 8]], &yolox).is_err(), "3 classes");
        assert!(check_output_shapes(&[vec![1, 3381, 85], vec![1, 3381, 85]], &yolox).is_err(), "two outputs");
        let rows = DetectorConfig::yolo_fastest();
        check_output_shapes(&[vec![1200, 85], vec![300, 85]], &rows).expect("two YOLO layers");
        let e = check_output_shapes(&[vec![1, 3381, 85]], &rows).expect_err("3-D").to_string();
        assert!(e.contains("reads 2-D outputs of 85 columns"), "{e}");
    }
}
