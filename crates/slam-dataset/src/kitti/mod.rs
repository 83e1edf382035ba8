//! KITTI readers.

pub mod calib;
pub mod poses;
pub mod tracking;
