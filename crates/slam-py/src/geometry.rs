//! Cameras, ellipsoids, their projection to dual conics and image boxes, one at a time or many in one
//! call.

use pyo3::prelude::*;
use slam_quadric::{
    self as q,
    nalgebra::{Isometry3, Matrix3, Vector3},
    BoundsModel,
};

use crate::convert::{
    batch, bbox, fixed, image_size, matrix_to_numpy, pose, pose_rows, projection_error, rigid, to_numpy, value_error,
    vector_to_numpy, with_batch, Array, ProjectionError,
};

/// A pinhole camera at a pose: calibration ``K`` and its world-from-camera pose.
///
/// Camera frame: x right, y down, z forward. ``P = K [I | 0] inv(pose)`` maps world points to pixels.
///
/// Args:
///     K: the 3x3 calibration matrix ``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`` (fx, fy > 0).
///     pose: 4x4 world-from-camera pose (a rigid transform); the identity when omitted.
///
/// Raises:
///     ValueError: K is not a calibration matrix, or pose not a rigid transform, or either holds NaN.
#[pyclass(frozen, module = "quadric_slam")]
#[derive(Clone, Copy)]
pub struct Camera {
    pub inner: q::Camera,
}

impl Camera {
    fn check_intrinsics(k: q::Intrinsics) -> PyResult<q::Intrinsics> {
        if !k.is_valid() {
            return Err(value_error(format!(
                "K: focal lengths must be positive and every entry finite, got fx {}, fy {}",
                k.fx, k.fy
            )));
        }
        Ok(k)
    }

    fn from_parts(k: q::Intrinsics, pose_obj: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let k = Self::check_intrinsics(k)?;
        let world_from_camera = match pose_obj {
            Some(p) => pose(&fixed(p, "pose", &[4, 4])?, "pose")?,
            None => Isometry3::identity(),
        };
        Ok(Self { inner: q::Camera::new(k, world_from_camera) })
    }
}

#[pymethods]
impl Camera {
    #[new]
    #[pyo3(signature = (K, pose=None))]
    #[allow(non_snake_case)]
    fn new(K: &Bound<'_, PyAny>, pose: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let k = fixed(K, "K", &[3, 3])?;
        if [k[3], k[6], k[7]].iter().any(|v| *v != 0.0) || k[8] != 1.0 {
            return Err(value_error(format!(
                "K: not a calibration matrix: its last row must be [0, 0, 1] and K[1][0] 0, got rows {:?}, {:?}",
                &k[3..6],
                &k[6..9]
            )));
        }
        Self::from_parts(q::Intrinsics { fx: k[0], fy: k[4], skew: k[1], cx: k[2], cy: k[5] }, pose)
    }

    /// A camera from its focal lengths and principal point (pixels), skew 0 unless given.
    #[staticmethod]
    #[pyo3(signature = (fx, fy, cx, cy, pose=None, skew=0.0))]
    fn from_intrinsics(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        pose: Option<&Bound<'_, PyAny>>,
        skew: f64,
    ) -> PyResult<Self> {
        Self::from_parts(q::Intrinsics { fx, fy, skew, cx, cy }, pose)
    }

    /// The 3x3 calibration matrix.
    #[getter(K)]
    fn k<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        matrix_to_numpy(py, &self.inner.intrinsics.matrix())
    }

    /// The 4x4 world-from-camera pose.
    #[getter]
    fn pose<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        to_numpy(py, &[4, 4], pose_rows(&self.inner.world_from_camera).to_vec())
    }

    /// The 3x4 projection matrix ``P = K [I | 0] inv(pose)``.
    #[getter]
    fn projection_matrix<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        matrix_to_numpy(py, &self.inner.projection_matrix())
    }

    /// The camera centre in world coordinates, shape (3,).
    #[getter]
    fn centre<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        vector_to_numpy(py, self.inner.centre().as_slice())
    }

    /// The pixel ``(u, v)`` of a world point, or None when the point is not in front of the camera.
    fn project_point<'py>(&self, py: Python<'py>, point: &Bound<'py, PyAny>) -> PyResult<Option<Array<'py>>> {
        let p = fixed(point, "point", &[3])?;
        match self.inner.project_point(&q::nalgebra::Point3::new(p[0], p[1], p[2])) {
            Some(uv) => Ok(Some(vector_to_numpy(py, uv.as_slice())?)),
            None => Ok(None),
        }
    }

    fn __repr__(&self) -> String {
        let k = &self.inner.intrinsics;
        let c = self.inner.centre();
        format!(
            "Camera(fx={}, fy={}, cx={}, cy={}, skew={}, centre=[{}, {}, {}])",
            k.fx, k.fy, k.cx, k.cy, k.skew, c.x, c.y, c.z
        )
    }
}

/// An ellipsoid: a world-from-quadric pose and three semi-axes along its own x, y, z axes.
///
/// Its dual quadric is ``Q* = Z diag(a1^2, a2^2, a3^2, -1) Z^T`` with ``Z`` the pose (not normalised:
/// ``Q*[3, 3] == -1``), as in gtsam-quadrics.
///
/// Args:
///     pose: 4x4 world-from-quadric pose (a rigid transform).
///     axes: the three semi-axes, metres, all positive.
///
/// Raises:
///     ValueError: pose not a rigid transform, an axis not positive, or NaN anywhere.
#[pyclass(frozen, module = "quadric_slam")]
#[derive(Clone, Copy)]
pub struct Ellipsoid {
    pub inner: q::Ellipsoid,
}

/// Semi-axes that make an ellipsoid: finite and positive.
fn axes(values: &[f64], what: &str) -> PyResult<Vector3<f64>> {
    positive_axes(values).map_err(|reason| value_error(format!("{what}: {reason}")))
}

/// [`axes`] with the reason of a refusal as text.
fn positive_axes(values: &[f64]) -> Result<Vector3<f64>, String> {
    if values.iter().any(|a| !(a.is_finite() && *a > 0.0)) {
        return Err(format!("every semi-axis must be positive and finite, got {values:?}"));
    }
    Ok(Vector3::new(values[0], values[1], values[2]))
}

impl Ellipsoid {
    pub fn wrap(inner: q::Ellipsoid) -> Self {
        Self { inner }
    }
}

#[pymethods]
impl Ellipsoid {
    #[new]
    fn new(pose_obj: &Bound<'_, PyAny>, axes_obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        let p = pose(&fixed(pose_obj, "pose", &[4, 4])?, "pose")?;
        let a = axes(&fixed(axes_obj, "axes", &[3])?, "axes")?;
        Ok(Self::wrap(q::Ellipsoid::new(p, a)))
    }

    /// An ellipsoid from its centre, semi-axes and (optionally) a 3x3 world-from-quadric rotation.
    #[staticmethod]
    #[pyo3(signature = (centre, axes, rotation=None))]
    fn from_centre(
        centre: &Bound<'_, PyAny>,
        axes: &Bound<'_, PyAny>,
        rotation: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let t = fixed(centre, "centre", &[3])?;
        let a = self::axes(&fixed(axes, "axes", &[3])?, "axes")?;
        let r = match rotation {
            Some(r) => fixed(r, "rotation", &[3, 3])?,
            None => vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        };
        let mut m = [0.0; 16];
        for i in 0..3 {
            m[4 * i..4 * i + 3].copy_from_slice(&r[3 * i..3 * i + 3]);
            m[4 * i + 3] = t[i];
        }
        m[15] = 1.0;
        Ok(Self::wrap(q::Ellipsoid::new(pose(&m, "rotation")?, a)))
    }

    /// The ellipsoid of a symmetric 4x4 dual quadric of any scale and sign (the "constrain" step),
    /// in canonical form (semi-axes in decreasing order).
    ///
    /// Raises:
    ///     ValueError: the matrix is not the dual quadric of a real ellipsoid (a hyperboloid, no finite
    ///         centre, NaN).
    #[staticmethod]
    fn from_dual_quadric(matrix: &Bound<'_, PyAny>) -> PyResult<Self> {
        let m = q::nalgebra::Matrix4::from_row_slice(&fixed(matrix, "matrix", &[4, 4])?);
        q::Ellipsoid::from_dual_quadric(&m).map(Self::wrap).map_err(|e| value_error(format!("matrix: {e}")))
    }

    /// Like ``from_dual_quadric``, but as gtsam-quadrics does: the magnitude of each squared axis is
    /// taken, so a hyperboloid still gives an ellipsoid. Returns ``(ellipsoid, flipped)``, ``flipped``
    /// telling whether a sign had to be flipped.
    #[staticmethod]
    fn from_dual_quadric_lenient(matrix: &Bound<'_, PyAny>) -> PyResult<(Self, bool)> {
        let m = q::nalgebra::Matrix4::from_row_slice(&fixed(matrix, "matrix", &[4, 4])?);
        q::Ellipsoid::from_dual_quadric_lenient(&m)
            .map(|(e, flipped)| (Self::wrap(e), flipped))
            .map_err(|e| value_error(format!("matrix: {e}")))
    }

    /// The 4x4 world-from-quadric pose.
    #[getter]
    fn pose<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        to_numpy(py, &[4, 4], pose_rows(&self.inner.world_from_quadric).to_vec())
    }

    /// The centre, world frame, shape (3,).
    #[getter]
    fn centre<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        vector_to_numpy(py, self.inner.centre().as_slice())
    }

    /// The 3x3 world-from-quadric rotation; its columns are the axes in the world frame.
    #[getter]
    fn rotation<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        matrix_to_numpy(py, &self.inner.rotation())
    }

    /// The semi-axes, metres, shape (3,).
    #[getter]
    fn axes<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        vector_to_numpy(py, self.inner.semi_axes.as_slice())
    }

    /// The dual quadric ``Q*`` (4x4, ``Q*[3, 3] == -1``).
    #[getter]
    fn dual_quadric<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        matrix_to_numpy(py, &self.inner.dual_quadric())
    }

    /// ``Q* / Q*[3, 3]`` (so the last entry is +1): the scale-free form used to compare quadrics.
    #[getter]
    fn dual_quadric_normalized<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        matrix_to_numpy(py, &self.inner.dual_quadric_normalized())
    }

    /// The same ellipsoid in canonical form: semi-axes in decreasing order, a proper rotation.
    fn canonical(&self) -> Self {
        Self::wrap(self.inner.canonical())
    }

    /// The right retraction by a 9-vector ``[w (3), v (3), da (3)]``: ``pose Exp([w, v])``, ``axes + da``.
    fn retract(&self, delta: &Bound<'_, PyAny>) -> PyResult<Self> {
        let d = fixed(delta, "delta", &[9])?;
        let e = self.inner.retract(&q::Tangent9::from_column_slice(&d));
        axes(e.semi_axes.as_slice(), "retracted axes")?;
        Ok(Self::wrap(e))
    }

    /// The 9-vector ``[Log(inv(pose) other.pose), other.axes - axes]``, the inverse of ``retract``.
    fn local<'py>(&self, py: Python<'py>, other: &Ellipsoid) -> PyResult<Array<'py>> {
        vector_to_numpy(py, self.inner.local(&other.inner).as_slice())
    }

    /// True when the world point lies inside or on the ellipsoid.
    fn contains(&self, point: &Bound<'_, PyAny>) -> PyResult<bool> {
        let p = fixed(point, "point", &[3])?;
        Ok(self.inner.contains_point(&Vector3::new(p[0], p[1], p[2])))
    }

    /// Axis-aligned world bounds, shape (2, 3): ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``.
    fn aabb<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        let (lo, hi) = self.inner.aabb();
        to_numpy(py, &[2, 3], vec![lo.x, lo.y, lo.z, hi.x, hi.y, hi.z])
    }

    fn __repr__(&self) -> String {
        let c = self.inner.centre();
        let a = self.inner.semi_axes;
        format!("Ellipsoid(centre=[{}, {}, {}], axes=[{}, {}, {}])", c.x, c.y, c.z, a.x, a.y, a.z)
    }
}

/// A dual conic ``C*`` (3x3 symmetric, any scale): the image outline of a projected ellipsoid.
///
/// Args:
///     matrix: the 3x3 matrix (symmetrised).
#[pyclass(frozen, module = "quadric_slam")]
#[derive(Clone, Copy)]
pub struct DualConic {
    pub inner: q::DualConic,
}

#[pymethods]
impl DualConic {
    #[new]
    fn new(matrix: &Bound<'_, PyAny>) -> PyResult<Self> {
        let m = Matrix3::from_row_slice(&fixed(matrix, "matrix", &[3, 3])?);
        Ok(Self { inner: q::DualConic(0.5 * (m + m.transpose())) })
    }

    /// The 3x3 matrix ``C* = P Q* P^T``.
    #[getter]
    fn matrix<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        matrix_to_numpy(py, &self.inner.0)
    }

    /// ``C* / C*[2, 2]``.
    fn normalized<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        matrix_to_numpy(py, &self.inner.normalized())
    }

    /// True when the conic is a real, non-degenerate ellipse.
    #[getter]
    fn is_ellipse(&self) -> bool {
        self.inner.is_ellipse()
    }

    /// The image ellipse as ``(centre (2,), shape (2, 2))``: its points ``x`` satisfy
    /// ``(x - c)^T inv(shape) (x - c) = 1``.
    ///
    /// Raises:
    ///     ProjectionError: the conic is not a real ellipse.
    fn ellipse<'py>(&self, py: Python<'py>) -> PyResult<(Array<'py>, Array<'py>)> {
        let e = self.inner.ellipse().ok_or_else(|| projection_error(q::ProjectionError::NotEllipse, "conic"))?;
        Ok((vector_to_numpy(py, e.centre.as_slice())?, matrix_to_numpy(py, &e.shape)?))
    }

    /// The axis-aligned bounds ``[xmin, ymin, xmax, ymax]`` of the whole ellipse (may exceed the image).
    ///
    /// Raises:
    ///     ProjectionError: the conic is not a real ellipse.
    fn bounds<'py>(&self, py: Python<'py>) -> PyResult<Array<'py>> {
        let b = self.inner.bounds().map_err(|e| projection_error(e, "conic"))?;
        vector_to_numpy(py, &b.to_array())
    }

    /// The exact bounds ``[xmin, ymin, xmax, ymax]`` of the part of the filled ellipse inside the image
    /// ``[0, width] x [0, height]``.
    ///
    /// Raises:
    ///     ProjectionError: not an ellipse, or it does not overlap the image.
    fn clipped_bounds<'py>(&self, py: Python<'py>, image_size: &Bound<'py, PyAny>) -> PyResult<Array<'py>> {
        let size = self::image_size(image_size, "image_size")?;
        let b = self.inner.clipped_bounds(&size).map_err(|e| projection_error(e, "conic"))?;
        vector_to_numpy(py, &b.to_array())
    }

    fn __repr__(&self) -> String {
        let m = &self.inner.0;
        format!(
            "DualConic([[{}, {}, {}], [{}, {}, {}], [{}, {}, {}]])",
            m[(0, 0)],
            m[(0, 1)],
            m[(0, 2)],
            m[(1, 0)],
            m[(1, 1)],
            m[(1, 2)],
            m[(2, 0)],
            m[(2, 1)],
            m[(2, 2)]
        )
    }
}

/// Project an ellipsoid into a camera: its dual conic ``C* = P Q* P^T``.
///
/// Raises:
///     ProjectionError: the ellipsoid is behind the camera, contains it, or crosses its principal plane
///         (its outline is then not an ellipse).
#[pyfunction]
pub fn project(ellipsoid: &Ellipsoid, camera: &Camera) -> PyResult<DualConic> {
    let inner = q::project(&ellipsoid.inner, &camera.inner).map_err(|e| projection_error(e, "ellipsoid"))?;
    if !finite_conic(&inner) {
        return Err(ProjectionError::new_err(format!("ellipsoid: {OVERFLOW}")));
    }
    Ok(DualConic { inner })
}

/// Why a projection of finite inputs is refused when its conic is not finite.
const OVERFLOW: &str = "its projection overflows: the ellipsoid's or the camera's numbers are too large for \
                        double precision (a conic entry is infinite or NaN)";

/// Every entry of the conic finite: finite inputs can still overflow (a centre at 1e300 m).
fn finite_conic(c: &q::DualConic) -> bool {
    c.0.iter().all(|v| v.is_finite())
}

/// Ellipsoids of a batch: poses `(N, 4, 4)` and axes `(N, 3)`.
fn ellipsoids(poses: &Bound<'_, PyAny>, axes_obj: &Bound<'_, PyAny>) -> PyResult<Vec<q::Ellipsoid>> {
    with_batch(poses, "poses", &[4, 4], |n, p| {
        with_batch(axes_obj, "axes", &[3], |m, a| {
            if n != m {
                return Err(value_error(format!("poses and axes: {n} poses but {m} rows of axes")));
            }
            // the item is named only when it is refused: formatting its name every time would cost more
            // than projecting it
            (0..n)
                .map(|i| {
                    let pose = rigid(&p[16 * i..16 * i + 16]).map_err(|r| value_error(format!("poses[{i}]: {r}")))?;
                    let a = positive_axes(&a[3 * i..3 * i + 3]).map_err(|r| value_error(format!("axes[{i}]: {r}")))?;
                    Ok(q::Ellipsoid::new(pose, a))
                })
                .collect()
        })
    })
}

/// What a batch does with an ellipsoid that has no conic or box.
#[derive(Clone, Copy, PartialEq)]
enum OnError {
    Raise,
    Nan,
}

fn on_error(errors: &str) -> PyResult<OnError> {
    match errors {
        "raise" => Ok(OnError::Raise),
        "nan" => Ok(OnError::Nan),
        other => Err(value_error(format!("errors: must be 'raise' or 'nan', got {other:?}"))),
    }
}

/// Run `f` on every ellipsoid without holding the GIL, `width` numbers out per ellipsoid; a failure
/// raises (naming the first failing index) or fills its row with NaN.
fn run_batch<F>(py: Python<'_>, es: Vec<q::Ellipsoid>, width: usize, mode: OnError, f: F) -> PyResult<Vec<f64>>
where
    F: Fn(&q::Ellipsoid, &mut [f64]) -> Result<(), q::ProjectionError> + Send + Sync,
{
    let (out, first_error) = py.detach(|| {
        let mut out = vec![0.0; es.len() * width];
        let mut first_error = None;
        for (i, (e, row)) in es.iter().zip(out.chunks_exact_mut(width)).enumerate() {
            if let Err(err) = f(e, row) {
                row.fill(f64::NAN);
                if first_error.is_none() {
                    first_error = Some((i, err));
                    if mode == OnError::Raise {
                        break;
                    }
                }
            }
        }
        (out, first_error)
    });
    match (first_error, mode) {
        // finite inputs whose projection is not finite overflowed (the inputs were checked)
        (Some((i, q::ProjectionError::NotFinite)), OnError::Raise) => {
            Err(ProjectionError::new_err(format!("ellipsoid {i}: {OVERFLOW}")))
        }
        (Some((i, err)), OnError::Raise) => Err(projection_error(err, &format!("ellipsoid {i}"))),
        _ => Ok(out),
    }
}

/// Project many ellipsoids into one camera in one call.
///
/// Args:
///     poses: (N, 4, 4) world-from-quadric poses.
///     axes: (N, 3) semi-axes.
///     camera: the camera.
///     errors: ``"raise"`` (default): an ellipsoid without an ellipse raises ProjectionError naming its
///         index; ``"nan"``: its conic is NaN.
///
/// Returns:
///     (N, 3, 3) dual conics.
#[pyfunction]
#[pyo3(signature = (poses, axes, camera, errors="raise"))]
pub fn project_many<'py>(
    py: Python<'py>,
    poses: &Bound<'py, PyAny>,
    axes: &Bound<'py, PyAny>,
    camera: &Camera,
    errors: &str,
) -> PyResult<Array<'py>> {
    let mode = on_error(errors)?;
    let es = ellipsoids(poses, axes)?;
    let n = es.len();
    let cam = camera.inner;
    let out = run_batch(py, es, 9, mode, move |e, row| {
        let c = q::project(e, &cam)?;
        if !finite_conic(&c) {
            return Err(q::ProjectionError::NotFinite);
        }
        for (k, v) in row.iter_mut().enumerate() {
            *v = c.0[(k / 3, k % 3)];
        }
        Ok(())
    })?;
    to_numpy(py, &[n, 3, 3], out)
}

/// The image boxes ``[xmin, ymin, xmax, ymax]`` of many ellipsoids in one camera, in one call: the full
/// bounds of each ellipse, or, with ``image_size``, the exact bounds of its part inside the image.
///
/// Args:
///     poses: (N, 4, 4) world-from-quadric poses.
///     axes: (N, 3) semi-axes.
///     camera: the camera.
///     image_size: ``(width, height)`` to clip to, or None.
///     errors: ``"raise"`` (default) or ``"nan"``, as in ``project_many``.
///
/// Returns:
///     (N, 4) boxes.
#[pyfunction]
#[pyo3(signature = (poses, axes, camera, image_size=None, errors="raise"))]
pub fn bounds_many<'py>(
    py: Python<'py>,
    poses: &Bound<'py, PyAny>,
    axes: &Bound<'py, PyAny>,
    camera: &Camera,
    image_size: Option<&Bound<'py, PyAny>>,
    errors: &str,
) -> PyResult<Array<'py>> {
    let mode = on_error(errors)?;
    let model = match image_size {
        Some(s) => BoundsModel::Clipped(self::image_size(s, "image_size")?),
        None => BoundsModel::Full,
    };
    let es = ellipsoids(poses, axes)?;
    let n = es.len();
    let cam = camera.inner;
    let out = run_batch(py, es, 4, mode, move |e, row| {
        let c = q::project(e, &cam)?;
        if !finite_conic(&c) {
            return Err(q::ProjectionError::NotFinite);
        }
        let b = model.bounds(&c)?;
        row.copy_from_slice(&b.to_array());
        Ok(())
    })?;
    to_numpy(py, &[n, 4], out)
}

/// The predicted box of an ellipsoid in a camera with its analytic Jacobians (the box factor's
/// measurement model).
///
/// Args:
///     ellipsoid: the ellipsoid.
///     camera: the camera.
///     image_size: ``(width, height)``: the exact clipped box (sides on the image border have zero
///         derivative); None: the full bounds.
///
/// Returns:
///     ``(box (4,), d_camera (4, 6), d_quadric (4, 9))``: derivatives with respect to the camera pose's
///     tangent ``[w, v]`` (right perturbation of world-from-camera) and the ellipsoid's ``[w, v, da]``.
///
/// Raises:
///     ProjectionError: no ellipse, or (clipped) outside the image.
#[pyfunction]
#[pyo3(signature = (ellipsoid, camera, image_size=None))]
pub fn predict_box<'py>(
    py: Python<'py>,
    ellipsoid: &Ellipsoid,
    camera: &Camera,
    image_size: Option<&Bound<'py, PyAny>>,
) -> PyResult<(Array<'py>, Array<'py>, Array<'py>)> {
    let model = match image_size {
        Some(s) => BoundsModel::Clipped(self::image_size(s, "image_size")?),
        None => BoundsModel::Full,
    };
    // refuses what project refuses, an overflow included, with the same text
    project(ellipsoid, camera)?;
    let p = q::predict_box(&ellipsoid.inner, &camera.inner, &model).map_err(|e| projection_error(e, "ellipsoid"))?;
    Ok((
        vector_to_numpy(py, &p.bbox.to_array())?,
        matrix_to_numpy(py, &p.d_camera)?,
        matrix_to_numpy(py, &p.d_quadric)?,
    ))
}

/// Boxes `(N, 4)` checked one by one.
pub fn boxes(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<q::BBox>> {
    let (n, v) = batch(obj, what, &[4])?;
    (0..n).map(|i| bbox(&v[4 * i..4 * i + 4], &format!("{what}[{i}]"))).collect()
}
