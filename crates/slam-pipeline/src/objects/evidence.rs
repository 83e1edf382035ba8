//! Evidence for and against a static ellipsoid: where the object's stereo points put it (the gate
//! of a fit), the frames in which it should have been detected and was not
//! ([`MapperConfig::max_misses`]), free space seen through it ([`ObjectMapper::check_free_space`]),
//! and the stereo depth of its visible surface ([`surface_cue`]).

use std::collections::BTreeMap;

use nalgebra::Vector3;
use slam_core::figure::median;
use slam_core::{geometry::BBox, Detection, FramePoint, TrackId};
use slam_optim::object::SurfaceCue;
use slam_quadric::{project, Camera, Ellipsoid};

use super::{class_prior, motion::MIN_MOTION_CENTROIDS, MappedObject, ObjectMapper, Observation, RaySplit};

impl ObjectMapper {
    /// Count, for every mapped static object, the frames in which it should have been detected and was
    /// not; remove its ellipsoid after `max_misses` in a row (see [`MapperConfig::max_misses`]).
    pub(super) fn count_misses(
        &mut self,
        camera: &Camera,
        projected: &BTreeMap<TrackId, BBox>,
        detections: &[Detection],
        tracks: &[Option<TrackId>],
    ) {
        let cfg = self.config;
        let Some(limit) = cfg.max_misses else { return };
        // a frame without boxes may be one the detector skipped
        if detections.is_empty() {
            return;
        }
        let seen: std::collections::BTreeSet<TrackId> =
            tracks.iter().flatten().map(|t| self.merged.get(t).copied().unwrap_or(*t)).collect();
        let from_world = camera.world_from_camera.inverse();
        let usable_of = |o: &MappedObject| {
            o.observations.iter().filter(|x| !x.bbox.touches_border(&cfg.image, cfg.border_margin_px)).count()
        };
        for o in self.objects.values_mut() {
            let (Some(e), Some(b)) = (o.ellipsoid, projected.get(&o.id)) else { continue };
            if o.dynamic || seen.contains(&o.id) {
                o.misses = 0;
                continue;
            }
            let depth = (from_world * nalgebra::Point3::from(e.centre())).z;
            // expected only as near as the detector has found it: a car's box shrinks with distance and
            // a small detector's recall with it, so the farthest of its own detections is the bound
            let centre = nalgebra::Point3::from(e.centre());
            let farthest = o.observations.iter().map(|x| (x.camera.camera_from_world() * centre).z).fold(0.0, f64::max);
            let in_view = depth > 0.0
                && depth < cfg.visible_depth_m.min(farthest + 1e-6)
                && !b.touches_border(&cfg.image, cfg.border_margin_px);
            let covered = detections.iter().any(|d| d.bbox.intersection(b).is_some_and(|x| x.area() >= 0.3 * b.area()));
            if !in_view || covered {
                continue;
            }
            o.misses += 1;
            if o.misses >= limit {
                tracing::debug!(object = %o.id, misses = o.misses, "visible but not detected: ellipsoid removed");
                o.ellipsoid = None;
                o.misses = 0;
                o.fitted_at = usable_of(o);
            }
        }
    }

    /// The free-space test ([`MapperConfig::free_space_frames`]) on one tracked frame: for every mapped
    /// static ellipsoid in full view within `visible_depth_m`, the frame's stereo points inside the
    /// central part of its projected box vote ([`free_space_votes`]); when at least
    /// [`MIN_FREE_SPACE_RAYS`] do and most of them see through it, the frame counts against it, and
    /// after `free_space_frames` such frames in a row its ellipsoid is removed (refitted when more
    /// boxes come; counted, [`ObjectMapper::free_space_removals`]). A frame with too few votes, or the
    /// object out of view, leaves the count as it is.
    pub fn check_free_space(&mut self, camera: &Camera, points: &[FramePoint], noise: &StereoNoise) {
        let cfg = self.config;
        let Some(limit) = cfg.free_space_frames else { return };
        if points.is_empty() {
            return;
        }
        let from_world = camera.world_from_camera.inverse();
        for o in self.objects.values_mut() {
            let Some(e) = o.ellipsoid else { continue };
            if o.dynamic || o.moving {
                continue;
            }
            let depth = (from_world * nalgebra::Point3::from(e.centre())).z;
            let Ok(b) = project(&e, camera).and_then(|c| c.clipped_bounds(&cfg.image)) else { continue };
            if depth <= 0.0 || depth >= cfg.visible_depth_m || b.touches_border(&cfg.image, cfg.border_margin_px) {
                continue;
            }
            // the fit may be off by about the object's own size: a point within that of its far side
            // may still lie on it
            let margin = class_prior(o.class).axes.x;
            let (through, on) = free_space_votes(&e, camera, &b, points, noise, margin);
            tracing::trace!(object = %o.id, through, on, depth, "free-space votes");
            if through + on < MIN_FREE_SPACE_RAYS {
                continue;
            }
            if through <= on {
                o.free_frames = 0;
                continue;
            }
            o.free_frames += 1;
            if o.free_frames >= limit {
                tracing::info!(
                    "object {} ({}): stereo sees free space where its ellipsoid stands ({through} of {} rays through it, {} frames in a row): removed",
                    o.id.0,
                    o.class.name(),
                    through + on,
                    o.free_frames
                );
                o.ellipsoid = None;
                o.free_frames = 0;
                o.fitted_at =
                    o.observations.iter().filter(|x| !x.bbox.touches_border(&cfg.image, cfg.border_margin_px)).count();
                self.free_space_removed += 1;
            }
        }
    }
}

/// The object's observations that have a stereo centroid, in frame order.
pub(super) fn with_centroids(obj: &MappedObject) -> Vec<&Observation> {
    obj.observations.iter().filter(|o| o.centroid.is_some()).collect()
}

/// Where the stereo points of `with` (observations with a centroid, at least one) put the object: the
/// per-axis median of their centroids, and the median of their depth σ.
pub(super) fn median_centroid(with: &[&Observation]) -> (Vector3<f64>, f64) {
    let axis = |k: usize| {
        median(&mut with.iter().filter_map(|o| o.centroid.map(|c| c[k])).collect::<Vec<_>>()).unwrap_or(f64::NAN)
    };
    (
        Vector3::new(axis(0), axis(1), axis(2)),
        median(&mut with.iter().map(|o| o.depth_sigma).collect::<Vec<_>>()).unwrap_or(f64::NAN),
    )
}

/// Whether an ellipsoid lies where the object's stereo points put it (see
/// [`MapperConfig::stereo_evidence`]): Mahalanobis distance of its centre from the median keyframe
/// centroid, along the ray (depth noise and surface spread) and across it (surface spread).
pub(super) fn stereo_agrees(obj: &MappedObject, e: &Ellipsoid, sigmas: f64) -> Result<(), String> {
    let with = with_centroids(obj);
    let Some(last) = with.last() else { return Err("no stereo points on it".into()) };
    let (c, sigma_z) = median_centroid(&with);
    let ray =
        (c - last.camera.world_from_camera.translation.vector).try_normalize(1e-9).ok_or("centroid at the camera")?;
    let RaySplit { along, across } = RaySplit::of(&(e.centre() - c), &ray);
    let s = class_prior(obj.class).axes.x / 3f64.sqrt();
    let m = RaySplit { along, across }.sigmas(((sigma_z * sigma_z + s * s).sqrt(), s));
    if m > sigmas {
        return Err(format!("{m:.1} σ from its stereo points ({along:+.1} m along the ray, {across:.1} m across)"));
    }
    Ok(())
}

/// The stereo rig's depth noise and the part of a box whose points are read: the object's stereo
/// points of the running system and [`ObjectMapper::check_free_space`] read them alike.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StereoNoise {
    /// Focal length times baseline, pixel metres (depth = this / disparity).
    pub focal_baseline: f64,
    /// Disparity noise σ, pixels.
    pub disparity_sigma_px: f64,
    /// Share of a box, per axis and about its centre, whose points are read (the running system's
    /// `object_core`).
    pub core: f64,
}

impl StereoNoise {
    /// Depth noise σ at depth `z`: `z² σ_d / (f b)`, metres.
    pub fn depth_sigma(&self, z: f64) -> f64 {
        z * z * self.disparity_sigma_px / self.focal_baseline
    }

    /// Whether pixel `(u, v)` lies in the central part (`core` of its width and height) of box `b`.
    pub fn in_core(&self, b: &BBox, u: f64, v: f64) -> bool {
        let [cu, cv] = b.centre();
        (u - cu).abs() <= 0.5 * self.core * b.width() && (v - cv).abs() <= 0.5 * self.core * b.height()
    }
}

/// Fewest stereo rays through an ellipsoid's central part for a free-space vote: with ten, a lone
/// point behind it (a reflection in a window, a mismatch) cannot make a majority.
pub const MIN_FREE_SPACE_RAYS: usize = 10;

/// How the frame's stereo points inside the central part (`noise.core`) of an ellipsoid's projected
/// box `b` relate to it, along each point's ray from `camera`: `(through, on)`, the rays that end
/// beyond its far side by more than 3 σ of their depth noise plus `margin` (free space where it
/// stands), and those that end on it (between its near side less that noise and margin, and that
/// limit). Rays that end in front of it (an occluder) or miss it do not vote.
pub fn free_space_votes(
    e: &Ellipsoid,
    camera: &Camera,
    b: &BBox,
    points: &[FramePoint],
    noise: &StereoNoise,
    margin: f64,
) -> (usize, usize) {
    let from_world = camera.world_from_camera.inverse();
    let centre = (from_world * nalgebra::Point3::from(e.centre())).coords;
    // camera-frame directions into the ellipsoid's own frame, scaled to the unit sphere
    let own_from_camera =
        e.rotation().transpose() * camera.world_from_camera.rotation.to_rotation_matrix().into_inner();
    let to_unit = |v: Vector3<f64>| (own_from_camera * v).component_div(&e.semi_axes);
    let c = -to_unit(centre);
    let (mut through, mut on) = (0, 0);
    for p in points {
        let [u, v, _] = p.observation;
        if !noise.in_core(b, u, v) {
            continue;
        }
        let x = p.camera_point;
        let range = x.norm();
        if !(range > 0.0 && x.z > 0.0) {
            continue;
        }
        // |s·d + c|² = 1 along the ray s·r (r unit), d = to_unit(r)
        let d = to_unit(x / range);
        let (qa, qb, qc) = (d.dot(&d), 2.0 * d.dot(&c), c.dot(&c) - 1.0);
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 || qa <= 0.0 {
            continue;
        }
        let (near, far) = ((-qb - disc.sqrt()) / (2.0 * qa), (-qb + disc.sqrt()) / (2.0 * qa));
        let slack = 3.0 * noise.depth_sigma(x.z) * range / x.z + margin;
        if range > far + slack {
            through += 1;
        } else if range >= near - slack {
            on += 1;
        }
    }
    (through, on)
}

/// Standard deviation of where a real object's visible surface lies, as a share of its class's
/// length semi-axis (the longest chord it can have): over the central part of the silhouette the
/// surface of an ellipsoid lies 0.88 chord half-lengths in front of the centre and that of the box
/// around it 1.0–1.27 (any side of a car or van), so a vehicle's lies within about ±0.15 of one.
const SURFACE_SHAPE_SIGMA: f64 = 0.15;

/// The stereo depth of an object's visible surface for its fit ([`MapperConfig::surface_depth`]): the
/// median of its centroids (needs [`MIN_MOTION_CENTROIDS`], so that one centroid on another object
/// cannot move it), seen along the mean direction towards the cameras that measured them; σ combines
/// their median depth noise with [`SURFACE_SHAPE_SIGMA`]. `None` without enough centroids.
pub fn surface_cue(obj: &MappedObject) -> Option<SurfaceCue> {
    let with = with_centroids(obj);
    if with.len() < MIN_MOTION_CENTROIDS {
        return None;
    }
    let (surface, sigma_z) = median_centroid(&with);
    let towards_camera = with
        .iter()
        .filter_map(|o| (o.camera.world_from_camera.translation.vector - surface).try_normalize(1e-9))
        .sum::<Vector3<f64>>();
    let shape = SURFACE_SHAPE_SIGMA * class_prior(obj.class).axes.x;
    let sigma_m = (sigma_z * sigma_z + shape * shape).sqrt();
    (towards_camera.norm() > 1e-9 && sigma_m > 0.0).then_some(SurfaceCue { surface, towards_camera, sigma_m })
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_core::ClassId;
    use slam_quadric::ImageSize;

    #[test]
    fn surface_cue_is_the_median_centroid_seen_from_the_cameras_once_four_exist() {
        let k = slam_quadric::Intrinsics { fx: 721.5, fy: 721.5, skew: 0.0, cx: 609.6, cy: 172.9 };
        let observation = |i: usize, centroid: Vector3<f64>| Observation {
            frame: i,
            camera: Camera::new(k, nalgebra::Isometry3::translation(0.0, 0.0, i as f64)),
            bbox: BBox::new(600.0, 150.0, 700.0, 220.0),
            class: ClassId(2),
            detection: 0,
            centroid: Some(centroid),
            depth_sigma: 0.4,
            reference: None,
        };
        let mut obj = MappedObject::new(TrackId(1), ClassId(2));
        let parked = Vector3::new(-2.0, 1.0, 30.0);
        for i in 0..3 {
            obj.observations.push(observation(i, parked));
        }
        assert!(surface_cue(&obj).is_none(), "three centroids are too few");
        // a fourth on a car passing 10 m nearer, then a fifth on the parked one: the median holds
        obj.observations.push(observation(3, parked - Vector3::new(0.0, 0.0, 10.0)));
        obj.observations.push(observation(4, parked));
        let cue = surface_cue(&obj).expect("five centroids");
        assert!((cue.surface - parked).norm() < 1e-12, "{:?}", cue.surface);
        // towards the cameras (all on the z axis behind it), σ from the depth noise and the car's length
        let dir = cue.towards_camera.normalize();
        assert!(dir.z < -0.99 && dir.x > 0.0, "{dir:?}");
        let shape = SURFACE_SHAPE_SIGMA * class_prior(ClassId(2)).axes.x;
        assert!((cue.sigma_m - (0.4f64.powi(2) + shape * shape).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn free_space_votes_count_rays_through_and_on_an_ellipsoid_and_skip_occluders() {
        let k = slam_quadric::Intrinsics { fx: 721.5, fy: 721.5, skew: 0.0, cx: 609.6, cy: 172.9 };
        let camera = Camera::new(k, nalgebra::Isometry3::identity());
        let e = Ellipsoid::new(nalgebra::Isometry3::translation(0.0, 0.0, 20.0), Vector3::new(2.0, 0.8, 0.85));
        let image = ImageSize::new(1242.0, 375.0);
        let b = project(&e, &camera).and_then(|c| c.clipped_bounds(&image)).expect("in view");
        let noise = StereoNoise { focal_baseline: 721.5 * 0.54, disparity_sigma_px: 0.5, core: 0.6 };
        // points along rays through the box's centre region at a given depth
        let at = |z: f64| -> Vec<FramePoint> {
            [(-0.03, -0.01), (0.0, 0.0), (0.03, 0.01), (0.015, -0.015)]
                .iter()
                .map(|&(x, y)| {
                    let p = Vector3::new(x, y, 1.0) * z;
                    let (u, v) = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
                    FramePoint { camera_point: p, observation: [u, v, u - 721.5 * 0.54 / z] }
                })
                .collect()
        };
        // its surface faces the camera at z 19.15; 3 σ at 20 m is 1.5 m, the margin 2 m
        assert_eq!(free_space_votes(&e, &camera, &b, &at(19.2), &noise, 2.0), (0, 4));
        assert_eq!(free_space_votes(&e, &camera, &b, &at(40.0), &noise, 2.0), (4, 0));
        assert_eq!(free_space_votes(&e, &camera, &b, &at(10.0), &noise, 2.0), (0, 0), "an occluder");
        // points outside the box's central part do not vote
        let aside: Vec<FramePoint> =
            at(40.0).into_iter().map(|p| FramePoint { observation: [b.xmin + 1.0, b.ymin + 1.0, 0.0], ..p }).collect();
        assert_eq!(free_space_votes(&e, &camera, &b, &aside, &noise, 2.0), (0, 0));
        // the same scene from a camera elsewhere, turned 0.8 rad (the ellipsoid with it): the same votes.
        // Its far side is 20.85 m away along the view, so a point at 26 m is beyond it by more than
        // 3 σ (2.60 m there) and the 2 m margin; had the car's long axis (2 m) been taken along the
        // view, it would not be.
        let pose = nalgebra::Isometry3::new(Vector3::new(3.0, 0.0, -2.0), Vector3::y() * 0.8);
        let turned = Camera::new(k, pose);
        let e2 = Ellipsoid::new(pose * nalgebra::Isometry3::translation(0.0, 0.0, 20.0), e.semi_axes);
        let b2 = project(&e2, &turned).and_then(|c| c.clipped_bounds(&image)).expect("in view");
        for (cam, ell, bb) in [(&camera, &e, &b), (&turned, &e2, &b2)] {
            assert_eq!(free_space_votes(ell, cam, bb, &at(26.0), &noise, 2.0), (4, 0));
            assert_eq!(free_space_votes(ell, cam, bb, &at(19.2), &noise, 2.0), (0, 4));
        }
    }
}
