//! QuadricSLAM's SVD initialisation (Nicholson et al., RA-L 2019, §IV-B).
//!
//! Each box edge `l` back-projects to the plane `π = Pᵀ l`, tangent to the ellipsoid:
//! `πᵀ Q* π = 0`, one linear equation in the 10 unique entries of the symmetric `Q*`. With three or
//! more views (12+ planes) the stacked system is solved by SVD and the result is repaired into an
//! ellipsoid by [`Ellipsoid::from_dual_quadric`] (the "constrain" step). Each plane is scaled to a
//! unit normal first, which changes no exact solution and evens out the rows' weights.

use nalgebra::DMatrix;

use super::{
    check_result,
    dqp::isolated_null_vector,
    linalg::{plane_row, sym4_from_vec, unit_normal},
    validate_views, BoxView, InitError, Initializer,
};
use crate::ellipsoid::Ellipsoid;

/// The QuadricSLAM SVD initialiser ("Q-SLAM" in the tables).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct QSlamSvd;

impl Initializer for QSlamSvd {
    fn name(&self) -> &'static str {
        "Q-SLAM"
    }

    fn min_views(&self) -> usize {
        3
    }

    fn initialize(&self, views: &[BoxView]) -> Result<Ellipsoid, InitError> {
        validate_views(views, self.min_views())?;
        let mut a = DMatrix::zeros(4 * views.len(), 10);
        for (i, v) in views.iter().enumerate() {
            let p = v.camera.projection_matrix();
            for (k, plane) in v.bbox.planes(&p).into_iter().enumerate() {
                let row = plane_row(&unit_normal(plane));
                for (c, val) in row.iter().enumerate() {
                    a[(4 * i + k, c)] = *val;
                }
            }
        }
        let q = isolated_null_vector(&a)?;
        let e = Ellipsoid::from_dual_quadric(&sym4_from_vec(q.as_slice()))?;
        check_result(e, views)
    }
}
