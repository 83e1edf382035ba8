//! The OpenCV side of quadric SLAM: stereo visual odometry ([`StereoVo`], a `slam_core::StereoTracker`),
//! image I/O and overlays, and an object detector (ONNX models on ONNX Runtime, [`onnx`]; Darknet models
//! on OpenCV's dnn module).
//!
//! This is the only crate (with `slam-app`) that links OpenCV, and the only one that uses ONNX Runtime;
//! neither's types cross its public API: images are `slam_core::Image`, detections
//! `slam_core::Detection`.

#![warn(missing_docs)]

pub mod batch;
pub mod darknet;
pub mod detector;
pub mod detectors;
pub mod diagnosis;
pub mod disparity;
pub use detector::{decode_yolox, nms, nms_by_group};
pub use slam_map::hamming;
pub mod image_io;
pub mod image_size;
mod keyframe_index;
mod keyframe_motion;
pub mod model;
pub mod odometry;
pub mod onnx;
mod pose_only;
pub mod rectify;
mod settings;
pub mod stereo_vo;

pub use detector::{DetectorConfig, DnnDetector, InputMode, ModelFamily};
pub use image_io::{
    draw_detections, draw_overlay, ellipse_outline, encode_jpeg, read_image, write_image, FrontendError, Overlay,
};
pub use model::{parse_input_size, FamilyName, InputSize, ModeName, ModelError, ModelSpec, OptionError, ShippedModel};
pub use odometry::Odometry;
pub use onnx::{Device, OnnxError, RuntimeOptions};
pub use stereo_vo::{StereoRig, StereoVo, VoConfig};
