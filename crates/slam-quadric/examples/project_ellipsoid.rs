//! Project a car-sized ellipsoid into a KITTI-like camera and print its image box.
//!
//! ```text
//! cargo run --release -p slam-quadric --example project_ellipsoid
//! cargo run --release -p slam-quadric --example project_ellipsoid -- 6.0 0.9 12.0 0.3
//! ```
//! Optional arguments: centre x y z (metres, camera frame) and yaw (radians).

use std::process::ExitCode;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use slam_quadric::{metrics, predict_box, project, BoundsModel, Camera, Ellipsoid, ImageSize, Intrinsics};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let parsed: Result<Vec<f64>, _> = args.iter().map(|a| a.parse::<f64>()).collect();
    let vals = match parsed {
        Ok(v) if v.is_empty() => vec![2.0, 0.9, 15.0, 0.2],
        Ok(v) if v.len() == 4 => v,
        _ => {
            eprintln!(
                "usage: project_ellipsoid [X Y Z YAW]   (camera frame: x right, y down, z forward; metres, radians)"
            );
            return ExitCode::from(2);
        }
    };
    let k = Intrinsics::new(721.5377, 721.5377, 609.5593, 172.854);
    let image = ImageSize::new(1242.0, 375.0);
    let camera = Camera::new(k, Isometry3::identity());
    let car = Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(vals[0], vals[1], vals[2]),
            UnitQuaternion::from_euler_angles(0.0, vals[3], 0.0),
        ),
        Vector3::new(2.1, 0.8, 0.85),
    );
    println!("camera  : KITTI colour intrinsics, image 1242x375, at the world origin looking along +z");
    println!(
        "ellipsoid: centre [{:.2}, {:.2}, {:.2}] m, yaw {:.3} rad, semi-axes [2.10, 0.80, 0.85] m",
        vals[0], vals[1], vals[2], vals[3]
    );
    let conic = match project(&car, &camera) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("no image box: {e}");
            return ExitCode::FAILURE;
        }
    };
    let show = |name: &str, b: slam_quadric::BBox| {
        println!("{name:<8}: [xmin {:8.2}, ymin {:8.2}, xmax {:8.2}, ymax {:8.2}] px", b.xmin, b.ymin, b.xmax, b.ymax)
    };
    match conic.bounds() {
        Ok(b) => show("bounds", b),
        Err(e) => println!("bounds  : {e}"),
    }
    match conic.clipped_bounds(&image) {
        Ok(b) => {
            show("clipped", b);
            match predict_box(&car, &camera, &BoundsModel::Clipped(image)) {
                Ok(p) => println!("d xmin / d yaw of the ellipsoid: {:.3} px/rad", p.d_quadric[(0, 1)]),
                Err(e) => println!("jacobian: {e}"),
            }
            println!("IoU of the clipped box with itself: {:.3}", metrics::projected_iou(&car, &camera, &image, &b));
        }
        Err(e) => println!("clipped : {e}"),
    }
    ExitCode::SUCCESS
}
