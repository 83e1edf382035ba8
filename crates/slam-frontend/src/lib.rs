//! The OpenCV side of quadric SLAM's tracking: stereo visual odometry ([`StereoVo`], a
//! `slam_core::StereoTracker` that answers the objects' `slam_core::ObjectMeasurements` too, with its
//! helpers in [`stereo_vo`]), rectification, the disparity offset's estimate, and image I/O and
//! overlays ([`image_io`]). The object detector is the crate `slam-detect`, which reads and converts
//! its images through [`image_io`].
//!
//! This crate links OpenCV but not ONNX Runtime. OpenCV's types stay out of its API (images are
//! `slam_core::Image`), but for the two conversions [`image_io::image_to_mat`] and
//! [`image_io::mat_to_image`], which exist for `slam-detect`'s own OpenCV calls.

#![warn(missing_docs)]

pub mod diagnosis;
pub mod disparity;
pub use slam_map::hamming;
pub mod image_io;
pub mod image_size;
pub mod odometry;
pub mod rectify;
pub mod stereo_vo;

pub use image_io::{draw_overlay, ellipse_outline, encode_jpeg, read_image, write_image, FrontendError, Overlay};
pub use odometry::Odometry;
pub use stereo_vo::{StereoRig, StereoVo, VoConfig};
