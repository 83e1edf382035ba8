//! What an object's scene flow reads ([`SceneFlow`]) and how every motion test splits a displacement
//! ([`RaySplit`]): data kept with an object ([`super::MappedObject`]) and made by
//! [`super::scene_flow`], in a file of its own so that the object and the motion tests do not import
//! each other.

use nalgebra::Vector3;

/// The scene flow of an object's points: the median of their world motions between two frames, split
/// along the viewing ray (from the camera to the points' median position now) and across it, with
/// the σ of each (the median of n values with σ has σ ≈ 1.25 σ / √n; the points' noise combined with
/// [`super::FLOW_POSE_SIGMA_M`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneFlow {
    /// The motion, world frame, metres.
    pub motion: Vector3<f64>,
    /// The viewing ray it is split along (unit, world frame).
    pub ray: Vector3<f64>,
    /// σ of the motion along the ray, metres.
    pub sigma_along: f64,
    /// σ of the motion across the ray, metres.
    pub sigma_across: f64,
    /// Points it was read from.
    pub points: usize,
}

impl SceneFlow {
    /// A reading from a motion (world frame, metres) and its σ along and across `ray` (unit).
    pub fn new(
        motion: Vector3<f64>,
        ray: Vector3<f64>,
        (sigma_along, sigma_across): (f64, f64),
        points: usize,
    ) -> Self {
        Self { motion, ray, sigma_along, sigma_across, points }
    }

    /// The motion over two consecutive readings (`first`, then `then`): their sum along `then`'s ray,
    /// σ combined.
    pub fn over_both(first: &SceneFlow, then: &SceneFlow) -> SceneFlow {
        let s = |a: f64, b: f64| a.hypot(b);
        SceneFlow::new(
            first.motion + then.motion,
            then.ray,
            (s(first.sigma_along, then.sigma_along), s(first.sigma_across, then.sigma_across)),
            first.points.min(then.points),
        )
    }

    /// The motion along the ray (away from the camera positive) and across it, metres.
    pub fn split(&self) -> RaySplit {
        RaySplit::of(&self.motion, &self.ray)
    }

    /// The motion in σ of its noise (Mahalanobis, along and across the ray).
    pub fn sigmas(&self) -> f64 {
        self.split().sigmas((self.sigma_along, self.sigma_across))
    }
}

/// A displacement split along a viewing ray (unit) and across it, metres: how every motion test here
/// reads a displacement, since stereo depth noise lies along the ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RaySplit {
    /// Along the ray (away from the camera positive).
    pub along: f64,
    /// Across it.
    pub across: f64,
}

impl RaySplit {
    /// `v` split along and across `ray`.
    pub fn of(v: &Vector3<f64>, ray: &Vector3<f64>) -> Self {
        let along = v.dot(ray);
        Self { along, across: (v - ray * along).norm() }
    }

    /// In σ of noise with these σ along and across (Mahalanobis, the two independent).
    pub fn sigmas(&self, (sigma_along, sigma_across): (f64, f64)) -> f64 {
        ((self.along / sigma_along).powi(2) + (self.across / sigma_across).powi(2)).sqrt()
    }

    /// Its length, metres.
    pub fn norm(&self) -> f64 {
        self.along.hypot(self.across)
    }
}
