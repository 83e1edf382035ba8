//! Motion evidence from the stereo points: the robust trend of an object's centroids
//! ([`ObjectMapper::add_points`]), the scene flow of its points between frames
//! ([`ObjectMapper::add_flow`], [`scene_flow`]), and the flow that refutes a trend.

use nalgebra::Vector3;
use slam_core::figure::median;
use slam_core::{PointId, TrackId};

use super::{class_prior, object::TrendFlag, MappedObject, ObjectMapper, PointsCentroid};

impl ObjectMapper {
    /// Keep a sample of the object's stereo points in the frame of its latest box (its left camera's
    /// frame, each with its depth σ), for the surface cue of its fits
    /// ([`slam_optim::object::Cues::surface_points`]).
    pub fn add_surface(&mut self, id: TrackId, points: &[(Vector3<f64>, f64)]) {
        let Some(obj) = self.objects.get_mut(&id) else { return };
        let Some(frame) = obj.observations.last().map(|o| o.frame) else { return };
        obj.surface.insert(frame, points.to_vec());
    }

    /// Attach map points seen inside the object's latest box and where they put the object (callers pass
    /// `None` when too few points support it); flags the object as moving when its stereo points have
    /// carried it away from where they first put it.
    ///
    /// The displacement `d` is the robust trend of the object's centroids ([`trend`]: a repeated-median
    /// slope over the latest centroids times the frames they span), read once the object has
    /// [`MIN_MOTION_CENTROIDS`]. A trend, not the distance of the latest centroid from the median of
    /// the earlier ones: that median trails a steady motion by half the track, and one centroid on the
    /// wrong surface moves neither the trend nor the test.
    ///
    /// `d` is split along the latest viewing ray and across it. Along the ray its σ combines the stereo
    /// depth noise (`σ_z = z² σ_d / (f b)`, the median over the first and over the latest
    /// [`MOTION_WINDOW`] of the centroids the trend reads) with the wander of the
    /// visible surface over the object (`s = a / √3`, the σ of a point uniform over the class's
    /// half-length `a`: which side of a car is seen changes with the view); across the ray, `s` and the
    /// first views' depth noise (the ray turns as the camera passes). A static object stays within a
    /// few σ whatever its depth, since its visible surface cannot leave the object; a car driving ahead
    /// at the camera's speed keeps its depth, so its points move with the camera and leave them. The
    /// object is flagged after two failing tests in a row.
    pub fn add_points(&mut self, id: TrackId, points: &[PointId], centroid: Option<PointsCentroid>) {
        let cfg = self.config;
        let Some(obj) = self.objects.get_mut(&id) else { return };
        obj.points.extend(points.iter().copied());
        let class = obj.class;
        let Some(last) = obj.observations.last_mut() else { return };
        last.centroid = centroid.map(|c| c.position);
        last.depth_sigma = centroid.map_or(0.0, |c| c.depth_sigma);
        tracing::trace!(object = %id, frame = last.frame, bbox = ?last.bbox, ?centroid, points = points.len(), "object points");
        let camera = last.camera.world_from_camera.translation.vector;
        if centroid.is_none() {
            return;
        }
        let all: Vec<(usize, Vector3<f64>, f64)> =
            obj.observations.iter().filter_map(|o| o.centroid.map(|c| (o.frame, c, o.depth_sigma))).collect();
        if all.len() < MIN_MOTION_CENTROIDS {
            return;
        }
        // the trend's own span: the depth noise at both ends of the centroids it reads
        let read = &all[all.len().saturating_sub(TREND_CENTROIDS)..];
        let k = MOTION_WINDOW.min(read.len() / 2);
        let (first, now) = (median_sigma(&read[..k]), median_sigma(&read[read.len() - k..]));
        let d = trend(read);
        let Some(ray) = (all[all.len() - 1].1 - camera).try_normalize(1e-9) else {
            return;
        };
        let split = RaySplit::of(&d, &ray);
        let s = class_prior(class).axes.x / 3f64.sqrt();
        let sigma_along = (now.powi(2) + first.powi(2) + s * s).sqrt();
        let sigma_across = (first.powi(2) + s * s).sqrt();
        let m = split.sigmas((sigma_along, sigma_across));
        let (from, to) = (read[0].0, read[read.len() - 1].0);
        // the trend's rate (motion per frame id) and its σ along and across the ray
        let span = (to - from).max(1) as f64;
        let trend_rate = (d / span, (sigma_along / span, sigma_across / span));
        let vetoed = m > cfg.dynamic_motion_sigmas
            && flow_refutes(&obj.flows, (from, to), trend_rate, &ray, cfg.dynamic_motion_sigmas);
        if vetoed {
            tracing::debug!(object = %id, sigmas = m, "centroid trend refuted by the points' own scene flow");
        }
        obj.motion_strikes = if m > cfg.dynamic_motion_sigmas && !vetoed { obj.motion_strikes + 1 } else { 0 };
        if obj.motion_strikes >= 2 && !obj.moving {
            tracing::info!(
                "object {} ({}) moved {:.1} m from frame {from} to {to} ({:.1} m along the viewing ray, {:.1} m across; {m:.1} σ of the stereo noise): moving, not mapped",
                id.0,
                obj.class.name(),
                d.norm(),
                split.along,
                split.across
            );
            obj.trend_flag = Some(TrendFlag {
                frame: to,
                rate: trend_rate.0,
                rate_sigma: trend_rate.1,
                ray,
                was_dynamic: obj.dynamic,
            });
            obj.moving = true;
            obj.dynamic = true;
        }
    }

    /// The scene flow of the object's points between the frame before and this one (`frame` and `gap`:
    /// this frame's id and the ids since the frame before, [`scene_flow`]): two readings of consecutive
    /// frames that each stand more than `dynamic_motion_sigmas` σ above their noise, and whose sum (the
    /// motion over both frames) does too, flag the object as moving. The first reading is the object's
    /// own, or else `same_box`: that of the box its box overlaps in the frame before (the caller's
    /// IoU ≥ 0.5), the same physical object under another track (the association
    /// starts a new track when the detector calls a van a car, then a truck). The sum is what a single
    /// bad pose cannot fake: an error of frame k moves every point by +δ in the reading that ends at k
    /// and by −δ in the next, which cancel. The same points seen in two consecutive frames barely change
    /// view, so their 3-D motion is measured to their depth noise alone (with twenty points, about 0.4 m
    /// per frame at 15 m, 0.16 m at 6 m is 3 σ): traffic moving against the camera is found within a few
    /// frames, where the centroid test ([`ObjectMapper::add_points`]), which must allow for the visible
    /// surface wandering over the object as the view turns, needs it to move by about its own size. An
    /// object already mapped as static is left to the centroid test: two frames of motion under a track
    /// its boxes and points have agreed with for many views are likelier another object taken over by
    /// the association than a parked car pulling out.
    pub fn add_flow(
        &mut self,
        id: TrackId,
        (frame, gap): (usize, usize),
        flow: &SceneFlow,
        same_box: Option<&SceneFlow>,
    ) {
        let cfg = self.config;
        let Some(obj) = self.objects.get_mut(&id) else { return };
        // the reading of the frame before: its own, else that of the box it overlaps there
        let own = obj.flows.last().filter(|(f, _, _)| f + gap == frame).map(|&(_, _, b)| b);
        let before = own.or(same_box.copied());
        obj.flows.push((frame, gap, *flow));
        if obj.moving {
            // flagged by its centroid trend (which mixes the objects an association switch put under
            // one track), refuted by its own points: still, and excluding the trend's rate, over the
            // last readings, all after the flag
            let Some(t) = obj.trend_flag else { return };
            let k = obj.flows.len();
            if k < MIN_REFUTING_READINGS {
                return;
            }
            let (first, first_gap, _) = obj.flows[k - MIN_REFUTING_READINGS];
            let from = first.saturating_sub(first_gap);
            if from >= t.frame
                && flow_refutes(&obj.flows, (from, frame), (t.rate, t.rate_sigma), &t.ray, cfg.dynamic_motion_sigmas)
            {
                tracing::info!(
                    "object {} ({}): flagged moving by its centroid trend at frame {}, its points have stood still since frame {from} (scene flow): static again, its observations before that dropped",
                    id.0,
                    obj.class.name(),
                    t.frame
                );
                obj.moving = false;
                obj.dynamic = t.was_dynamic;
                obj.trend_flag = None;
                obj.motion_strikes = 0;
                // what made the trend was another object under this track: its boxes, centroids and
                // map points before the still readings are dropped (the next keyframes give it points
                // again), and the object is fitted afresh from the rest, with fresh counters
                // (this run's: the boxes of an earlier run, a loaded map's, have frame ids of their own and
                // are kept)
                let earlier = obj.earlier.min(obj.observations.len());
                let mut k = 0;
                obj.observations.retain(|o| {
                    k += 1;
                    k <= earlier || o.frame >= from
                });
                obj.surface.retain(|&f, _| f >= from);
                obj.points.clear();
                obj.ellipsoid = None;
                obj.fitted_at = 0;
                obj.misses = 0;
                obj.free_frames = 0;
                obj.generation += 1;
            }
            return;
        }
        if obj.ellipsoid.is_some() && !obj.dynamic {
            // mapped as static: its own boxes and points have agreed for views on end, so two frames
            // of motion are likelier another object under its track (an association switch) than a
            // parked car pulling out; the centroid test still watches it
            return;
        }
        let m = flow.sigmas();
        tracing::debug!(
            object = %id,
            points = flow.points,
            along = flow.split().along,
            across = flow.split().across,
            sigmas = m,
            "scene flow"
        );
        let limit = cfg.dynamic_motion_sigmas;
        let confirmed = before.is_some_and(|b| b.sigmas() > limit && SceneFlow::over_both(&b, flow).sigmas() > limit);
        if m > limit && confirmed && !obj.moving {
            tracing::info!(
                "object {} ({}): its {} points moved {:.2} m into frame {frame} ({:.2} m along the viewing ray, {:.2} m across; {m:.1} σ of the stereo noise): moving, not mapped",
                id.0,
                obj.class.name(),
                flow.points,
                flow.split().norm(),
                flow.split().along,
                flow.split().across
            );
            obj.moving = true;
            obj.dynamic = true;
        }
    }
}

/// A stereo point of an object followed from the frame before into this one (optical flow): its world
/// positions in both frames and the σ of each along its viewing ray (stereo depth noise) and across it
/// (a pixel of image noise at its depth), metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlowedPoint {
    /// World position in the frame before, metres.
    pub before: Vector3<f64>,
    /// World position in this frame, metres.
    pub now: Vector3<f64>,
    /// σ of the motion along the viewing ray (both frames' depth noise), metres.
    pub sigma_along: f64,
    /// σ of the motion across the ray (a pixel at both depths), metres.
    pub sigma_across: f64,
}

/// Fewest flowed points for a scene-flow reading (as for a centroid: [`MIN_OBJECT_POINTS`] in the
/// pipeline).
pub const MIN_FLOW_POINTS: usize = 5;

/// What every point's motion between two frames shares beyond its own noise, as a σ in metres: the
/// error of the tracker's frame-to-frame step (median 0.027 m on odometry 06 and 0.028 m on drive 0005
/// against the INS, session 11) and a keyframe correction from the mapper applied between the two
/// frames (up to 0.04 m, session 10).
pub const FLOW_POSE_SIGMA_M: f64 = 0.05;

pub use super::flow::{RaySplit, SceneFlow};

/// The scene flow of `points` seen from a camera at `camera` (world position, this frame); `None`
/// below [`MIN_FLOW_POINTS`]. The median per world axis: up to half the points may be followed onto
/// another surface (a flow vector that slid off the object onto the road behind it). Each point's σ is
/// its stereo noise, or the points' own scatter about their median where that is larger (1.4826 × the
/// median absolute deviation, along and across the ray: points followed onto another surface, or
/// depths of neighbouring pixels that share their errors, spread more than each one's noise says), so
/// that a reading is never more certain than its points agree.
pub fn scene_flow(points: &[FlowedPoint], camera: &Vector3<f64>) -> Option<SceneFlow> {
    let n = points.len();
    if n < MIN_FLOW_POINTS {
        return None;
    }
    let axis_median =
        |f: &dyn Fn(&FlowedPoint) -> f64| median(&mut points.iter().map(f).collect::<Vec<_>>()).unwrap_or(f64::NAN);
    let motion = Vector3::new(
        axis_median(&|p| p.now.x - p.before.x),
        axis_median(&|p| p.now.y - p.before.y),
        axis_median(&|p| p.now.z - p.before.z),
    );
    let at = Vector3::new(axis_median(&|p| p.now.x), axis_median(&|p| p.now.y), axis_median(&|p| p.now.z));
    let ray = (at - camera).try_normalize(1e-9)?;
    let rms = |f: &dyn Fn(&FlowedPoint) -> f64| (points.iter().map(|p| f(p).powi(2)).sum::<f64>() / n as f64).sqrt();
    // the points' scatter about the median motion, along and across the ray
    let spread = |f: &dyn Fn(&Vector3<f64>) -> f64| {
        1.4826
            * median(&mut points.iter().map(|p| f(&(p.now - p.before - motion)).abs()).collect::<Vec<_>>())
                .unwrap_or(f64::NAN)
    };
    let along = rms(&|p| p.sigma_along).max(spread(&|d| d.dot(&ray)));
    let across = rms(&|p| p.sigma_across).max(spread(&|d| (d - ray * d.dot(&ray)).norm()));
    let of_median = |s: f64| ((1.2533 * s / (n as f64).sqrt()).powi(2) + FLOW_POSE_SIGMA_M.powi(2)).sqrt();
    Some(SceneFlow::new(motion, ray, (of_median(along), of_median(across)), n))
}

/// Fewest scene-flow readings over a trend's span that can refute it ([`flow_refutes`]).
const MIN_REFUTING_READINGS: usize = 3;

/// Whether the object's scene-flow readings over the frames `span` (at least
/// [`MIN_REFUTING_READINGS`]) refute its centroid trend: their mean rate (motion per frame id, σ from
/// each reading's) stands within `limit` σ of standing still and more than `limit` σ (the two rates'
/// σ combined) away from the trend's rate (`trend`: rate, motion per frame id, and its σ along and
/// across `ray`). The trend reads where the
/// object's points put it frame after frame, so centroids on another object (a box that slid, a track
/// merged into this one) move it; the flow follows the same points from each frame to the next and
/// does not see them. A slow mover whose flow is too noisy to exclude its trend is not refuted.
fn flow_refutes(
    flows: &[(usize, usize, SceneFlow)],
    (from, to): (usize, usize),
    (rate, (rate_along, rate_across)): (Vector3<f64>, (f64, f64)),
    ray: &Vector3<f64>,
    limit: f64,
) -> bool {
    let within: Vec<&(usize, usize, SceneFlow)> =
        flows.iter().filter(|(f, gap, _)| *f > from && *f <= to && *gap > 0).collect();
    let k = within.len();
    if k < MIN_REFUTING_READINGS {
        return false;
    }
    let kf = k as f64;
    let mean = within.iter().map(|(_, gap, r)| r.motion / *gap as f64).sum::<Vector3<f64>>() / kf;
    let var = |s: &dyn Fn(&SceneFlow) -> f64| {
        within.iter().map(|(_, gap, r)| (s(r) / *gap as f64).powi(2)).sum::<f64>() / (kf * kf)
    };
    let (flow_along, flow_across) = (var(&|r| r.sigma_along).sqrt(), var(&|r| r.sigma_across).sqrt());
    let still = RaySplit::of(&mean, ray).sigmas((flow_along, flow_across)) <= limit;
    let combined = (flow_along.hypot(rate_along), flow_across.hypot(rate_across));
    still && RaySplit::of(&(rate - mean), ray).sigmas(combined) > limit
}

/// Centroids at each end of those the motion test reads whose median depth noise it takes for that
/// end (see [`ObjectMapper::add_points`]).
pub const MOTION_WINDOW: usize = 3;

/// Fewest centroids the motion test reads: with four, the repeated median still holds when one of
/// them lies on another object.
pub(super) const MIN_MOTION_CENTROIDS: usize = 4;

/// Median depth σ of centroids.
fn median_sigma(c: &[(usize, Vector3<f64>, f64)]) -> f64 {
    median(&mut c.iter().map(|p| p.2).collect::<Vec<_>>()).unwrap_or(f64::NAN)
}

/// The displacement of an object over centroids `c` (the latest [`TREND_CENTROIDS`] of its track)
/// that their trend explains: the repeated-median slope (Siegel's estimator, per world axis: for each
/// centroid the median of its slopes to every other, then the median of those) times the frames they
/// span. A robust trend: up to
/// half of the centroids can lie on another object (a box that slid onto a car passing in front)
/// without moving it, and the noise of single frames averages out.
fn trend(c: &[(usize, Vector3<f64>, f64)]) -> Vector3<f64> {
    let span = (c[c.len() - 1].0 - c[0].0) as f64;
    let (mut to_others, mut per_point) = (Vec::with_capacity(c.len()), Vec::with_capacity(c.len()));
    let mut slope = |k: usize| {
        per_point.clear();
        for a in c {
            to_others.clear();
            to_others.extend(c.iter().filter(|b| b.0 != a.0).map(|b| (b.1[k] - a.1[k]) / (b.0 as f64 - a.0 as f64)));
            if !to_others.is_empty() {
                per_point.push(median(&mut to_others).unwrap_or(f64::NAN));
            }
        }
        if per_point.is_empty() {
            0.0
        } else {
            median(&mut per_point).unwrap_or(f64::NAN)
        }
    };
    Vector3::new(slope(0), slope(1), slope(2)) * span
}

/// A moving object's world motion per frame id now, for predicting where it is next
/// ([`super::association::predict_box`]): two measurements of it fused by their noise, along the
/// viewing ray (where stereo is poor) and across it, each where it has one:
/// - the repeated-median slope ([`trend`]) of its latest [`MIN_MOTION_CENTROIDS`] centroids (the
///   fewest over which one centroid on another object cannot move it), its σ the motion test's
///   ([`ObjectMapper::add_points`]: the depth noise at both ends and the visible surface's wander
///   over the object, `a / √3` for the class's half-length `a`) over the frames they span;
/// - the per-axis median of its latest [`RATE_READINGS`] scene-flow readings (one reading that slid
///   onto another surface cannot carry the box away) that are fresh, ending in one of its latest
///   [`RATE_READINGS`] observed frames; σ the latest one's over its gap. A reading older than that tells the motion of
///   another moment: at low frame rates the optical flow loses a thin object (a rider) for several
///   frames, and its last reading would otherwise be replayed while the object turns.
///
/// `None` with neither.
pub(super) fn current_rate(o: &MappedObject) -> Option<Vector3<f64>> {
    let last = o.observations.last()?;
    let camera = last.camera.centre();
    let centroids: Vec<(usize, Vector3<f64>, f64)> =
        o.observations.iter().filter_map(|x| x.centroid.map(|c| (x.frame, c, x.depth_sigma))).collect();
    let by_centroids = (centroids.len() >= MIN_MOTION_CENTROIDS)
        .then(|| &centroids[centroids.len() - MIN_MOTION_CENTROIDS..])
        .and_then(|c| {
            let span = (c[c.len() - 1].0 - c[0].0) as f64;
            let ray = (c[c.len() - 1].1 - camera).try_normalize(1e-9)?;
            let (first, now) = (median_sigma(&c[..2]), median_sigma(&c[2..]));
            let s = class_prior(o.class).axes.x / 3f64.sqrt();
            let sigmas = ((first.powi(2) + now.powi(2) + s * s).sqrt() / span, (first.powi(2) + s * s).sqrt() / span);
            (span > 0.0 && sigmas.0 > 0.0).then(|| (trend(c) / span, ray, sigmas))
        });
    let since = o.observations.iter().rev().nth(RATE_READINGS - 1).map_or(0, |x| x.frame);
    let recent = &o.flows[o.flows.len().saturating_sub(RATE_READINGS)..];
    let fresh: Vec<&(usize, usize, SceneFlow)> = recent.iter().filter(|r| r.0 >= since).collect();
    let by_flow = fresh.last().map(|&&(_, gap, latest)| {
        let axis = |k: usize| {
            let mut v: Vec<f64> = fresh.iter().map(|(_, gap, f)| f.motion[k] / (*gap).max(1) as f64).collect();
            median(&mut v).unwrap_or(f64::NAN)
        };
        let g = gap.max(1) as f64;
        (Vector3::new(axis(0), axis(1), axis(2)), latest.ray, (latest.sigma_along / g, latest.sigma_across / g))
    });
    match (by_centroids, by_flow) {
        (Some(c), Some(f)) => Some(fuse_along_ray(c, f)),
        (c, f) => c.or(f).map(|x| x.0),
    }
}

/// Two measurements of one motion `(value, ray, (σ along, σ across))` fused by inverse variance
/// along the first's ray and across it.
fn fuse_along_ray(
    (a, ray, (sa, sa_x)): (Vector3<f64>, Vector3<f64>, (f64, f64)),
    (b, _, (sb, sb_x)): (Vector3<f64>, Vector3<f64>, (f64, f64)),
) -> Vector3<f64> {
    let w = |x: f64| 1.0 / (x * x).max(1e-18);
    let blend = |s: f64, t: f64, u: f64, v: f64| (w(s) * u + w(t) * v) / (w(s) + w(t));
    let (ia, ib) = (a.dot(&ray), b.dot(&ray));
    let along = blend(sa, sb, ia, ib);
    let across = (a - ray * ia) * (w(sa_x) / (w(sa_x) + w(sb_x))) + (b - ray * ib) * (w(sb_x) / (w(sa_x) + w(sb_x)));
    ray * along + across
}

/// Scene-flow readings a moving object's rate is the median of ([`current_rate`]).
const RATE_READINGS: usize = 3;

/// Most centroids the motion test reads (the latest ones): 30 frames, three seconds of KITTI; the
/// slope is the object's motion now, and the pairs of the repeated median stay few.
const TREND_CENTROIDS: usize = 30;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::objects::StereoNoise;

    /// Centroids of frames `0..n`: `at(i)` each, with a seeded jitter of ±`noise` metres per axis.
    fn centroids(n: usize, noise: f64, at: impl Fn(usize) -> Vector3<f64>) -> Vec<(usize, Vector3<f64>, f64)> {
        let mut rng = slam_core::rng::SimRng::new(7);
        (0..n)
            .map(|i| {
                let jitter =
                    Vector3::new(rng.uniform(-noise, noise), rng.uniform(-noise, noise), rng.uniform(-noise, noise));
                (i, at(i) + jitter, 0.4)
            })
            .collect()
    }

    /// A rider 8 m ahead crossing at 0.35 m per frame id towards -x, seen every third frame: its rate
    /// comes from its centroids when its only scene-flow reading is stale (the optical flow lost it
    /// 12 frames ago, when it still rode straight ahead), from both fused by their noise when a fresh
    /// reading exists (a reading precise along the viewing ray wins along it, the centroids across
    /// it), from a fresh reading alone before it
    /// has centroids enough, and not at all with neither.
    #[test]
    fn a_moving_object_s_rate_is_read_from_fresh_evidence() {
        use crate::objects::Observation;
        use slam_core::ClassId;
        use slam_quadric::{Camera, Intrinsics};
        let k = Intrinsics::new(721.5, 721.5, 609.6, 172.9);
        let mut rider = MappedObject::new(TrackId(1), ClassId(0));
        let at = |f: usize| Vector3::new(2.0 - 0.35 * f as f64, 0.5, 8.0 + 0.4 * f as f64);
        for f in (0..=15).step_by(3) {
            let camera = Camera::new(k, nalgebra::Isometry3::translation(0.0, 0.0, 0.4 * f as f64));
            let bbox = slam_core::geometry::BBox::new(600.0, 150.0, 680.0, 330.0);
            rider.observations.push(Observation {
                frame: f,
                camera,
                bbox,
                class: ClassId(0),
                detection: 0,
                centroid: Some(at(f)),
                depth_sigma: 0.05,
                reference: None,
            });
        }
        let truth = Vector3::new(-0.35, 0.0, 0.4);
        let straight = SceneFlow::new(Vector3::new(0.0, 0.0, 1.2), Vector3::z(), (0.02, 0.02), 30);
        rider.flows = vec![(3, 3, straight)];
        let stale = current_rate(&rider).expect("centroids");
        assert!((stale - truth).norm() < 1e-9, "{stale:?}");
        // a fresh reading, precise along the ray and vague across it, pulls the along part only
        let fresh = SceneFlow::new(Vector3::new(-0.6, 0.0, 1.5), Vector3::z(), (0.003, 3.0), 30);
        rider.flows.push((15, 3, fresh));
        let fused = current_rate(&rider).expect("both");
        let ray = (at(15) - Vector3::new(0.0, 0.0, 6.0)).normalize();
        let (read, split) = (fresh.motion / 3.0, |v: Vector3<f64>| (v.dot(&ray), v - ray * v.dot(&ray)));
        assert!((split(fused).0 - split(read).0).abs() < 0.01, "along the ray the reading wins: {fused:?}");
        assert!((split(fused).1 - split(truth).1).norm() < 0.01, "across it the centroids win: {fused:?}");
        assert!((split(read).0 - split(truth).0).abs() > 0.03, "the two differ along the ray");
        // before four centroids: the fresh reading alone
        let mut young = rider.clone();
        young.observations.truncate(3);
        young.flows = vec![(6, 3, fresh)];
        assert!((current_rate(&young).expect("a reading") - fresh.motion / 3.0).norm() < 1e-9);
        young.flows.clear();
        assert!(current_rate(&young).is_none());
    }

    /// Scene flow: twenty points on a car 15 m ahead, each with its stereo depth noise (σ_z at 15 m,
    /// 0.5 px of disparity, KITTI's rig: 0.29 m) in both frames. Parked, the flow stays within 3 σ;
    /// pulling away by 0.5 m per frame (5 m/s faster than the camera at 10 Hz) it stands above; with a
    /// quarter of thirty points followed onto the static road under it, the median still sees the car's
    /// motion (0.8 m per frame); fewer than five points give no reading.
    #[test]
    fn scene_flow_sees_a_car_pull_away_and_not_a_parked_one() {
        let noise = StereoNoise { focal_baseline: 721.5 * 0.54, disparity_sigma_px: 0.5, core: 0.6 };
        let camera = Vector3::zeros();
        let mut rng = slam_core::rng::SimRng::new(11);
        let mut points = |motion: f64, n: usize, static_share: f64| -> Vec<FlowedPoint> {
            (0..n)
                .map(|k| {
                    let x = Vector3::new(rng.uniform(-0.8, 0.8), rng.uniform(-0.5, 0.5), 15.0 + rng.uniform(0.0, 0.3));
                    let sz = noise.depth_sigma(x.z);
                    let moved = if (k as f64) < static_share * n as f64 { 0.0 } else { motion };
                    let ray = x.normalize();
                    let before = x + ray * (sz * rng.normal());
                    let now = x + Vector3::new(0.0, 0.0, moved) + ray * (sz * rng.normal());
                    FlowedPoint { before, now, sigma_along: sz * 2f64.sqrt(), sigma_across: x.z / 721.5 * 2f64.sqrt() }
                })
                .collect()
        };
        let parked = scene_flow(&points(0.0, 20, 0.0), &camera).expect("a reading");
        assert!(parked.sigmas() < 3.0, "{parked:?}");
        let pulling = scene_flow(&points(0.5, 20, 0.0), &camera).expect("a reading");
        assert!(pulling.sigmas() > 3.0 && pulling.split().along > 0.3, "{pulling:?}");
        let partly_road = scene_flow(&points(0.8, 30, 0.25), &camera).expect("a reading");
        assert!(partly_road.sigmas() > 3.0 && partly_road.split().along > 0.3, "{partly_road:?}");
        assert!(scene_flow(&points(1.0, MIN_FLOW_POINTS - 1, 0.0), &camera).is_none());
        // points whose motions scatter far beyond their stereo noise (flows that slid between a parked
        // van and a rack 18 m in front of it: half read +1.5 m, half -1.5 m, each claiming 0.1 m of
        // noise) make a reading as uncertain as their scatter, not a confident 3 σ motion
        let sliding: Vec<FlowedPoint> = (0..24)
            .map(|k| {
                let x = Vector3::new(0.1 * k as f64, 0.0, 40.0);
                let dz = if k % 2 == 0 { 1.5 } else { -1.45 };
                FlowedPoint { before: x, now: x + Vector3::new(0.0, 0.0, dz), sigma_along: 0.1, sigma_across: 0.05 }
            })
            .collect();
        let r = scene_flow(&sliding, &camera).expect("a reading");
        assert!(r.sigma_along > 0.5, "{r:?}");
        assert!(r.sigmas() < 3.0, "{r:?}");
    }

    /// The scene flow refutes a centroid trend only when its own readings over the trend's span say
    /// "still" precisely enough to exclude the trend's rate: a parked van whose centroids were pulled
    /// 10 m by another object's (0.33 m per frame over 30 frames) is refuted by readings of 0 ± 0.1 m
    /// per frame; a van pulling away at that rate, read so by its flow, is not; a slow mover (0.05 m per
    /// frame) whose readings are too noisy to tell is not; nor with fewer than three readings in the
    /// span, or readings outside it.
    #[test]
    fn scene_flow_refutes_a_trend_only_when_it_can_exclude_it() {
        let ray = Vector3::new(0.0, 0.0, 1.0);
        let reading = |dz: f64, sigma: f64| SceneFlow::new(Vector3::new(0.0, 0.0, dz), ray, (sigma, 0.05), 20);
        let readings = |dz: f64, sigma: f64, frames: &[usize]| -> Vec<(usize, usize, SceneFlow)> {
            frames.iter().map(|&f| (f, 1, reading(dz, sigma))).collect()
        };
        // the trend's displacement σ (1.3 m along, 1.2 m across) over its 30 frames
        let trend = |rate: f64| (Vector3::new(0.0, 0.0, rate), (1.3 / 30.0, 1.2 / 30.0));
        let span = (10, 40);
        let some: Vec<usize> = vec![12, 20, 27, 33, 38];
        assert!(flow_refutes(&readings(0.02, 0.1, &some), span, trend(10.0 / 30.0), &ray, 3.0), "a parked van");
        assert!(!flow_refutes(&readings(0.33, 0.1, &some), span, trend(10.0 / 30.0), &ray, 3.0), "a van pulling away");
        assert!(!flow_refutes(&readings(0.0, 0.6, &some), span, trend(0.05), &ray, 3.0), "a slow mover, noisy flow");
        assert!(!flow_refutes(&readings(0.02, 0.1, &[12, 20]), span, trend(10.0 / 30.0), &ray, 3.0), "two readings");
        assert!(!flow_refutes(&readings(0.02, 0.1, &[2, 5, 8, 45]), span, trend(10.0 / 30.0), &ray, 3.0), "outside");
    }

    #[test]
    fn trend_sees_a_steady_motion_and_not_centroids_on_another_object() {
        // a van driving ahead: 0.45 m per frame away from the camera, 0.2 m of depth noise
        let moving = centroids(12, 0.2, |i| Vector3::new(-4.0, 1.0, 11.0 + 0.45 * i as f64));
        let d = trend(&moving);
        assert!((d.z - 0.45 * 11.0).abs() < 0.5 && d.x.abs() < 0.5, "{d:?}");
        // a parked van 40 m ahead whose box slid onto a car passing 20 m nearer in the two latest frames
        // (two of five, then two of eight): the trend stays put; a least-squares slope would not
        for n in [5, 8] {
            let parked = centroids(n, 0.3, |i| Vector3::new(-13.3, 1.2, if i + 2 >= n { 21.0 } else { 40.0 }));
            let d = trend(&parked);
            // far inside what the motion test allows a static car (3 σ, over 3.6 m from its size alone)
            assert!(d.norm() < 2.0, "{n} centroids: {d:?}");
            let (t, z): (Vec<f64>, Vec<f64>) = parked.iter().map(|c| (c.0 as f64, c.1.z)).unzip();
            let (tm, zm) = (t.iter().sum::<f64>() / n as f64, z.iter().sum::<f64>() / n as f64);
            let ls = t.iter().zip(&z).map(|(a, b)| (a - tm) * (b - zm)).sum::<f64>()
                / t.iter().map(|a| (a - tm).powi(2)).sum::<f64>();
            assert!((ls * (n - 1) as f64).abs() > 3.0, "least squares is pulled by the other object: {ls}");
        }
        // one centroid and none: no trend
        assert_eq!(trend(&moving[..1]), Vector3::zeros());
    }
}
