//! The multi-view initialisers: each estimates an ellipsoid from the boxes of one object seen by
//! several calibrated cameras.

use pyo3::prelude::*;
use slam_quadric::{
    self as q,
    init::{BoxView, Initializer, Reference},
};

use crate::{
    convert::{fixed, pose, value_error, InitError},
    geometry::{boxes, Camera, Ellipsoid},
};

/// The views of `cameras` (a sequence of Camera) with `boxes` ((N, 4)).
fn views(cameras: &Bound<'_, PyAny>, boxes_obj: &Bound<'_, PyAny>) -> PyResult<Vec<BoxView>> {
    let cams: Vec<q::Camera> = cameras
        .try_iter()
        .map_err(|_| value_error("cameras: expected a sequence of Camera"))?
        .enumerate()
        .map(|(i, c)| {
            let c = c?;
            let cam = c
                .cast::<Camera>()
                .map_err(|_| value_error(format!("cameras[{i}]: expected a Camera, got {}", type_name(&c))))?;
            Ok(cam.get().inner)
        })
        .collect::<PyResult<_>>()?;
    let bs = boxes(boxes_obj, "boxes")?;
    if bs.len() != cams.len() {
        return Err(value_error(format!("cameras and boxes: {} cameras but {} boxes", cams.len(), bs.len())));
    }
    Ok(cams.into_iter().zip(bs).map(|(c, b)| BoxView::new(c, b)).collect())
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "an unknown type".into())
}

/// Run an initialiser without the GIL; its error as InitError.
fn run(py: Python<'_>, method: &dyn Initializer, views: Vec<BoxView>) -> PyResult<Ellipsoid> {
    py.detach(|| method.initialize(&views))
        .map(Ellipsoid::wrap)
        .map_err(|e| InitError::new_err(format!("{}: {e}", method.name())))
}

/// The reference frame of the yaw-only (DQP) or conditioning (Tri) model.
fn reference(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Reference> {
    match obj {
        Some(r) => Ok(Reference::Frame(pose(&fixed(r, "reference", &[4, 4])?, "reference")?)),
        None => Ok(Reference::FirstCamera),
    }
}

fn centre_iterations(centre_correction: bool) -> usize {
    if centre_correction {
        q::init::Dqp::with_centre_correction().centre_iterations
    } else {
        0
    }
}

/// DQP (Tian et al. 2022, "Tri+Yaw"): the centre by triangulating the box centres, then a linear solve
/// for an ellipsoid that only yaws about the reference frame's y axis.
///
/// Args:
///     centre_correction: also correct the centre for the offset between a box's centre and the
///         projected ellipsoid centre (up to 20 Newton rounds; the paper's method has none).
///     reference: 4x4 world-from-reference pose whose y axis points down along gravity; None: the
///         first view's camera (the paper's choice, right for a level camera).
#[pyclass(frozen, module = "quadric_slam")]
pub struct Dqp {
    inner: q::init::Dqp,
}

#[pymethods]
impl Dqp {
    #[new]
    #[pyo3(signature = (centre_correction=false, reference=None))]
    fn new(centre_correction: bool, reference: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let reference = self::reference(reference)?;
        let inner =
            q::init::Dqp { reference, centre_iterations: centre_iterations(centre_correction), ..Default::default() };
        Ok(Self { inner })
    }

    /// The method's name in tables ("Tri+Yaw", "Tri+Yaw+cc").
    #[getter]
    fn name(&self) -> &'static str {
        self.inner.name()
    }

    /// The fewest views the method accepts.
    #[getter]
    fn min_views(&self) -> usize {
        self.inner.min_views()
    }

    /// The ellipsoid seen as ``boxes`` ((N, 4), ``[xmin, ymin, xmax, ymax]``) by ``cameras``.
    ///
    /// Raises:
    ///     InitError: too few or invalid views, degenerate views, or no ellipsoid in front of every camera.
    fn initialize(&self, py: Python<'_>, cameras: &Bound<'_, PyAny>, boxes: &Bound<'_, PyAny>) -> PyResult<Ellipsoid> {
        run(py, &self.inner, views(cameras, boxes)?)
    }
}

/// Tri: the centre by triangulating the box centres, then the full 3x3 block of ``Q*`` (any rotation).
///
/// Args:
///     centre_correction: correct the triangulated centre as in ``Dqp``.
#[pyclass(frozen, module = "quadric_slam")]
pub struct Tri {
    inner: q::init::Tri,
}

#[pymethods]
impl Tri {
    #[new]
    #[pyo3(signature = (centre_correction=false))]
    fn new(centre_correction: bool) -> Self {
        Self { inner: q::init::Tri { centre_iterations: centre_iterations(centre_correction), ..Default::default() } }
    }

    /// The method's name in tables.
    #[getter]
    fn name(&self) -> &'static str {
        self.inner.name()
    }

    /// The fewest views the method accepts.
    #[getter]
    fn min_views(&self) -> usize {
        self.inner.min_views()
    }

    /// The ellipsoid seen as ``boxes`` by ``cameras`` (see ``Dqp.initialize``).
    fn initialize(&self, py: Python<'_>, cameras: &Bound<'_, PyAny>, boxes: &Bound<'_, PyAny>) -> PyResult<Ellipsoid> {
        run(py, &self.inner, views(cameras, boxes)?)
    }
}

/// QuadricSLAM's SVD initialiser (Nicholson et al. 2019): all ten entries of ``Q*`` from the planes of
/// the box edges, then the "constrain" step. Needs views around the object: on a straight, level drive
/// one entry is unobserved and it raises InitError (degenerate).
#[pyclass(frozen, module = "quadric_slam")]
pub struct QSlamSvd;

#[pymethods]
impl QSlamSvd {
    #[new]
    fn new() -> Self {
        Self
    }

    /// The method's name in tables ("Q-SLAM").
    #[getter]
    fn name(&self) -> &'static str {
        q::init::QSlamSvd.name()
    }

    /// The fewest views the method accepts.
    #[getter]
    fn min_views(&self) -> usize {
        q::init::QSlamSvd.min_views()
    }

    /// The ellipsoid seen as ``boxes`` by ``cameras`` (see ``Dqp.initialize``).
    fn initialize(&self, py: Python<'_>, cameras: &Bound<'_, PyAny>, boxes: &Bound<'_, PyAny>) -> PyResult<Ellipsoid> {
        run(py, &q::init::QSlamSvd, views(cameras, boxes)?)
    }
}

/// The Conic method (Rubino et al. 2018): the ellipse inscribed in each box, solved jointly with one
/// scale per view. From boxes alone it carries a model error (a box's inscribed ellipse is not the true
/// outline).
#[pyclass(frozen, module = "quadric_slam")]
pub struct Conic;

#[pymethods]
impl Conic {
    #[new]
    fn new() -> Self {
        Self
    }

    /// The method's name in tables ("Conic").
    #[getter]
    fn name(&self) -> &'static str {
        q::init::Conic::default().name()
    }

    /// The fewest views the method accepts.
    #[getter]
    fn min_views(&self) -> usize {
        q::init::Conic::default().min_views()
    }

    /// The ellipsoid seen as ``boxes`` by ``cameras`` (see ``Dqp.initialize``).
    fn initialize(&self, py: Python<'_>, cameras: &Bound<'_, PyAny>, boxes: &Bound<'_, PyAny>) -> PyResult<Ellipsoid> {
        run(py, &q::init::Conic::default(), views(cameras, boxes)?)
    }
}
