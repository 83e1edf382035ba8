//! Projection of an ellipsoid to a dual conic, and the conic's image bounds.
//!
//! `C* = P Q* Pᵀ` (3×3, symmetric). A line `l` is tangent to the image ellipse iff `lᵀ C* l = 0`.
//! When the ellipsoid lies wholly in front of the camera, `C*₂₂ < 0` and the conic is an ellipse with
//!
//! ```text
//! centre c = (C*₀₂, C*₁₂) / C*₂₂,      shape E = −C*[0..2, 0..2] / C*₂₂ + c cᵀ
//! ```
//!
//! so that its points satisfy `(x − c)ᵀ E⁻¹ (x − c) = 1`. The axis-aligned bounds are `c ± sqrt(diag E)`,
//! the same numbers as gtsam-quadrics' `(C₀₂ ± sqrt(C₀₂² − C₀₀C₂₂)) / C₂₂` but always sorted.
//!
//! The **clipped** bounds are the tight box of the part of the filled ellipse inside the image
//! `[0, W] × [0, H]`: the extremes of a convex intersection are attained at the ellipse's own extreme
//! points inside the image, at crossings of the ellipse with the image border, or at image corners
//! inside the ellipse, so the box is the bounds of those candidates.

use std::fmt;

use nalgebra::{Matrix2, Matrix3, Matrix3x4, Matrix4, Vector2, Vector3};

use crate::{
    bbox::{BBox, ImageSize},
    camera::Camera,
    ellipsoid::Ellipsoid,
    se3,
};

/// Why an ellipsoid has no usable image box in a camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProjectionError {
    /// An input has a NaN or infinite entry.
    NotFinite,
    /// The whole ellipsoid is behind the camera's principal plane.
    BehindCamera,
    /// The camera centre is inside (or on) the ellipsoid.
    CameraInside,
    /// The ellipsoid crosses the principal plane (partly behind the camera): its outline is a
    /// hyperbola or parabola, not an ellipse.
    NotEllipse,
    /// The ellipse does not overlap the image (clipped bounds only).
    OutsideImage,
}

impl fmt::Display for ProjectionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            ProjectionError::NotFinite => "ellipsoid or camera has NaN or infinite values",
            ProjectionError::BehindCamera => "ellipsoid is behind the camera",
            ProjectionError::CameraInside => "camera is inside the ellipsoid",
            ProjectionError::NotEllipse => {
                "ellipsoid crosses the camera's principal plane; its outline is not an ellipse"
            }
            ProjectionError::OutsideImage => "projected ellipse does not overlap the image",
        };
        f.write_str(s)
    }
}

impl std::error::Error for ProjectionError {}

/// A dual conic `C*` (3×3 symmetric, any scale).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct DualConic(pub Matrix3<f64>);

/// Where the ellipsoid lies relative to the camera; see [`classify`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Visibility {
    /// Wholly in front of the principal plane: projects to an ellipse.
    InFront,
    /// Wholly behind the principal plane.
    Behind,
    /// Crosses the principal plane, camera outside.
    Straddles,
    /// Camera centre inside or on the ellipsoid.
    CameraInside,
}

/// Where the (whole) ellipsoid lies relative to the camera. Unlike gtsam-quadrics' `isBehind`, which
/// tests only the centre, this uses the ellipsoid's extent `t_z ± sqrt(zᵀ S z)` along the optical axis.
pub fn classify(ellipsoid: &Ellipsoid, camera: &Camera) -> Visibility {
    if ellipsoid.contains_point(&camera.centre()) {
        return Visibility::CameraInside;
    }
    let z_axis = camera.world_from_camera.rotation * Vector3::z();
    let depth = z_axis.dot(&(ellipsoid.centre() - camera.centre()));
    let h = ellipsoid.half_extent(&z_axis);
    if depth - h > 0.0 {
        Visibility::InFront
    } else if depth + h < 0.0 {
        Visibility::Behind
    } else {
        Visibility::Straddles
    }
}

/// `C* = P Q* Pᵀ` with no checks (a wholly-behind ellipsoid also gives a finite "ghost" ellipse).
pub fn project_unchecked(q: &Matrix4<f64>, p: &Matrix3x4<f64>) -> DualConic {
    DualConic(p * q * p.transpose())
}

/// Project an ellipsoid into a camera, refusing ellipsoids that are behind, straddling, or around it.
pub fn project(ellipsoid: &Ellipsoid, camera: &Camera) -> Result<DualConic, ProjectionError> {
    if !ellipsoid.is_valid() || !camera.intrinsics.is_valid() {
        return Err(ProjectionError::NotFinite);
    }
    match classify(ellipsoid, camera) {
        Visibility::InFront => Ok(project_unchecked(&ellipsoid.dual_quadric(), &camera.projection_matrix())),
        Visibility::Behind => Err(ProjectionError::BehindCamera),
        Visibility::Straddles => Err(ProjectionError::NotEllipse),
        Visibility::CameraInside => Err(ProjectionError::CameraInside),
    }
}

/// An image ellipse as centre `c` and shape `E`: points `x` with `(x − c)ᵀ E⁻¹ (x − c) = 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipse2 {
    /// Centre, pixels.
    pub centre: Vector2<f64>,
    /// Symmetric positive-definite shape matrix, pixels².
    pub shape: Matrix2<f64>,
}

impl Ellipse2 {
    /// The dual conic of this ellipse, scaled so that `C*₂₂ = −1`.
    pub fn dual_conic(&self) -> DualConic {
        let c = self.centre;
        let s = self.shape - c * c.transpose();
        DualConic(Matrix3::new(s[(0, 0)], s[(0, 1)], -c.x, s[(1, 0)], s[(1, 1)], -c.y, -c.x, -c.y, -1.0))
    }

    /// The axis-aligned ellipse inscribed in a box (centre at the box centre, semi-axes half the
    /// width and height).
    pub fn inscribed_in(b: &BBox) -> Self {
        let [cx, cy] = b.centre();
        let (a, h) = (0.5 * b.width(), 0.5 * b.height());
        Self { centre: Vector2::new(cx, cy), shape: Matrix2::new(a * a, 0.0, 0.0, h * h) }
    }

    /// Axis-aligned bounds `c ± sqrt(diag E)`.
    pub fn bounds(&self) -> BBox {
        let hx = self.shape[(0, 0)].sqrt();
        let hy = self.shape[(1, 1)].sqrt();
        BBox::new(self.centre.x - hx, self.centre.y - hy, self.centre.x + hx, self.centre.y + hy)
    }

    /// Value of `(x − c)ᵀ E⁻¹ (x − c) − 1` (negative inside).
    fn level(&self, f: &Matrix2<f64>, x: &Vector2<f64>) -> f64 {
        let d = x - self.centre;
        (d.transpose() * f * d)[(0, 0)] - 1.0
    }
}

impl DualConic {
    /// The conic scaled so that its (2,2) entry is +1 (the oracle's `dual_conic_C_normalized`).
    pub fn normalized(&self) -> Matrix3<f64> {
        self.0 / self.0[(2, 2)]
    }

    /// True when the conic is a real, non-degenerate ellipse: `C*₂₂ · det(C*) > 0` (the point conic
    /// `adj(C*)` then has a positive-definite 2×2 block up to sign) and `C*₂₂ ≠ 0`.
    pub fn is_ellipse(&self) -> bool {
        let c = &self.0;
        let scale = c.amax();
        if !(scale.is_finite() && scale > 0.0) {
            return false;
        }
        let n = c / scale;
        let det = n.determinant();
        n[(2, 2)] * det > 0.0 && self.ellipse().is_some()
    }

    /// Centre and shape of the ellipse, or `None` when `C*` is not a real ellipse.
    pub fn ellipse(&self) -> Option<Ellipse2> {
        let c = &self.0;
        let c22 = c[(2, 2)];
        if c22 == 0.0 || !c22.is_finite() {
            return None;
        }
        let centre = Vector2::new(c[(0, 2)] / c22, c[(1, 2)] / c22);
        let top = Matrix2::new(c[(0, 0)], c[(0, 1)], c[(1, 0)], c[(1, 1)]);
        let mut shape = -top / c22 + centre * centre.transpose();
        shape = 0.5 * (shape + shape.transpose());
        let det = shape.determinant();
        (shape[(0, 0)] > 0.0 && det > 0.0 && det.is_finite()).then_some(Ellipse2 { centre, shape })
    }

    /// Axis-aligned bounds of the (unclipped) ellipse; the box may exceed the image.
    pub fn bounds(&self) -> Result<BBox, ProjectionError> {
        self.ellipse().map(|e| e.bounds()).ok_or(ProjectionError::NotEllipse)
    }

    /// Exact bounds of the part of the filled ellipse inside the image `[0, W] × [0, H]`.
    pub fn clipped_bounds(&self, image: &ImageSize) -> Result<BBox, ProjectionError> {
        let e = self.ellipse().ok_or(ProjectionError::NotEllipse)?;
        clip(&e, image).map(|c| c.bbox).ok_or(ProjectionError::OutsideImage)
    }
}

/// What kind of point defines one side of a clipped box; needed for its derivative.
#[derive(Debug, Clone, Copy, PartialEq)]
enum CandidateKind {
    /// Ellipse extreme point along x (`sign` ±1): `c + sign E e_x / sqrt(E₀₀)`.
    ExtremeX(f64),
    /// Ellipse extreme point along y.
    ExtremeY(f64),
    /// Crossing of the ellipse with the vertical border `x = const`.
    OnVertical,
    /// Crossing with the horizontal border `y = const`.
    OnHorizontal,
    /// Image corner (fixed).
    Corner,
}

#[derive(Debug, Clone, Copy)]
struct Candidate {
    p: Vector2<f64>,
    kind: CandidateKind,
}

/// The clipped box and the candidate that defines each side `[xmin, ymin, xmax, ymax]`.
#[derive(Debug, Clone, Copy)]
struct Clip {
    bbox: BBox,
    sides: [Candidate; 4],
}

const CLIP_TOL: f64 = 1e-9;

fn clip(e: &Ellipse2, image: &ImageSize) -> Option<Clip> {
    let (w, h) = (image.width, image.height);
    let inside_rect =
        |p: &Vector2<f64>| p.x >= -CLIP_TOL && p.x <= w + CLIP_TOL && p.y >= -CLIP_TOL && p.y <= h + CLIP_TOL;
    let f = e.shape.try_inverse()?;
    let mut cands: Vec<Candidate> = Vec::with_capacity(16);
    let sx = e.shape.column(0) / e.shape[(0, 0)].sqrt();
    let sy = e.shape.column(1) / e.shape[(1, 1)].sqrt();
    for sign in [-1.0, 1.0] {
        let px = e.centre + sign * sx;
        if inside_rect(&px) {
            cands.push(Candidate { p: px, kind: CandidateKind::ExtremeX(sign) });
        }
        let py = e.centre + sign * sy;
        if inside_rect(&py) {
            cands.push(Candidate { p: py, kind: CandidateKind::ExtremeY(sign) });
        }
    }
    // Crossings with the vertical borders x = 0, x = w.
    for x0 in [0.0, w] {
        let dx = x0 - e.centre.x;
        // F11 dy² + 2 F01 dx dy + (F00 dx² − 1) = 0
        for dy in quadratic_roots(f[(1, 1)], 2.0 * f[(0, 1)] * dx, f[(0, 0)] * dx * dx - 1.0) {
            let p = Vector2::new(x0, e.centre.y + dy);
            if inside_rect(&p) {
                cands.push(Candidate { p, kind: CandidateKind::OnVertical });
            }
        }
    }
    for y0 in [0.0, h] {
        let dy = y0 - e.centre.y;
        for dx in quadratic_roots(f[(0, 0)], 2.0 * f[(0, 1)] * dy, f[(1, 1)] * dy * dy - 1.0) {
            let p = Vector2::new(e.centre.x + dx, y0);
            if inside_rect(&p) {
                cands.push(Candidate { p, kind: CandidateKind::OnHorizontal });
            }
        }
    }
    for (x, y) in [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)] {
        let p = Vector2::new(x, y);
        if e.level(&f, &p) <= 0.0 {
            cands.push(Candidate { p, kind: CandidateKind::Corner });
        }
    }
    let first = *cands.first()?;
    let mut sides = [first; 4];
    for c in &cands[1..] {
        if c.p.x < sides[0].p.x {
            sides[0] = *c;
        }
        if c.p.y < sides[1].p.y {
            sides[1] = *c;
        }
        if c.p.x > sides[2].p.x {
            sides[2] = *c;
        }
        if c.p.y > sides[3].p.y {
            sides[3] = *c;
        }
    }
    let clamp_x = |v: f64| v.clamp(0.0, w);
    let clamp_y = |v: f64| v.clamp(0.0, h);
    let bbox = BBox::new(clamp_x(sides[0].p.x), clamp_y(sides[1].p.y), clamp_x(sides[2].p.x), clamp_y(sides[3].p.y));
    // A single tangent point or a corner touching the rim has no area: treat as outside.
    (bbox.xmax > bbox.xmin && bbox.ymax > bbox.ymin).then_some(Clip { bbox, sides })
}

/// Real roots of `a t² + b t + c = 0` (`a > 0` for an ellipse), numerically stable form.
fn quadratic_roots(a: f64, b: f64, c: f64) -> Vec<f64> {
    if a == 0.0 {
        return Vec::new();
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return Vec::new();
    }
    let s = disc.sqrt();
    let q = -0.5 * (b + b.signum() * s);
    if q == 0.0 {
        return vec![0.0];
    }
    vec![q / a, c / q]
}

/// First-order change of an [`Ellipse2`] for a change `dc` of its dual conic.
fn ellipse_derivative(c: &Matrix3<f64>, e: &Ellipse2, dc: &Matrix3<f64>) -> (Vector2<f64>, Matrix2<f64>) {
    let c22 = c[(2, 2)];
    let d22 = dc[(2, 2)];
    let dcent = Vector2::new(
        dc[(0, 2)] / c22 - c[(0, 2)] * d22 / (c22 * c22),
        dc[(1, 2)] / c22 - c[(1, 2)] * d22 / (c22 * c22),
    );
    let top = Matrix2::new(c[(0, 0)], c[(0, 1)], c[(1, 0)], c[(1, 1)]);
    let dtop = Matrix2::new(dc[(0, 0)], dc[(0, 1)], dc[(1, 0)], dc[(1, 1)]);
    let mut dshape =
        -dtop / c22 + top * d22 / (c22 * c22) + dcent * e.centre.transpose() + e.centre * dcent.transpose();
    dshape = 0.5 * (dshape + dshape.transpose());
    (dcent, dshape)
}

/// Derivative of a clip candidate point for a change `(dc, dE)` of the ellipse.
fn candidate_derivative(e: &Ellipse2, cand: &Candidate, dcent: &Vector2<f64>, dshape: &Matrix2<f64>) -> Vector2<f64> {
    let s = &e.shape;
    match cand.kind {
        CandidateKind::ExtremeX(sign) | CandidateKind::ExtremeY(sign) => {
            let i = if matches!(cand.kind, CandidateKind::ExtremeX(_)) { 0 } else { 1 };
            let sii = s[(i, i)];
            let col = s.column(i).into_owned();
            let dcol = dshape.column(i).into_owned();
            dcent + sign * (dcol / sii.sqrt() - col * dshape[(i, i)] / (2.0 * sii * sii.sqrt()))
        }
        CandidateKind::OnVertical | CandidateKind::OnHorizontal => {
            // g(p; θ) = (p − c)ᵀ F (p − c) − 1 = 0 with one coordinate of p fixed.
            let Some(f) = s.try_inverse() else { return Vector2::zeros() };
            let d = cand.p - e.centre;
            let fd = f * d;
            let df = -f * dshape * f;
            let dg_dtheta = -2.0 * fd.dot(dcent) + (d.transpose() * df * d)[(0, 0)];
            let grad = 2.0 * fd;
            if matches!(cand.kind, CandidateKind::OnVertical) {
                if grad.y == 0.0 {
                    return Vector2::zeros();
                }
                Vector2::new(0.0, -dg_dtheta / grad.y)
            } else {
                if grad.x == 0.0 {
                    return Vector2::zeros();
                }
                Vector2::new(-dg_dtheta / grad.x, 0.0)
            }
        }
        CandidateKind::Corner => Vector2::zeros(),
    }
}

/// How predicted boxes are computed from a projected ellipse.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum BoundsModel {
    /// The full axis-aligned bounds of the ellipse, even beyond the image (gtsam-quadrics "STANDARD").
    Full,
    /// The exact bounds of the part of the ellipse inside an image of this size: right for objects
    /// truncated by the image border.
    Clipped(ImageSize),
}

impl BoundsModel {
    /// The predicted box of a dual conic under this model.
    pub fn bounds(&self, conic: &DualConic) -> Result<BBox, ProjectionError> {
        match self {
            BoundsModel::Full => conic.bounds(),
            BoundsModel::Clipped(img) => conic.clipped_bounds(img),
        }
    }
}

/// Derivatives of `C* = P Q* Pᵀ` with respect to the camera pose tangent (6, right perturbation of
/// world-from-camera, `[ω, v]`) and the ellipsoid tangent (9, see [`Ellipsoid::retract`]).
pub fn conic_derivatives(
    ellipsoid: &Ellipsoid,
    camera: &Camera,
) -> (Matrix3<f64>, [Matrix3<f64>; 6], [Matrix3<f64>; 9]) {
    let k = camera.intrinsics.matrix();
    let t_cw = camera.camera_from_world().to_homogeneous();
    let p = camera.projection_matrix();
    let q = ellipsoid.dual_quadric();
    let c = p * q * p.transpose();
    let qpt = q * p.transpose();
    let k34 = k * Matrix3x4::identity();
    let d_cam = std::array::from_fn(|i| {
        // T_wc Exp(ξ) ⇒ T_cw ← Exp(−ξ) T_cw, so dP = −K [I|0] G_i T_cw.
        let dp = -(k34 * se3::generator(i) * t_cw);
        let a = dp * qpt;
        a + a.transpose()
    });
    let z = ellipsoid.world_from_quadric.to_homogeneous();
    let a2 = ellipsoid.semi_axes.component_mul(&ellipsoid.semi_axes);
    let d = Matrix4::from_diagonal(&nalgebra::Vector4::new(a2.x, a2.y, a2.z, -1.0));
    let pz = p * z;
    let d_quad = std::array::from_fn(|i| {
        let inner = if i < 6 {
            let g = se3::generator(i);
            let gd = g * d;
            gd + gd.transpose()
        } else {
            let j = i - 6;
            let mut m = Matrix4::zeros();
            m[(j, j)] = 2.0 * ellipsoid.semi_axes[j];
            m
        };
        pz * inner * pz.transpose()
    });
    (c, d_cam, d_quad)
}

/// A predicted box with its Jacobians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxPrediction {
    /// The predicted box.
    pub bbox: BBox,
    /// `∂[xmin, ymin, xmax, ymax] / ∂ξ_camera` (4×6, `[ω, v]`, right perturbation of world-from-camera).
    pub d_camera: nalgebra::SMatrix<f64, 4, 6>,
    /// `∂[xmin, ymin, xmax, ymax] / ∂ξ_quadric` (4×9, `[ω, v, δa]`, see [`Ellipsoid::retract`]).
    pub d_quadric: nalgebra::SMatrix<f64, 4, 9>,
}

/// Predicted box of an ellipsoid in a camera under a bounds model, with analytic Jacobians.
///
/// Sides of a clipped box that sit on the image border or at a corner have zero derivative.
pub fn predict_box(
    ellipsoid: &Ellipsoid,
    camera: &Camera,
    model: &BoundsModel,
) -> Result<BoxPrediction, ProjectionError> {
    let conic = project(ellipsoid, camera)?;
    let e = conic.ellipse().ok_or(ProjectionError::NotEllipse)?;
    let (c, d_cam, d_quad) = conic_derivatives(ellipsoid, camera);
    let sides: [Candidate; 4] = match model {
        BoundsModel::Full => [
            Candidate { p: e.centre - e.shape.column(0) / e.shape[(0, 0)].sqrt(), kind: CandidateKind::ExtremeX(-1.0) },
            Candidate { p: e.centre - e.shape.column(1) / e.shape[(1, 1)].sqrt(), kind: CandidateKind::ExtremeY(-1.0) },
            Candidate { p: e.centre + e.shape.column(0) / e.shape[(0, 0)].sqrt(), kind: CandidateKind::ExtremeX(1.0) },
            Candidate { p: e.centre + e.shape.column(1) / e.shape[(1, 1)].sqrt(), kind: CandidateKind::ExtremeY(1.0) },
        ],
        BoundsModel::Clipped(img) => clip(&e, img).ok_or(ProjectionError::OutsideImage)?.sides,
    };
    let bbox = match model {
        BoundsModel::Full => e.bounds(),
        BoundsModel::Clipped(img) => BBox::new(
            sides[0].p.x.clamp(0.0, img.width),
            sides[1].p.y.clamp(0.0, img.height),
            sides[2].p.x.clamp(0.0, img.width),
            sides[3].p.y.clamp(0.0, img.height),
        ),
    };
    let column = |dc: &Matrix3<f64>| {
        let (dcent, dshape) = ellipse_derivative(&c, &e, dc);
        let mut out = nalgebra::Vector4::zeros();
        for (k, side) in sides.iter().enumerate() {
            let dp = candidate_derivative(&e, side, &dcent, &dshape);
            out[k] = if k % 2 == 0 { dp.x } else { dp.y };
        }
        out
    };
    let mut d_camera = nalgebra::SMatrix::<f64, 4, 6>::zeros();
    for (i, dc) in d_cam.iter().enumerate() {
        d_camera.set_column(i, &column(dc));
    }
    let mut d_quadric = nalgebra::SMatrix::<f64, 4, 9>::zeros();
    for (i, dc) in d_quad.iter().enumerate() {
        d_quadric.set_column(i, &column(dc));
    }
    Ok(BoxPrediction { bbox, d_camera, d_quadric })
}

/// A box-measurement residual with its Jacobians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxResidual {
    /// `predicted − measured`, `[xmin, ymin, xmax, ymax]`, pixels.
    pub error: nalgebra::Vector4<f64>,
    /// `∂error / ∂ξ_camera` (4×6), as in [`BoxPrediction::d_camera`].
    pub d_camera: nalgebra::SMatrix<f64, 4, 6>,
    /// `∂error / ∂ξ_quadric` (4×9), as in [`BoxPrediction::d_quadric`].
    pub d_quadric: nalgebra::SMatrix<f64, 4, 9>,
}

/// Box-measurement error `predicted − measured` with the Jacobians of [`predict_box`] (the measured
/// box is a constant). This is the residual of the box factor in object optimisation.
pub fn box_error(
    ellipsoid: &Ellipsoid,
    camera: &Camera,
    measured: &BBox,
    model: &BoundsModel,
) -> Result<BoxResidual, ProjectionError> {
    let p = predict_box(ellipsoid, camera, model)?;
    Ok(BoxResidual { error: p.bbox.to_vector() - measured.to_vector(), d_camera: p.d_camera, d_quadric: p.d_quadric })
}

/// Intersection over union of an ellipsoid's projected (clipped) box with a box; 0 when the ellipsoid
/// does not project into the image.
pub fn projected_iou(ellipsoid: &Ellipsoid, camera: &Camera, image: &ImageSize, bbox: &BBox) -> f64 {
    project(ellipsoid, camera).and_then(|c| c.clipped_bounds(image)).map(|b| b.iou(bbox)).unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Intrinsics;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    fn scene() -> (Ellipsoid, Camera) {
        let e = Ellipsoid::new(
            Isometry3::from_parts(Translation3::new(2.0, 0.5, 15.0), UnitQuaternion::from_euler_angles(0.1, 0.6, -0.2)),
            nalgebra::Vector3::new(2.0, 0.8, 0.9),
        );
        let cam = Camera::new(Intrinsics::new(721.5, 721.5, 609.6, 172.9), Isometry3::identity());
        (e, cam)
    }

    #[test]
    fn ellipse_round_trip() {
        let el = Ellipse2 { centre: Vector2::new(10.0, 20.0), shape: Matrix2::new(9.0, 2.0, 2.0, 4.0) };
        let back = el.dual_conic().ellipse().expect("ellipse");
        assert!((back.centre - el.centre).norm() < 1e-12);
        assert!((back.shape - el.shape).norm() < 1e-12);
    }

    #[test]
    fn inside_image_clip_equals_bounds() {
        let (e, cam) = scene();
        let c = project(&e, &cam).expect("visible");
        let img = ImageSize::new(1242.0, 375.0);
        let b = c.bounds().expect("ellipse");
        let cb = c.clipped_bounds(&img).expect("inside");
        assert!((b.to_vector() - cb.to_vector()).norm() < 1e-9);
    }

    #[test]
    fn clip_by_dense_sampling() {
        let (mut e, cam) = scene();
        e.world_from_quadric.translation.vector.x = 12.0; // partly out on the right
        let c = project(&e, &cam).expect("visible");
        let img = ImageSize::new(1242.0, 375.0);
        let cb = c.clipped_bounds(&img).expect("overlaps");
        assert!(c.bounds().expect("ellipse").xmax > img.width);
        // Dense sampling of the filled ellipse.
        let el = c.ellipse().expect("ellipse");
        let l = el.shape.cholesky().expect("pd").l();
        let mut bb = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for i in 0..400 {
            for j in 0..=100 {
                let th = i as f64 / 400.0 * std::f64::consts::TAU;
                let r = j as f64 / 100.0;
                let p = el.centre + l * Vector2::new(r * th.cos(), r * th.sin());
                if p.x >= 0.0 && p.x <= img.width && p.y >= 0.0 && p.y <= img.height {
                    bb = [bb[0].min(p.x), bb[1].min(p.y), bb[2].max(p.x), bb[3].max(p.y)];
                }
            }
        }
        for (k, (sampled, exact)) in bb.iter().zip(cb.to_array()).enumerate() {
            assert!((sampled - exact).abs() < 1.0, "side {k}: sampled {sampled} exact {exact}");
        }
    }

    #[test]
    fn classification() {
        let (e, cam) = scene();
        assert_eq!(classify(&e, &cam), Visibility::InFront);
        let mut behind = e;
        behind.world_from_quadric.translation.vector.z = -15.0;
        assert_eq!(classify(&behind, &cam), Visibility::Behind);
        assert_eq!(project(&behind, &cam), Err(ProjectionError::BehindCamera));
        let mut straddle = e;
        straddle.world_from_quadric.translation.vector = nalgebra::Vector3::new(5.0, 0.0, 0.5);
        assert_eq!(project(&straddle, &cam), Err(ProjectionError::NotEllipse));
        let mut around = e;
        around.world_from_quadric.translation.vector = nalgebra::Vector3::new(0.1, 0.0, 0.2);
        assert_eq!(project(&around, &cam), Err(ProjectionError::CameraInside));
    }
}
