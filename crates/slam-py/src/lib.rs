//! The Python module `quadric_slam` (its native part, `quadric_slam._quadric_slam`): the geometry of
//! `slam-quadric` with numpy arrays in and out. Cameras and ellipsoids are immutable objects built once
//! from arrays; [`geometry::project`] projects one ellipsoid, [`geometry::project_many`] and
//! [`geometry::bounds_many`] many in one call without the GIL; the initialisers and the paper's metrics
//! take them. Every bad input (a wrong shape, NaN, a matrix that is not a rotation, a degenerate view)
//! is a `ValueError` naming the argument and the reason ([`convert`]); projection and initialisation
//! failures are its subclasses `ProjectionError` and `InitError`.
//!
//! The pure-Python part of the package (reading a run's output, running `slam-app`, the Ray fleet) is
//! in `python/quadric_slam/`.

mod convert;
mod geometry;
mod init;
mod metrics;

use pyo3::prelude::*;

/// The native part of `quadric_slam`.
#[pymodule]
fn _quadric_slam(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("ProjectionError", py.get_type::<convert::ProjectionError>())?;
    m.add("InitError", py.get_type::<convert::InitError>())?;
    m.add("ROTATION_TOLERANCE", convert::ROTATION_TOLERANCE)?;
    m.add_class::<geometry::Camera>()?;
    m.add_class::<geometry::Ellipsoid>()?;
    m.add_class::<geometry::DualConic>()?;
    m.add_class::<init::Dqp>()?;
    m.add_class::<init::Tri>()?;
    m.add_class::<init::QSlamSvd>()?;
    m.add_class::<init::Conic>()?;
    m.add_function(wrap_pyfunction!(geometry::project, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::project_many, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::bounds_many, m)?)?;
    m.add_function(wrap_pyfunction!(geometry::predict_box, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::e_trans, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::e_axe, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::e_yaw, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::iou, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::projected_iou, m)?)?;
    m.add_function(wrap_pyfunction!(metrics::box_iou, m)?)?;
    Ok(())
}
