//! Pictures of quadric-SLAM results, kept out of the command-line app so that every front end draws
//! the same way:
//! - [`plot`]: figures through plotters (SVG and PNG): the simulation study and the top-down map;
//! - [`map`]: the top-down picture of a saved or finished map (trajectory, points, object footprints);
//! - [`overlay`]: the per-frame overlay of a run (boxes, projected ellipsoids, trails), drawn on the
//!   frame's image through `slam-frontend`.
//!
//! This is a composition crate: it sits above the front end (it links OpenCV through
//! `slam-frontend`) and the pipeline (whose run output it draws).

#![warn(missing_docs)]

pub mod map;
pub mod overlay;
pub mod plot;

use std::path::PathBuf;

pub use map::{footprint, map_picture, MAP_PICTURE_FILES};
pub use overlay::{
    box_style, frame_overlay, overlay_of, projected_object, write_overlays, FrameState, OverlayOptions, ProjectedObject,
};
pub use plot::{simulation_figure, topdown_figure, MapShape, ObjectState, TopDown};

/// Errors of drawing and writing pictures.
#[derive(Debug, thiserror::Error)]
pub enum VizError {
    /// A figure could not be drawn or written (the message is the plotting backend's).
    #[error("drawing {}: {message}", path.display())]
    Draw {
        /// The figure's file.
        path: PathBuf,
        /// The backend's report.
        message: String,
    },
    /// What was asked cannot be drawn (a non-finite position, positions spread wider than a continent);
    /// nothing was written.
    #[error("not drawn: {message}")]
    NotDrawable {
        /// Why.
        message: String,
    },
    /// A folder could not be created.
    #[error("cannot create {}: {source}", path.display())]
    CreateDir {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Image reading, drawing or writing failed in the front end.
    #[error(transparent)]
    Frontend(#[from] slam_frontend::FrontendError),
}
