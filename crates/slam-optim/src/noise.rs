//! Noise models: whitening `W` with `‖W r‖² = rᵀ Σ⁻¹ r`.

use nalgebra::{DMatrix, DVector};

/// How a factor's residual is whitened before the robust kernel.
#[derive(Debug, Clone, PartialEq)]
pub enum NoiseModel {
    /// No whitening (σ = 1).
    Unit,
    /// Same σ for every component.
    Isotropic(f64),
    /// One σ per component.
    Diagonal(Vec<f64>),
    /// A full square-root information matrix `W` (upper triangular, `Wᵀ W = Σ⁻¹`).
    SqrtInformation(DMatrix<f64>),
}

impl NoiseModel {
    /// A noise model from a full information matrix `Ω = Σ⁻¹` (symmetric positive definite);
    /// `None` when `Ω` is not positive definite.
    pub fn from_information(omega: &DMatrix<f64>) -> Option<Self> {
        let l = omega.clone().cholesky()?.l();
        Some(NoiseModel::SqrtInformation(l.transpose()))
    }

    /// Whiten a residual in place.
    pub fn whiten(&self, r: &mut DVector<f64>) {
        match self {
            NoiseModel::Unit => {}
            NoiseModel::Isotropic(s) => *r /= *s,
            NoiseModel::Diagonal(s) => {
                for (x, s) in r.iter_mut().zip(s) {
                    *x /= s;
                }
            }
            NoiseModel::SqrtInformation(w) => *r = w * &*r,
        }
    }

    /// Whiten a Jacobian block (rows = residual components) in place.
    pub fn whiten_jacobian(&self, j: &mut DMatrix<f64>) {
        match self {
            NoiseModel::Unit => {}
            NoiseModel::Isotropic(s) => *j /= *s,
            NoiseModel::Diagonal(s) => {
                for (mut row, s) in j.row_iter_mut().zip(s) {
                    row /= *s;
                }
            }
            NoiseModel::SqrtInformation(w) => *j = w * &*j,
        }
    }

    /// [`Self::whiten`] on a plain slice (the same arithmetic).
    pub fn whiten_slice(&self, r: &mut [f64]) {
        match self {
            NoiseModel::Unit => {}
            NoiseModel::Isotropic(s) => r.iter_mut().for_each(|x| *x /= *s),
            NoiseModel::Diagonal(s) => {
                for (x, s) in r.iter_mut().zip(s) {
                    *x /= s;
                }
            }
            NoiseModel::SqrtInformation(w) => {
                let v = w * DVector::from_column_slice(r);
                r.copy_from_slice(v.as_slice());
            }
        }
    }

    /// [`Self::whiten_jacobian`] on a column-major block of `rows` rows held in a slice.
    pub fn whiten_jacobian_slice(&self, j: &mut [f64], rows: usize) {
        match self {
            NoiseModel::Unit => {}
            NoiseModel::Isotropic(s) => j.iter_mut().for_each(|x| *x /= *s),
            NoiseModel::Diagonal(s) => {
                for col in j.chunks_exact_mut(rows.max(1)) {
                    for (x, s) in col.iter_mut().zip(s) {
                        *x /= s;
                    }
                }
            }
            NoiseModel::SqrtInformation(w) => {
                let cols = j.len().checked_div(rows).unwrap_or(0);
                let m = w * DMatrix::from_column_slice(rows, cols, j);
                j.copy_from_slice(m.as_slice());
            }
        }
    }

    /// True when the model fits a residual of dimension `dim` and has positive finite σs.
    pub fn fits(&self, dim: usize) -> bool {
        match self {
            NoiseModel::Unit => true,
            NoiseModel::Isotropic(s) => s.is_finite() && *s > 0.0,
            NoiseModel::Diagonal(s) => s.len() == dim && s.iter().all(|x| x.is_finite() && *x > 0.0),
            NoiseModel::SqrtInformation(w) => w.nrows() == dim && w.ncols() == dim && w.iter().all(|x| x.is_finite()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whitening_gives_mahalanobis() {
        let omega = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 3.0]);
        let n = NoiseModel::from_information(&omega).expect("pd");
        let mut r = DVector::from_column_slice(&[0.7, -1.3]);
        let m = (r.transpose() * &omega * &r)[(0, 0)];
        n.whiten(&mut r);
        assert!((r.norm_squared() - m).abs() < 1e-12);
        let mut r = DVector::from_column_slice(&[2.0, 3.0]);
        NoiseModel::Diagonal(vec![2.0, 0.5]).whiten(&mut r);
        assert_eq!(r.as_slice(), &[1.0, 6.0]);
    }

    #[test]
    fn slice_whitening_matches_the_matrix_whitening() {
        let omega = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 3.0]);
        let models = [
            NoiseModel::Unit,
            NoiseModel::Isotropic(0.3),
            NoiseModel::Diagonal(vec![2.0, 0.5]),
            NoiseModel::from_information(&omega).expect("pd"),
        ];
        for n in &models {
            let mut r = DVector::from_column_slice(&[0.7, -1.3]);
            let mut rs = r.as_slice().to_vec();
            n.whiten(&mut r);
            n.whiten_slice(&mut rs);
            assert_eq!(r.as_slice(), &rs[..], "{n:?}");
            let mut j = DMatrix::from_fn(2, 3, |i, k| (i * 3 + k) as f64 - 2.5);
            let mut js = j.as_slice().to_vec();
            n.whiten_jacobian(&mut j);
            n.whiten_jacobian_slice(&mut js, 2);
            assert_eq!(j.as_slice(), &js[..], "{n:?}");
        }
    }
}
