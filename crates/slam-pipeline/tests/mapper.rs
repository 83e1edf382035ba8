//! The object mapper on a synthetic drive: a parked car gets an accurate ellipsoid, a car driving
//! alongside is flagged dynamic or gets none, and the object map JSON is written.

mod common;

use common::{lm, IMAGE, K};
use nalgebra::Isometry3;
use slam_assoc::Oda;
use slam_core::{ClassId, Detection};
use slam_pipeline::objects::{write_object_map, MapperConfig, ObjectMapper};
use slam_quadric::{metrics, Camera, Ellipsoid};

fn car(x: f64, z: f64) -> Ellipsoid {
    common::car(x, z, 0.05)
}

#[test]
fn parked_car_is_mapped_and_moving_car_is_not() {
    let parked = car(5.0, 30.0);
    let mut mapper = ObjectMapper::new(Box::new(Oda::default()), MapperConfig::default(), lm());
    for f in 0..22 {
        let z = f as f64; // 1 m per frame
        let cam = Camera::new(K, Isometry3::translation(0.0, 0.0, z));
        let moving = car(-4.0, z + 12.0 + 0.8 * f as f64); // overtaking on the left
        let mut dets = Vec::new();
        for e in [&parked, &moving] {
            if let Some(b) = common::detected_box(e, &cam) {
                dets.push(Detection::new(ClassId(2), 1.0, b));
            }
        }
        let ids = mapper.step(f, &cam, &dets);
        assert_eq!(ids.len(), dets.len());
    }
    let objs: Vec<_> = mapper.objects().collect();
    let good: Vec<_> = objs.iter().filter(|o| o.ellipsoid.is_some() && !o.dynamic).collect();
    assert_eq!(good.len(), 1, "{objs:?}");
    let e = good[0].ellipsoid.as_ref().expect("ellipsoid");
    assert!(metrics::e_trans(e, &parked) < 0.05, "{}", metrics::e_trans(e, &parked));
    assert!(metrics::e_axe(e, &parked) < 0.05, "{}", metrics::e_axe(e, &parked));
    let out = std::env::temp_dir().join(format!("mapper-{}.json", std::process::id()));
    write_object_map(&out, &objs).expect("writes");
    let text = std::fs::read_to_string(&out).expect("reads");
    assert!(text.contains("\"semi_axes\"") && text.contains("\"dynamic\""));
}

/// A car ahead driving the same way at half the camera's speed: its boxes are exactly those of a static
/// car twice as far and twice as large, so the box misfit cannot tell; the fitted size, far from the
/// class prior, can (`dynamic_prior_sigmas`), under the ellipse box model; under the cuboid model (the
/// default) the fit of twice a car's size lies beyond the physical limits of a car (8 m long) and is
/// refused whether or not the size test runs: it is never mapped as a static car.
#[test]
fn a_slower_car_ahead_is_flagged_by_its_size() {
    let fit = |config: MapperConfig| {
        let mut mapper = ObjectMapper::new(Box::new(Oda::default()), config, lm());
        for f in 0..30 {
            let cam = Camera::new(K, Isometry3::translation(0.0, 0.0, f as f64));
            let ahead = car(-3.5, 25.0 + 0.5 * f as f64);
            let dets: Vec<Detection> = common::detected_box(&ahead, &cam)
                .map(|b| vec![Detection::new(ClassId(2), 1.0, b)])
                .unwrap_or_default();
            mapper.step(f, &cam, &dets);
        }
        mapper.objects().filter(|o| o.ellipsoid.is_some()).map(|o| o.dynamic).collect::<Vec<bool>>()
    };
    let ellipse = MapperConfig { box_shape: slam_optim::object::BoxShape::Ellipse, ..MapperConfig::default() };
    let without = fit(MapperConfig { dynamic_prior_sigmas: None, ..ellipse });
    assert_eq!(without, vec![false], "fitted as a static car when only the box misfit is tested");
    let with = fit(ellipse);
    assert_eq!(with, vec![true], "flagged dynamic by its size");
    for config in [MapperConfig::default(), MapperConfig { dynamic_prior_sigmas: None, ..MapperConfig::default() }] {
        assert_eq!(fit(config), Vec::<bool>::new(), "the cuboid model's fit is no car at all");
    }
}

/// A parked car boxed in three frames, fitted, then never detected again while it stays in full view
/// (the camera slides sideways past it; another car is detected in every frame): its ellipsoid is
/// removed after `max_misses` frames; the car that keeps being detected keeps its ellipsoid. With the
/// rule off, the phantom stays.
#[test]
fn a_car_missing_where_it_should_be_visible_is_removed() {
    let run = |max_misses: Option<usize>| {
        let mut mapper =
            ObjectMapper::new(Box::new(Oda::default()), MapperConfig { max_misses, ..MapperConfig::default() }, lm());
        let phantom = car(0.0, 15.0);
        let kept = car(4.5, 17.0);
        let mut fitted_early = false;
        for f in 0..12 {
            let cam = Camera::new(K, Isometry3::translation(0.5 * f as f64, 0.0, 0.0));
            let mut dets = Vec::new();
            for (e, boxed) in [(&phantom, f < 3), (&kept, true)] {
                if let (true, Some(b)) = (boxed, common::detected_box(e, &cam)) {
                    assert!(!b.touches_border(&IMAGE, 5.0), "frame {f}: in full view");
                    dets.push(Detection::new(ClassId(2), 1.0, b));
                }
            }
            mapper.step(f, &cam, &dets);
            if f == 2 {
                fitted_early = mapper.objects().filter(|o| o.ellipsoid.is_some()).count() == 2;
            }
        }
        let with: Vec<f64> = mapper.objects().filter_map(|o| o.ellipsoid.map(|e| e.centre().z)).collect();
        (fitted_early, with)
    };
    let (fitted, left) = run(MapperConfig::default().max_misses);
    assert!(fitted, "both cars get an ellipsoid from their first three boxes");
    assert_eq!(left.len(), 1, "only the car still detected keeps an ellipsoid: {left:?}");
    assert!((left[0] - 17.0).abs() < 0.5, "{left:?}");
    let (_, without) = run(None);
    assert_eq!(without.len(), 2, "{without:?}");
}

/// Stereo points of a frame from camera `cam` on a pixel grid (every 8 px): where a ray meets one of
/// `solid` first, the point on its surface; elsewhere a wall 45 m ahead of the camera.
fn stereo_points(cam: &Camera, solid: &[Ellipsoid]) -> Vec<slam_core::FramePoint> {
    let from_world = cam.world_from_camera.inverse();
    let mut out = Vec::new();
    for v in (0..375).step_by(8) {
        for u in (0..1242).step_by(8) {
            let (u, v) = (u as f64, v as f64);
            let ray = nalgebra::Vector3::new((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0);
            let mut depth = 45.0;
            for e in solid {
                // the ray s·ray against the ellipsoid, in its unit-sphere frame
                let to_unit = |x: nalgebra::Vector3<f64>| {
                    (e.rotation().transpose() * (cam.world_from_camera.rotation * x)).component_div(&e.semi_axes)
                };
                let c = -to_unit((from_world * nalgebra::Point3::from(e.centre())).coords);
                let d = to_unit(ray);
                let (a, b, q) = (d.dot(&d), 2.0 * d.dot(&c), c.dot(&c) - 1.0);
                let disc = b * b - 4.0 * a * q;
                if disc >= 0.0 {
                    depth = f64::min(depth, (-b - disc.sqrt()) / (2.0 * a));
                }
            }
            out.push(slam_core::FramePoint {
                camera_point: ray * depth,
                observation: [u, v, u - K.fx * common::B / depth],
            });
        }
    }
    out
}

/// The free-space test: a car boxed in three frames where there is none (a phantom: its boxes stop,
/// and the miss rule is off), then frames whose stereo points see the wall 45 m ahead through it; a
/// real car whose points lie on its surface. After `free_space_frames` frames the phantom's ellipsoid
/// is removed and counted; the real car keeps its own. With the test off, the phantom stays.
#[test]
fn an_ellipsoid_the_stereo_points_see_through_is_removed() {
    use slam_pipeline::objects::StereoNoise;
    let noise = StereoNoise { focal_baseline: K.fx * common::B, disparity_sigma_px: 0.5, core: 0.6 };
    let run = |free_space_frames: Option<usize>| {
        let config = MapperConfig { max_misses: None, free_space_frames, ..MapperConfig::default() };
        let mut mapper = ObjectMapper::new(Box::new(Oda::default()), config, lm());
        let (phantom, real) = (car(0.0, 15.0), car(4.5, 17.0));
        let mut after = Vec::new();
        for f in 0..12 {
            let cam = Camera::new(K, Isometry3::translation(0.5 * f as f64, 0.0, 0.0));
            let mut dets = Vec::new();
            for (e, boxed) in [(&phantom, f < 3), (&real, true)] {
                if let (true, Some(b)) = (boxed, common::detected_box(e, &cam)) {
                    dets.push(Detection::new(ClassId(2), 1.0, b));
                }
            }
            mapper.step(f, &cam, &dets);
            if f >= 3 {
                mapper.check_free_space(&cam, &stereo_points(&cam, &[real]), &noise);
            }
            after.push(mapper.objects().filter(|o| o.ellipsoid.is_some()).count());
        }
        let left: Vec<f64> = mapper.objects().filter_map(|o| o.ellipsoid.map(|e| e.centre().z)).collect();
        (after, left, mapper.free_space_removals())
    };
    let (after, left, removed) = run(MapperConfig::default().free_space_frames);
    assert_eq!(after[2], 2, "both cars are fitted from their first three boxes: {after:?}");
    // frames 3..=7 see through the phantom: removed at the fifth
    assert_eq!(after[6], 2, "{after:?}");
    assert_eq!(after[7], 1, "{after:?}");
    assert_eq!(removed, 1);
    assert_eq!(left.len(), 1, "{left:?}");
    assert!((left[0] - 17.0).abs() < 0.5, "the real car stays: {left:?}");
    let (_, without, removed) = run(None);
    assert_eq!((without.len(), removed), (2, 0), "{without:?}");
}

/// Two scene-flow readings of consecutive frames far above their noise, and agreeing (their sum too),
/// flag an object not yet mapped as moving; the first may be its own or that of the box it overlaps in
/// the frame before (a new track of the same object). One is not enough; two readings that cancel (what one bad
/// pose makes: +δ into its frame, −δ out of it) or that are not of consecutive frames do not flag it;
/// an object already mapped as static is left to the centroid test (two frames of motion under its
/// track are likelier another object taken over by the association).
#[test]
fn scene_flow_flags_a_new_object_and_leaves_a_mapped_one_to_the_centroid_test() {
    use nalgebra::Vector3;
    use slam_pipeline::objects::SceneFlow;
    let setup = || {
        let mut mapper = ObjectMapper::new(Box::new(Oda::default()), MapperConfig::default(), lm());
        let (parked, newcomer) = (car(4.5, 17.0), car(-3.0, 12.0));
        for f in 0..4 {
            let cam = Camera::new(K, Isometry3::translation(0.5 * f as f64, 0.0, 0.0));
            let mut dets = Vec::new();
            for (e, seen) in [(&parked, true), (&newcomer, f == 3)] {
                if let (true, Some(b)) = (seen, common::detected_box(e, &cam)) {
                    dets.push(Detection::new(ClassId(2), 1.0, b));
                }
            }
            mapper.step(f, &cam, &dets);
        }
        let id_of =
            |fitted: bool| mapper.objects().find(|o| o.ellipsoid.is_some() == fitted).map(|o| o.id).expect("object");
        let (mapped, new) = (id_of(true), id_of(false));
        (mapper, mapped, new)
    };
    let ray = Vector3::new(0.0, 0.0, 1.0);
    let flow = |dz: f64| SceneFlow::new(Vector3::new(0.0, 0.0, dz), ray, (0.1, 0.05), 20);
    let moving = |m: &ObjectMapper, id| m.objects().find(|o| o.id == id).expect("object").moving;
    // pulling away 0.6 m per frame (6 σ) in frames 10 and 11
    let (mut m, mapped, new) = setup();
    for id in [mapped, new] {
        m.add_flow(id, (10, 1), &flow(0.6), None);
    }
    assert!(!moving(&m, new) && !moving(&m, mapped), "one reading is not enough");
    for id in [mapped, new] {
        m.add_flow(id, (11, 1), &flow(0.6), None);
    }
    assert!(moving(&m, new), "the new object is moving");
    assert!(!moving(&m, mapped), "the mapped car stays");
    // one bad pose: +0.6 m into frame 10, −0.6 m out of it
    let (mut m, _, new) = setup();
    m.add_flow(new, (10, 1), &flow(0.6), None);
    m.add_flow(new, (11, 1), &flow(-0.6), None);
    assert!(!moving(&m, new), "readings that cancel");
    // readings of frames 10 and 12
    let (mut m, _, new) = setup();
    m.add_flow(new, (10, 1), &flow(0.6), None);
    m.add_flow(new, (12, 1), &flow(0.6), None);
    assert!(!moving(&m, new), "not consecutive");
    // a new track (no reading of its own before) whose box overlaps a box of the frame before that read
    // the same motion: the same object under another track id
    let (mut m, _, new) = setup();
    m.add_flow(new, (11, 1), &flow(0.6), Some(&flow(0.6)));
    assert!(moving(&m, new), "the box's reading of the frame before confirms it");
    let (mut m, _, new) = setup();
    m.add_flow(new, (11, 1), &flow(0.6), Some(&flow(-0.6)));
    assert!(!moving(&m, new), "a box reading that cancels does not");
}

/// An object flagged moving by its centroid trend because its track took in another object's
/// centroids (an association switch: from frame 6 on, those of a car crossing 1 m per frame) is static
/// again once its own points, followed from frame to frame, stand still precisely enough to exclude the
/// trend's rate over 3 readings after the flag (the track back on a parked car), and its observations
/// from before those readings are dropped; readings too noisy to exclude it leave the flag.
#[test]
fn scene_flow_that_excludes_the_trend_lifts_its_moving_flag() {
    use nalgebra::Vector3;
    use slam_pipeline::objects::{PointsCentroid, SceneFlow};
    let flagged = || {
        let mut m = ObjectMapper::new(Box::new(Oda::default()), MapperConfig::default(), lm());
        let parked = car(4.0, 20.0);
        let mut id = None;
        for f in 0..18 {
            let cam = Camera::new(K, Isometry3::translation(0.0, 0.0, 0.4 * f as f64));
            let b = common::detected_box(&parked, &cam).expect("in view");
            let ids = m.step(f, &cam, &[Detection::new(ClassId(2), 1.0, b)]);
            let track = ids[0].expect("associated");
            assert!(id.is_none_or(|i| i == track), "one track");
            id = Some(track);
            // from frame 6 the centroids are those of a car crossing 1 m per frame
            let x = if f < 6 { 3.2 } else { 3.2 - 1.0 * (f - 5) as f64 };
            m.add_points(track, &[], Some(PointsCentroid { position: Vector3::new(x, 0.9, 19.0), depth_sigma: 0.3 }));
        }
        let id = id.expect("track");
        let o = m.objects().find(|o| o.id == id).expect("object");
        assert!(o.moving, "the trend flags it");
        (m, id)
    };
    let ray = Vector3::new(0.2, 0.0, 1.0).normalize();
    let still = |sigma: f64| SceneFlow::new(Vector3::new(0.01, 0.0, -0.02), ray, (sigma, sigma / 2.0), 20);
    let moving = |m: &ObjectMapper, id| m.objects().find(|o| o.id == id).expect("object").moving;
    let (mut m, id) = flagged();
    m.add_flow(id, (18, 1), &still(0.1), None);
    m.add_flow(id, (19, 1), &still(0.1), None);
    assert!(moving(&m, id), "two readings are not enough");
    m.add_flow(id, (20, 1), &still(0.1), None);
    assert!(!moving(&m, id), "three precise readings of standing still refute the trend");
    // what made the trend was another object under the track: its observations are dropped, and the
    // object is fitted afresh from those since the still readings began (none yet here)
    let o = m.objects().find(|o| o.id == id).expect("object");
    assert!(o.observations.iter().all(|x| x.frame >= 17) && o.ellipsoid.is_none(), "{:?}", o.observations.first());
    let (mut m, id) = flagged();
    for f in 18..22 {
        m.add_flow(id, (f, 1), &still(3.0), None);
    }
    assert!(moving(&m, id), "readings with 3 m of noise cannot exclude 1 m per frame");
}

/// A parked car mapped in one run and saved keeps its id in the next run that loads the map: its
/// boxes join it from the first frame it projects into (it comes back as a track), no second object
/// is made for it, a car the first run never saw gets a new id, and the next fit uses both runs' boxes.
#[test]
fn a_car_of_a_loaded_map_keeps_its_id_and_is_refined_by_both_runs() {
    let parked = car(5.0, 30.0);
    let mut first = ObjectMapper::new(Box::new(Oda::default()), MapperConfig::default(), lm());
    let drive = |mapper: &mut ObjectMapper, frames: std::ops::Range<usize>, extra: Option<&Ellipsoid>| {
        let mut ids = Vec::new();
        for f in frames {
            let cam = Camera::new(K, Isometry3::translation(0.0, 0.0, (f % 100) as f64));
            let dets: Vec<Detection> = std::iter::once(&parked)
                .chain(extra)
                .filter_map(|e| common::detected_box(e, &cam))
                .map(|b| Detection::new(ClassId(2), 1.0, b))
                .collect();
            ids.push(mapper.step(f, &cam, &dets));
        }
        ids
    };
    drive(&mut first, 0..22, None);
    let saved: Vec<_> = first.objects().filter_map(|o| o.to_saved_object()).collect();
    assert_eq!(saved.len(), 1, "one car mapped");
    let (id, views) = (saved[0].id, saved[0].views.len());
    assert!(views >= 10, "{views} views saved");

    let mut second = ObjectMapper::new(Box::new(Oda::default()), MapperConfig::default(), lm());
    assert_eq!(second.restore(&saved, K), 1);
    // the same road again (frame ids 100-121), with a car parked on the other side this time
    let other = car(-5.0, 34.0);
    let ids = drive(&mut second, 100..122, Some(&other));
    let parked_ids: Vec<u64> = ids.iter().filter_map(|f| f.first().copied().flatten()).map(|t| t.0).collect();
    assert_eq!(parked_ids.len(), 22);
    assert!(parked_ids.iter().all(|&t| t == id), "the loaded car's id every frame: {parked_ids:?}");
    let new_ids: Vec<u64> = ids.iter().filter_map(|f| f.get(1).copied().flatten()).map(|t| t.0).collect();
    assert!(!new_ids.is_empty() && new_ids.iter().all(|&t| t > id), "a new car gets a new id: {new_ids:?}");
    let back = second.object(slam_core::TrackId(id)).expect("kept").to_saved_object().expect("ellipsoid");
    assert_eq!((back.earlier_views, back.views.len()), (views, views + 22));
    assert_eq!(back.frames, (100..122).collect::<Vec<_>>(), "frames: this run's only");
    let e = second.object(slam_core::TrackId(id)).and_then(|o| o.ellipsoid).expect("ellipsoid");
    assert!(metrics::e_trans(&e, &parked) < 0.05, "{}", metrics::e_trans(&e, &parked));
    let cars = second
        .objects()
        .filter(|o| o.ellipsoid.is_some() && (o.ellipsoid.expect("e").centre() - parked.centre()).norm() < 3.0);
    assert_eq!(cars.count(), 1, "no second object for the loaded car");
}

/// A parked car boxed only while it is near (a small detector misses it farther away), then the
/// camera backs away from it with another car boxed in every frame: it is not counted missing beyond
/// the farthest it was detected at, so it keeps its ellipsoid; the miss test still removes a car
/// missing nearer (`a_car_missing_where_it_should_be_visible_is_removed`).
#[test]
fn a_car_is_not_missed_farther_away_than_it_was_ever_detected() {
    let near_only = car(-4.0, 30.0);
    let always = car(4.5, 36.0);
    let mut mapper = ObjectMapper::new(Box::new(Oda::default()), MapperConfig::default(), lm());
    let mut farthest_boxed: f64 = 0.0;
    for f in 0..16usize {
        // towards the car from 16 to 11 m, then backing away to 26 m
        let z = if f < 6 { 14.0 + f as f64 } else { 19.0 - 1.5 * (f - 5) as f64 };
        let cam = Camera::new(K, Isometry3::translation(0.0, 0.0, z));
        let mut dets = Vec::new();
        for (e, boxed) in [(&near_only, f < 6), (&always, true)] {
            if let (true, Some(b)) = (boxed, common::detected_box(e, &cam)) {
                dets.push(Detection::new(ClassId(2), 1.0, b));
            }
        }
        if f < 6 {
            farthest_boxed = farthest_boxed.max(30.0 - z);
        }
        mapper.step(f, &cam, &dets);
    }
    assert!((farthest_boxed - 16.0).abs() < 1e-9);
    let kept: Vec<f64> = mapper.objects().filter_map(|o| o.ellipsoid.map(|e| e.centre().z)).collect();
    assert_eq!(kept.len(), 2, "both cars keep their ellipsoids: {kept:?}");
    let backed_off =
        mapper.objects().filter(|o| o.ellipsoid.is_some_and(|e| (e.centre().z - 30.0).abs() < 1.0)).count();
    assert_eq!(backed_off, 1, "{kept:?}");
}
