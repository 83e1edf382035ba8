//! A user-defined factor from outside the optimisation crates, and the object refinement of
//! `slam_optim::object` driven by this backend.

use nalgebra::{DMatrix, DVector, Isometry3, Translation3, UnitQuaternion, Vector3, Vector4};
use slam_lm::LevenbergMarquardt;
use slam_optim::{Factor, FactorError, Graph, Key, NoiseModel, Optimizer, Options, Values, Var};
use slam_quadric::{metrics, project, Camera, Ellipsoid, ImageSize, Intrinsics};

/// Range from a fixed beacon to a point: a factor written by a "user".
struct Range {
    keys: [Key; 1],
    beacon: Vector3<f64>,
    range: f64,
}

impl Factor for Range {
    fn keys(&self) -> &[Key] {
        &self.keys
    }
    fn dim(&self) -> usize {
        1
    }
    fn evaluate(&self, values: &Values, jac: Option<&mut Vec<DMatrix<f64>>>) -> Result<DVector<f64>, FactorError> {
        let p = values.point(self.keys[0]).ok_or(FactorError::WrongVariable(self.keys[0]))?;
        let d = p - self.beacon;
        let n = d.norm();
        if let Some(j) = jac {
            j.clear();
            j.push(DMatrix::from_row_slice(1, 3, (d / n).as_slice()));
        }
        Ok(DVector::from_element(1, n - self.range))
    }
}

#[test]
fn custom_factor_trilateration() {
    let truth = Vector3::new(1.0, 2.0, 3.0);
    let mut values = Values::new();
    let k = values.add(Var::Point(Vector3::new(0.0, 0.0, 0.0)));
    let mut graph = Graph::new();
    for b in [
        Vector3::new(10.0, 0.0, 0.0),
        Vector3::new(0.0, 10.0, 0.0),
        Vector3::new(0.0, 0.0, 10.0),
        Vector3::new(-5.0, -5.0, 5.0),
    ] {
        graph
            .add(Range { keys: [k], beacon: b, range: (truth - b).norm() }, NoiseModel::Isotropic(0.1), slam_optim::L2)
            .expect("fits");
    }
    let s = LevenbergMarquardt::default().optimize(&graph, &mut values, &Options::default(), None).expect("solves");
    assert!((values.point(k).expect("point") - truth).norm() < 1e-6, "{s:?}");
    // a noise model that does not fit is refused
    assert!(graph
        .add(Range { keys: [k], beacon: truth, range: 1.0 }, NoiseModel::Diagonal(vec![1.0, 2.0]), slam_optim::L2)
        .is_err());
}

const K: Intrinsics = Intrinsics { fx: 721.5377, fy: 721.5377, skew: 0.0, cx: 609.5593, cy: 172.854 };

/// `refine_with_planes`: with boxes from a straight drive-by that all sit too far right (a pose or
/// detector bias the boxes cannot reveal), texture planes from the car's true surface pull the centre
/// back; without them the bias stays.
#[test]
fn texture_planes_correct_a_box_bias() {
    use slam_optim::object::{refine, refine_with_planes, ObjectPrior, RefineConfig};
    use slam_quadric::{init::BoxView, BBox};
    let image = ImageSize::new(1242.0, 375.0);
    let truth = Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(4.0, 0.9, 16.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.1),
        ),
        Vector3::new(2.1, 0.8, 0.85),
    );
    let mut views = Vec::new();
    for i in 0..8 {
        let cam = Camera::new(K, Isometry3::translation(0.0, 0.0, 1.2 * i as f64));
        let b = project(&truth, &cam).and_then(|c| c.clipped_bounds(&image)).expect("visible");
        // every box shifted 6 px to the right
        let b = BBox::new(b.xmin + 6.0, b.ymin, b.xmax + 6.0, b.ymax);
        if !b.touches_border(&image, 5.0) {
            views.push(BoxView::new(cam, b));
        }
    }
    assert!(views.len() >= 5);
    // planes tangent to the true surface facing the cameras, as a Delaunay triangulation of points on
    // the side and the back gives them: five near-coplanar triangles per face
    let planes: Vec<Vector4<f64>> = [Vector3::new(0.0, 0.0, -1.0), Vector3::new(-1.0, 0.0, 0.0)]
        .iter()
        .flat_map(|own| std::iter::repeat_n(*own, 5))
        .map(|own| {
            let n = truth.rotation() * own;
            Vector4::new(n.x, n.y, n.z, -(n.dot(&truth.centre()) + truth.half_extent(&n)))
        })
        .collect();
    let config = RefineConfig { pose_drift: None, ..RefineConfig::default() };
    let prior = ObjectPrior::car();
    let lm = LevenbergMarquardt::default();
    let plain = refine(&views, &image, &prior, &config, &lm).expect("fits");
    let with = refine_with_planes(&views, &image, &prior, &config, &planes, &lm).expect("fits");
    let (e0, e1) = (metrics::e_trans(&plain, &truth), metrics::e_trans(&with, &truth));
    assert!(e1 < 0.7 * e0, "planes should cut the centre error by 30 %: {e0:.3} m -> {e1:.3} m");
}

/// Boxes that bound a box-shaped car (its cuboid's projected corners): the ellipse model has to bring
/// the ellipsoid nearer or make it larger to fill them; the cuboid model recovers the car.
#[test]
fn the_cuboid_model_fits_boxes_of_a_box_shaped_car() {
    use slam_optim::object::{refine, BoxShape, ObjectPrior, RefineConfig};
    use slam_quadric::{cuboid_bounds, init::BoxView};
    let image = ImageSize::new(1242.0, 375.0);
    // a parked car ahead on the left, seen obliquely from a camera driving past
    let truth = Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(-4.5, 0.9, 20.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.15),
        ),
        Vector3::new(2.0, 0.75, 0.85),
    );
    let mut views = Vec::new();
    for i in 0..10 {
        let cam = Camera::new(K, Isometry3::translation(0.0, 0.0, 1.2 * i as f64));
        let b = cuboid_bounds(&truth, &cam).expect("in front");
        if image.as_box().contains(&b) && !b.touches_border(&image, 5.0) {
            views.push(BoxView::new(cam, b));
        }
    }
    assert!(views.len() >= 6, "{} views", views.len());
    let prior = ObjectPrior::car();
    let fit = |shape| {
        let config = RefineConfig { box_shape: shape, pose_drift: None, ..RefineConfig::default() };
        refine(&views, &image, &prior, &config, &LevenbergMarquardt::default()).expect("fits")
    };
    let (ellipse, cuboid) = (fit(BoxShape::Ellipse), fit(BoxShape::Cuboid));
    let (e0, e1) = (metrics::e_trans(&ellipse, &truth), metrics::e_trans(&cuboid, &truth));
    let (a0, a1) = (metrics::e_axe(&ellipse, &truth), metrics::e_axe(&cuboid, &truth));
    assert!(e1 < 0.1 && a1 < 0.1, "cuboid model: e_trans {e1:.3} m, e_axe {a1:.3} m");
    assert!(e0 > 3.0 * e1.max(0.05) || a0 > 3.0 * a1.max(0.05), "ellipse model: {e0:.3} m / {a0:.3} m");
    // two stages: the cuboid stage's yaw is held while the ellipse model fills the boxes, so the yaw
    // stays the cuboid's and the ellipse-model box error falls to that of the plain ellipse fit
    let two = fit(BoxShape::TwoStage);
    let up = Vector3::y();
    let (y1, y2) = (metrics::e_yaw(&cuboid, &truth, &up), metrics::e_yaw(&two, &truth, &up));
    assert!(y1 < 1.0 && y2 < 1.5, "yaw: cuboid {y1:.2}°, two stages {y2:.2}°");
    let rms = |e: &Ellipsoid| {
        let sum: f64 = views
            .iter()
            .map(|v| {
                slam_optim::object::box_residual(v, &image, e, BoxShape::Ellipse).expect("projects").norm_squared()
            })
            .sum();
        (sum / (4 * views.len()) as f64).sqrt()
    };
    let (r1, r2) = (rms(&cuboid), rms(&two));
    assert!(r2 < 0.5 * r1, "ellipse-model box error: cuboid fit {r1:.2} px, two stages {r2:.2} px");
}

/// `Cues::surface`: a van (larger than the car prior) ahead, approached along the road, so its boxes fix
/// its depth only through the prior's size, which puts it too near. The stereo depth of its visible
/// surface (where the true ellipsoid's surface lies along the line of sight) brings the centre back.
#[test]
fn the_stereo_depth_of_the_surface_corrects_a_size_biased_depth() {
    use slam_optim::object::{refine, refine_with_cues, Cues, ObjectPrior, RefineConfig, SurfaceCue};
    use slam_quadric::{
        init::{BoxView, Dqp},
        BBox,
    };
    let image = ImageSize::new(1242.0, 375.0);
    let truth = Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(-3.0, 0.6, 30.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.3),
        ),
        Vector3::new(2.77, 1.1, 0.95),
    );
    let cameras: Vec<Camera> =
        (0..10).map(|i| Camera::new(K, Isometry3::translation(0.0, 0.0, 0.4 * i as f64))).collect();
    // a detector's box noise, ±2 px on every edge (a fixed pseudo-random pattern)
    let mut state = 7u64;
    let mut noise = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 33) as f64 / (1u64 << 31) as f64 - 0.5) * 4.0
    };
    let views: Vec<BoxView> = cameras
        .iter()
        .map(|c| {
            let b = project(&truth, c).and_then(|p| p.clipped_bounds(&image)).expect("visible");
            BoxView::new(*c, BBox::new(b.xmin + noise(), b.ymin + noise(), b.xmax + noise(), b.ymax + noise()))
        })
        .collect();
    // the surface along the line of sight from the middle camera
    let towards = (cameras[5].world_from_camera.translation.vector - truth.centre()).normalize();
    let m = truth.rotation().transpose() * towards;
    let chord = 1.0 / m.component_div(&truth.semi_axes).norm();
    let surface = SurfaceCue { surface: truth.centre() + towards * chord, towards_camera: towards, sigma_m: 0.3 };
    let config = RefineConfig { pose_drift: None, ..RefineConfig::default() };
    let prior = ObjectPrior::car();
    let lm = LevenbergMarquardt::default();
    let plain = refine(&views, &image, &prior, &config, &lm).expect("fits");
    let cues = Cues { surface: Some(surface), ..Cues::default() };
    let with = refine_with_cues(&Dqp::default(), &views, &image, &prior, &config, &cues, &lm).expect("fits");
    let (e0, e1) = (metrics::e_trans(&plain, &truth), metrics::e_trans(&with, &truth));
    eprintln!("van centre error: boxes {e0:.3} m, with the surface depth {e1:.3} m");
    assert!(e0 > 1.0, "the car prior should misplace the van: {e0:.3} m");
    assert!(e1 < 0.5 * e0, "the surface depth should halve the centre error: {e0:.3} m -> {e1:.3} m");
}
