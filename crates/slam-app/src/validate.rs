//! Validation at the edge: command-line numbers, settings-file values, calibration and image sizes are
//! checked before any work starts, and every message names the value, what was given and the valid
//! range. Inside the libraries these values are trusted.

pub use slam_dataset::check::{count, number, Range};

/// A library setting's error under its command-line flag (`min_frames` → `--min-frames`).
pub fn flag(e: slam_core::check::InvalidValue) -> slam_core::check::InvalidValue {
    let key = format!("--{}", e.key.replace('_', "-"));
    e.rename(key)
}
