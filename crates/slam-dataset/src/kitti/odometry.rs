//! KITTI odometry sequences: `sequences/NN/{calib.txt, times.txt, image_0/, image_1/, image_2/,
//! image_3/}` and optional ground truth `poses/NN.txt` beside `sequences/`.

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3x4};

use crate::{
    kitti::{
        calib::Calib,
        frames::{no_truth, nominal_times, nominal_times_note, pair_frames, read_frame_times, values_of_ids, IdRuns},
        poses::read_ground_truth_poses,
    },
    DatasetError,
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
    /// Frame id of each entry (the number in the image file names), increasing.
    pub ids: Vec<usize>,
    /// Frame time of each entry, seconds (line `id` of `times.txt`, else `0.1 · id`).
    pub times: Vec<f64>,
    /// Left grey image of each entry (for a frame whose left image is missing: the path it should have).
    pub left: Vec<PathBuf>,
    /// Right grey image of each entry (same rule).
    pub right: Vec<PathBuf>,
    /// Ground-truth camera-0-to-world pose of each entry (line `id` of `poses/NN.txt`), when that file
    /// exists and covers every frame.
    pub ground_truth: Option<Vec<Isometry3<f64>>>,
    /// Frame ids missing in both cameras between the first and the last frame (skipped, ids kept), as runs.
    pub gaps: IdRuns,
    /// Frame ids with one image missing (played as unreadable frames).
    pub one_camera: Vec<usize>,
    /// What was odd about the input and how it was handled (gaps, one-sided frames, files that are not
    /// frames, ground truth dropped), one sentence each; the caller logs them.
    pub warnings: Vec<String>,
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
        let pairs = pair_frames(&dir.join("image_0"), &dir.join("image_1"))?;
        let mut warnings = pairs.warnings;
        let times_path = dir.join("times.txt");
        let times = if times_path.exists() {
            let t = read_frame_times(&times_path)?;
            values_of_ids(&t, &pairs.ids, &times_path, "times", "the images")?
        } else {
            warnings.push(nominal_times_note(&times_path));
            nominal_times(&pairs.ids)
        };
        let gt_path = dir
            .parent()
            .and_then(|seqs| seqs.parent())
            .zip(dir.file_name())
            .map(|(root, name)| root.join("poses").join(format!("{}.txt", name.to_string_lossy())));
        let ground_truth = match gt_path {
            Some(p) if p.exists() => {
                match values_of_ids(&read_ground_truth_poses(&p)?, &pairs.ids, &p, "poses", "the images") {
                    Ok(g) => Some(g),
                    Err(e) => {
                        warnings.push(no_truth(e));
                        None
                    }
                }
            }
            Some(p) => {
                warnings.push(no_truth(format_args!("{} not found (no ATE/RPE)", p.display())));
                None
            }
            None => None,
        };
        Ok(Self {
            p0: calib.matrix3x4("P0")?,
            p1: calib.matrix3x4("P1")?,
            p_colour,
            tr,
            ids: pairs.ids,
            times,
            left: pairs.left,
            right: pairs.right,
            ground_truth,
            gaps: pairs.gaps,
            one_camera: pairs.one_camera,
            warnings,
            dir,
        })
    }

    /// Stereo baseline of the grey pair, metres (`−P1[0,3] / P1[0,0]`).
    pub fn baseline(&self) -> f64 {
        -self.p1[(0, 3)] / self.p1[(0, 0)]
    }
}
