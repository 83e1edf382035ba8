//! Texture planes of an object (Tian et al. §V-C): a Delaunay triangulation (`spade`) of the object's
//! map points as seen from a camera; each triangle is a small plane of the visible surface, its normal
//! turned towards the camera. Object optimisation asks the ellipsoid's tangent plane with that normal to
//! coincide with it ([`slam_optim::object::refine_with_planes`]).

use nalgebra::{Point3, Vector3, Vector4};
use slam_quadric::Camera;
use spade::{DelaunayTriangulation, Point2, Triangulation};

/// Which triangles become planes.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize, documented::DocumentedFieldsOpt)]
#[serde(default, deny_unknown_fields)]
pub struct TextureConfig {
    /// Longest triangle edge, metres (longer ones bridge the object and its background). Default 1.5.
    pub max_edge_m: f64,
    /// Triangles seen more edge-on than this (|cos| of the angle between normal and viewing ray) are
    /// dropped: their normals are unreliable. Default 0.3.
    pub min_facing: f64,
    /// Most planes kept (the largest triangles). Default 30.
    pub max_planes: usize,
    /// Fewest points for a triangulation. Default 4.
    pub min_points: usize,
}

impl Default for TextureConfig {
    fn default() -> Self {
        Self { max_edge_m: 1.5, min_facing: 0.3, max_planes: 30, min_points: 4 }
    }
}

/// Planes `[n, d]` (`nᵀx + d = 0`, `n` unit towards the camera) of the triangles of `points` (world
/// frame) triangulated in `camera`'s image.
pub fn texture_planes(points: &[Vector3<f64>], camera: &Camera, config: &TextureConfig) -> Vec<Vector4<f64>> {
    if points.len() < config.min_points.max(3) {
        return Vec::new();
    }
    let centre = camera.world_from_camera.translation.vector;
    let from_world = camera.world_from_camera.inverse();
    let mut tri: DelaunayTriangulation<Point2<f64>> = DelaunayTriangulation::new();
    let mut world_of = Vec::new();
    for x in points {
        let c = from_world * Point3::from(*x);
        if c.z <= 0.1 || !x.iter().all(|v| v.is_finite()) {
            continue;
        }
        let k = &camera.intrinsics;
        let p = Point2::new(k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
        // a repeated pixel position returns the existing vertex: the later point wins
        let Ok(h) = tri.insert(p) else { continue };
        if world_of.len() <= h.index() {
            world_of.resize(h.index() + 1, Vector3::zeros());
        }
        world_of[h.index()] = *x;
    }
    let mut planes: Vec<(f64, Vector4<f64>)> = Vec::new();
    for face in tri.inner_faces() {
        let [a, b, c] = face.vertices().map(|v| world_of[v.fix().index()]);
        if [(a, b), (b, c), (c, a)].iter().any(|(p, q)| (p - q).norm() > config.max_edge_m) {
            continue;
        }
        let cross = (b - a).cross(&(c - a));
        let area = 0.5 * cross.norm();
        if area < 1e-4 {
            continue;
        }
        let mut n = cross / (2.0 * area);
        let centroid = (a + b + c) / 3.0;
        let to_camera = (centre - centroid).normalize();
        if n.dot(&to_camera) < 0.0 {
            n = -n;
        }
        if n.dot(&to_camera) < config.min_facing {
            continue;
        }
        planes.push((area, Vector4::new(n.x, n.y, n.z, -n.dot(&centroid))));
    }
    planes.sort_by(|p, q| q.0.total_cmp(&p.0));
    planes.truncate(config.max_planes);
    planes.into_iter().map(|p| p.1).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Isometry3;
    use slam_quadric::Intrinsics;

    #[test]
    fn points_on_a_facing_wall_give_its_plane() {
        let cam = Camera::new(Intrinsics::new(700.0, 700.0, 600.0, 180.0), Isometry3::identity());
        // a 3 m × 1.5 m wall at z = 12, facing the camera, sampled on a jittered grid
        let mut pts = Vec::new();
        for i in 0..8 {
            for j in 0..5 {
                let jitter = 0.01 * (((i * 7 + j * 3) % 5) as f64 - 2.0);
                pts.push(Vector3::new(-1.5 + 0.4 * i as f64 + jitter, -0.7 + 0.35 * j as f64, 12.0));
            }
        }
        let planes = texture_planes(&pts, &cam, &TextureConfig::default());
        assert!(planes.len() >= 20, "{} planes", planes.len());
        for p in &planes {
            // normal towards the camera (−z), distance 12
            assert!((p[2] + 1.0).abs() < 1e-6 && (p[3] - 12.0).abs() < 1e-6, "{p:?}");
        }
        // a point far behind joins no triangle with long edges
        pts.push(Vector3::new(0.0, 0.0, 30.0));
        let with_far = texture_planes(&pts, &cam, &TextureConfig::default());
        assert!(with_far.iter().all(|p| (p[3] - 12.0).abs() < 1e-6));
        // too few points: nothing
        assert!(texture_planes(&pts[..3], &cam, &TextureConfig::default()).is_empty());
    }
}
