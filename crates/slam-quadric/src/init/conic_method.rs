//! The Conic method of Rubino, Crocco and Del Bue ("3D Object Localisation from Multi-view Image
//! Detections", TPAMI 2018; arXiv 2017).
//!
//! Each detection is turned into an image ellipse (by default the axis-aligned ellipse inscribed in the
//! box) with dual conic `C_i`. The projection `C_i ∝ P_i Q* P_iᵀ` is linear in the 10 unique entries of
//! `Q*` up to an unknown scale `β_i` per view:
//!
//! ```text
//! G_i q − β_i c_i = 0,      G_i[(a,b),(j,k)] = P_aj P_bk + P_ak P_bj  (j ≠ k),   P_aj P_bj  (j = k)
//! ```
//!
//! six equations per view in `10 + n` unknowns, solved jointly by SVD. As in the paper, the data are
//! normalised first: each image by a similarity that moves the box centre to the origin and scales its
//! half-diagonal to 1; the world by a similarity that moves the triangulated box-centre point to the
//! origin and scales the mean camera distance to 1. The result is repaired into an ellipsoid with
//! [`Ellipsoid::from_dual_quadric`].
//!
//! With ellipses that are the exact projections of the ellipsoid, the solution is exact. An ellipse
//! inscribed in a box is only tangent to the box, not the true outline (which is generally rotated), so
//! from boxes alone the method carries a model error even without noise.

use nalgebra::{DMatrix, Matrix3, Matrix3x4, Matrix4};

use super::{
    check_result,
    dqp::isolated_null_vector,
    linalg::{sym4_from_vec, SYM3, SYM4},
    triangulate::{triangulate_box_centres, TriangulationConfig},
    validate_views, BoxView, Degeneracy, InitError, Initializer,
};
use crate::{
    conic::{DualConic, Ellipse2},
    ellipsoid::Ellipsoid,
};

/// The Conic initialiser ("Conic" in the tables).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Conic {
    /// Triangulation settings for the world normalisation point.
    pub triangulation: TriangulationConfig,
}

impl Conic {
    /// Estimate the ellipsoid from one image ellipse per view (e.g. fitted to instance masks). `views`
    /// supplies the cameras and boxes (the boxes are used only for normalisation and validation).
    pub fn initialize_from_ellipses(&self, views: &[BoxView], ellipses: &[Ellipse2]) -> Result<Ellipsoid, InitError> {
        validate_views(views, self.min_views())?;
        if ellipses.len() != views.len() {
            return Err(InitError::TooFewViews { got: ellipses.len(), need: views.len() });
        }
        let origin = triangulate_box_centres(views, &self.triangulation)?;
        let scale = views.iter().map(|v| (v.camera.centre() - origin).norm()).sum::<f64>() / views.len() as f64;
        if !(scale.is_finite() && scale > 0.0) {
            return Err(InitError::Degenerate(Degeneracy::SingleCentre));
        }
        // X_world = T_inv X_norm
        let mut t_inv = Matrix4::identity() * scale;
        t_inv[(3, 3)] = 1.0;
        t_inv.fixed_view_mut::<3, 1>(0, 3).copy_from(&origin);
        let n = views.len();
        let mut a = DMatrix::zeros(6 * n, 10 + n);
        for (i, (v, el)) in views.iter().zip(ellipses).enumerate() {
            let [cx, cy] = v.bbox.centre();
            let s = 0.5 * (v.bbox.width().powi(2) + v.bbox.height().powi(2)).sqrt();
            let h = Matrix3::new(1.0 / s, 0.0, -cx / s, 0.0, 1.0 / s, -cy / s, 0.0, 0.0, 1.0);
            let p: Matrix3x4<f64> = h * v.camera.projection_matrix() * t_inv;
            let c: Matrix3<f64> = h * el.dual_conic().0 * h.transpose();
            let c = c / c.norm();
            for (r, &(ra, rb)) in SYM3.iter().enumerate() {
                for (col, &(j, k)) in SYM4.iter().enumerate() {
                    a[(6 * i + r, col)] = if j == k {
                        p[(ra, j)] * p[(rb, j)]
                    } else {
                        p[(ra, j)] * p[(rb, k)] + p[(ra, k)] * p[(rb, j)]
                    };
                }
                a[(6 * i + r, 10 + i)] = -c[(ra, rb)];
            }
        }
        let x = isolated_null_vector(&a)?;
        let q_norm = sym4_from_vec(&x.as_slice()[..10]);
        let q = t_inv * q_norm * t_inv.transpose();
        let e = Ellipsoid::from_dual_quadric(&q)?;
        check_result(e, views)
    }

    /// Estimate the ellipsoid from exact dual conics (for example, the projections of a known
    /// ellipsoid); convenience over [`Conic::initialize_from_ellipses`].
    pub fn initialize_from_conics(&self, views: &[BoxView], conics: &[DualConic]) -> Result<Ellipsoid, InitError> {
        let ellipses: Option<Vec<Ellipse2>> = conics.iter().map(|c| c.ellipse()).collect();
        let ellipses = ellipses.ok_or(InitError::Degenerate(Degeneracy::RankDeficient))?;
        self.initialize_from_ellipses(views, &ellipses)
    }
}

impl Initializer for Conic {
    fn name(&self) -> &'static str {
        "Conic"
    }

    fn min_views(&self) -> usize {
        2
    }

    fn initialize(&self, views: &[BoxView]) -> Result<Ellipsoid, InitError> {
        let ellipses: Vec<Ellipse2> = views.iter().map(|v| Ellipse2::inscribed_in(&v.bbox)).collect();
        self.initialize_from_ellipses(views, &ellipses)
    }
}
