//! Every built-in factor's analytic Jacobian against central differences, at random points.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3, Vector4};
use slam_optim::{
    factor::numeric_jacobians,
    factors::{
        AxisDirection, AxisPrior, BalReprojection, Between, BoxFactor, CuboidBoxFactor, CuboidSurface,
        MonoReprojection, PointPrior, PosePrior, StereoReprojection, SurfaceDepth, TexturePlane,
    },
    BalCamera, Factor, Values, Var,
};
use slam_quadric::{project, BoundsModel, Camera, Ellipsoid, ImageSize, Intrinsics};

/// Seeded test points (ChaCha8: the same stream on every platform and version).
struct TestRng(rand::rngs::ChaCha8Rng);
impl TestRng {
    fn new(seed: u64) -> Self {
        Self(rand::SeedableRng::seed_from_u64(seed))
    }
    fn u(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * rand::RngExt::random::<f64>(&mut self.0)
    }
    fn pose(&mut self, t: f64, r: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.u(-t, t), self.u(-t, t), self.u(-t, t)),
            UnitQuaternion::from_euler_angles(self.u(-r, r), self.u(-r, r), self.u(-r, r)),
        )
    }
}

fn check(f: &dyn Factor, values: &Values, name: &str) {
    let mut analytic = Vec::new();
    f.evaluate(values, Some(&mut analytic)).unwrap_or_else(|e| panic!("{name}: {e}"));
    let numeric = numeric_jacobians(f, values, 1e-6).expect("numeric");
    assert_eq!(analytic.len(), f.keys().len(), "{name}");
    for (k, (a, n)) in analytic.iter().zip(&numeric).enumerate() {
        assert_eq!(a.shape(), n.shape(), "{name} key {k}");
        let err = (a - n).norm() / n.norm().max(1.0);
        assert!(err < 1e-6, "{name} key {k}: rel err {err:e}\nanalytic {a}\nnumeric {n}");
    }
    // the solvers' entry point gives exactly the same numbers (the BAL factor overrides it, the
    // others use the provided copy), and refuses buffers of the wrong size
    let r = f.evaluate(values, None).expect("residual");
    let mut r_into = vec![0.0; f.dim()];
    let mut j_into = vec![0.0; analytic.iter().map(|j| j.len()).sum()];
    f.evaluate_into(values, &mut r_into, Some(&mut j_into)).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(r.as_slice(), &r_into[..], "{name}: evaluate_into residual");
    let flat: Vec<f64> = analytic.iter().flat_map(|j| j.iter().copied()).collect();
    assert_eq!(flat, j_into, "{name}: evaluate_into Jacobians");
    let mut short = vec![0.0; j_into.len() - 1];
    assert!(f.evaluate_into(values, &mut r_into, Some(&mut short)).is_err(), "{name}: short Jacobian buffer");
    let mut long_r = vec![0.0; f.dim() + 1];
    assert!(f.evaluate_into(values, &mut long_r, None).is_err(), "{name}: long residual buffer");
}

const K: Intrinsics = Intrinsics { fx: 721.5, fy: 718.0, skew: 0.0, cx: 609.6, cy: 172.9 };

#[test]
fn reprojection_factors() {
    let mut rng = TestRng::new(1);
    for _ in 0..50 {
        let mut v = Values::new();
        let pose = rng.pose(2.0, 0.3);
        let pc = Vector3::new(rng.u(-5.0, 5.0), rng.u(-2.0, 2.0), rng.u(4.0, 40.0));
        let pw = pose * nalgebra::Point3::from(pc);
        let kp = v.add(Var::Pose(pose));
        let kx = v.add(Var::Point(pw.coords));
        check(&MonoReprojection::new(kp, kx, K, [600.0, 170.0]), &v, "mono");
        check(&StereoReprojection::new(kp, kx, K, 0.54, [600.0, 170.0, 580.0]), &v, "stereo");
        // BAL: camera looks down −z
        let cam = [
            rng.u(-0.5, 0.5),
            rng.u(-0.5, 0.5),
            rng.u(-0.5, 0.5),
            rng.u(-1.0, 1.0),
            rng.u(-1.0, 1.0),
            rng.u(-1.0, 1.0),
            rng.u(400.0, 900.0),
            rng.u(-0.3, 0.3),
            rng.u(-0.1, 0.1),
        ];
        let r = nalgebra::Rotation3::from_scaled_axis(Vector3::new(cam[0], cam[1], cam[2]));
        let want_cam = Vector3::new(rng.u(-1.0, 1.0), rng.u(-1.0, 1.0), -rng.u(3.0, 10.0));
        let x = r.inverse() * (want_cam - Vector3::new(cam[3], cam[4], cam[5]));
        let mut b = Values::new();
        let kc = b.add(Var::Bal(BalCamera(cam)));
        let kx = b.add(Var::Point(x));
        check(&BalReprojection::new(kc, kx, [10.0, -20.0]), &b, "bal");
    }
}

#[test]
fn pose_factors() {
    let mut rng = TestRng::new(2);
    for _ in 0..50 {
        let mut v = Values::new();
        let a = v.add(Var::Pose(rng.pose(10.0, 3.0)));
        let b = v.add(Var::Pose(rng.pose(10.0, 3.0)));
        let x = v.add(Var::Point(Vector3::new(1.0, 2.0, 3.0)));
        let z = rng.pose(5.0, 1.0);
        check(&Between::new(a, b, z), &v, "between");
        check(&PosePrior::new(a, z), &v, "pose prior");
        check(&PointPrior::new(x, Vector3::new(0.5, 0.1, -2.0)), &v, "point prior");
    }
}

#[test]
fn object_factors() {
    let mut rng = TestRng::new(3);
    let image = ImageSize::new(1242.0, 375.0);
    let mut checked = 0;
    let mut cuboid = 0;
    for _ in 0..100 {
        let cam_pose = rng.pose(1.0, 0.1);
        let e = Ellipsoid::new(
            cam_pose
                * Isometry3::from_parts(
                    Translation3::new(rng.u(-8.0, 8.0), rng.u(0.0, 2.0), rng.u(8.0, 30.0)),
                    UnitQuaternion::from_euler_angles(rng.u(-0.2, 0.2), rng.u(-3.0, 3.0), rng.u(-0.2, 0.2)),
                ),
            Vector3::new(rng.u(1.5, 2.5), rng.u(0.6, 0.9), rng.u(0.7, 1.0)),
        );
        let mut v = Values::new();
        let kp = v.add(Var::Pose(cam_pose));
        let ke = v.add(Var::Ellipsoid(e));
        let Ok(b) = project(&e, &Camera::new(K, cam_pose)).and_then(|c| c.bounds()) else { continue };
        let measured = slam_quadric::BBox::new(b.xmin + 3.0, b.ymin - 2.0, b.xmax + 1.0, b.ymax + 4.0);
        check(&BoxFactor::new(kp, ke, K, measured, BoundsModel::Full), &v, "box/full");
        if b.clipped(&image).is_some() && !image.as_box().contains(&b) {
            // truncated object: clipped model (skip the rare kinks where a side switches kind)
            let f = BoxFactor::new(kp, ke, K, measured, BoundsModel::Clipped(image));
            let mut a = Vec::new();
            if f.evaluate(&v, Some(&mut a)).is_ok() {
                let n = numeric_jacobians(&f, &v, 1e-6).expect("numeric");
                let err = (&a[1] - &n[1]).norm() / n[1].norm().max(1.0);
                if err < 1e-3 {
                    assert!(err < 1e-6, "clipped: {err:e}");
                }
            }
        }
        // the cuboid model, where its box lies inside the image (a clamped side has zero derivative and
        // a kink there); skip the rare points where two corners tie for a side
        if let Some(cb) = slam_quadric::cuboid_bounds(&e, &Camera::new(K, cam_pose)) {
            if image.as_box().contains(&cb) {
                let f = CuboidBoxFactor::new(kp, ke, K, measured, image);
                let mut a = Vec::new();
                f.evaluate(&v, Some(&mut a)).expect("cuboid");
                let n = numeric_jacobians(&f, &v, 1e-6).expect("numeric");
                let err = (0..2).map(|i| (&a[i] - &n[i]).norm() / n[i].norm().max(1.0)).fold(0.0, f64::max);
                if err < 1e-3 {
                    check(&f, &v, "cuboid box");
                    cuboid += 1;
                }
            }
        }
        check(&AxisPrior::new(ke, Vector3::new(2.0, 0.8, 0.9)), &v, "axis prior");
        for axis in 0..3 {
            let ad =
                AxisDirection::new(ke, axis, Vector3::new(rng.u(-1.0, 1.0), 1.0, rng.u(-1.0, 1.0))).expect("direction");
            check(&ad, &v, "axis direction");
        }
        let n = Vector3::new(rng.u(-1.0, 1.0), rng.u(-1.0, 1.0), rng.u(-1.0, 1.0));
        let tp = TexturePlane::new(ke, Vector4::new(n.x, n.y, n.z, rng.u(-20.0, 20.0))).expect("plane");
        check(&tp, &v, "texture plane");
        let towards = Vector3::new(rng.u(-1.0, 1.0), rng.u(-1.0, 1.0), rng.u(-1.0, 1.0));
        let at = Vector3::new(rng.u(-20.0, 20.0), rng.u(-2.0, 2.0), rng.u(5.0, 40.0));
        check(&SurfaceDepth::new(ke, at, towards).expect("direction"), &v, "surface depth");
        checked += 1;
    }
    assert!(checked > 50);
    assert!(cuboid > 30, "cuboid box checked at {cuboid} points");
    assert!(TexturePlane::new(slam_optim::Key(0), Vector4::zeros()).is_none());
    assert!(SurfaceDepth::new(slam_optim::Key(0), Vector3::zeros(), Vector3::zeros()).is_none());
    assert!(SurfaceDepth::new(slam_optim::Key(0), Vector3::new(f64::NAN, 0.0, 1.0), Vector3::z()).is_none());
}

/// The cuboid-surface factor at stereo points around a box seen from cameras on every side: points near
/// a visible side (inside and outside the footprint), beyond its ends (nearest to a corner) and far off;
/// points where the nearest side or the nearest point's kind is about to change (a kink) are skipped
/// by comparing with the numeric derivative first, as for the cuboid box model.
#[test]
fn cuboid_surface_factor() {
    let mut rng = TestRng::new(7);
    let mut checked = 0;
    for _ in 0..400 {
        let e = Ellipsoid::new(
            Isometry3::from_parts(
                Translation3::new(rng.u(-8.0, 8.0), rng.u(0.0, 2.0), rng.u(8.0, 40.0)),
                UnitQuaternion::from_euler_angles(rng.u(-0.02, 0.02), rng.u(-3.0, 3.0), rng.u(-0.02, 0.02)),
            ),
            Vector3::new(rng.u(1.5, 2.5), rng.u(0.6, 0.9), rng.u(0.7, 1.0)),
        );
        let mut v = Values::new();
        let ke = v.add(Var::Ellipsoid(e));
        let camera = Vector3::new(rng.u(-20.0, 20.0), rng.u(-1.0, 1.0), rng.u(-10.0, 60.0));
        let a = e.semi_axes;
        let q = Vector3::new(rng.u(-1.5, 1.5) * a.x, rng.u(-1.0, 1.0) * a.y, rng.u(-1.5, 1.5) * a.z);
        let point = e.centre() + e.rotation() * q;
        let up = Vector3::new(0.0, -1.0, 0.0);
        let Some(f) = CuboidSurface::new(ke, (point, camera, up), rng.u(0.2, 2.0), 0.03, 0.1) else { continue };
        let mut analytic = Vec::new();
        f.evaluate(&v, Some(&mut analytic)).expect("residual");
        let n = numeric_jacobians(&f, &v, 1e-6).expect("numeric");
        if (&analytic[0] - &n[0]).norm() / n[0].norm().max(1.0) < 1e-3 && n[0].norm() > 0.0 {
            check(&f, &v, "cuboid surface");
            checked += 1;
        }
    }
    assert!(checked > 200, "{checked} points checked");
    let up = Vector3::new(0.0, -1.0, 0.0);
    let bad = |p: Vector3<f64>, c: Vector3<f64>, u: Vector3<f64>, s: f64| {
        CuboidSurface::new(slam_optim::Key(0), (p, c, u), s, 0.1, 0.1).is_none()
    };
    assert!(bad(Vector3::new(f64::NAN, 0.0, 1.0), Vector3::zeros(), up, 1.0));
    assert!(bad(Vector3::new(0.0, -3.0, 0.0), Vector3::zeros(), up, 1.0), "straight above the camera");
    assert!(bad(Vector3::z(), Vector3::zeros(), Vector3::zeros(), 1.0));
    assert!(bad(Vector3::z(), Vector3::zeros(), up, 0.0));
}

/// Seen from above, whitened by the point's noise: a point on a rear face seen head-on is measured to
/// its depth noise, one beside the box (its ray passes the box) to its noise across the ray; points on
/// a visible side have no residual, points inside the footprint a negative one, and a side the camera
/// cannot see does not count.
#[test]
fn cuboid_surface_residual_is_the_distance_to_a_visible_side_in_the_noise() {
    // a car 20 m ahead, length along z: its rear face (own -x, since own x is the length turned by
    // 90° about y... kept simple: own axes = world axes, length along x) faces the camera at the origin
    let e = Ellipsoid::new(Isometry3::translation(0.0, 0.0, 20.0), Vector3::new(0.9, 0.8, 2.0));
    let mut v = Values::new();
    let ke = v.add(Var::Ellipsoid(e));
    let up = Vector3::new(0.0, -1.0, 0.0);
    let residual = |p: Vector3<f64>, c: Vector3<f64>| {
        CuboidSurface::new(ke, (p, c, up), 1.0, 0.02, 0.1).expect("valid").evaluate(&v, None).expect("residual")[0]
    };
    let origin = Vector3::zeros();
    // the rear face is at z = 18: a point 0.5 m in front of it, on the camera's axis
    let r = residual(Vector3::new(0.0, 0.0, 17.5), origin);
    assert!((r - 0.5 / 1.0f64.hypot(0.1)).abs() < 1e-9, "{r}");
    // on the face: nothing; behind it (inside): negative
    assert!(residual(Vector3::new(0.3, 0.0, 18.0), origin).abs() < 1e-9);
    assert!(residual(Vector3::new(0.3, 0.0, 18.8), origin) < 0.0);
    // a point 0.4 m beside the box (x = 1.3), at the rear face's depth: its ray passes the box, and
    // across the ray stereo is precise: many σ
    let beside = residual(Vector3::new(1.3, 0.0, 18.0), origin);
    assert!(beside > 3.0, "{beside}");
    // seen from the right (x = 10), the right side (x = 0.9) is visible: a point on it has none
    assert!(residual(Vector3::new(0.9, 0.0, 20.5), Vector3::new(10.0, 0.0, 20.0)).abs() < 1e-9);
    // a camera inside the footprint sees no side
    assert_eq!(residual(Vector3::new(0.0, 0.0, 25.0), Vector3::new(0.0, 0.0, 20.0)), 0.0);
}

#[test]
fn surface_depth_is_zero_on_the_ellipsoid_surface_along_the_line_of_sight() {
    let rot = UnitQuaternion::from_euler_angles(0.0, 0.7, 0.0);
    let e = Ellipsoid::new(Isometry3::from_parts(Translation3::new(3.0, 1.0, 25.0), rot), Vector3::new(2.1, 0.8, 0.85));
    let mut v = Values::new();
    let ke = v.add(Var::Ellipsoid(e));
    // the camera at the origin: the direction from the object towards it
    let n = -e.centre().normalize();
    let m = rot.inverse() * n;
    let chord = 1.0 / (m.x * m.x / (2.1 * 2.1) + m.y * m.y / (0.8 * 0.8) + m.z * m.z / (0.85 * 0.85)).sqrt();
    assert!(chord > 0.85 && chord < 2.1, "{chord}");
    let residual = |surface: Vector3<f64>| {
        SurfaceDepth::new(ke, surface, n).expect("direction").evaluate(&v, None).expect("residual")[0]
    };
    assert!(residual(e.centre() + n * chord).abs() < 1e-12);
    // a surface seen 0.5 m nearer the camera than the ellipsoid's: its centre lies 0.5 m too far behind
    assert!((residual(e.centre() + n * (chord + 0.5)) - 0.5).abs() < 1e-12);
    // a shift across the line of sight changes nothing
    let across = n.cross(&Vector3::y()).normalize();
    assert!(residual(e.centre() + n * chord + across * 0.7).abs() < 1e-12);
}
