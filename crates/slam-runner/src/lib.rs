//! `slam-runner`: the composition just below `slam-app`. The app parses arguments, loads settings and
//! prints; this crate does the work of its run-related commands:
//!
//! - [`detector`]: the detection source a run uses ([`DetectorChoice`]: none, network, file, labels);
//! - [`run`]: one run of the whole system on a KITTI stereo sequence ([`RunSettings`] → [`prepare`] →
//!   [`Prepared::run`] → [`Outcome`]);
//! - [`report`]: the run's output files, summary, object score and pictures;
//! - [`run_summary`]: figures of a finished run (frames per second, per-stage medians, frame period,
//!   tracking states, `tracking.csv`);
//! - [`bench`]: the `run-bench` and `track-bench` runs and table rows;
//! - [`objects_bench`]: `objects-bench`, the object map of every dev case (labelled drive at several
//!   strides, the image-free study, the main job's street);
//! - [`stereo`]: `stereo-check`, the rig's disparity offset in rounds;
//! - [`depth`]: `depth-check`, the stereo depth against a raw drive's Velodyne scans;
//! - [`inspect`]: `map` (a saved map's summary and exports) and `trajectory-eval`;
//! - [`map_export`]: a saved map's PLY exports (its points, and the scene as a coloured mesh);
//! - [`detect`]: `detect` (a detector over a folder into a detection file) and `detect-recall`;
//! - [`settings`]: the run's settings from TOML over the libraries' defaults ([`RunConfig`]);
//! - [`simulation`]: `sim`, the paper's simulation sweep into an output folder;
//! - [`studies`] (feature `console`): `eval`'s image-free study table with progress and CSV;
//! - [`console`] (feature `console`): progress, Ctrl-C and stdout of a command-line program;
//! - [`wiring`]: the implementations behind each seam by name ([`Wiring`]; `ValueEnum`s with `clap`).
//!
//! Only `slam-app` depends on this crate (`tools/check-deps.sh`).

pub mod bag_edit;
pub mod bench;
#[cfg(feature = "console")]
pub mod console;
pub mod depth;
pub mod detect;
pub mod detector;
pub mod error;
pub mod in_map;
pub mod inspect;
pub mod map_bench;
pub mod map_export;
pub mod objects_bench;
pub mod raw_rig;
pub mod report;
pub mod ros_output;
pub mod run;
pub mod run_summary;
pub mod settings;
pub mod simulation;
pub mod source;
pub mod stereo;
#[cfg(feature = "console")]
pub mod studies;
pub mod wiring;

pub use detector::{DetectorChoice, DetectorKind, DetectorOptions, NetworkLoader};
pub use error::{Result, RunnerError};
pub use report::OverlayChoice;
pub use run::{
    prepare, AssociatorFactory, ObserverFactory, OptimizerFactory, Outcome, Prepared, RunObserver, RunSettings,
};
pub use settings::RunConfig;
pub use source::SourceArgs;
pub use wiring::{AssociatorKind, Method, OptimizerKind, Shape, Wiring};
