//! Arrays in and out: any array-like of numbers is read as float64 with its shape checked, poses and
//! boxes checked before the geometry sees them, and every refusal a `ValueError` that names the argument
//! and what is wrong with it.

use std::borrow::Cow;

use numpy::{
    ndarray::{ArrayD, Dimension, IxDyn},
    AllowTypeChange, IntoPyArray, PyArrayDyn, PyArrayLikeDyn,
};
use pyo3::{exceptions::PyValueError, prelude::*};
use slam_quadric::{
    nalgebra::{Isometry3, Matrix3, Matrix4},
    se3, BBox, ImageSize,
};

/// How far a pose's rotation block may be from orthonormal (largest entry of `RᵀR − I`). A rotation
/// written with 9 significant digits is within 1e-8; a matrix further off is not a rotation, and
/// reading it as one would silently change it.
pub const ROTATION_TOLERANCE: f64 = 1e-6;

/// A float64 numpy array handed to Python.
pub type Array<'py> = Bound<'py, PyArrayDyn<f64>>;

/// A `ValueError` with the message.
pub fn value_error(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}

/// The numbers of an array-like argument as float64, row-major, with its shape. `what` names it in errors.
pub struct Numbers {
    /// Row-major values.
    pub values: Vec<f64>,
    /// Its shape.
    pub shape: Vec<usize>,
}

fn shape_text(shape: &[usize]) -> String {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    format!("({})", dims.join(", "))
}

fn pattern_text(tail: &[usize], batch: bool) -> String {
    let mut dims: Vec<String> = tail.iter().map(|d| d.to_string()).collect();
    if batch {
        dims.insert(0, "N".into());
    }
    if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    }
}

/// Read any array-like (a numpy array of any real dtype, nested lists, a tuple) as float64.
pub fn numbers(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Numbers> {
    let array: PyArrayLikeDyn<'_, f64, AllowTypeChange> =
        obj.extract().map_err(|e| value_error(format!("{what}: expected an array of real numbers ({e})")))?;
    let view = array.as_array();
    let shape = view.shape().to_vec();
    let values: Cow<'_, [f64]> = match view.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(view.iter().copied().collect()),
    };
    Ok(Numbers { values: values.into_owned(), shape })
}

/// An array of exactly this shape, every value finite.
pub fn fixed(obj: &Bound<'_, PyAny>, what: &str, shape: &[usize]) -> PyResult<Vec<f64>> {
    let n = numbers(obj, what)?;
    if n.shape != shape {
        return Err(value_error(format!(
            "{what}: expected shape {}, got {}",
            pattern_text(shape, false),
            shape_text(&n.shape)
        )));
    }
    finite(&n.values, what, None)?;
    Ok(n.values)
}

/// A batch `(N, *tail)` (N may be 0): its length and values, every value finite.
pub fn batch(obj: &Bound<'_, PyAny>, what: &str, tail: &[usize]) -> PyResult<(usize, Vec<f64>)> {
    with_batch(obj, what, tail, |n, values| Ok((n, values.to_vec())))
}

/// Hand a batch `(N, *tail)` to `f` as its length and row-major values without copying them when the
/// array is already contiguous float64 (every value checked finite first).
pub fn with_batch<R>(
    obj: &Bound<'_, PyAny>,
    what: &str,
    tail: &[usize],
    f: impl FnOnce(usize, &[f64]) -> PyResult<R>,
) -> PyResult<R> {
    let array: PyArrayLikeDyn<'_, f64, AllowTypeChange> =
        obj.extract().map_err(|e| value_error(format!("{what}: expected an array of real numbers ({e})")))?;
    let view = array.as_array();
    let shape = view.shape().to_vec();
    if shape.len() != tail.len() + 1 || shape[1..] != *tail {
        return Err(value_error(format!(
            "{what}: expected shape {}, got {}",
            pattern_text(tail, true),
            shape_text(&shape)
        )));
    }
    let values: Cow<'_, [f64]> = match view.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(view.iter().copied().collect()),
    };
    let per: usize = tail.iter().product();
    if let Some(bad) = values.iter().position(|v| !v.is_finite()) {
        let item = bad.checked_div(per).unwrap_or(0);
        return Err(value_error(format!("{what}[{item}]: holds NaN or infinity")));
    }
    f(shape[0], &values)
}

/// Refuse NaN and infinity, naming the argument (and the item of a batch).
pub fn finite(values: &[f64], what: &str, item: Option<usize>) -> PyResult<()> {
    if values.iter().all(|v| v.is_finite()) {
        return Ok(());
    }
    Err(match item {
        Some(i) => value_error(format!("{what}[{i}]: holds NaN or infinity")),
        None => value_error(format!("{what}: holds NaN or infinity")),
    })
}

/// A rigid pose from a row-major 4×4 homogeneous matrix: last row `[0, 0, 0, 1]`, rotation block
/// orthonormal with determinant +1 (within [`ROTATION_TOLERANCE`]).
pub fn pose(values: &[f64], what: &str) -> PyResult<Isometry3<f64>> {
    rigid(values).map_err(|reason| value_error(format!("{what}: {reason}")))
}

/// [`pose`] with the reason of a refusal as text, for batches that name the item only when it fails.
pub fn rigid(values: &[f64]) -> Result<Isometry3<f64>, String> {
    let m = Matrix4::from_row_slice(values);
    if !m.iter().all(|v| v.is_finite()) {
        return Err("holds NaN or infinity".into());
    }
    let last = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
    if last.iter().zip([0.0, 0.0, 0.0, 1.0]).any(|(a, b)| (a - b).abs() > 1e-9) {
        return Err(format!("not a rigid pose: its last row is {last:?}, not [0, 0, 0, 1]"));
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let off = (r.transpose() * r - Matrix3::identity()).abs().max();
    let det = r.determinant();
    if off > ROTATION_TOLERANCE || det <= 0.0 {
        return Err(format!(
            "the top-left 3x3 block is not a rotation (largest entry of R^T R - I is {off:.3e}, determinant {det:.6}; \
             a rotation has 0 and +1)"
        ));
    }
    Ok(se3::isometry_from_matrix(&m))
}

/// A row-major 4×4 matrix of a pose.
pub fn pose_rows(p: &Isometry3<f64>) -> [f64; 16] {
    let m = p.to_homogeneous();
    std::array::from_fn(|k| m[(k / 4, k % 4)])
}

/// A box `[xmin, ymin, xmax, ymax]` with positive width and height.
pub fn bbox(values: &[f64], what: &str) -> PyResult<BBox> {
    let b = BBox::new(values[0], values[1], values[2], values[3]);
    b.validated().map_err(|e| value_error(format!("{what}: {e} ({:?})", b.to_array())))
}

/// An image size `(width, height)`, both positive.
pub fn image_size(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<ImageSize> {
    let v = fixed(obj, what, &[2])?;
    if v[0] <= 0.0 || v[1] <= 0.0 {
        return Err(value_error(format!("{what}: width and height must be positive, got ({}, {})", v[0], v[1])));
    }
    Ok(ImageSize::new(v[0], v[1]))
}

/// A numpy array of the shape from row-major values.
pub fn to_numpy<'py>(py: Python<'py>, shape: &[usize], values: Vec<f64>) -> PyResult<Array<'py>> {
    let array =
        ArrayD::from_shape_vec(IxDyn(shape), values).map_err(|e| value_error(format!("internal shape error: {e}")))?;
    debug_assert_eq!(array.raw_dim().ndim(), shape.len());
    Ok(array.into_pyarray(py))
}

/// A numpy array of a fixed-size nalgebra matrix (row-major in numpy).
pub fn matrix_to_numpy<'py, const R: usize, const C: usize>(
    py: Python<'py>,
    m: &slam_quadric::nalgebra::SMatrix<f64, R, C>,
) -> PyResult<Array<'py>> {
    let values: Vec<f64> = (0..R * C).map(|k| m[(k / C, k % C)]).collect();
    to_numpy(py, &[R, C], values)
}

/// A numpy vector.
pub fn vector_to_numpy<'py>(py: Python<'py>, values: &[f64]) -> PyResult<Array<'py>> {
    to_numpy(py, &[values.len()], values.to_vec())
}

pyo3::create_exception!(
    quadric_slam,
    ProjectionError,
    PyValueError,
    "An ellipsoid has no image ellipse or box in a camera: it is behind the camera, around it, crosses its \
     principal plane, or (clipped bounds) lies outside the image. A ValueError."
);
pyo3::create_exception!(
    quadric_slam,
    InitError,
    PyValueError,
    "An initialiser found no ellipsoid: too few or invalid views, degenerate views, or a solution that is not an \
     ellipsoid wholly in front of every camera. A ValueError."
);

/// A projection failure as the Python exception, naming what was projected.
pub fn projection_error(e: slam_quadric::ProjectionError, what: &str) -> PyErr {
    ProjectionError::new_err(format!("{what}: {e}"))
}
