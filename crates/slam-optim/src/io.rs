//! Readers of the BAL bundle-adjustment format and the g2o 3-D pose-graph format, building a
//! [`Graph`] and [`Values`]. Errors name the file and line.

use std::path::{Path, PathBuf};

use nalgebra::{DMatrix, Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::{
    factors::{BalReprojection, Between},
    graph::Graph,
    noise::NoiseModel,
    robust::{Huber, RobustKernel, L2},
    values::{BalCamera, Key, Values, Var},
};

/// Errors of the problem readers.
#[derive(Debug, thiserror::Error)]
pub enum ProblemError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Not a regular file, larger than a problem file may be, or not UTF-8 ([`slam_core::files`]).
    #[error(transparent)]
    Read(#[from] slam_core::files::ReadError),
    /// Malformed content.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// File.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

/// A loaded problem.
pub struct Problem {
    /// The factors.
    pub graph: Graph,
    /// The initial values.
    pub values: Values,
    /// Keys of the cameras (BAL) or poses (g2o), in file order.
    pub cameras: Vec<Key>,
    /// Keys of the points (BAL only).
    pub points: Vec<Key>,
}

struct Tokens<'a> {
    path: &'a Path,
    iter: Box<dyn Iterator<Item = (usize, &'a str)> + 'a>,
}

impl<'a> Tokens<'a> {
    fn new(path: &'a Path, text: &'a str) -> Self {
        let iter = text.lines().enumerate().flat_map(|(i, l)| l.split_whitespace().map(move |t| (i + 1, t)));
        Self { path, iter: Box::new(iter) }
    }
    fn next<T: std::str::FromStr>(&mut self, what: &str) -> Result<T, ProblemError> {
        let (line, tok) = self.iter.next().ok_or_else(|| ProblemError::Parse {
            path: self.path.to_path_buf(),
            line: 0,
            message: format!("unexpected end of file, expected {what}"),
        })?;
        tok.parse::<T>().map_err(|_| ProblemError::Parse {
            path: self.path.to_path_buf(),
            line,
            message: format!("expected {what}, found '{tok}'"),
        })
    }
    fn finite(&mut self, what: &str) -> Result<f64, ProblemError> {
        let v: f64 = self.next(what)?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(ProblemError::Parse { path: self.path.to_path_buf(), line: 0, message: format!("non-finite {what}") })
        }
    }
}

fn read(path: &Path) -> Result<String, ProblemError> {
    slam_core::files::read_text(path, &slam_core::files::PROBLEM).map_err(|e| match e {
        slam_core::files::ReadError::Io { path, source } => ProblemError::Io { path, source },
        other => ProblemError::Read(other),
    })
}

/// Read a BAL problem; `huber` gives the Huber threshold in pixels (σ = 1 px), `None` for plain L2.
/// Points are the variables to eliminate (`Problem::points`).
pub fn read_bal(path: impl AsRef<Path>, huber: Option<f64>) -> Result<Problem, ProblemError> {
    let path = path.as_ref();
    let text = read(path)?;
    parse_bal(path, &text, huber)
}

/// Parse a BAL problem's text; `path` only names it in error messages.
pub fn parse_bal(path: &Path, text: &str, huber: Option<f64>) -> Result<Problem, ProblemError> {
    let mut t = Tokens::new(path, text);
    let n_cam: usize = t.next("camera count")?;
    let n_pt: usize = t.next("point count")?;
    let n_obs: usize = t.next("observation count")?;
    // counts come from the file: never allocate more than the text could hold (found by fuzzing)
    let cap = |n: usize| n.min(text.len() / 2);
    let mut obs = Vec::with_capacity(cap(n_obs));
    for _ in 0..n_obs {
        let c: usize = t.next("camera index")?;
        let p: usize = t.next("point index")?;
        let u = t.finite("u")?;
        let v = t.finite("v")?;
        if c >= n_cam || p >= n_pt {
            return Err(ProblemError::Parse {
                path: path.to_path_buf(),
                line: 0,
                message: format!("observation refers to camera {c} / point {p} beyond {n_cam} / {n_pt}"),
            });
        }
        obs.push((c, p, [u, v]));
    }
    let mut values = Values::new();
    let mut cameras = Vec::with_capacity(cap(n_cam));
    for _ in 0..n_cam {
        let mut c = [0.0; 9];
        for x in c.iter_mut() {
            *x = t.finite("camera parameter")?;
        }
        cameras.push(values.add(Var::Bal(BalCamera(c))));
    }
    let mut points = Vec::with_capacity(cap(n_pt));
    for _ in 0..n_pt {
        let x = t.finite("point x")?;
        let y = t.finite("point y")?;
        let z = t.finite("point z")?;
        points.push(values.add(Var::Point(Vector3::new(x, y, z))));
    }
    let mut graph = Graph::new();
    for (c, p, uv) in obs {
        let kernel: Box<dyn RobustKernel> = match huber {
            Some(d) => Box::new(Huber(d)),
            None => Box::new(L2),
        };
        graph
            .add_boxed(Box::new(BalReprojection::new(cameras[c], points[p], uv)), NoiseModel::Unit, kernel)
            .map_err(|e| ProblemError::Parse { path: path.to_path_buf(), line: 0, message: e.to_string() })?;
    }
    Ok(Problem { graph, values, cameras, points })
}

/// Read a g2o 3-D pose graph (`VERTEX_SE3:QUAT`, `EDGE_SE3:QUAT`). The information matrix, given in
/// (translation, rotation) order, is reordered to our `[ω, v]` tangent; the residual is
/// `Log(Z⁻¹ X_i⁻¹ X_j)` (gtsam's reading of the format). Vertex ids may be sparse; keys follow file order.
pub fn read_g2o(path: impl AsRef<Path>) -> Result<Problem, ProblemError> {
    let path = path.as_ref();
    let text = read(path)?;
    parse_g2o(path, &text)
}

/// Parse a g2o 3-D pose graph's text; `path` only names it in error messages.
pub fn parse_g2o(path: &Path, text: &str) -> Result<Problem, ProblemError> {
    let mut values = Values::new();
    let mut ids = std::collections::HashMap::new();
    let mut cameras = Vec::new();
    let mut edges = Vec::new();
    let parse_err = |line: usize, message: String| ProblemError::Parse { path: path.to_path_buf(), line, message };
    for (i, line) in text.lines().enumerate() {
        let f: Vec<&str> = line.split_whitespace().collect();
        let Some(tag) = f.first() else { continue };
        let nums = |from: usize, n: usize| -> Result<Vec<f64>, ProblemError> {
            if f.len() < from + n {
                return Err(parse_err(i + 1, format!("{tag}: expected {} fields, found {}", from + n, f.len())));
            }
            f[from..from + n]
                .iter()
                .map(|s| match s.parse::<f64>() {
                    Ok(v) if v.is_finite() => Ok(v),
                    _ => Err(parse_err(i + 1, format!("not a finite number: '{s}'"))),
                })
                .collect()
        };
        let pose_of = |v: &[f64]| -> Result<Isometry3<f64>, ProblemError> {
            let q = Quaternion::new(v[6], v[3], v[4], v[5]);
            if q.norm() < 1e-9 {
                return Err(parse_err(i + 1, "zero quaternion".into()));
            }
            Ok(Isometry3::from_parts(Translation3::new(v[0], v[1], v[2]), UnitQuaternion::from_quaternion(q)))
        };
        match *tag {
            "VERTEX_SE3:QUAT" => {
                let id: i64 =
                    f.get(1).and_then(|s| s.parse().ok()).ok_or_else(|| parse_err(i + 1, "bad vertex id".into()))?;
                let v = nums(2, 7)?;
                let k = values.add(Var::Pose(pose_of(&v)?));
                if ids.insert(id, k).is_some() {
                    return Err(parse_err(i + 1, format!("duplicate vertex {id}")));
                }
                cameras.push(k);
            }
            "EDGE_SE3:QUAT" => {
                let a: i64 =
                    f.get(1).and_then(|s| s.parse().ok()).ok_or_else(|| parse_err(i + 1, "bad edge id".into()))?;
                let b: i64 =
                    f.get(2).and_then(|s| s.parse().ok()).ok_or_else(|| parse_err(i + 1, "bad edge id".into()))?;
                let v = nums(3, 7 + 21)?;
                let z = pose_of(&v[..7])?;
                let mut info = DMatrix::zeros(6, 6);
                let mut idx = 7;
                for r in 0..6 {
                    for c in r..6 {
                        info[(r, c)] = v[idx];
                        info[(c, r)] = v[idx];
                        idx += 1;
                    }
                }
                // (t, rot) → (rot, t)
                let perm = [3, 4, 5, 0, 1, 2];
                let swapped = DMatrix::from_fn(6, 6, |r, c| info[(perm[r], perm[c])]);
                edges.push((i + 1, a, b, z, swapped));
            }
            _ => {}
        }
    }
    let mut graph = Graph::new();
    for (line, a, b, z, info) in edges {
        let (Some(&ka), Some(&kb)) = (ids.get(&a), ids.get(&b)) else {
            return Err(parse_err(line, format!("edge {a}-{b} refers to an unknown vertex")));
        };
        let noise = NoiseModel::from_information(&info)
            .ok_or_else(|| parse_err(line, "information matrix not positive definite".into()))?;
        graph.add(Between::new(ka, kb, z), noise, L2).map_err(|e| parse_err(line, e.to_string()))?;
    }
    Ok(Problem { graph, values, cameras, points: Vec::new() })
}
