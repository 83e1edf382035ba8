//! Variables and their storage.

use nalgebra::{DVector, Isometry3, Vector3, Vector6};
use slam_quadric::{Ellipsoid, Tangent9};

use crate::{error::FactorError, lie};

pub use crate::key::Key;

/// A BAL camera: angle-axis rotation `r`, translation `t`, focal `f`, radial `k1`, `k2`
/// (`[r0, r1, r2, t0, t1, t2, f, k1, k2]`), world to camera `P = R(r) X + t`. Updated additively, as in
/// Ceres' BAL examples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BalCamera(pub [f64; 9]);

/// One variable.
#[derive(Debug, Clone, PartialEq)]
pub enum Var {
    /// A pose (e.g. world-from-camera), tangent `[ω, v]`, right perturbation `T · Exp(ξ)`.
    Pose(Isometry3<f64>),
    /// A 3-D point, additive.
    Point(Vector3<f64>),
    /// An ellipsoid, tangent `[ω, v, δa]` (see `slam_quadric::Ellipsoid::retract`).
    Ellipsoid(Ellipsoid),
    /// A BAL camera, additive.
    Bal(BalCamera),
}

impl Var {
    /// Tangent dimension.
    pub fn dim(&self) -> usize {
        match self {
            Var::Pose(_) => 6,
            Var::Point(_) => 3,
            Var::Ellipsoid(_) => 9,
            Var::Bal(_) => 9,
        }
    }

    /// `self ⊕ delta` (`delta.len() == self.dim()`).
    pub fn retract(&self, delta: &[f64]) -> Var {
        match self {
            Var::Pose(p) => Var::Pose(lie::retract(p, &Vector6::from_column_slice(delta))),
            Var::Point(p) => Var::Point(p + Vector3::from_column_slice(delta)),
            Var::Ellipsoid(e) => Var::Ellipsoid(e.retract(&Tangent9::from_column_slice(delta))),
            Var::Bal(c) => {
                let mut v = c.0;
                for (x, d) in v.iter_mut().zip(delta) {
                    *x += d;
                }
                Var::Bal(BalCamera(v))
            }
        }
    }

    /// `other ⊖ self`, the tangent vector taking `self` to `other` (same kind; `None` otherwise).
    pub fn local(&self, other: &Var) -> Option<DVector<f64>> {
        Some(match (self, other) {
            (Var::Pose(a), Var::Pose(b)) => DVector::from_column_slice(lie::local(a, b).as_slice()),
            (Var::Point(a), Var::Point(b)) => DVector::from_column_slice((b - a).as_slice()),
            (Var::Ellipsoid(a), Var::Ellipsoid(b)) => DVector::from_column_slice(a.local(b).as_slice()),
            (Var::Bal(a), Var::Bal(b)) => DVector::from_iterator(9, a.0.iter().zip(&b.0).map(|(x, y)| y - x)),
            _ => return None,
        })
    }

    /// Squared norm of the parameters (for the relative step-size test).
    pub fn norm_squared(&self) -> f64 {
        match self {
            Var::Pose(p) => p.translation.vector.norm_squared() + p.rotation.scaled_axis().norm_squared(),
            Var::Point(p) => p.norm_squared(),
            Var::Ellipsoid(e) => e.centre().norm_squared() + e.semi_axes.norm_squared(),
            Var::Bal(c) => c.0.iter().map(|x| x * x).sum(),
        }
    }
}

/// The variables of a problem, addressed by [`Key`] in insertion order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Values {
    vars: Vec<Var>,
}

impl Values {
    /// No variables.
    pub fn new() -> Self {
        Self::default()
    }

    /// Add a variable; returns its key.
    pub fn add(&mut self, v: Var) -> Key {
        self.vars.push(v);
        Key(self.vars.len() - 1)
    }

    /// Number of variables.
    pub fn len(&self) -> usize {
        self.vars.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.vars.is_empty()
    }

    /// The variable at a key.
    pub fn get(&self, k: Key) -> Option<&Var> {
        self.vars.get(k.0)
    }

    /// Replace the variable at a key (must exist).
    pub fn set(&mut self, k: Key, v: Var) -> bool {
        match self.vars.get_mut(k.0) {
            Some(slot) => {
                *slot = v;
                true
            }
            None => false,
        }
    }

    /// All variables in key order.
    pub fn iter(&self) -> impl Iterator<Item = (Key, &Var)> {
        self.vars.iter().enumerate().map(|(i, v)| (Key(i), v))
    }

    /// The pose at a key.
    pub fn pose(&self, k: Key) -> Option<&Isometry3<f64>> {
        match self.get(k) {
            Some(Var::Pose(p)) => Some(p),
            _ => None,
        }
    }

    /// The point at a key.
    pub fn point(&self, k: Key) -> Option<&Vector3<f64>> {
        match self.get(k) {
            Some(Var::Point(p)) => Some(p),
            _ => None,
        }
    }

    /// The ellipsoid at a key.
    pub fn ellipsoid(&self, k: Key) -> Option<&Ellipsoid> {
        match self.get(k) {
            Some(Var::Ellipsoid(e)) => Some(e),
            _ => None,
        }
    }

    /// The BAL camera at a key.
    pub fn bal(&self, k: Key) -> Option<&BalCamera> {
        match self.get(k) {
            Some(Var::Bal(c)) => Some(c),
            _ => None,
        }
    }

    /// [`Self::pose`], or the error a factor returns when its key holds something else.
    pub fn require_pose(&self, k: Key) -> Result<&Isometry3<f64>, FactorError> {
        self.pose(k).ok_or(FactorError::WrongVariable(k))
    }

    /// [`Self::point`], or [`FactorError::WrongVariable`].
    pub fn require_point(&self, k: Key) -> Result<&Vector3<f64>, FactorError> {
        self.point(k).ok_or(FactorError::WrongVariable(k))
    }

    /// [`Self::ellipsoid`], or [`FactorError::WrongVariable`].
    pub fn require_ellipsoid(&self, k: Key) -> Result<&Ellipsoid, FactorError> {
        self.ellipsoid(k).ok_or(FactorError::WrongVariable(k))
    }

    /// [`Self::bal`], or [`FactorError::WrongVariable`].
    pub fn require_bal(&self, k: Key) -> Result<&BalCamera, FactorError> {
        self.bal(k).ok_or(FactorError::WrongVariable(k))
    }
}
