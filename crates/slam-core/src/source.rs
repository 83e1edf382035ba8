//! Where detections come from: a detector on the pixels, a file written by another detector, or ground
//! truth with chosen noise. One trait, so the pipeline and `slam-app detect` can use any of them.

use crate::detection::Detection;

/// An 8-bit image owned by the caller: `channels` interleaved bytes per pixel, rows top to bottom
/// (`data.len() == width · height · channels`). Colour images are BGR, as OpenCV and KITTI's PNGs decode.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// 1 (grey) or 3 (BGR).
    pub channels: u8,
    /// Pixel bytes.
    pub data: Vec<u8>,
}

impl Image {
    /// An image; `None` when the buffer does not match the size.
    pub fn new(width: u32, height: u32, channels: u8, data: Vec<u8>) -> Option<Self> {
        (data.len() == width as usize * height as usize * channels as usize && matches!(channels, 1 | 3))
            .then_some(Self { width, height, channels, data })
    }
}

/// Why a detection source failed for a frame.
#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    /// The source has nothing for this frame index (e.g. past the end of a file).
    #[error("frame {0} is not covered by the detection source")]
    NoSuchFrame(usize),
    /// The source needs the image and none was given.
    #[error("this detection source needs the image of frame {0}")]
    NeedsImage(usize),
    /// The source's backend failed for this frame (model inference, decoding); the cause is the
    /// error's source.
    #[error("frame {frame}: {source}")]
    Failed {
        /// Frame index.
        frame: usize,
        /// Why.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

impl DetectError {
    /// A backend failure for `frame`.
    pub fn failed(frame: usize, e: impl std::error::Error + Send + Sync + 'static) -> Self {
        DetectError::Failed { frame, source: Box::new(e) }
    }
}

/// A source of detections for the frames of a sequence.
///
/// Contract: `detect` returns the detections of frame `frame` (0-based index in the sequence); boxes are
/// in pixels of the left image, finite and non-empty (sources drop, count and log invalid ones); the
/// same frame and image give the same detections (seeded sources are deterministic).
pub trait DetectionSource: Send {
    /// Short name for logs.
    fn name(&self) -> &str;
    /// Whether [`DetectionSource::detect`] needs the image.
    fn needs_image(&self) -> bool;
    /// Detections of one frame.
    fn detect(&mut self, frame: usize, image: Option<&Image>) -> Result<Vec<Detection>, DetectError>;
    /// Milliseconds the network's forward passes took in the last [`DetectionSource::detect`], for a source
    /// that runs one (the rest of that call is its pre- and post-processing); `None` for the others.
    fn forward_ms(&self) -> Option<f64> {
        None
    }
    /// Boxes of the last [`DetectionSource::detect`] that the source itself clipped to the image (a
    /// network's boxes reaching past its input), so that a guard counting clipped boxes counts them
    /// too; 0 for a source that clips nothing.
    fn clipped(&self) -> usize {
        0
    }
}
