//! KITTI readers.

pub mod calib;
pub mod frames;
pub mod odometry;
pub mod poses;
pub mod raw;
pub mod stereo;
pub mod tracking;
pub mod tracklets;
pub mod velodyne;
