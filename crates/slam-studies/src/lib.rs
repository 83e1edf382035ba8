//! Benchmarks and studies of the reusable crates, in a crate of their own so that the libraries hold
//! only what a user of them runs (no process spawning, no `/proc`, no study tables in `slam-optim` or
//! `slam-assoc`):
//!
//! * [`optim_bench`]: `slam-app optim-bench`, the optimiser on the anchor problems of
//!   `fixtures/optim/ANCHORS.md` and on a generated bundle adjustment (dense against sparse);
//! * [`assoc_sim`]: simulated multi-object scenes with crossings, occlusion and clutter, and CLEAR-MOT
//!   style counting, to compare associators;
//! * [`assoc_study`]: `slam-app assoc`, the associators compared on those scenes and on labelled boxes
//!   played as detections.

#![warn(missing_docs)]

pub mod assoc_sim;
pub mod assoc_study;
pub mod optim_bench;
