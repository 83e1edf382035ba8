//! The paper's accuracy metrics (Tian et al. 2022, §VI) and box overlaps.

use pyo3::prelude::*;
use slam_quadric::{self as q, metrics};

use crate::{
    convert::{bbox, fixed, image_size, value_error},
    geometry::{Camera, Ellipsoid},
};

/// Centre distance between an estimate and the truth, metres.
#[pyfunction]
pub fn e_trans(estimate: &Ellipsoid, truth: &Ellipsoid) -> f64 {
    metrics::e_trans(&estimate.inner, &truth.inner)
}

/// Semi-axis error, metres: the norm of the difference of the semi-axes in the axis order that matches
/// best (``ordered=True``: in the order given).
#[pyfunction]
#[pyo3(signature = (estimate, truth, ordered=false))]
pub fn e_axe(estimate: &Ellipsoid, truth: &Ellipsoid, ordered: bool) -> f64 {
    if ordered {
        metrics::e_axe_ordered(&estimate.inner, &truth.inner)
    } else {
        metrics::e_axe(&estimate.inner, &truth.inner)
    }
}

/// Yaw error, degrees in [0, 90]: the angle between the estimate's longest horizontal axis and the
/// truth's heading (its own x axis) on the plane orthogonal to ``up``, modulo 180 degrees.
///
/// Raises:
///     ValueError: ``up`` is zero, or the truth's heading is vertical.
#[pyfunction]
#[pyo3(signature = (estimate, truth, up=None))]
pub fn e_yaw(estimate: &Ellipsoid, truth: &Ellipsoid, up: Option<&Bound<'_, PyAny>>) -> PyResult<f64> {
    let u = match up {
        Some(u) => fixed(u, "up", &[3])?,
        None => vec![0.0, -1.0, 0.0],
    };
    let e = metrics::e_yaw(&estimate.inner, &truth.inner, &q::nalgebra::Vector3::new(u[0], u[1], u[2]));
    if e.is_nan() {
        return Err(value_error(format!("e_yaw: no yaw: up {u:?} is zero or the truth's heading is vertical")));
    }
    Ok(e)
}

/// Intersection over union of two boxes ``[xmin, ymin, xmax, ymax]``.
#[pyfunction]
pub fn iou(a: &Bound<'_, PyAny>, b: &Bound<'_, PyAny>) -> PyResult<f64> {
    let a = bbox(&fixed(a, "a", &[4])?, "a")?;
    let b = bbox(&fixed(b, "b", &[4])?, "b")?;
    Ok(a.iou(&b))
}

/// IoU2D of the paper: the IoU of the ellipsoid's projected, image-clipped box with a box; 0 when the
/// ellipsoid has no box in the image.
#[pyfunction]
pub fn projected_iou(
    ellipsoid: &Ellipsoid,
    camera: &Camera,
    image_size: &Bound<'_, PyAny>,
    bbox: &Bound<'_, PyAny>,
) -> PyResult<f64> {
    let size = self::image_size(image_size, "image_size")?;
    let b = self::bbox(&fixed(bbox, "bbox", &[4])?, "bbox")?;
    Ok(metrics::projected_iou(&ellipsoid.inner, &camera.inner, &size, &b))
}

/// Box IoU2D: the IoU of the image-clipped box of the ellipsoid's circumscribed cuboid, projected, with
/// a box (a ground-truth ellipsoid inscribed in a labelled 3-D box scores 1 against that box's projection).
#[pyfunction]
pub fn box_iou(
    ellipsoid: &Ellipsoid,
    camera: &Camera,
    image_size: &Bound<'_, PyAny>,
    bbox: &Bound<'_, PyAny>,
) -> PyResult<f64> {
    let size = self::image_size(image_size, "image_size")?;
    let b = self::bbox(&fixed(bbox, "bbox", &[4])?, "bbox")?;
    Ok(metrics::box_iou(&ellipsoid.inner, &camera.inner, &size, &b))
}
