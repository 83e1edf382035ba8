//! KITTI odometry sequences: `sequences/NN/{calib.txt, times.txt, image_0/, image_1/, image_2/,
//! image_3/}` and optional ground truth `poses/NN.txt` beside `sequences/`.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3x4};

use crate::{
    kitti::{calib::Calib, poses::read_kitti_poses},
    read_text, DatasetError,
};

/// A sequence on disk (images are listed, not decoded).
#[derive(Debug, Clone)]
pub struct OdometrySequence {
    /// The sequence folder (`…/sequences/NN`).
    pub dir: PathBuf,
    /// Grey left / right projection matrices `P0`, `P1` (required).
    pub p0: Matrix3x4<f64>,
    /// Right grey camera.
    pub p1: Matrix3x4<f64>,
    /// Colour cameras `P2`, `P3`, when the calibration has them.
    pub p_colour: Option<[Matrix3x4<f64>; 2]>,
    /// Velodyne-to-camera `Tr`, when present.
    pub tr: Option<Matrix3x4<f64>>,
    /// Frame times, seconds (from `times.txt`, else 0.1 s steps).
    pub times: Vec<f64>,
    /// Left and right grey images, sorted by name.
    pub left: Vec<PathBuf>,
    /// Right grey images.
    pub right: Vec<PathBuf>,
    /// Ground-truth camera-0-to-world poses, when `poses/NN.txt` exists.
    pub ground_truth: Option<Vec<Isometry3<f64>>>,
}

/// Frame times of a sequence without a time file: KITTI's nominal 10 Hz.
pub(crate) fn nominal_times(frames: usize) -> Vec<f64> {
    (0..frames).map(|i| 0.1 * i as f64).collect()
}

pub(crate) fn list_images(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    let rd = std::fs::read_dir(dir).map_err(|source| DatasetError::Io { path: dir.to_path_buf(), source })?;
    let mut v: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
        .collect();
    v.sort();
    Ok(v)
}

impl OdometrySequence {
    /// Open `sequences/NN` (the folder containing `calib.txt`).
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let dir = dir.as_ref().to_path_buf();
        let calib = Calib::read(dir.join("calib.txt"))?;
        let p_colour = if calib.has("P2") && calib.has("P3") {
            Some([calib.matrix3x4("P2")?, calib.matrix3x4("P3")?])
        } else {
            None
        };
        let tr = if calib.has("Tr") { Some(calib.matrix3x4("Tr")?) } else { None };
        let left = list_images(&dir.join("image_0"))?;
        let right = list_images(&dir.join("image_1"))?;
        if left.len() != right.len() {
            return Err(DatasetError::Invalid {
                path: dir.clone(),
                message: format!("{} left images but {} right images", left.len(), right.len()),
            });
        }
        let times_path = dir.join("times.txt");
        let times = if times_path.exists() {
            let text = read_text(&times_path)?;
            let mut t = Vec::new();
            for (i, l) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
                t.extend(crate::parse_numbers(&times_path, i + 1, &[l.trim()])?);
            }
            t
        } else {
            nominal_times(left.len())
        };
        let gt_path = dir
            .parent()
            .and_then(|seqs| seqs.parent())
            .zip(dir.file_name())
            .map(|(root, name)| root.join("poses").join(format!("{}.txt", name.to_string_lossy())));
        let ground_truth = match gt_path {
            Some(p) if p.exists() => Some(read_kitti_poses(&p)?),
            _ => None,
        };
        Ok(Self {
            p0: calib.matrix3x4("P0")?,
            p1: calib.matrix3x4("P1")?,
            p_colour,
            tr,
            times,
            left,
            right,
            ground_truth,
            dir,
        })
    }

    /// Stereo baseline of the grey pair, metres (`−P1[0,3] / P1[0,0]`).
    pub fn baseline(&self) -> f64 {
        -self.p1[(0, 3)] / self.p1[(0, 0)]
    }
}
