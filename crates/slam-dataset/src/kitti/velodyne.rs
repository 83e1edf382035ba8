//! KITTI Velodyne scans (`velodyne_points/data/NNNNNNNNNN.bin`): little-endian `f32` x, y, z and
//! reflectance per point, in the Velodyne frame (x forward, y left, z up, metres), and their projection
//! into the rectified left camera with a raw drive's calibration ([`super::raw::RawCalib`]).

use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};

use super::raw::RawCalib;
use crate::DatasetError;

/// Bytes per point: four little-endian `f32`.
const POINT_BYTES: usize = 16;

/// Largest scan read, bytes: an HDL-64E turn holds about 120 000 points (1.9 MB); 64 MiB is thirty
/// times that, so a real scan always fits and a wrong file (a device, an image) is refused early.
pub const MAX_SCAN_BYTES: u64 = 64 << 20;

/// One Velodyne return: position in the Velodyne frame, metres, and reflectance (0–1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VeloPoint {
    /// Position, Velodyne frame.
    pub position: Vector3<f64>,
    /// Reflectance.
    pub reflectance: f64,
}

/// Read one scan; errors name the file: not a regular file, larger than [`MAX_SCAN_BYTES`], a length
/// that is not a whole number of points, or a non-finite coordinate (with the point's index).
pub fn read_scan(path: impl AsRef<Path>) -> Result<Vec<VeloPoint>, DatasetError> {
    let path = path.as_ref();
    let limit = slam_core::files::Limit {
        bytes: MAX_SCAN_BYTES,
        what: "a Velodyne scan",
        why: "an HDL-64E turn holds about 120 000 points, 1.9 MB",
    };
    let bytes = slam_core::files::read_bytes(path, &limit).map_err(|e| match e {
        slam_core::files::ReadError::Io { path, source } => DatasetError::Io { path, source },
        other => DatasetError::Read(other),
    })?;
    parse_scan(path, &bytes)
}

/// Parse the bytes of a scan read from `path` (named in errors).
pub fn parse_scan(path: &Path, bytes: &[u8]) -> Result<Vec<VeloPoint>, DatasetError> {
    if bytes.len() % POINT_BYTES != 0 {
        return Err(DatasetError::Invalid {
            path: path.to_path_buf(),
            message: format!("{} bytes is not a whole number of 16-byte points (x, y, z, reflectance)", bytes.len()),
        });
    }
    bytes
        .chunks_exact(POINT_BYTES)
        .enumerate()
        .map(|(i, c)| {
            let f = |k: usize| f32::from_le_bytes([c[4 * k], c[4 * k + 1], c[4 * k + 2], c[4 * k + 3]]) as f64;
            let (x, y, z, r) = (f(0), f(1), f(2), f(3));
            if ![x, y, z, r].iter().all(|v| v.is_finite()) {
                return Err(DatasetError::Invalid {
                    path: path.to_path_buf(),
                    message: format!("point {i} (byte {}) has a non-finite value", i * POINT_BYTES),
                });
            }
            Ok(VeloPoint { position: Vector3::new(x, y, z), reflectance: r })
        })
        .collect()
}

/// A Velodyne return seen by the rectified left camera: pixel `(u, v)` and depth `z`, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectedPoint {
    /// Column, row (pixels, `P_rect_00`).
    pub u: f64,
    /// Row.
    pub v: f64,
    /// Depth along the rectified camera's axis, metres.
    pub z: f64,
}

/// The points of `scan` in front of rectified camera 0 (depth above `min_depth`) that project inside
/// an image of `size` (width, height), with `calib`'s `R_rect_00 · T_cam0←velo` and `P_rect_00`.
pub fn project_into_left(
    scan: &[VeloPoint],
    calib: &RawCalib,
    size: (f64, f64),
    min_depth: f64,
) -> Vec<ProjectedPoint> {
    let rect_from_velo = calib.rect_from_velo();
    let p = &calib.p_rect[0];
    scan.iter()
        .filter_map(|q| {
            let c = rect_from_velo * Point3::from(q.position);
            if c.z <= min_depth {
                return None;
            }
            let h = p * c.to_homogeneous();
            let (u, v) = (h.x / h.z, h.y / h.z);
            (u >= 0.0 && v >= 0.0 && u < size.0 && v < size.1).then_some(ProjectedPoint { u, v, z: c.z })
        })
        .collect()
}

/// The scan file of frame `frame` in a raw drive folder (`.../2011_09_26_drive_0005_sync`), if it
/// exists: `velodyne_points/data/NNNNNNNNNN.bin`.
pub fn scan_path(drive: &Path, frame: usize) -> Option<PathBuf> {
    let p = drive.join("velodyne_points").join("data").join(format!("{frame:010}.bin"));
    p.is_file().then_some(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes_of(points: &[[f32; 4]]) -> Vec<u8> {
        points.iter().flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes())).collect()
    }

    #[test]
    fn scans_parse_and_bad_lengths_and_values_are_named() {
        let p = Path::new("scan.bin");
        let pts = parse_scan(p, &bytes_of(&[[1.0, 2.0, 3.0, 0.5], [-4.0, 0.0, 1.5, 0.0]])).expect("two points");
        assert_eq!(pts.len(), 2);
        assert_eq!(pts[1].position, Vector3::new(-4.0, 0.0, 1.5));
        assert_eq!(pts[0].reflectance, 0.5);
        let short = parse_scan(p, &bytes_of(&[[1.0, 2.0, 3.0, 0.5]])[..15]).expect_err("15 bytes");
        assert!(short.to_string().contains("scan.bin") && short.to_string().contains("15 bytes"), "{short}");
        let nan = parse_scan(p, &bytes_of(&[[1.0, 2.0, 3.0, 0.5], [f32::NAN, 0.0, 0.0, 0.0]])).expect_err("NaN");
        assert!(nan.to_string().contains("point 1"), "{nan}");
    }

    #[test]
    fn a_folder_is_not_a_scan() {
        let e = read_scan(std::env::temp_dir()).expect_err("a folder");
        assert!(e.to_string().contains("not a regular file"), "{e}");
    }

    /// The shipped scan of drive 0005 frame 0 (cropped to the left image) projects almost entirely
    /// into the image, 5–80 m away, and its points ahead of the car lie near the road plane's height
    /// below the camera (KITTI's cameras are 1.65 m above the road).
    #[test]
    fn the_shipped_scan_projects_into_the_left_image() {
        let date = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/kitti_raw_0005/2011_09_26"));
        let drive = date.join("2011_09_26_drive_0005_sync");
        let calib = RawCalib::read(&date).expect("calibration");
        let scan = read_scan(scan_path(&drive, 0).expect("scan 0")).expect("readable");
        let seen = project_into_left(&scan, &calib, (1242.0, 375.0), 1.0);
        assert!(seen.len() * 10 >= scan.len() * 9, "{} of {}", seen.len(), scan.len());
        assert!(seen.iter().all(|p| p.z < 120.0));
        // rows below the horizon near the bottom of the image are road: about 1.65 m below the camera
        let road: Vec<f64> = seen.iter().filter(|p| p.v > 340.0).map(|p| (p.v - 172.854) * p.z / 721.5377).collect();
        assert!(road.len() > 100, "{}", road.len());
        let mut heights = road;
        heights.sort_by(f64::total_cmp);
        let median = heights[heights.len() / 2];
        assert!((median - 1.65).abs() < 0.15, "road {median} m below the camera");
        assert!(scan_path(&drive, 5).is_none(), "frames 0-4 only");
    }
}
