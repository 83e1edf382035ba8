//! The detector's error: a model that does not load, a network whose output is not what its family
//! says, ONNX Runtime's failures, and the image conversions and OpenCV calls around a forward pass.

use std::path::PathBuf;

use slam_frontend::FrontendError;

use crate::onnx::OnnxError;

/// Errors of the detector ([`crate::DnnDetector`]).
#[derive(Debug, thiserror::Error)]
pub enum DetectorError {
    /// An image could not be converted, or OpenCV failed while running (the front end's image I/O, whose
    /// words it keeps).
    #[error(transparent)]
    Image(#[from] FrontendError),
    /// The detector model could not be loaded.
    #[error("cannot load detector model {path}: {message}")]
    Model {
        /// Model file.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// ONNX Runtime: not found, not loadable, or failed on a forward pass.
    #[error(transparent)]
    Onnx(#[from] OnnxError),
    /// A network's output is not what its family says.
    #[error("{0}")]
    Network(String),
}

impl From<opencv::Error> for DetectorError {
    fn from(e: opencv::Error) -> Self {
        DetectorError::Image(FrontendError::from(e))
    }
}
