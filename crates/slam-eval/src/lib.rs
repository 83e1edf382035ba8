//! Evaluation of a run's object map against KITTI tracking labels ([`score`]), with the labels'
//! geometry in the run's camera ([`labels`]); and the image-free object study on KITTI tracking
//! sequences, label boxes as detections ([`labelled`]); a trajectory file against ground truth
//! ([`trajectory`]) and the errors themselves, ATE, RPE and drift ([`trajectory_errors`]). Used by `slam-app run --labels`, `objects`, `eval` and `trajectory-eval`; kept out
//! of the app so that every front end scores the same way.

#![warn(missing_docs)]

pub mod assoc;
pub mod labelled;
pub mod labels;
pub mod recall;
pub mod score;
pub mod street;
pub mod study;
pub mod trajectory;
pub mod trajectory_errors;

use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;
use slam_core::geometry::Ellipsoid;

pub use labels::LabelGeometry;
pub use score::{
    association_score, score_run, AssociationScore, Census, Fate, FrameBoxes, RunScore, ScoreConfig, ScoredInput,
};

/// Errors of the evaluation.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A file could not be read or written.
    #[error("{0}: {1}")]
    Io(String, std::io::Error),
    /// Not a regular file, or larger than its reader takes ([`slam_core::files`]).
    #[error(transparent)]
    Read(#[from] slam_core::files::ReadError),
    /// A file could not be written (atomically, [`slam_core::files`]).
    #[error(transparent)]
    Write(#[from] slam_core::files::WriteError),
    /// A dataset file is malformed.
    #[error(transparent)]
    Dataset(#[from] slam_dataset::DatasetError),
    /// An output file could not be written.
    #[error(transparent)]
    Output(#[from] slam_dataset::output::OutputError),
    /// Something else is inconsistent (the message names the file).
    #[error("{0}")]
    Invalid(String),
}

#[derive(Deserialize)]
struct ObjectJson {
    id: u64,
    class: u16,
    center: [f64; 3],
    semi_axes: [f64; 3],
    rotation: [f64; 9],
    frames: Vec<usize>,
    dynamic: bool,
}

#[derive(Deserialize)]
struct ObjectMapJson {
    version: u32,
    objects: Vec<ObjectJson>,
}

/// Read an object map (`objects.json`, version 1, as `slam-app run` and `slam-app objects` write it)
/// as objects to score. Errors name the file; an object whose rotation is not a rotation or whose
/// semi-axes are not positive is an error naming its id.
pub fn read_object_map(path: &Path) -> Result<Vec<ScoredInput>, EvalError> {
    let text = slam_core::files::read_text(path, &slam_core::files::DOCUMENT)?;
    let map: ObjectMapJson =
        serde_json::from_str(&text).map_err(|e| EvalError::Invalid(format!("{}: {e}", path.display())))?;
    if map.version != 1 {
        return Err(EvalError::Invalid(format!("{}: object map version {} (expected 1)", path.display(), map.version)));
    }
    map.objects
        .into_iter()
        .map(|o| {
            let m = Matrix3::from_row_slice(&o.rotation);
            let orthonormal = (m.transpose() * m - Matrix3::identity()).norm() < 1e-6 && m.determinant() > 0.0;
            if !orthonormal || o.semi_axes.iter().any(|a| !(*a > 0.0 && a.is_finite())) {
                return Err(EvalError::Invalid(format!(
                    "{}: object {} has an invalid rotation or semi-axes",
                    path.display(),
                    o.id
                )));
            }
            let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
            Ok(ScoredInput {
                id: o.id,
                class: o.class,
                ellipsoid: Ellipsoid::new(
                    Isometry3::from_parts(Translation3::from(Vector3::from(o.center)), r),
                    Vector3::from(o.semi_axes),
                ),
                frames: o.frames,
                dynamic: o.dynamic,
            })
        })
        .collect()
}
