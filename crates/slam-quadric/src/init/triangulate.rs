//! Least-squares triangulation of the box centres (the translation step of DQP and Tri).
//!
//! Each view contributes the two DLT rows `(u P₃ − P₁) X = 0`, `(v P₃ − P₂) X = 0` for the box centre
//! `(u, v)` (Tian et al. eq. 2); the rows are scaled to unit length and the homogeneous point is the
//! right singular vector of the smallest singular value.

use nalgebra::{DMatrix, Vector3};

use super::{linalg::null_vector, validate_views, BoxView, Degeneracy, InitError};

/// Settings of [`triangulate_box_centres`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct TriangulationConfig {
    /// Smallest angle (radians) between any two rays through the box centres; below it the rays count
    /// as parallel and the depth as unobservable. Default 1e-4 rad (0.006°).
    pub min_parallax_rad: f64,
}

impl Default for TriangulationConfig {
    fn default() -> Self {
        Self { min_parallax_rad: 1e-4 }
    }
}

/// Triangulate the rays through the box centres of two or more views; the point must be in front of
/// every camera.
pub fn triangulate_box_centres(views: &[BoxView], config: &TriangulationConfig) -> Result<Vector3<f64>, InitError> {
    validate_views(views, 2)?;
    let dirs: Vec<Vector3<f64>> = views
        .iter()
        .map(|v| {
            let [u, w] = v.bbox.centre();
            v.camera.ray_direction(u, w)
        })
        .collect();
    let mut max_angle: f64 = 0.0;
    for i in 0..dirs.len() {
        for j in i + 1..dirs.len() {
            max_angle = max_angle.max(dirs[i].cross(&dirs[j]).norm().atan2(dirs[i].dot(&dirs[j])));
        }
    }
    if max_angle < config.min_parallax_rad {
        return Err(InitError::Degenerate(Degeneracy::ParallelRays));
    }
    let mut a = DMatrix::zeros(2 * views.len(), 4);
    for (i, v) in views.iter().enumerate() {
        let p = v.camera.projection_matrix();
        let [u, w] = v.bbox.centre();
        for (k, row) in [u * p.row(2) - p.row(0), w * p.row(2) - p.row(1)].iter().enumerate() {
            let n = row.norm();
            let row = if n > 0.0 { row / n } else { *row };
            for c in 0..4 {
                a[(2 * i + k, c)] = row[c];
            }
        }
    }
    let (x, _) = null_vector(&a).ok_or(InitError::Degenerate(Degeneracy::RankDeficient))?;
    if x[3].abs() < 1e-12 * x.amax() {
        return Err(InitError::Degenerate(Degeneracy::ParallelRays));
    }
    let point = Vector3::new(x[0] / x[3], x[1] / x[3], x[2] / x[3]);
    for (i, v) in views.iter().enumerate() {
        let pc = v.camera.camera_from_world() * nalgebra::Point3::from(point);
        if pc.z <= 0.0 {
            return Err(InitError::BehindCamera { view: i });
        }
    }
    Ok(point)
}
