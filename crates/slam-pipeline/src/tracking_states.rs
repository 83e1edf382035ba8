//! The names of the tracking states a frame's row of `tracking.csv` and a saved map's trajectory can
//! hold: what the report counts ([`crate::report`]) and what reading a map file accepts
//! ([`crate::saved_map`]), in a file of its own so that neither imports the other.

/// Every state a frame's row of `tracking.csv` can name, in the order of `track-bench`'s columns.
pub const STATE_NAMES: [&str; 7] = ["initialised", "tracked", "weak", "relocalised", "predicted", "lost", "unreadable"];
