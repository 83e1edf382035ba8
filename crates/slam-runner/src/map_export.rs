//! The PLY exports of a saved map (`slam-app map --ply/--scene`): its points as a point cloud, and
//! the scene (ellipsoids, keyframe cameras, trajectory, points) as a coloured mesh that MeshLab,
//! Blender and CloudCompare open. Both write atomically and refuse values a PLY file's 32-bit floats
//! cannot hold.

use std::path::Path;

use nalgebra::{Isometry3, Vector3};
use slam_pipeline::saved_map::{pose_from_array, SavedMap, SavedMapError, SavedObject, MAP_WORLD};

/// Export the map points as an ASCII PLY point cloud (atomically).
pub fn export_points_ply(map: &SavedMap, path: &Path) -> Result<(), SavedMapError> {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = write!(
        s,
        "ply\nformat ascii 1.0\ncomment quadric-slam map points\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        map.points.len()
    );
    for (id, p) in &map.points {
        ply_float(path, &format!("points.{id}.position"), &p.position)?;
        let _ = writeln!(s, "{} {} {}", p.position[0], p.position[1], p.position[2]);
    }
    Ok(slam_core::files::write_atomic(path, s.as_bytes())?)
}

/// A PLY vertex's coordinates must fit the file's 32-bit floats (a larger value would be written as
/// a number the reader turns into infinity).
fn ply_float(path: &Path, what: &str, v: &[f64; 3]) -> Result<(), SavedMapError> {
    if v.iter().all(|x| x.is_finite() && x.abs() <= f64::from(f32::MAX)) {
        return Ok(());
    }
    Err(SavedMapError::Invalid {
        path: path.to_path_buf(),
        field: what.to_string(),
        message: format!("{v:?} does not fit the PLY file's 32-bit floats (at most {:.3e})", f32::MAX),
    })
}

/// What [`export_scene_ply`] wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SceneCounts {
    /// Ellipsoid meshes (static and dynamic objects; moving ones are not mapped and not written).
    pub ellipsoids: usize,
    /// Keyframe camera frusta.
    pub cameras: usize,
    /// Trajectory vertices (one per frame with a pose).
    pub trajectory: usize,
    /// Map points.
    pub points: usize,
    /// Vertices, faces and edges in the file.
    pub vertices: usize,
    /// Triangles.
    pub faces: usize,
    /// Edges.
    pub edges: usize,
}

/// Colours of the 3-D scene (RGB): static objects green, dynamic orange, cameras blue, trajectory black,
/// points grey; the same as the pictures' (docs/system.md).
const SCENE_STATIC: [u8; 3] = [40, 170, 60];
const SCENE_DYNAMIC: [u8; 3] = [240, 140, 20];
const SCENE_CAMERA: [u8; 3] = [31, 119, 180];
const SCENE_TRAJECTORY: [u8; 3] = [0, 0, 0];
const SCENE_POINT: [u8; 3] = [150, 150, 150];

/// Export the scene as an ASCII PLY mesh (atomically) that MeshLab, Blender and CloudCompare open:
/// each mapped object's ellipsoid as a triangle mesh (12 × 24 facets, coloured by state), each
/// keyframe's camera as a frustum of four triangles (1 m deep, looking along its z), the frame
/// trajectory as edges, and the map points as vertices; world frame of the map ([`MAP_WORLD`]).
pub fn export_scene_ply(map: &SavedMap, path: &Path) -> Result<SceneCounts, SavedMapError> {
    let mut mesh = SceneMesh::default();
    let mut counts = SceneCounts::default();
    for o in map.objects.iter().filter(|o| !o.moving) {
        mesh.add_ellipsoid(o);
        counts.ellipsoids += 1;
    }
    for k in map.keyframes.values() {
        mesh.add_frustum(&pose_from_array(&k.pose));
        counts.cameras += 1;
    }
    let first = mesh.vertices.len();
    for p in map.frame_poses().into_iter().flatten() {
        let t = p.translation.vector;
        mesh.vertices.push(([t.x, t.y, t.z], SCENE_TRAJECTORY));
    }
    counts.trajectory = mesh.vertices.len() - first;
    for i in first + 1..mesh.vertices.len() {
        mesh.edges.push([i - 1, i]);
    }
    for p in map.points.values() {
        mesh.vertices.push((p.position, SCENE_POINT));
    }
    counts.points = map.points.len();
    (counts.vertices, counts.faces, counts.edges) = (mesh.vertices.len(), mesh.faces.len(), mesh.edges.len());
    for (i, (v, _)) in mesh.vertices.iter().enumerate() {
        ply_float(path, &format!("vertex {i}"), v)?;
    }
    slam_core::files::write_atomic(path, mesh.to_ply().as_bytes())?;
    Ok(counts)
}

/// Coloured vertices, triangles and edges of an exported scene.
#[derive(Default)]
struct SceneMesh {
    vertices: Vec<([f64; 3], [u8; 3])>,
    faces: Vec<[usize; 3]>,
    edges: Vec<[usize; 2]>,
}

impl SceneMesh {
    /// An ellipsoid as 12 rings × 24 segments between two poles, coloured by its state.
    fn add_ellipsoid(&mut self, o: &SavedObject) {
        let (rings, segments) = (12usize, 24usize);
        let colour = if o.dynamic { SCENE_DYNAMIC } else { SCENE_STATIC };
        let r = nalgebra::Matrix3::from_row_slice(&o.rotation);
        let base = self.vertices.len();
        // poles, then rings × segments
        for z in [-1.0, 1.0] {
            let p = r * Vector3::new(0.0, 0.0, z * o.semi_axes[2]) + Vector3::from(o.center);
            self.vertices.push(([p.x, p.y, p.z], colour));
        }
        for i in 1..rings {
            let theta = std::f64::consts::PI * i as f64 / rings as f64 - std::f64::consts::FRAC_PI_2;
            for j in 0..segments {
                let phi = std::f64::consts::TAU * j as f64 / segments as f64;
                let u = Vector3::new(
                    o.semi_axes[0] * theta.cos() * phi.cos(),
                    o.semi_axes[1] * theta.cos() * phi.sin(),
                    o.semi_axes[2] * theta.sin(),
                );
                let p = r * u + Vector3::from(o.center);
                self.vertices.push(([p.x, p.y, p.z], colour));
            }
        }
        let at = |i: usize, j: usize| base + 2 + (i - 1) * segments + j % segments;
        for j in 0..segments {
            self.faces.push([base, at(1, j + 1), at(1, j)]);
            self.faces.push([base + 1, at(rings - 1, j), at(rings - 1, j + 1)]);
            for i in 1..rings - 1 {
                self.faces.push([at(i, j), at(i, j + 1), at(i + 1, j + 1)]);
                self.faces.push([at(i, j), at(i + 1, j + 1), at(i + 1, j)]);
            }
        }
    }

    /// A camera as a frustum of four triangles, 1 m deep along its z.
    fn add_frustum(&mut self, pose: &Isometry3<f64>) {
        let base = self.vertices.len();
        let apex = pose.translation.vector;
        self.vertices.push(([apex.x, apex.y, apex.z], SCENE_CAMERA));
        for (x, y) in [(-0.6, -0.2), (0.6, -0.2), (0.6, 0.2), (-0.6, 0.2)] {
            let p = pose * nalgebra::Point3::new(x, y, 1.0);
            self.vertices.push(([p.x, p.y, p.z], SCENE_CAMERA));
        }
        for c in 0..4 {
            self.faces.push([base, base + 1 + c, base + 1 + (c + 1) % 4]);
        }
    }

    /// The ASCII PLY text.
    fn to_ply(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        // writing into a String cannot fail
        let _ = write!(
            s,
            "ply\nformat ascii 1.0\ncomment quadric-slam scene: ellipsoids (green static, orange dynamic), camera \
             frusta (blue), trajectory (black edges), map points (grey)\ncomment {MAP_WORLD}\nelement vertex {}\n\
             property float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n\
             property uchar blue\nelement face {}\nproperty list uchar int vertex_indices\nelement edge {}\n\
             property int vertex1\nproperty int vertex2\nend_header\n",
            self.vertices.len(),
            self.faces.len(),
            self.edges.len()
        );
        for (p, c) in &self.vertices {
            let _ = writeln!(s, "{:.4} {:.4} {:.4} {} {} {}", p[0], p[1], p[2], c[0], c[1], c[2]);
        }
        for f in &self.faces {
            let _ = writeln!(s, "3 {} {} {}", f[0], f[1], f[2]);
        }
        for e in &self.edges {
            let _ = writeln!(s, "{} {}", e[0], e[1]);
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Isometry3;
    use slam_pipeline::saved_map::{pose_to_array, FramePose, SavedKeyframe, SavedMapPoint};

    use super::*;

    /// Two keyframes (one a metre off), a point and two frames, each placed at its keyframe.
    fn two_keyframes() -> SavedMap {
        let identity = pose_to_array(&Isometry3::identity());
        let keyframe = |frame, pose, parent| SavedKeyframe { frame, pose, parent, observations: vec![], culled: false };
        let mut m = SavedMap::default();
        m.keyframes.insert(0, keyframe(0, identity, None));
        m.keyframes.insert(1, keyframe(3, pose_to_array(&Isometry3::translation(1.0, 2.0, 3.0)), Some(0)));
        m.points.insert(7, SavedMapPoint { position: [0.5, 0.1, 9.0], observed_by: vec![0] });
        for k in [0, 1] {
            let state = "tracked".to_string();
            m.trajectory.push(FramePose { frame: k as usize, keyframe: Some(k), relative: identity, state });
        }
        m
    }

    /// A point beyond a 32-bit float is refused by both exports, which then write nothing; one within
    /// it is written.
    #[test]
    fn coordinates_beyond_a_float32_are_refused() {
        let dir = std::env::temp_dir().join(format!("map-export-far-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let mut m = two_keyframes();
        m.points.insert(9, SavedMapPoint { position: [0.0, 1e300, 0.0], observed_by: vec![0] });
        let e = export_points_ply(&m, &dir.join("p.ply")).expect_err("1e300").to_string();
        assert!(e.contains("points.9.position") && e.contains("32-bit floats"), "{e}");
        let e = export_scene_ply(&m, &dir.join("s.ply")).expect_err("1e300").to_string();
        assert!(e.contains("32-bit floats"), "{e}");
        m.points.get_mut(&9).expect("point").position = [0.0, 1.2e7, 0.0];
        export_points_ply(&m, &dir.join("p.ply")).expect("within a float32");
        let names: Vec<String> = std::fs::read_dir(&dir)
            .expect("list")
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["p.ply"], "no temporary, nothing of the refused exports: {names:?}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// The point cloud holds the point; the scene one ellipsoid (a moving object is left out), two
    /// frusta, two trajectory vertices and a point, its header counting its body.
    #[test]
    fn points_and_scene_are_written() {
        let dir = std::env::temp_dir().join(format!("map-export-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp dir");
        let mut m = two_keyframes();
        export_points_ply(&m, &dir.join("points.ply")).expect("ply");
        let ply = std::fs::read_to_string(dir.join("points.ply")).expect("ply text");
        assert!(ply.contains("element vertex 1") && ply.trim_end().ends_with("0.5 0.1 9"));
        let object = SavedObject {
            id: 4,
            class: 2,
            class_name: "car".into(),
            center: [1.0, 0.0, 10.0],
            semi_axes: [2.0, 0.8, 0.9],
            rotation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            frames: vec![0, 1],
            dynamic: false,
            moving: false,
            points: vec![],
            views: vec![],
            earlier_views: 0,
        };
        m.objects.push(object.clone());
        m.objects.push(SavedObject { id: 5, moving: true, dynamic: true, ..object });
        let c = export_scene_ply(&m, &dir.join("scene.ply")).expect("scene");
        assert_eq!((c.ellipsoids, c.cameras, c.trajectory, c.points), (1, 2, 2, 1));
        let ellipsoid_vertices = 2 + 11 * 24;
        assert_eq!(c.vertices, ellipsoid_vertices + 2 * 5 + 2 + 1);
        assert_eq!((c.faces, c.edges), (2 * 24 + 2 * 24 * 10 + 2 * 4, 1));
        let scene = std::fs::read_to_string(dir.join("scene.ply")).expect("scene text");
        let body: Vec<&str> = scene.split("end_header\n").nth(1).expect("body").lines().collect();
        assert_eq!(body.len(), c.vertices + c.faces + c.edges, "header counts match the body");
        // every ellipsoid vertex lies on the ellipsoid ((x−c)ᵀ A⁻² (x−c) = 1)
        for line in &body[..ellipsoid_vertices] {
            let v: Vec<f64> = line.split_whitespace().take(3).map(|x| x.parse().expect("number")).collect();
            let q = ((v[0] - 1.0) / 2.0).powi(2) + (v[1] / 0.8).powi(2) + ((v[2] - 10.0) / 0.9).powi(2);
            assert!((q - 1.0).abs() < 1e-3, "{line}: {q}");
        }
        assert!(body[..ellipsoid_vertices].iter().all(|l| l.ends_with(" 40 170 60")), "static: green");
        std::fs::remove_dir_all(&dir).ok();
    }
}
