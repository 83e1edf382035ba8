//! The stereo-point yaw cue: the principal horizontal direction of an object's map points.
//!
//! A car's stereo points lie on its visible faces. Projected onto the ground plane they spread along
//! the faces; the principal direction of that spread (the leading eigenvector of the points' 2×2
//! horizontal covariance) is the direction of the face that dominates. Stereo depth noise spreads
//! points along the viewing ray, so its expected variance (`σ_z²` along the ray's horizontal direction)
//! is taken out of the covariance first. The cue is used only when it is confident: the remaining
//! spread across the principal direction is small against the spread along it.
//!
//! The direction itself is the axis, nearest the principal one, of the rectangle that best fits the
//! points (each point's distance to the nearest edge of the bounding rectangle, least squares over
//! orientations): PCA alone leans towards the short face when a rear and a side are both seen.
//!
//! Which axis the principal direction is follows from its extent: a uniform spread over a segment of
//! length `L` has variance `L²/12`, so `L = √(12 λ₁)`. An extent nearer the class's length than its
//! width is the side of the car: the heading is along it. A shorter one, across the viewing ray, is
//! the rear (or front) face seen from behind: the heading is the face's normal. A short extent that is
//! not across the ray (part of a side, cut by the image border or occluded) or shorter than a narrow
//! car's width decides nothing, and so does one longer than a large car's diagonal (2 prior σ above
//! the class's mean: background or mismatched depths, not the object's faces).

use nalgebra::{Matrix2, Vector2, Vector3};
use slam_optim::object::{ObjectPrior, YawCue};

/// Settings of [`point_yaw`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointYawConfig {
    /// Fewest points (after the outlier gate) for a cue.
    pub min_points: usize,
    /// Largest ratio of the noise-corrected eigenvalues `λ₂ / λ₁` for a confident direction: 0.25 is
    /// a spread twice as long as it is wide (in standard deviations).
    pub max_ratio: f64,
    /// Least standard deviation of the cue, degrees: a car's faces are not exactly along or across
    /// its heading (rounded corners, mirrors, wheels), and an oblique view mixes two faces.
    pub floor_deg: f64,
    /// Stereo disparity noise, pixels (the depth noise `σ_z = z² σ_d / (f b)` comes from it).
    pub disparity_sigma_px: f64,
}

impl Default for PointYawConfig {
    fn default() -> Self {
        Self { min_points: 8, max_ratio: 0.25, floor_deg: 3.0, disparity_sigma_px: 0.5 }
    }
}

/// What the points say about the yaw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PointYaw {
    /// Fewer than `min_points` points near the object.
    TooFew(usize),
    /// No confident direction (eigenvalue ratio, or a short face that is not across the ray).
    Ambiguous {
        /// Noise-corrected eigenvalue ratio `λ₂ / λ₁`.
        ratio: f64,
        /// Extent along the principal direction, `√(12 λ₁)`, metres.
        extent_m: f64,
    },
    /// A direction for the object's length axis.
    Cue {
        /// The prior on the length axis.
        cue: YawCue,
        /// Noise-corrected eigenvalue ratio `λ₂ / λ₁`.
        ratio: f64,
        /// Extent along the principal direction, `√(12 λ₁)`, metres.
        extent_m: f64,
        /// The points are one short face across the ray (rear or front): the heading is its normal.
        rear_face: bool,
    },
}

impl PointYaw {
    /// The cue, when there is one.
    pub fn cue(&self) -> Option<YawCue> {
        match self {
            PointYaw::Cue { cue, .. } => Some(*cue),
            _ => None,
        }
    }
}

/// The yaw cue of an object's `points` (world frame) seen from `camera` (world position of the
/// latest camera), with `up` the world's vertical, `prior` the class's semi-axes (own x = length,
/// z = width), `focal_px` and `baseline_m` the stereo rig.
pub fn point_yaw(
    points: &[Vector3<f64>],
    up: &Vector3<f64>,
    camera: &Vector3<f64>,
    prior: &ObjectPrior,
    focal_px: f64,
    baseline_m: f64,
    config: &PointYawConfig,
) -> PointYaw {
    let (b1, b2) = horizontal_basis(up);
    let flat = |p: &Vector3<f64>| Vector2::new(b1.dot(p), b2.dot(p));
    let all: Vec<Vector2<f64>> = points.iter().filter(|p| p.iter().all(|c| c.is_finite())).map(flat).collect();
    if all.len() < config.min_points {
        return PointYaw::TooFew(all.len());
    }
    // gate: within the class's full length of the median (points of the object lie within its length of
    // any point of it, wherever on the car the median falls)
    let near = near_median(&all, 2.0 * prior.axes.x);
    if near.len() < config.min_points {
        return PointYaw::TooFew(near.len());
    }
    let count = near.len() as f64;
    let mean = near.iter().fold(Vector2::zeros(), |a, p| a + p) / count;
    let cov = near.iter().fold(Matrix2::zeros(), |a, p| a + (p - mean) * (p - mean).transpose()) / count;
    // depth noise along the horizontal viewing ray
    let cam = flat(camera);
    let ray = mean - cam;
    let depth = {
        let c3 = b1 * mean.x + b2 * mean.y;
        let cam3 = b1 * cam.x + b2 * cam.y;
        (c3 - cam3).norm()
    };
    let Some(d) = (ray.norm() > 1e-9).then(|| ray / ray.norm()) else {
        return PointYaw::Ambiguous { ratio: 1.0, extent_m: 0.0 };
    };
    let sigma_z = depth * depth * config.disparity_sigma_px / (focal_px * baseline_m).max(1e-9);
    let (l1, l2, v1) = principal_axis(cov, d, sigma_z);
    let extent_m = (12.0 * l1.max(0.0)).sqrt();
    let ratio = if l1 > 0.0 { l2 / l1 } else { 1.0 };
    // the direction must stand above the noise: at least twice the depth noise's σ in extent
    if l1 <= 0.0 || ratio > config.max_ratio || l1 < 4.0 * sigma_z * sigma_z {
        return PointYaw::Ambiguous { ratio, extent_m };
    }
    let sigma_rad = direction_sigma(cov, v1, l1, count, config.floor_deg);
    let (length, width) = (2.0 * prior.axes.x, 2.0 * prior.axes.z);
    // points of one object span at most the diagonal of a large one of its class (2 σ above the prior):
    // a longer spread is background or a streak of mismatched depths, not the object's faces
    let (long, wide) = (2.0 * (prior.axes.x + 2.0 * prior.sigma.x), 2.0 * (prior.axes.z + 2.0 * prior.sigma.z));
    if extent_m > long.hypot(wide) {
        return PointYaw::Ambiguous { ratio, extent_m };
    }
    let to3 = |v: Vector2<f64>| b1 * v.x + b2 * v.y;
    // PCA of an L (a rear face and a side) leans towards the short face (about 11° for a whole car's
    // rear and side); the axes of the best-fitting rectangle do not: take the rectangle's axis nearest
    // the principal direction
    let v1 = rectangle_axis(&near, &v1);
    if extent_m >= 0.5 * (length + width) {
        return PointYaw::Cue { cue: YawCue { direction: to3(v1), sigma_rad }, ratio, extent_m, rear_face: false };
    }
    // a short face: the rear or front seen from behind or ahead, i.e. across the viewing ray (within
    // 30°), and a whole one (at least the width of a narrow car of the class, 2 σ below the prior)
    let narrow = 2.0 * (prior.axes.z - 2.0 * prior.sigma.z);
    if v1.dot(&d).abs() < 30f64.to_radians().sin() && extent_m >= narrow {
        let normal = Vector2::new(-v1.y, v1.x);
        return PointYaw::Cue { cue: YawCue { direction: to3(normal), sigma_rad }, ratio, extent_m, rear_face: true };
    }
    PointYaw::Ambiguous { ratio, extent_m }
}

/// Two unit vectors spanning the plane normal to `up` (the horizontal).
fn horizontal_basis(up: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let n = up.normalize();
    // a horizontal basis
    let seed = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::z() };
    let b1 = (seed - n * n.dot(&seed)).normalize();
    let b2 = n.cross(&b1);
    (b1, b2)
}

/// The points within `reach` of the points' median (taken coordinate by coordinate).
fn near_median(all: &[Vector2<f64>], reach: f64) -> Vec<Vector2<f64>> {
    let median = |k: usize| {
        let mut v: Vec<f64> = all.iter().map(|p| p[k]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let m = Vector2::new(median(0), median(1));
    all.iter().copied().filter(|p| (p - m).norm() <= reach).collect()
}

/// The principal axis of the spread `cov` once the depth noise (`sigma_z` along the unit viewing ray
/// `d`) is taken out: the larger eigenvalue, the smaller one (at least 0), and the larger one's direction.
fn principal_axis(cov: Matrix2<f64>, d: Vector2<f64>, sigma_z: f64) -> (f64, f64, Vector2<f64>) {
    let corrected = cov - d * d.transpose() * (sigma_z * sigma_z);
    let eig = corrected.symmetric_eigen();
    let (i1, i2) = if eig.eigenvalues[0] >= eig.eigenvalues[1] { (0, 1) } else { (1, 0) };
    let (l1, l2) = (eig.eigenvalues[i1], eig.eigenvalues[i2].max(0.0));
    let v1: Vector2<f64> = eig.eigenvectors.column(i1).into_owned();
    (l1, l2, v1)
}

/// Angular standard error of the principal direction `v1` from `count` points (spread `l1` along it,
/// the raw spread `cov` across it), never below `floor_deg`.
fn direction_sigma(cov: Matrix2<f64>, v1: Vector2<f64>, l1: f64, count: f64, floor_deg: f64) -> f64 {
    // angular standard error of a principal direction from `count` points (spread λ₁ along, the raw
    // spread across it), never below the floor
    let along_raw = (v1.transpose() * cov * v1)[0];
    let across = (cov.trace() - along_raw).max(0.0);
    let along = l1;
    let stat = (along * across / (count * (along - across).powi(2).max(1e-12))).sqrt();
    stat.max(floor_deg.to_radians())
}

/// The axis nearest `principal` of the rectangle that fits `points` best: over orientations in steps of
/// 0.5°, each point's distance to the nearest edge of the points' bounding rectangle (the points lie on
/// the object's outline), summed in squares; the orientation with the least sum wins.
fn rectangle_axis(points: &[Vector2<f64>], principal: &Vector2<f64>) -> Vector2<f64> {
    let cost = |t: f64| {
        let (e1, e2) = (Vector2::new(t.cos(), t.sin()), Vector2::new(-t.sin(), t.cos()));
        let (mut lo1, mut hi1, mut lo2, mut hi2) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in points {
            let (a, b) = (p.dot(&e1), p.dot(&e2));
            (lo1, hi1, lo2, hi2) = (lo1.min(a), hi1.max(a), lo2.min(b), hi2.max(b));
        }
        points
            .iter()
            .map(|p| {
                let (a, b) = (p.dot(&e1), p.dot(&e2));
                (a - lo1).min(hi1 - a).min(b - lo2).min(hi2 - b).powi(2)
            })
            .sum::<f64>()
    };
    let best =
        (0..180).map(|i| (i as f64 * 0.5).to_radians()).min_by(|a, b| cost(*a).total_cmp(&cost(*b))).unwrap_or(0.0);
    let (e1, e2) = (Vector2::new(best.cos(), best.sin()), Vector2::new(-best.sin(), best.cos()));
    if e1.dot(principal).abs() >= e2.dot(principal).abs() {
        e1
    } else {
        e2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn car_points(heading: f64, faces: &[(f64, f64, f64, f64)], n: usize) -> Vec<Vector3<f64>> {
        // faces in the car's frame as segments (x0, z0) → (x1, z1) at height 0 (camera y down is up)
        let (c, s) = (heading.cos(), heading.sin());
        let mut out = Vec::new();
        for &(x0, z0, x1, z1) in faces {
            for i in 0..n {
                let t = (i as f64 + 0.5) / n as f64;
                let (x, z) = (x0 + t * (x1 - x0), z0 + t * (z1 - z0));
                // world: x right, z forward; heading measured from world x towards z; car centre at (0, 0, 15)
                let h = (i % 3) as f64 * 0.3;
                out.push(Vector3::new(c * x - s * z, -h, 15.0 + s * x + c * z));
            }
        }
        out
    }

    const F: f64 = 718.0;
    const B: f64 = 0.54;

    #[test]
    fn a_side_face_gives_the_heading_along_it() {
        let heading = 0.3;
        let pts = car_points(heading, &[(-2.1, -0.85, 2.1, -0.85)], 30);
        let r = point_yaw(&pts, &Vector3::y(), &Vector3::zeros(), &ObjectPrior::car(), F, B, &Default::default());
        let PointYaw::Cue { cue, rear_face, .. } = r else { panic!("{r:?}") };
        assert!(!rear_face);
        let dir = cue.direction.normalize();
        let want = Vector3::new(heading.cos(), 0.0, heading.sin());
        // the test's points carry no depth noise, but the model takes the expected noise out: a small bias
        assert!(dir.cross(&want).norm() < 0.03, "{dir:?}");
    }

    #[test]
    fn a_rear_face_seen_from_behind_gives_its_normal() {
        // car heading along world z (away from the camera), only its rear face (x = -2.1) visible
        let heading = std::f64::consts::FRAC_PI_2;
        let pts = car_points(heading, &[(-2.1, -0.85, -2.1, 0.85)], 30);
        let r = point_yaw(&pts, &Vector3::y(), &Vector3::zeros(), &ObjectPrior::car(), F, B, &Default::default());
        let PointYaw::Cue { cue, rear_face, .. } = r else { panic!("{r:?}") };
        assert!(rear_face);
        assert!(cue.direction.normalize().cross(&Vector3::z()).norm() < 0.01, "{cue:?}");
    }

    #[test]
    fn a_blob_or_too_few_points_decide_nothing() {
        let few = car_points(0.0, &[(-2.1, -0.85, 2.1, -0.85)], 5);
        let r = point_yaw(&few, &Vector3::y(), &Vector3::zeros(), &ObjectPrior::car(), F, B, &Default::default());
        assert!(matches!(r, PointYaw::TooFew(5)), "{r:?}");
        // both long faces: a 4.2 × 1.7 m rectangle's outline is elongated, but a square blob is not
        let square = car_points(
            0.0,
            &[(-1.0, -1.0, 1.0, -1.0), (1.0, -1.0, 1.0, 1.0), (1.0, 1.0, -1.0, 1.0), (-1.0, 1.0, -1.0, -1.0)],
            10,
        );
        let r = point_yaw(&square, &Vector3::y(), &Vector3::zeros(), &ObjectPrior::car(), F, B, &Default::default());
        assert!(matches!(r, PointYaw::Ambiguous { .. }), "{r:?}");
    }

    #[test]
    fn depth_noise_is_taken_out_before_the_direction_is_read() {
        // a rear face 1.7 m wide at 30 m with points spread ±σ_z along the ray: uncorrected, the spread
        // along the ray (σ_z ≈ 1.2 m, a 4 m extent) would look like a car's side and turn it across
        let z = 30.0;
        let sz = z * z * 0.5 / (F * B);
        let mut pts = Vec::new();
        for i in 0..40 {
            let x = -0.85 + 1.7 * (i as f64 + 0.5) / 40.0;
            // a deterministic ±σ_z pattern (mean 0, variance σ_z²)
            let dz = if i % 2 == 0 { sz } else { -sz };
            pts.push(Vector3::new(x, 0.0, z + dz));
        }
        let raw = point_yaw(&pts, &Vector3::y(), &Vector3::zeros(), &ObjectPrior::car(), F, 1e9, &Default::default());
        // without noise (huge baseline) the spread along the ray looks like a car's side
        assert!(matches!(raw, PointYaw::Cue { rear_face: false, .. }), "{raw:?}");
        let r = point_yaw(&pts, &Vector3::y(), &Vector3::zeros(), &ObjectPrior::car(), F, B, &Default::default());
        // with the noise taken out what is left (1.7 m across) is shorter than twice σ_z: not confident
        assert!(!matches!(r, PointYaw::Cue { rear_face: false, .. }), "{r:?}");
    }
}
