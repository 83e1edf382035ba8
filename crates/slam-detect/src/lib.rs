//! The object detector of quadric SLAM: a YOLO-style network behind `slam_core::DetectionSource`
//! ([`DnnDetector`]), ONNX models on ONNX Runtime ([`onnx`]) and Darknet models (cfg + weights) on OpenCV's
//! dnn module ([`darknet`]), the frame feeding (letterbox, tiles) and the decoding of the two output layouts
//! ([`detector`]); models as a user names them ([`model`]); the other detection sources and the guard a run
//! puts around any of them ([`detectors`]); and a detector over a list of image files ([`batch`]).
//!
//! This is the only crate that uses ONNX Runtime. Neither its nor OpenCV's types cross its API: frames
//! are `slam_core::Image`, detections `slam_core::Detection`. Images are read and converted through
//! `slam-frontend`'s image I/O.

#![warn(missing_docs)]

pub mod batch;
pub mod darknet;
pub mod detector;
pub mod detectors;
mod error;
pub mod model;
pub mod onnx;

pub use batch::draw_detections;
pub use detector::{decode_yolox, nms, nms_by_group, DetectorConfig, DnnDetector, InputMode, ModelFamily};
pub use error::DetectorError;
pub use model::{parse_input_size, FamilyName, InputSize, ModeName, ModelError, ModelSpec, OptionError, ShippedModel};
pub use onnx::{Device, OnnxError, RuntimeOptions};
