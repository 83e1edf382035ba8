//! DQP ("Tri+Yaw", Tian et al. 2022 §III) and "Tri" (translation decoupled only).
//!
//! Both first triangulate the box centres for the centre `t` (see [`triangulate_box_centres`]) and
//! express everything in a reference frame `r` (default: the first view's camera; y down). With the
//! centre known, write `Q*_r = λ [[S − t tᵀ, −t], [−tᵀ, −1]]` where `S = R diag(a²) Rᵀ`. For a plane
//! `π = (n, d)` (in frame r, scaled so `|n| = 1`):
//!
//! ```text
//! πᵀ Q* π = Σ n_i n_j q_ij  +  q₄₄ (d² + 2 d n·t + Σ_{known i≠j} 2 n_i n_j t_i t_j)
//! ```
//!
//! * **Tri** keeps the six entries `q_ij` of the 3×3 block as unknowns: 7 unknowns `(q_ij, q₄₄)`.
//! * **DQP** assumes the ellipsoid only yaws about the reference y axis,
//!   `R = R_y(θ) = [[cos θ, 0, sin θ], [0, 1, 0], [−sin θ, 0, cos θ]]`, so `S₁₂ = S₂₃ = 0` and
//!   `q₁₂ = q₄₄ t_x t_y`, `q₂₃ = q₄₄ t_y t_z` move into the last column: 5 unknowns
//!   `(q₁₁, q₁₃, q₂₂, q₃₃, q₄₄)` (Tian et al. eq. 5–6).
//!
//! The homogeneous system is solved by SVD; then `S = q₃ₓ₃ / (−q₄₄) + t tᵀ`. For DQP the axes and yaw
//! come from the 2×2 x–z block `[[S₁₁, S₁₃], [S₁₃, S₃₃]] = R₂(θ) diag(a_x², a_z²) R₂(θ)ᵀ` by its
//! eigen-decomposition: the eigenvector `(cos θ, −sin θ)` nearest the reference x axis gives `θ ∈ (−45°, 45°]`
//! and `a_x`, the other one `a_z`; `a_y = sqrt(S₂₂)`. This replaces the paper's eq. 7, which is wrong
//! except at θ = 45° (see [`printed_eq7`]), and uses `q₃₃` where eq. 8 prints `q₂₃`.

use nalgebra::{DMatrix, Isometry3, Matrix2, Matrix3, SymmetricEigen, Vector3, Vector4};

use super::{
    check_result,
    linalg::{null_vector, unit_normal},
    triangulate::{triangulate_box_centres, TriangulationConfig},
    validate_views, BoxView, Degeneracy, InitError, Initializer,
};
use crate::{
    ellipsoid::{ConstrainError, Ellipsoid},
    se3,
};

/// Which frame the yaw-only assumption refers to.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Reference {
    /// The camera frame of the first view (the paper's choice; right for a level camera).
    #[default]
    FirstCamera,
    /// A given world-from-reference pose whose y axis points down along gravity.
    Frame(Isometry3<f64>),
}

impl Reference {
    fn world_from_reference(&self, views: &[BoxView]) -> Isometry3<f64> {
        match self {
            Reference::FirstCamera => views[0].camera.world_from_camera,
            Reference::Frame(f) => *f,
        }
    }

    /// The reference frame, the centre in it, and all box planes in it (unit normals).
    fn setup(
        &self,
        views: &[BoxView],
        centre_world: &Vector3<f64>,
    ) -> (Isometry3<f64>, Vector3<f64>, Vec<Vector4<f64>>) {
        let world_from_ref = self.world_from_reference(views);
        let t = world_from_ref.inverse_transform_point(&nalgebra::Point3::from(*centre_world)).coords;
        let planes = reference_planes(views, &world_from_ref);
        (world_from_ref, t, planes)
    }
}

/// Smallest `|q₄₄|` (relative to the largest entry of the unit solution) accepted as a finite scale.
const MIN_SCALE: f64 = 1e-12;

/// Planes of all views in the reference frame, each with a unit normal.
fn reference_planes(views: &[BoxView], world_from_ref: &Isometry3<f64>) -> Vec<Vector4<f64>> {
    let t_wr = world_from_ref.to_homogeneous();
    views
        .iter()
        .flat_map(|v| v.bbox.planes(&v.camera.projection_matrix()))
        .map(|p| unit_normal(t_wr.transpose() * p))
        .collect()
}

/// DQP: the paper's Tri+Yaw initialiser.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Dqp {
    /// Frame whose y axis the object yaws about.
    pub reference: Reference,
    /// Triangulation settings for the centre.
    pub triangulation: TriangulationConfig,
    /// Rounds of box-centre correction after the first solve (0 = the paper's method as printed).
    /// See [`refine_centre`].
    pub centre_iterations: usize,
}

impl Dqp {
    /// DQP with the box-centre correction switched on (at most 20 Newton rounds).
    pub fn with_centre_correction() -> Self {
        Self { centre_iterations: 20, ..Self::default() }
    }

    /// Solve the yaw-only system for a known world centre; shared with refinement code that has a
    /// better centre than the triangulated box centres.
    pub fn solve_with_centre(&self, views: &[BoxView], centre_world: &Vector3<f64>) -> Result<Ellipsoid, InitError> {
        let e = self.solve(views, centre_world, false)?;
        check_result(e, views)
    }

    /// The linear solve. `lenient` replaces non-positive squared axes by their magnitude (floored), so
    /// that an intermediate estimate exists for the centre correction; the final answer is never lenient.
    fn solve(&self, views: &[BoxView], centre_world: &Vector3<f64>, lenient: bool) -> Result<Ellipsoid, InitError> {
        validate_views(views, self.min_views())?;
        let (world_from_ref, t, planes) = self.reference.setup(views, centre_world);
        let mut a = DMatrix::zeros(planes.len(), 5);
        for (r, p) in planes.iter().enumerate() {
            let (n, d) = (Vector3::new(p[0], p[1], p[2]), p[3]);
            a[(r, 0)] = n.x * n.x;
            a[(r, 1)] = 2.0 * n.x * n.z;
            a[(r, 2)] = n.y * n.y;
            a[(r, 3)] = n.z * n.z;
            a[(r, 4)] = d * d + 2.0 * d * n.dot(&t) + 2.0 * n.x * n.y * t.x * t.y + 2.0 * n.y * n.z * t.y * t.z;
        }
        let q = isolated_null_vector(&a)?;
        if q[4].abs() <= MIN_SCALE * q.amax() {
            return Err(InitError::Degenerate(Degeneracy::RankDeficient));
        }
        let lambda = -q[4];
        let s11 = q[0] / lambda + t.x * t.x;
        let s13 = q[1] / lambda + t.x * t.z;
        let s22 = q[2] / lambda + t.y * t.y;
        let s33 = q[3] / lambda + t.z * t.z;
        let (theta, mut ax2, mut az2) = yaw_and_axes(s11, s13, s33);
        let mut ay2 = s22;
        if lenient {
            let floor = 1e-6 * ax2.abs().max(ay2.abs()).max(az2.abs()).max(1e-12);
            (ax2, ay2, az2) = (ax2.abs().max(floor), ay2.abs().max(floor), az2.abs().max(floor));
        }
        let min = ax2.min(az2).min(ay2);
        if min <= 0.0 || !min.is_finite() {
            return Err(InitError::NotEllipsoid(ConstrainError::NotEllipsoid { min_eigenvalue: min }));
        }
        let r_rq = Matrix3::new(theta.cos(), 0.0, theta.sin(), 0.0, 1.0, 0.0, -theta.sin(), 0.0, theta.cos());
        let ref_from_q = se3::isometry_from_parts(&r_rq, &t);
        Ok(Ellipsoid::new(world_from_ref * ref_from_q, Vector3::new(ax2.sqrt(), ay2.sqrt(), az2.sqrt())))
    }
}

/// Largest ratio of the second-smallest to the largest singular value at which the null space counts
/// as more than one-dimensional (the views cannot separate two solutions).
const RANK_TOL: f64 = 1e-9;

/// The null vector of `a` if it is isolated; `Degenerate(RankDeficient)` otherwise.
pub(crate) fn isolated_null_vector(a: &DMatrix<f64>) -> Result<nalgebra::DVector<f64>, InitError> {
    let (q, second) = null_vector(a).ok_or(InitError::Degenerate(Degeneracy::RankDeficient))?;
    if second < RANK_TOL {
        return Err(InitError::Degenerate(Degeneracy::RankDeficient));
    }
    Ok(q)
}

/// Yaw `θ ∈ (−45°, 45°]` and squared axes `(a_x², a_z²)` from the x–z block of `S` by eigen-decomposition.
fn yaw_and_axes(s11: f64, s13: f64, s33: f64) -> (f64, f64, f64) {
    let eig = SymmetricEigen::new(Matrix2::new(s11, s13, s13, s33));
    // The column of R_y(θ) for the x axis is (cos θ, −sin θ) in (x, z).
    let (ix, iz) = if eig.eigenvectors[(0, 0)].abs() >= eig.eigenvectors[(0, 1)].abs() { (0, 1) } else { (1, 0) };
    let mut v = eig.eigenvectors.column(ix).into_owned();
    if v.x < 0.0 {
        v = -v;
    }
    let theta = (-v.y).atan2(v.x);
    (theta, eig.eigenvalues[ix], eig.eigenvalues[iz])
}

/// Tian et al.'s eq. 7 exactly as printed, from `Q₁ = S₁₁, Q₂ = S₂₂, Q₃ = S₁₃, Q₈ = S₃₃`:
/// returns `(θ_y, a_x, a_y, a_z)` with `θ_y = atan(2Q₃/(Q₈ − Q₁))/2`, `a_x = sqrt(|Q₁ − 2Q₃ + Q₈|/2)`,
/// `a_y = sqrt(Q₂)`, `a_z = sqrt(|Q₁ + 2Q₃ + Q₈|/2)`.
///
/// Kept only to show, in tests and docs, that it is wrong: since `Q₁ + Q₈ = a_x² + a_z²` and
/// `2Q₃ = −(a_x² − a_z²) sin 2θ`, the printed `a_x² = (a_x² + a_z² + (a_x² − a_z²) sin 2θ)/2` equals
/// `a_x²` only when `sin 2θ = 1`. [`Dqp`] uses the eigen-decomposition instead.
pub fn printed_eq7(q1: f64, q2: f64, q3: f64, q8: f64) -> (f64, f64, f64, f64) {
    let theta = (2.0 * q3 / (q8 - q1)).atan() / 2.0;
    let ax = ((q1 - 2.0 * q3 + q8).abs() / 2.0).sqrt();
    let ay = q2.sqrt();
    let az = ((q1 + 2.0 * q3 + q8).abs() / 2.0).sqrt();
    (theta, ax, ay, az)
}

impl Initializer for Dqp {
    fn name(&self) -> &'static str {
        if self.centre_iterations > 0 {
            "Tri+Yaw+cc"
        } else {
            "Tri+Yaw"
        }
    }

    fn min_views(&self) -> usize {
        2
    }

    fn initialize(&self, views: &[BoxView]) -> Result<Ellipsoid, InitError> {
        let centre = refine_centre(views, self.centre_iterations, &self.triangulation, |c| self.solve(views, c, true))?;
        self.solve_with_centre(views, &centre)
    }
}

/// Box-centre correction: a box's centre is the centre of the projected *ellipse*, which is not the
/// projection of the ellipsoid's centre (they differ by a few pixels for a car at 15 m, which moves the
/// triangulated centre by decimetres and, through the weakly observed depth axis, the axes by up to a
/// metre).
///
/// Let `F(c)` be: solve for an (intermediate, possibly repaired) ellipsoid `e` with centre `c`, shift
/// each box centre by `π(t_e) − centre(bounds(π(e)))`, and triangulate the shifted centres. With exact
/// boxes the true centre is a fixed point `F(c) = c`. Plain iteration converges only linearly (factor
/// ~0.9 per round on an 18° arc), so each round takes a Newton step on `G(c) = F(c) − c` with a
/// forward-difference Jacobian, falling back to the plain step `c ← F(c)` when the Newton step does not
/// reduce `|G|`. Views in which `e` does not project keep their box centre. Stops when `|G|` is below
/// 1e-10 of the centre's distance, or after `iterations` rounds. Returns the centre for the final solve.
pub fn refine_centre(
    views: &[BoxView],
    iterations: usize,
    triangulation: &TriangulationConfig,
    solve: impl Fn(&Vector3<f64>) -> Result<Ellipsoid, InitError>,
) -> Result<Vector3<f64>, InitError> {
    let start = triangulate_box_centres(views, triangulation)?;
    let f = |c: &Vector3<f64>| -> Result<Vector3<f64>, InitError> {
        let e = solve(c)?;
        let shifted: Vec<BoxView> = views
            .iter()
            .map(|v| {
                let offset = crate::conic::project(&e, &v.camera).ok().and_then(|conic| {
                    let b = conic.bounds().ok()?;
                    let p = v.camera.project_point(&nalgebra::Point3::from(e.centre()))?;
                    let [bx, by] = b.centre();
                    Some((p.x - bx, p.y - by))
                });
                let (dx, dy) = offset.unwrap_or((0.0, 0.0));
                let b = v.bbox;
                BoxView::new(v.camera, crate::BBox::new(b.xmin + dx, b.ymin + dy, b.xmax + dx, b.ymax + dy))
            })
            .collect();
        triangulate_box_centres(&shifted, triangulation)
    };
    let mut c = start;
    let Ok(mut fc) = f(&c) else { return Ok(start) };
    for _ in 0..iterations {
        let g = fc - c;
        let tol = 1e-10 * c.norm().max(1.0);
        if g.norm() <= tol {
            break;
        }
        let h = 1e-6 * c.norm().max(1.0);
        let mut jac = Matrix3::zeros();
        let mut jac_ok = true;
        for k in 0..3 {
            let mut cp = c;
            cp[k] += h;
            match f(&cp) {
                Ok(fp) => jac.set_column(k, &(((fp - cp) - g) / h)),
                Err(_) => jac_ok = false,
            }
        }
        let newton = if jac_ok { jac.try_inverse().map(|ji| c - ji * g) } else { None };
        let accepted = newton.and_then(|cn| {
            let fn_ = f(&cn).ok()?;
            ((fn_ - cn).norm() < g.norm()).then_some((cn, fn_))
        });
        match accepted {
            Some((cn, fn_)) => (c, fc) = (cn, fn_),
            None => {
                let next = fc;
                let Ok(fnext) = f(&next) else { break };
                (c, fc) = (next, fnext);
            }
        }
    }
    Ok(c)
}

/// Tri: triangulated centre, then the full 3×3 block of `Q*` (general rotation) by SVD.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Tri {
    /// Frame in which the linear system is written (conditioning only; the result does not depend on
    /// it for exact data).
    pub reference: Reference,
    /// Triangulation settings for the centre.
    pub triangulation: TriangulationConfig,
    /// Rounds of box-centre correction after the first solve (0 = as printed). See [`refine_centre`].
    pub centre_iterations: usize,
}

impl Tri {
    /// Tri with the box-centre correction switched on (at most 20 Newton rounds).
    pub fn with_centre_correction() -> Self {
        Self { centre_iterations: 20, ..Self::default() }
    }

    /// Solve for rotation and axes with a known world centre.
    pub fn solve_with_centre(&self, views: &[BoxView], centre_world: &Vector3<f64>) -> Result<Ellipsoid, InitError> {
        let e = self.solve(views, centre_world, false)?;
        check_result(e, views)
    }

    fn solve(&self, views: &[BoxView], centre_world: &Vector3<f64>, lenient: bool) -> Result<Ellipsoid, InitError> {
        validate_views(views, self.min_views())?;
        let (world_from_ref, t, planes) = self.reference.setup(views, centre_world);
        let mut a = DMatrix::zeros(planes.len(), 7);
        for (r, p) in planes.iter().enumerate() {
            let (n, d) = (Vector3::new(p[0], p[1], p[2]), p[3]);
            let row = [
                n.x * n.x,
                2.0 * n.x * n.y,
                2.0 * n.x * n.z,
                n.y * n.y,
                2.0 * n.y * n.z,
                n.z * n.z,
                d * d + 2.0 * d * n.dot(&t),
            ];
            for (c, v) in row.iter().enumerate() {
                a[(r, c)] = *v;
            }
        }
        let q = isolated_null_vector(&a)?;
        if q[6].abs() <= MIN_SCALE * q.amax() {
            return Err(InitError::Degenerate(Degeneracy::RankDeficient));
        }
        let lambda = -q[6];
        let block = Matrix3::new(q[0], q[1], q[2], q[1], q[3], q[4], q[2], q[4], q[5]) / lambda;
        let mut s = block + t * t.transpose();
        if lenient {
            let eig = SymmetricEigen::new(0.5 * (s + s.transpose()));
            let floor = 1e-6 * eig.eigenvalues.amax().max(1e-12);
            let fixed = eig.eigenvalues.map(|l| l.abs().max(floor));
            s = eig.eigenvectors * Matrix3::from_diagonal(&fixed) * eig.eigenvectors.transpose();
        }
        let local = Ellipsoid::from_centre_and_shape(t, &s)?;
        Ok(Ellipsoid::new(world_from_ref * local.world_from_quadric, local.semi_axes))
    }
}

impl Initializer for Tri {
    fn name(&self) -> &'static str {
        if self.centre_iterations > 0 {
            "Tri+cc"
        } else {
            "Tri"
        }
    }

    fn min_views(&self) -> usize {
        2
    }

    fn initialize(&self, views: &[BoxView]) -> Result<Ellipsoid, InitError> {
        let centre = refine_centre(views, self.centre_iterations, &self.triangulation, |c| self.solve(views, c, true))?;
        self.solve_with_centre(views, &centre)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaw_and_axes_recovers_truth() {
        for theta in [-0.7f64, -0.3, 0.0, 0.05, 0.3, 0.7] {
            let (ax2, az2) = (4.0, 0.81);
            let (c, s) = (theta.cos(), theta.sin());
            let s11 = ax2 * c * c + az2 * s * s;
            let s33 = ax2 * s * s + az2 * c * c;
            let s13 = c * s * (az2 - ax2);
            let (th, a, b) = yaw_and_axes(s11, s13, s33);
            // within (−45°, 45°] the recovery is exact
            if theta.abs() <= std::f64::consts::FRAC_PI_4 {
                assert!((th - theta).abs() < 1e-12, "{th} vs {theta}");
                assert!((a - ax2).abs() < 1e-12 && (b - az2).abs() < 1e-12);
            } else {
                // outside, the same ellipsoid is described with swapped axes and θ ∓ 90°
                assert!((a - az2).abs() < 1e-12 && (b - ax2).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn printed_eq7_is_wrong_off_45_degrees() {
        let (ax2, az2, theta) = (4.0f64, 0.81f64, 0.05f64);
        let (c, s) = (theta.cos(), theta.sin());
        let s11 = ax2 * c * c + az2 * s * s;
        let s33 = ax2 * s * s + az2 * c * c;
        let s13 = c * s * (az2 - ax2);
        let (_, ax, _, az) = printed_eq7(s11, 1.0, s13, s33);
        // printed: a_x² = (a_x² + a_z² + (a_x² − a_z²) sin 2θ) / 2, far from a_x² = 4 at θ ≈ 3°
        assert!((ax * ax - ax2).abs() > 1.0);
        assert!((az * az - az2).abs() > 1.0);
        let (_, a, b) = yaw_and_axes(s11, s13, s33);
        assert!((a - ax2).abs() < 1e-12 && (b - az2).abs() < 1e-12);
    }
}
