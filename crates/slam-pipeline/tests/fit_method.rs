//! The object fits go through the `slam_quadric::Initializer` seam: a `FitMethod` uses the initialiser
//! it is given, as it is or as a start of the object optimisation, and the built-in methods are found
//! by their table names.

use std::sync::{
    atomic::{AtomicUsize, Ordering},
    Arc, Mutex,
};

mod common;

use common::{IMAGE, K};
use nalgebra::Isometry3;
use slam_assoc::Oda;
use slam_core::{ClassId, Detection};
use slam_pipeline::objects::{FitMethod, MapperConfig, ObjectMapper};
use slam_quadric::{
    init::{BoxView, Dqp, InitError, Initializer},
    metrics, project, Camera, Ellipsoid,
};

fn parked() -> Ellipsoid {
    common::car(5.0, 30.0, 0.05)
}

/// DQP, counting its calls and keeping its latest answer; or, with `fail`, refusing every time.
#[derive(Default)]
struct Recording {
    calls: AtomicUsize,
    last: Mutex<Option<Ellipsoid>>,
    fail: bool,
}

impl Initializer for Recording {
    fn name(&self) -> &'static str {
        "recording"
    }
    fn min_views(&self) -> usize {
        Dqp::default().min_views()
    }
    fn initialize(&self, views: &[BoxView]) -> Result<Ellipsoid, InitError> {
        self.calls.fetch_add(1, Ordering::SeqCst);
        if self.fail {
            return Err(InitError::TooFewViews { got: views.len(), need: usize::MAX });
        }
        let e = Dqp::default().initialize(views)?;
        if let Ok(mut last) = self.last.lock() {
            *last = Some(e);
        }
        Ok(e)
    }
}

/// The parked car seen over 22 frames (1 m per frame, exact boxes of its ellipsoid, so fitted with the
/// ellipse box model); the ellipsoids mapped.
fn map_with(method: FitMethod) -> Vec<Ellipsoid> {
    let optimizer = common::lm();
    let config = MapperConfig { box_shape: slam_optim::object::BoxShape::Ellipse, ..MapperConfig::default() };
    let mut mapper = ObjectMapper::new(Box::new(Oda::default()), config, optimizer).with_method(method);
    for f in 0..22 {
        let cam = Camera::new(K, Isometry3::translation(0.0, 0.0, f as f64));
        let dets: Vec<Detection> = project(&parked(), &cam)
            .and_then(|c| c.clipped_bounds(&IMAGE))
            .map(|b| vec![Detection::new(ClassId(2), 1.0, b)])
            .unwrap_or_default();
        mapper.step(f, &cam, &dets);
    }
    mapper.objects().filter_map(|o| o.ellipsoid).collect()
}

#[test]
fn an_initial_only_method_maps_its_initializers_ellipsoid() {
    let init = Arc::new(Recording::default());
    let mapped = map_with(FitMethod::initial(init.clone(), "recorded DQP"));
    assert!(init.calls.load(Ordering::SeqCst) > 0, "the initialiser was called");
    let last = init.last.lock().expect("lock").expect("an answer");
    assert_eq!(mapped, vec![last], "the map holds the initialiser's latest ellipsoid as it is");
    let failing = Arc::new(Recording { fail: true, ..Recording::default() });
    assert!(map_with(FitMethod::initial(failing.clone(), "failing")).is_empty(), "no ellipsoid without one");
    assert!(failing.calls.load(Ordering::SeqCst) > 0);
}

#[test]
fn a_refined_method_starts_the_optimisation_from_its_initializer() {
    let init = Arc::new(Recording::default());
    let mapped = map_with(FitMethod::refined(init.clone(), "recorded DQP+refine"));
    assert!(init.calls.load(Ordering::SeqCst) > 0, "the initialiser gave a start");
    assert_eq!(mapped.len(), 1);
    assert!(metrics::e_trans(&mapped[0], &parked()) < 0.05, "{}", metrics::e_trans(&mapped[0], &parked()));
    // refinement is a stage of its own: with a failing initialiser its other starts still map the car
    let failing = Arc::new(Recording { fail: true, ..Recording::default() });
    assert_eq!(map_with(FitMethod::refined(failing, "failing+refine")).len(), 1);
}

#[test]
fn built_in_methods_are_found_by_their_table_names() {
    for (i, name) in FitMethod::NAMES.iter().enumerate() {
        let m = FitMethod::by_name(name).expect("a built-in method");
        assert_eq!(m.name(), *name);
        assert_eq!(m.refines(), i == 0, "{name}: only Tri+Yaw+refine refines");
    }
    assert_eq!(FitMethod::by_name("Tri+Yaw+refine"), Some(FitMethod::default()));
    assert!(FitMethod::by_name("DQP++").is_none());
}
