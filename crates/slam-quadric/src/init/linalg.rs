//! Small linear-algebra helpers shared by the initialisers.

use nalgebra::{DMatrix, DVector, Matrix4, Vector4};

/// The unit vector `x` minimising `‖A x‖` (right singular vector of the smallest singular value), and
/// the ratio of the second-smallest to the largest singular value (near 0 when the null space is more
/// than one-dimensional). Rows are zero-padded when `A` has fewer rows than columns.
pub(crate) fn null_vector(a: &DMatrix<f64>) -> Option<(DVector<f64>, f64)> {
    let (r, c) = a.shape();
    if c == 0 || !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let padded;
    let m = if r < c {
        padded = a.clone().resize_vertically(c, 0.0);
        &padded
    } else {
        a
    };
    let svd = m.clone().svd(false, true);
    let v_t = svd.v_t?;
    let s = &svd.singular_values;
    let mut idx: Vec<usize> = (0..s.len()).collect();
    idx.sort_by(|&i, &j| s[i].total_cmp(&s[j]));
    let imin = idx[0];
    let smax = s[idx[idx.len() - 1]];
    let ratio = if idx.len() > 1 && smax > 0.0 { s[idx[1]] / smax } else { 0.0 };
    let x = v_t.row(imin).transpose();
    x.iter().all(|v| v.is_finite()).then_some((x, ratio))
}

/// Row of the plane constraint `πᵀ Q π = 0` for the 10 unique entries of a symmetric 4×4 `Q`, ordered
/// `(00, 01, 02, 03, 11, 12, 13, 22, 23, 33)`; off-diagonal terms carry the factor 2.
pub(crate) fn plane_row(p: &Vector4<f64>) -> [f64; 10] {
    [
        p[0] * p[0],
        2.0 * p[0] * p[1],
        2.0 * p[0] * p[2],
        2.0 * p[0] * p[3],
        p[1] * p[1],
        2.0 * p[1] * p[2],
        2.0 * p[1] * p[3],
        p[2] * p[2],
        2.0 * p[2] * p[3],
        p[3] * p[3],
    ]
}

/// Symmetric 4×4 from its 10 unique entries in [`plane_row`] order.
pub(crate) fn sym4_from_vec(q: &[f64]) -> Matrix4<f64> {
    Matrix4::new(
        q[0], q[1], q[2], q[3], //
        q[1], q[4], q[5], q[6], //
        q[2], q[5], q[7], q[8], //
        q[3], q[6], q[8], q[9],
    )
}

/// Index pairs of the unique entries of a symmetric 4×4, in [`plane_row`] order.
pub(crate) const SYM4: [(usize, usize); 10] =
    [(0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3)];

/// Index pairs of the unique entries of a symmetric 3×3.
pub(crate) const SYM3: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Scale a plane so that its normal part `π[0..3]` has unit length (no-op for a zero normal).
pub(crate) fn unit_normal(p: Vector4<f64>) -> Vector4<f64> {
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    if n > 0.0 {
        p / n
    } else {
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_row_matches_quadratic_form() {
        let q = [1.0, 2.0, -0.5, 0.3, 4.0, 0.7, -1.1, 2.5, 0.9, -3.0];
        let m = sym4_from_vec(&q);
        let p = Vector4::new(0.3, -1.2, 0.8, 2.0);
        let lhs = (p.transpose() * m * p)[(0, 0)];
        let rhs: f64 = plane_row(&p).iter().zip(q.iter()).map(|(a, b)| a * b).sum();
        assert!((lhs - rhs).abs() < 1e-12);
    }

    #[test]
    fn null_vector_of_rank_deficient() {
        let a = DMatrix::from_row_slice(2, 3, &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        let (x, _) = null_vector(&a).expect("finite");
        assert!((x[2].abs() - 1.0).abs() < 1e-12);
        let nan = DMatrix::from_row_slice(1, 2, &[f64::NAN, 1.0]);
        assert!(null_vector(&nan).is_none());
    }
}
