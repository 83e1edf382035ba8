//! The Rust side of the Python module's oracle test (`crates/slam-py/tests/test_oracle.py`): this crate's
//! values on the inputs of the shipped oracle vectors (`fixtures/oracle/quadric_vectors.json`), written as
//! JSON for the test to compare with what `quadric_slam` gives on the same inputs (1e-12 relative).
//!
//! `cargo run --release -p slam-quadric --example oracle_values -- OUT.json [ORACLE.json]`
//!
//! Per projection case: Q*, P, the projection (C* or the error's text), full and clipped bounds (both
//! image sizes), the predicted boxes with their Jacobians, the camera-inside flag; per constrain case the
//! strict and lenient ellipsoids; per retract case the retracted ellipsoid and the local coordinates
//! back; per IoU case the IoU; per multi-view case every initialiser's ellipsoid (true and noisy boxes)
//! and its metrics against the truth. Matrices are row-major nested lists; an error is its text.

use std::path::PathBuf;

use nalgebra::{Isometry3, Matrix4, SMatrix, Vector3};
use serde_json::{json, Value};
use slam_quadric::{
    init::{BoxView, Conic, Dqp, Initializer, QSlamSvd, Reference, Tri},
    metrics, predict_box, project, se3, BBox, BoundsModel, Camera, Ellipsoid, ImageSize, Intrinsics, Tangent9,
};

fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Value {
    json!((0..R).map(|i| (0..C).map(|j| m[(i, j)]).collect::<Vec<f64>>()).collect::<Vec<_>>())
}

fn numbers(v: &Value) -> Vec<f64> {
    let flat = |x: &Value| -> Vec<f64> {
        match x.as_array() {
            Some(a) => a.iter().map(|y| y.as_f64().expect("number")).collect(),
            None => vec![x.as_f64().expect("number")],
        }
    };
    v.as_array().expect("array").iter().flat_map(flat).collect()
}

/// A row-major 4×4 from the oracle, as the Python module reads it (`from_row_slice`, then the pose).
fn pose(v: &Value) -> Isometry3<f64> {
    se3::isometry_from_matrix(&Matrix4::from_row_slice(&numbers(v)))
}

fn vec3(v: &Value) -> Vector3<f64> {
    let n = numbers(v);
    Vector3::new(n[0], n[1], n[2])
}

fn bbox(v: &Value) -> BBox {
    let n = numbers(v);
    BBox::new(n[0], n[1], n[2], n[3])
}

fn ellipsoid_value(r: Result<Ellipsoid, impl std::fmt::Display>) -> Value {
    match r {
        Ok(e) => json!({ "Q_normalized": rows(&e.dual_quadric_normalized()), "centre": e.centre().as_slice(),
                          "axes": e.semi_axes.as_slice() }),
        Err(e) => json!({ "error": e.to_string() }),
    }
}

fn prediction(e: &Ellipsoid, cam: &Camera, model: &BoundsModel) -> Value {
    match predict_box(e, cam, model) {
        Ok(p) => json!({ "box": p.bbox.to_array(), "d_camera": rows(&p.d_camera), "d_quadric": rows(&p.d_quadric) }),
        Err(err) => json!({ "error": err.to_string() }),
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().expect("usage: oracle_values OUT.json [ORACLE.json]"));
    let oracle_path = args.next().map(PathBuf::from).unwrap_or_else(|| {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/oracle/quadric_vectors.json")
    });
    let text = std::fs::read_to_string(&oracle_path).unwrap_or_else(|e| panic!("{}: {e}", oracle_path.display()));
    let o: Value = serde_json::from_str(&text).expect("oracle JSON");
    let c = &o["conventions"]["calibration"];
    let f = |k: &str| c[k].as_f64().expect("calibration");
    let k = Intrinsics { fx: f("fx"), fy: f("fy"), skew: f("s"), cx: f("cx"), cy: f("cy") };
    let wh = numbers(&c["image_wh"]);
    let sizes = [ImageSize::new(wh[0], wh[1]), ImageSize::new(640.0, 480.0)];

    let projection: Vec<Value> = o["projection_cases"]
        .as_array()
        .expect("cases")
        .iter()
        .map(|case| {
            let e = Ellipsoid::new(pose(&case["quadric"]["world_T_quadric"]), vec3(&case["quadric"]["radii"]));
            let cam = Camera::new(k, pose(&case["camera"]["world_T_camera"]));
            let projected = project(&e, &cam);
            let conic = match &projected {
                Ok(c) => {
                    json!({ "C": rows(&c.0), "C_normalized": rows(&c.normalized()), "is_ellipse": c.is_ellipse(),
                                  "bounds": c.bounds().map(|b| b.to_array().to_vec()).map_err(|e| e.to_string()).ok() })
                }
                Err(err) => json!({ "error": err.to_string() }),
            };
            let clipped: Vec<Value> = sizes
                .iter()
                .map(|s| match projected.and_then(|c| c.clipped_bounds(s)) {
                    Ok(b) => json!(b.to_array()),
                    Err(err) => json!({ "error": err.to_string() }),
                })
                .collect();
            json!({
                "id": case["id"],
                "Q": rows(&e.dual_quadric()),
                "Q_normalized": rows(&e.dual_quadric_normalized()),
                "P": rows(&cam.projection_matrix()),
                "projection": conic,
                "clipped": clipped,
                "predict_full": prediction(&e, &cam, &BoundsModel::Full),
                "predict_clipped": prediction(&e, &cam, &BoundsModel::Clipped(sizes[0])),
                "contains_camera": e.contains_point(&cam.centre()),
            })
        })
        .collect();

    let constrain: Vec<Value> = o["constrain_cases"]
        .as_array()
        .expect("cases")
        .iter()
        .map(|case| {
            let m = Matrix4::from_row_slice(&numbers(&case["input_matrix_M"]));
            let lenient = match Ellipsoid::from_dual_quadric_lenient(&m) {
                Ok((e, flipped)) => json!({ "Q_normalized": rows(&e.dual_quadric_normalized()), "flipped": flipped }),
                Err(err) => json!({ "error": err.to_string() }),
            };
            json!({ "id": case["id"], "strict": ellipsoid_value(Ellipsoid::from_dual_quadric(&m)), "lenient": lenient })
        })
        .collect();

    let retract: Vec<Value> = o["retract_cases"]
        .as_array()
        .expect("cases")
        .iter()
        .map(|case| {
            let e = Ellipsoid::new(pose(&case["world_T_quadric"]), vec3(&case["radii"]));
            let d = Tangent9::from_column_slice(&numbers(&case["delta_9"]));
            let r = e.retract(&d);
            json!({ "id": case["id"], "pose": rows(&r.world_from_quadric.to_homogeneous()),
                    "axes": r.semi_axes.as_slice(), "local": e.local(&r).as_slice() })
        })
        .collect();

    let iou: Vec<Value> = o["iou_cases"]
        .as_array()
        .expect("cases")
        .iter()
        .map(|case| json!({ "id": case["id"], "iou": bbox(&case["a_xyxy"]).iou(&bbox(&case["b_xyxy"])) }))
        .collect();

    let up = Vector3::new(0.0, -1.0, 0.0);
    let multiview: Vec<Value> = o["multiview_cases"]
        .as_array()
        .expect("cases")
        .iter()
        .map(|case| {
            let truth = Ellipsoid::new(pose(&case["truth_world_T_quadric"]), vec3(&case["truth_radii"]));
            let cams: Vec<Camera> = case["views"]
                .as_array()
                .expect("views")
                .iter()
                .map(|v| Camera::new(k, pose(&v["world_T_camera"])))
                .collect();
            // the yaw-only reference of the crate's own oracle test: sharing the truth's y axis
            let yaw = nalgebra::UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 20f64.to_radians());
            let frame =
                truth.world_from_quadric * Isometry3::from_parts(nalgebra::Translation3::new(3.0, -1.0, -30.0), yaw);
            // as the Python side reads it: from the 4×4 written below
            let written = frame.to_homogeneous();
            let frame = se3::isometry_from_matrix(&written);
            let methods: Vec<(&str, Box<dyn Initializer>)> = vec![
                ("qslam", Box::new(QSlamSvd)),
                ("conic", Box::new(Conic::default())),
                ("tri", Box::new(Tri::default())),
                ("tri_cc", Box::new(Tri::with_centre_correction())),
                ("dqp", Box::new(Dqp::default())),
                ("dqp_cc", Box::new(Dqp::with_centre_correction())),
                ("dqp_cc_frame", Box::new(Dqp { reference: Reference::Frame(frame), ..Dqp::with_centre_correction() })),
            ];
            let mut by_boxes = serde_json::Map::new();
            for key in ["true_box_xyxy", "noisy_box_xyxy"] {
                let views: Vec<BoxView> = case["views"]
                    .as_array()
                    .expect("views")
                    .iter()
                    .zip(&cams)
                    .map(|(v, cam)| BoxView::new(*cam, bbox(&v[key])))
                    .collect();
                let mut results = serde_json::Map::new();
                for (name, m) in &methods {
                    let r = m.initialize(&views);
                    let mut v = ellipsoid_value(r);
                    if let Ok(e) = r {
                        let yaw = metrics::e_yaw(&e, &truth, &up);
                        v["metrics"] = json!({
                            "e_trans": metrics::e_trans(&e, &truth),
                            "e_axe": metrics::e_axe(&e, &truth),
                            "e_axe_ordered": metrics::e_axe_ordered(&e, &truth),
                            "e_yaw": if yaw.is_nan() { Value::Null } else { json!(yaw) },
                            "projected_iou": metrics::projected_iou(&e, &views[0].camera, &sizes[0], &views[0].bbox),
                            "box_iou": metrics::box_iou(&e, &views[0].camera, &sizes[0], &views[0].bbox),
                        });
                    }
                    results.insert((*name).to_string(), v);
                }
                by_boxes.insert(key.to_string(), Value::Object(results));
            }
            json!({ "id": case["id"], "reference_frame": rows(&written), "results": by_boxes })
        })
        .collect();

    let doc = json!({
        "oracle": oracle_path.display().to_string(),
        "projection_cases": projection,
        "constrain_cases": constrain,
        "retract_cases": retract,
        "iou_cases": iou,
        "multiview_cases": multiview,
    });
    let text = serde_json::to_string(&doc).expect("JSON");
    std::fs::write(&out, text).unwrap_or_else(|e| panic!("{}: {e}", out.display()));
}
