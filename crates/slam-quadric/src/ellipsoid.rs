//! Ellipsoids as constrained dual quadrics.
//!
//! An ellipsoid is a pose `Z = T_wq` (world from quadric frame) and semi-axes `a = (a1, a2, a3)` along
//! the quadric-frame x, y, z axes. Its dual quadric is
//!
//! ```text
//! Q* = Z · diag(a1², a2², a3², −1) · Zᵀ  =  [ R D Rᵀ − t tᵀ   −t ]
//!                                           [      −tᵀ         −1 ]
//! ```
//!
//! (not normalised: `Q*₃₃ = −1`). A plane `π` is tangent to the ellipsoid iff `πᵀ Q* π = 0`.
//!
//! The 9-dof tangent space is `[ω (3), v (3), δa (3)]`: a right SE(3) perturbation of the pose
//! (`Z · Exp([ω, v])`, full SE(3) exponential) followed by an additive change of the semi-axes.

use std::fmt;

use nalgebra::{Isometry3, Matrix3, Matrix4, SymmetricEigen, Vector3, Vector4, Vector6};

use crate::se3;

/// A 9-vector tangent `[ω, v, δa]` of an ellipsoid.
pub type Tangent9 = nalgebra::SVector<f64, 9>;

/// An ellipsoid: pose + semi-axes.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Ellipsoid {
    /// Pose of the ellipsoid: maps quadric-frame points to world points (`T_wq`).
    pub world_from_quadric: Isometry3<f64>,
    /// Semi-axis lengths (metres) along the quadric-frame x, y, z axes; all positive.
    pub semi_axes: Vector3<f64>,
}

/// Why a symmetric 4×4 matrix is not the dual quadric of a real ellipsoid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ConstrainError {
    /// The matrix has a NaN or infinite entry.
    NotFinite,
    /// `M₃₃ ≈ 0`: the plane at infinity is (nearly) tangent; the quadric has no finite centre.
    NoCentre,
    /// The shape matrix `R D Rᵀ` is not positive definite (smallest eigenvalue given).
    NotEllipsoid {
        /// Smallest eigenvalue of the recovered shape matrix (squared semi-axis, m²).
        min_eigenvalue: f64,
    },
}

impl fmt::Display for ConstrainError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConstrainError::NotFinite => write!(f, "quadric matrix has NaN or infinite entries"),
            ConstrainError::NoCentre => write!(f, "quadric has no finite centre (Q*[3][3] ~ 0)"),
            ConstrainError::NotEllipsoid { min_eigenvalue } => {
                write!(f, "quadric is not an ellipsoid (shape eigenvalue {min_eigenvalue:.3e} <= 0)")
            }
        }
    }
}

impl std::error::Error for ConstrainError {}

/// Relative threshold below which `|M₃₃|` counts as zero in [`Ellipsoid::from_dual_quadric`].
const NO_CENTRE_REL: f64 = 1e-14;

impl Ellipsoid {
    /// An ellipsoid from its world-from-quadric pose and semi-axes.
    pub const fn new(world_from_quadric: Isometry3<f64>, semi_axes: Vector3<f64>) -> Self {
        Self { world_from_quadric, semi_axes }
    }

    /// Centre in world coordinates.
    pub fn centre(&self) -> Vector3<f64> {
        self.world_from_quadric.translation.vector
    }

    /// Rotation matrix `R_wq`; its columns are the ellipsoid axes in the world frame.
    pub fn rotation(&self) -> Matrix3<f64> {
        self.world_from_quadric.rotation.to_rotation_matrix().into_inner()
    }

    /// The shape matrix `S = R diag(a²) Rᵀ` (world frame): points `x` of the solid satisfy
    /// `(x − t)ᵀ S⁻¹ (x − t) ≤ 1`.
    pub fn shape_matrix(&self) -> Matrix3<f64> {
        let r = self.rotation();
        r * Matrix3::from_diagonal(&self.semi_axes.component_mul(&self.semi_axes)) * r.transpose()
    }

    /// The (unnormalised) dual quadric `Q* = Z diag(a², −1) Zᵀ`, with `Q*₃₃ = −1`.
    pub fn dual_quadric(&self) -> Matrix4<f64> {
        let t = self.centre();
        let s = self.shape_matrix() - t * t.transpose();
        let mut q = Matrix4::zeros();
        q.fixed_view_mut::<3, 3>(0, 0).copy_from(&s);
        q.fixed_view_mut::<3, 1>(0, 3).copy_from(&(-t));
        q.fixed_view_mut::<1, 3>(3, 0).copy_from(&(-t.transpose()));
        q[(3, 3)] = -1.0;
        q
    }

    /// `Q* / Q*₃₃` (so the (3,3) entry is +1): the scale-free form used to compare quadrics.
    pub fn dual_quadric_normalized(&self) -> Matrix4<f64> {
        -self.dual_quadric()
    }

    /// The "constrain" operation: the ellipsoid closest in form to a general symmetric 4×4 `m` (any
    /// scale and sign), following QuadricSLAM's `ConstrainedDualQuadric::constrain`:
    ///
    /// 1. normalise `m̂ = m / m₃₃`; the centre is `t = m̂[0..3, 3]` (the dual form's last column);
    /// 2. the point quadric `P = m̂⁻¹ / (m̂⁻¹)₃₃ = [[A, b], [bᵀ, c]]` gives rotation and shape: the
    ///    eigenvectors of `A` are the axes and `a_i² = −det(P) / det(A) / λ_i(A)` (Schur complement).
    ///
    /// Unlike the library, which takes `|·|` of those ratios and so turns a hyperboloid into an
    /// ellipsoid, a negative or zero ratio is an error. The result is in canonical form
    /// (see [`Ellipsoid::canonical`]). For an exact dual quadric both steps are exact.
    pub fn from_dual_quadric(m: &Matrix4<f64>) -> Result<Self, ConstrainError> {
        Self::constrain(m, false).map(|(e, _)| e)
    }

    /// Like [`Ellipsoid::from_dual_quadric`], but, as gtsam-quadrics does, takes the magnitude of each
    /// squared-axis ratio, so an indefinite input (a hyperboloid) still yields an ellipsoid. The flag
    /// says whether any sign had to be flipped. Useful for intermediate estimates; a final estimate
    /// should come from the strict form.
    pub fn from_dual_quadric_lenient(m: &Matrix4<f64>) -> Result<(Self, bool), ConstrainError> {
        Self::constrain(m, true)
    }

    fn constrain(m: &Matrix4<f64>, lenient: bool) -> Result<(Self, bool), ConstrainError> {
        if !m.iter().all(|v| v.is_finite()) {
            return Err(ConstrainError::NotFinite);
        }
        let scale = m.amax();
        if scale == 0.0 || m[(3, 3)].abs() <= NO_CENTRE_REL * scale {
            return Err(ConstrainError::NoCentre);
        }
        let q = m / m[(3, 3)];
        let q = 0.5 * (q + q.transpose());
        let t = Vector3::new(q[(0, 3)], q[(1, 3)], q[(2, 3)]);
        let Some(point) = q.try_inverse() else {
            return Err(ConstrainError::NotEllipsoid { min_eigenvalue: 0.0 });
        };
        if point[(3, 3)] == 0.0 || !point[(3, 3)].is_finite() {
            return Err(ConstrainError::NoCentre);
        }
        let point = point / point[(3, 3)];
        let a: Matrix3<f64> = point.fixed_view::<3, 3>(0, 0).into_owned();
        let a = 0.5 * (a + a.transpose());
        let det_a = a.determinant();
        if det_a == 0.0 || !det_a.is_finite() {
            return Err(ConstrainError::NotEllipsoid { min_eigenvalue: 0.0 });
        }
        let k = -point.determinant() / det_a;
        let eig = SymmetricEigen::new(a);
        let mut sq = eig.eigenvalues.map(|l| k / l);
        let min = sq.min();
        let flipped = min <= 0.0;
        if lenient {
            sq = sq.map(f64::abs);
        }
        let min = sq.min();
        if !(min > 0.0 && min.is_finite() && sq.max().is_finite()) {
            return Err(ConstrainError::NotEllipsoid { min_eigenvalue: min });
        }
        Ok((Self::canonical_from_parts(&eig.eigenvectors, &sq.map(f64::sqrt), &t), flipped))
    }

    /// The ellipsoid with centre `t` and shape matrix `s = R diag(a²) Rᵀ` (symmetrised), in canonical form.
    pub fn from_centre_and_shape(t: Vector3<f64>, s: &Matrix3<f64>) -> Result<Self, ConstrainError> {
        if !s.iter().chain(t.iter()).all(|v| v.is_finite()) {
            return Err(ConstrainError::NotFinite);
        }
        let s = 0.5 * (s + s.transpose());
        let eig = SymmetricEigen::new(s);
        let min = eig.eigenvalues.min();
        if min <= 0.0 {
            return Err(ConstrainError::NotEllipsoid { min_eigenvalue: min });
        }
        let axes = eig.eigenvalues.map(f64::sqrt);
        Ok(Self::canonical_from_parts(&eig.eigenvectors, &axes, &t))
    }

    /// Canonical form: semi-axes sorted in decreasing order, rotation a proper rotation whose first two
    /// columns have their largest-magnitude component positive. An ellipsoid is unchanged by permuting
    /// its axes together with the columns of `R` or by flipping an axis; the canonical form picks one
    /// representative, so equal ellipsoids compare equal.
    pub fn canonical(&self) -> Self {
        Self::canonical_from_parts(&self.rotation(), &self.semi_axes, &self.centre())
    }

    fn canonical_from_parts(r: &Matrix3<f64>, axes: &Vector3<f64>, t: &Vector3<f64>) -> Self {
        let mut order = [0usize, 1, 2];
        order.sort_by(|&i, &j| axes[j].total_cmp(&axes[i]).then(i.cmp(&j)));
        let mut cols = [Vector3::zeros(); 3];
        for (k, &i) in order.iter().enumerate() {
            let mut c: Vector3<f64> = r.column(i).into_owned();
            let imax = c.iamax();
            if c[imax] < 0.0 {
                c = -c;
            }
            cols[k] = c;
        }
        // Re-orthonormalise (Gram-Schmidt) and make the frame right-handed.
        let c0 = cols[0].normalize();
        let c1 = (cols[1] - c0 * c0.dot(&cols[1])).normalize();
        let c2 = c0.cross(&c1);
        let rot = Matrix3::from_columns(&[c0, c1, c2]);
        let sorted = Vector3::new(axes[order[0]], axes[order[1]], axes[order[2]]);
        Self::new(se3::isometry_from_parts(&rot, t), sorted)
    }

    /// Right retraction `[ω, v, δa] ↦ (Z · Exp([ω, v]), a + δa)`.
    pub fn retract(&self, delta: &Tangent9) -> Self {
        let xi = Vector6::new(delta[0], delta[1], delta[2], delta[3], delta[4], delta[5]);
        Self::new(
            se3::retract(&self.world_from_quadric, &xi),
            self.semi_axes + Vector3::new(delta[6], delta[7], delta[8]),
        )
    }

    /// Local coordinates of `other` about `self`: `[Log(Z⁻¹ Z_other), a_other − a]`, the inverse of
    /// [`Ellipsoid::retract`].
    pub fn local(&self, other: &Ellipsoid) -> Tangent9 {
        let xi = se3::local(&self.world_from_quadric, &other.world_from_quadric);
        let da = other.semi_axes - self.semi_axes;
        Tangent9::from_column_slice(&[xi[0], xi[1], xi[2], xi[3], xi[4], xi[5], da[0], da[1], da[2]])
    }

    /// True when the world point lies inside or on the ellipsoid.
    pub fn contains_point(&self, p: &Vector3<f64>) -> bool {
        let q = self.world_from_quadric.inverse_transform_vector(&(p - self.centre()));
        q.component_div(&self.semi_axes).norm_squared() <= 1.0
    }

    /// Half-width of the ellipsoid along a unit world direction `n`: `sqrt(nᵀ S n)`. The ellipsoid
    /// spans `n·t ± half_extent(n)` along `n`.
    pub fn half_extent(&self, n: &Vector3<f64>) -> f64 {
        (n.transpose() * self.shape_matrix() * n)[(0, 0)].max(0.0).sqrt()
    }

    /// Axis-aligned world bounds `([xmin, ymin, zmin], [xmax, ymax, zmax])`.
    pub fn aabb(&self) -> (Vector3<f64>, Vector3<f64>) {
        let s = self.shape_matrix();
        let h = Vector3::new(s[(0, 0)].sqrt(), s[(1, 1)].sqrt(), s[(2, 2)].sqrt());
        (self.centre() - h, self.centre() + h)
    }

    /// The 4-vector `πᵀ Q* π` for a plane: zero when tangent, negative when the plane misses the
    /// ellipsoid, positive when it cuts it.
    pub fn plane_tangency(&self, plane: &Vector4<f64>) -> f64 {
        (plane.transpose() * self.dual_quadric() * plane)[(0, 0)]
    }

    /// True when all entries are finite and the semi-axes are positive.
    pub fn is_valid(&self) -> bool {
        self.semi_axes.iter().all(|a| a.is_finite() && *a > 0.0)
            && self.world_from_quadric.translation.vector.iter().all(|v| v.is_finite())
            && self.world_from_quadric.rotation.coords.iter().all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn sample() -> Ellipsoid {
        Ellipsoid::new(
            Isometry3::from_parts(
                Translation3::new(3.0, -1.0, 12.0),
                UnitQuaternion::from_euler_angles(0.2, -0.4, 1.1),
            ),
            Vector3::new(2.1, 0.8, 0.9),
        )
    }

    #[test]
    fn constrain_round_trip_any_scale() {
        let e = sample();
        for s in [1.0, -3.5, 1e-4, 250.0] {
            let back = Ellipsoid::from_dual_quadric(&(e.dual_quadric() * s)).expect("ellipsoid");
            let d = (back.dual_quadric_normalized() - e.dual_quadric_normalized()).norm();
            assert!(d < 1e-9 * e.dual_quadric().norm(), "scale {s}: {d}");
            assert!(back.semi_axes[0] >= back.semi_axes[1] && back.semi_axes[1] >= back.semi_axes[2]);
        }
    }

    #[test]
    fn constrain_rejects_hyperboloid_and_nan() {
        let mut m = Matrix4::from_diagonal(&Vector4::new(1.0, 1.0, -1.0, -1.0));
        assert!(matches!(Ellipsoid::from_dual_quadric(&m), Err(ConstrainError::NotEllipsoid { .. })));
        m[(0, 0)] = f64::NAN;
        assert_eq!(Ellipsoid::from_dual_quadric(&m), Err(ConstrainError::NotFinite));
        let z = Matrix4::from_diagonal(&Vector4::new(1.0, 1.0, 1.0, 0.0));
        assert_eq!(Ellipsoid::from_dual_quadric(&z), Err(ConstrainError::NoCentre));
    }

    #[test]
    fn tangent_planes() {
        let e = Ellipsoid::new(Isometry3::translation(1.0, 2.0, 3.0), Vector3::new(2.0, 1.0, 0.5));
        // plane x = 1 + 2 is tangent: [1, 0, 0, -3]
        assert!(e.plane_tangency(&Vector4::new(1.0, 0.0, 0.0, -3.0)).abs() < 1e-12);
        assert!(e.plane_tangency(&Vector4::new(1.0, 0.0, 0.0, -1.0)) > 0.0);
        assert!(e.plane_tangency(&Vector4::new(1.0, 0.0, 0.0, -10.0)) < 0.0);
        assert!((e.half_extent(&Vector3::new(0.0, 0.0, 1.0)) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn retract_local_inverse() {
        let e = sample();
        let d = Tangent9::from_column_slice(&[0.1, -0.2, 0.05, 0.3, -0.1, 0.2, 0.1, -0.05, 0.02]);
        let f = e.retract(&d);
        assert!((e.local(&f) - d).norm() < 1e-12);
    }
}
