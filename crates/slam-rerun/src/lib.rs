//! A run of quadric SLAM, or a saved map, as a [rerun](https://rerun.io) recording (`.rrd`), to scrub
//! through in 3-D: the camera moving with its frustum, the left image with the detection boxes and the
//! projected ellipsoids, the estimated, final and ground-truth trajectories, the map points, the
//! ellipsoids appearing and being refined, and the tracking state, on a `frame` timeline (and `time`,
//! the frames' times).
//!
//! - [`scene`]: what is recorded, as plain data (entity paths, one frame's content from a running
//!   system's `FrameView` or a saved map, colours, the bounds that keep a recording's size in
//!   proportion to the run); no rerun needed;
//! - `record` (feature `rerun`): the writer, [`Recorder`] for a run as it goes (its own thread encodes
//!   the images and logs; rerun's file sink streams to disk) and [`record_map`] for a saved map;
//! - `read` (feature `rerun`): a recording decoded back with rerun's own decoder ([`read::summarise`]).
//!
//! The `rerun` feature brings rerun's logging SDK (`re_sdk`, `re_sdk_types`, `re_log_encoding`
//! 0.36.3, the newest that builds with Rust 1.95), 15-17 minutes of first build on two cores: it is off unless
//! asked for (`slam-app`'s feature `rerun`). Open a recording with the viewer of the same version
//! (`pip install rerun-sdk==0.36.3`, then `rerun FILE.rrd`).
//!
//! A composition crate beside `slam-viz`, whose overlay rules it shares (box labels and state colours,
//! projected outlines); only `slam-app` depends on it.

#![warn(missing_docs)]

pub mod scene;

#[cfg(feature = "rerun")]
pub mod read;
#[cfg(feature = "rerun")]
mod record;

#[cfg(feature = "rerun")]
pub use record::{record_map, RecordError, Recorder, RecordingStats, APPLICATION_ID};
pub use scene::{FrameScene, SceneSetup};
