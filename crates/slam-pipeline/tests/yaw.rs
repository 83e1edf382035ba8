//! The stereo-point yaw cue on a scripted scene where the boxes alone cannot decide the yaw: the camera
//! drives straight at a car parked at an angle dead ahead. A car turned by +θ and one turned by −θ
//! give mirror-image boxes, and a small sideways shift of the centre makes up most of the difference,
//! so a fit held at the wrong yaw still fits the boxes. The car's stereo points (its rear face and
//! the side facing the camera, with stereo depth noise) decide.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use slam_optim::object::{refine_with_cues, BoxShape, Cues, ObjectPrior, RefineConfig, YawCue};
use slam_pipeline::yaw_cue::{point_yaw, PointYaw, PointYawConfig};
use slam_quadric::{init::BoxView, init::Dqp, metrics, project, Camera, Ellipsoid, ImageSize, Intrinsics};

const K: Intrinsics = Intrinsics { fx: 721.5377, fy: 721.5377, skew: 0.0, cx: 609.5593, cy: 172.854 };
const B: f64 = 0.54;
const IMAGE: ImageSize = ImageSize::new(1242.0, 375.0);

/// A car parked dead ahead at 18 m, its length axis turned by `yaw` from the road (the camera's z).
fn car(yaw: f64) -> Ellipsoid {
    Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(0.0, 0.85, 18.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -std::f64::consts::FRAC_PI_2 + yaw),
        ),
        Vector3::new(2.1, 0.8, 0.85),
    )
}

fn cameras() -> Vec<Camera> {
    (0..8).map(|i| Camera::new(K, Isometry3::translation(0.0, 0.0, 0.75 * i as f64))).collect()
}

/// The car's boxes, each edge moved by `noise_px` pixels in a fixed pattern of signs (a detector's
/// boxes are off by a few pixels).
fn views(e: &Ellipsoid, noise_px: f64) -> Vec<BoxView> {
    const SIGNS: [f64; 8] = [1.0, -1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0];
    cameras()
        .into_iter()
        .enumerate()
        .map(|(i, c)| {
            let b = project(e, &c).and_then(|q| q.clipped_bounds(&IMAGE)).expect("projects");
            let n = |k: usize| noise_px * SIGNS[(i + 3 * k) % 8];
            let b = slam_quadric::BBox {
                xmin: b.xmin + n(0),
                ymin: b.ymin + n(1),
                xmax: b.xmax + n(2),
                ymax: b.ymax + n(3),
            };
            BoxView::new(c, b)
        })
        .collect()
}

/// Stereo points on the faces of the car's cuboid that face the last camera, at three heights, each
/// with a depth error of ±1 σ_z (alternating: mean 0, the stereo noise of 0.5 px disparity).
fn points(e: &Ellipsoid) -> Vec<Vector3<f64>> {
    let cam = cameras().last().expect("cameras").world_from_camera;
    let eye = cam.translation.vector;
    let (r, c, a) = (e.rotation(), e.centre(), e.semi_axes);
    let mut out = Vec::new();
    // faces: own ±x (rear/front, spanning own z) and own ±z (sides, spanning own x)
    for (normal_axis, span_axis) in [(0usize, 2usize), (2, 0)] {
        for sign in [-1.0, 1.0] {
            let n = r.column(normal_axis) * sign;
            let centre = c + n * a[normal_axis];
            if n.dot(&(eye - centre)) <= 0.0 {
                continue; // faces away
            }
            let along = r.column(span_axis).into_owned();
            let count = (12.0 * a[span_axis]).round() as usize;
            for i in 0..count {
                let s = -a[span_axis] + 2.0 * a[span_axis] * (i as f64 + 0.5) / count as f64;
                for h in [-0.4, 0.0, 0.4] {
                    let p = centre + along * s + r.column(1) * h;
                    let ray = p - eye;
                    let z = ray.norm();
                    let sz = z * z * 0.5 / (K.fx * B);
                    let k = if (i + (h * 10.0) as usize) % 2 == 0 { 1.0 } else { -1.0 };
                    out.push(p + ray / z * (k * sz));
                }
            }
        }
    }
    out
}

fn fit(views: &[BoxView], yaw: Option<YawCue>) -> Ellipsoid {
    let config = RefineConfig { box_shape: BoxShape::Ellipse, pose_drift: None, ..RefineConfig::default() };
    let lm = slam_lm::LevenbergMarquardt::default();
    refine_with_cues(
        &Dqp::default(),
        views,
        &IMAGE,
        &ObjectPrior::car(),
        &config,
        &Cues { yaw, ..Cues::default() },
        &lm,
    )
    .expect("fits")
}

fn rms(views: &[BoxView], e: &Ellipsoid) -> f64 {
    let mut sum = 0.0;
    for v in views {
        let r = slam_optim::object::box_residual(v, &IMAGE, e, BoxShape::Ellipse).expect("projects");
        sum += r.norm_squared() / 4.0;
    }
    (sum / views.len() as f64).sqrt()
}

#[test]
fn the_points_decide_a_yaw_the_boxes_cannot() {
    let theta = 25f64.to_radians();
    let up = Vector3::y();
    for sign in [1.0, -1.0] {
        let truth = car(sign * theta);
        let exact = views(&truth, 0.0);
        let views = views(&truth, 2.0);
        // box shape alone is ambiguous: held at the mirrored yaw, the fit still matches the boxes
        let mirrored = car(-sign * theta);
        let wrong = YawCue { direction: mirrored.rotation() * Vector3::x(), sigma_rad: 0.5f64.to_radians() };
        let held_wrong = fit(&exact, Some(wrong));
        let wrong_yaw = metrics::e_yaw(&held_wrong, &truth, &up);
        assert!(wrong_yaw > 30.0, "held at the mirrored yaw: {wrong_yaw:.1}°");
        // exact boxes, yet the misfit is a fraction of a pixel: far below a detector's box noise
        let wrong_rms = rms(&exact, &held_wrong);
        assert!(wrong_rms < 1.0, "the mirrored yaw fits the boxes to {wrong_rms:.2} px RMS");
        // the points decide
        let camera = cameras().last().expect("cameras").world_from_camera.translation.vector;
        let found = point_yaw(&points(&truth), &up, &camera, &ObjectPrior::car(), K.fx, B, &PointYawConfig::default());
        let PointYaw::Cue { cue, .. } = found else { panic!("no cue from the points: {found:?}") };
        let with = fit(&views, Some(cue));
        let plain = fit(&views, None);
        let e_plain = metrics::e_yaw(&plain, &truth, &up);
        eprintln!(
            "sign {sign}: held wrong {wrong_yaw:.1}° {wrong_rms:.2} px; boxes only {:.1}° {:.2} px; cue {found:?}; with cue {:.1}° {:.2} px",
            e_plain,
            rms(&views, &plain),
            metrics::e_yaw(&with, &truth, &up),
            rms(&views, &with)
        );
        let e_with = metrics::e_yaw(&with, &truth, &up);
        assert!(
            e_with < 3.0 && e_with < e_plain,
            "yaw {:+.0}°: with the points' cue {e_with:.1}° off, boxes alone {e_plain:.1}°",
            sign * 25.0
        );
        // and the boxes still fit
        assert!(rms(&views, &with) < 3.0, "{:.2} px", rms(&views, &with));
    }
}
