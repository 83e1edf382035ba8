//! The object terms of Tian et al. §V: box error, prior axis lengths, texture plane.

use nalgebra::{DMatrix, DVector, Vector3, Vector4};
use slam_quadric::{box_error, BBox, BoundsModel, Camera, ImageSize, Intrinsics};

use crate::{
    factor::{Factor, FactorError},
    values::{Key, Values},
};

/// Box error between the projected ellipsoid and a detected box: `predicted − detected` (4 pixels),
/// keys `[T_wc, ellipsoid]` (fix the pose key to optimise the object alone).
///
/// **Border policy.** A box touching the image border is probably truncated. The paper ignores such
/// detections; [`BoxFactor::usable`] is that test (the graph builder counts and logs what it skips).
/// With [`BoundsModel::Clipped`] a truncated box can instead be kept: the prediction is then the exact
/// image-clipped box of the ellipse, which is what the detector saw. When the ellipsoid does not project
/// (behind the camera, camera inside, outside the image) the factor returns
/// [`FactorError::Undefined`]; the solver rejects a trial step that causes it and refuses to start from
/// such a point.
#[derive(Debug, Clone)]
pub struct BoxFactor {
    keys: [Key; 2],
    k: Intrinsics,
    measured: BBox,
    model: BoundsModel,
}

impl BoxFactor {
    /// Detected box `measured` of ellipsoid `object` in the camera at `pose` with intrinsics `k`.
    pub fn new(pose: Key, object: Key, k: Intrinsics, measured: BBox, model: BoundsModel) -> Self {
        Self { keys: [pose, object], k, measured, model }
    }

    /// The paper's policy: use a box only when it is valid and at least `margin` pixels from every image
    /// border.
    pub fn usable(measured: &BBox, image: &ImageSize, margin: f64) -> bool {
        measured.validated().is_ok() && !measured.touches_border(image, margin)
    }
}

impl Factor for BoxFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        4
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let pose = values.require_pose(self.keys[0])?;
        let e = values.require_ellipsoid(self.keys[1])?;
        let cam = Camera::new(self.k, *pose);
        let r =
            box_error(e, &cam, &self.measured, &self.model).map_err(|err| FactorError::Undefined(err.to_string()))?;
        if let Some(jac) = jacobians {
            jac.clear();
            jac.push(DMatrix::from_column_slice(4, 6, r.d_camera.as_slice()));
            jac.push(DMatrix::from_column_slice(4, 9, r.d_quadric.as_slice()));
        }
        Ok(DVector::from_column_slice(r.error.as_slice()))
    }
}

/// Prior on an ellipsoid's semi-axes for its class: residual `a − a_prior` (3), in the ellipsoid's own
/// axis order (for cars: length, height, width along x, y, z).
#[derive(Debug, Clone)]
pub struct AxisPrior {
    keys: [Key; 1],
    prior: Vector3<f64>,
}

impl AxisPrior {
    /// `a ≈ prior`.
    pub fn new(object: Key, prior: Vector3<f64>) -> Self {
        Self { keys: [object], prior }
    }
}

impl Factor for AxisPrior {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        3
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let e = values.require_ellipsoid(self.keys[0])?;
        if let Some(jac) = jacobians {
            let mut j = DMatrix::zeros(3, 9);
            j.view_mut((0, 6), (3, 3)).fill_with_identity();
            jac.clear();
            jac.push(j);
        }
        Ok(DVector::from_column_slice((e.semi_axes - self.prior).as_slice()))
    }
}

/// Texture-plane error (after Ok et al. 2019, used by Tian et al. §V-C): a plane `nᵀx + d = 0` fitted to
/// the object's map points (the visible surface; `n` unit, pointing out of the object towards the
/// camera). The ellipsoid's tangent plane with the same normal on that side is `nᵀx = nᵀt + h(n)` with
/// `h(n) = sqrt(nᵀ S n)`; the residual is their signed distance `nᵀt + h(n) + d` (1, metres).
#[derive(Debug, Clone)]
pub struct TexturePlane {
    keys: [Key; 1],
    plane: Vector4<f64>,
}

impl TexturePlane {
    /// Plane `[n, d]` with `|n| = 1` (normalised here); `None` for a zero normal.
    pub fn new(object: Key, plane: Vector4<f64>) -> Option<Self> {
        let n = Vector3::new(plane[0], plane[1], plane[2]).norm();
        (n > 0.0 && n.is_finite()).then(|| Self { keys: [object], plane: plane / n })
    }
}

impl Factor for TexturePlane {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        1
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let e = values.require_ellipsoid(self.keys[0])?;
        let n = Vector3::new(self.plane[0], self.plane[1], self.plane[2]);
        let r = e.rotation();
        let m = r.transpose() * n;
        let a2 = e.semi_axes.component_mul(&e.semi_axes);
        let h = m.component_mul(&a2).dot(&m).sqrt();
        if h <= 0.0 || !h.is_finite() {
            return Err(FactorError::Undefined("degenerate ellipsoid".into()));
        }
        let res = n.dot(&e.centre()) + h + self.plane[3];
        if let Some(jac) = jacobians {
            let dm = a2.component_mul(&m); // D m
            let dh_dw = dm.cross(&m) / h;
            let dt_dv = r.transpose() * n; // d(nᵀt)/dv = nᵀ R
            let mut j = DMatrix::zeros(1, 9);
            for i in 0..3 {
                j[(0, i)] = dh_dw[i];
                j[(0, 3 + i)] = dt_dv[i];
                j[(0, 6 + i)] = e.semi_axes[i] * m[i] * m[i] / h;
            }
            jac.clear();
            jac.push(j);
        }
        Ok(DVector::from_element(1, res))
    }
}

/// Keeps one of an ellipsoid's axes along a direction: residual `d × (R e_k)` (3; its norm is the sine
/// of the angle between them), e.g. a car's height axis along gravity, the paper's yaw-only assumption
/// as a soft constraint. Without it, a straight drive cannot observe the object's tilt and the
/// optimisation drifts along that unobservable direction.
#[derive(Debug, Clone)]
pub struct AxisDirection {
    keys: [Key; 1],
    axis: usize,
    direction: Vector3<f64>,
}

impl AxisDirection {
    /// Axis `axis` (0, 1, 2 = own x, y, z) of `object` along `direction` (normalised; `None` for a zero
    /// direction or an axis index above 2).
    pub fn new(object: Key, axis: usize, direction: Vector3<f64>) -> Option<Self> {
        let n = direction.norm();
        (axis < 3 && n > 0.0 && n.is_finite()).then(|| Self { keys: [object], axis, direction: direction / n })
    }
}

impl Factor for AxisDirection {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        3
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let e = values.require_ellipsoid(self.keys[0])?;
        let r = e.rotation();
        let mut ek = Vector3::zeros();
        ek[self.axis] = 1.0;
        let a = r * ek;
        let res = self.direction.cross(&a);
        if let Some(jac) = jacobians {
            // R Exp(ω): d(R e_k) = −R [e_k]× ω
            let d = -crate::lie::hat(&self.direction) * r * crate::lie::hat(&ek);
            let mut j = DMatrix::zeros(3, 9);
            j.view_mut((0, 0), (3, 3)).copy_from(&d);
            jac.clear();
            jac.push(j);
        }
        Ok(DVector::from_column_slice(res.as_slice()))
    }
}
