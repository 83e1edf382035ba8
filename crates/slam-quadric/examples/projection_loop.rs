//! The Rust side of the Python module's speed benchmark (`crates/slam-py/bench/bench_geometry.py`):
//! how long `project` takes per ellipsoid in a plain Rust loop, and `project` + exact clipped bounds,
//! over the same scene the benchmark hands to `quadric_slam.project_many` / `bounds_many`.
//!
//! `cargo run --release -p slam-quadric --example projection_loop -- [N] [REPEATS]` (defaults 10000 and
//! 50) prints one line: `projection_loop n=N project_ms=… clipped_ms=… project_ns_each=…`, each the
//! fastest of REPEATS loops over all N ellipsoids.

use std::{hint::black_box, time::Instant};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use slam_quadric::{project, Camera, Ellipsoid, ImageSize, Intrinsics};

/// Ellipsoid `i` of the benchmark's scene: a grid 20 m wide and 10-50 m ahead of a level camera, each
/// turned about the vertical by `0.1 i` rad and scaled by `1 + 0.2 sin i` (bench_geometry.py builds the
/// same).
fn ellipsoid(i: usize) -> Ellipsoid {
    let x = -10.0 + 20.0 * (i % 100) as f64 / 100.0;
    let z = 10.0 + 40.0 * ((i / 100) % 100) as f64 / 100.0;
    let s = 1.0 + 0.2 * (i as f64).sin();
    Ellipsoid::new(
        Isometry3::from_parts(
            Translation3::new(x, 1.0, z),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.1 * i as f64),
        ),
        Vector3::new(2.1 * s, 0.8 * s, 0.85 * s),
    )
}

fn best_ms(repeats: usize, mut f: impl FnMut()) -> f64 {
    (0..repeats)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let arg = |k: usize, default: usize| std::env::args().nth(k).and_then(|a| a.parse().ok()).unwrap_or(default);
    let (n, repeats) = (arg(1, 10_000), arg(2, 50).max(1));
    let camera = Camera::new(Intrinsics::new(721.5377, 721.5377, 609.5593, 172.854), Isometry3::identity());
    let image = ImageSize::new(1242.0, 375.0);
    let scene: Vec<Ellipsoid> = (0..n).map(ellipsoid).collect();
    let project_ms = best_ms(repeats, || {
        for e in &scene {
            let _ = black_box(project(black_box(e), &camera));
        }
    });
    let clipped_ms = best_ms(repeats, || {
        for e in &scene {
            let _ = black_box(project(black_box(e), &camera).and_then(|c| c.clipped_bounds(&image)));
        }
    });
    println!(
        "projection_loop n={n} project_ms={project_ms:.4} clipped_ms={clipped_ms:.4} project_ns_each={:.1}",
        project_ms * 1e6 / n.max(1) as f64
    );
}
