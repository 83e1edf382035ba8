//! The object terms of Tian et al. §V: box error, prior axis lengths, texture plane.

use nalgebra::{DMatrix, DVector, Vector3, Vector4};
use slam_quadric::{box_error, BBox, BoundsModel, Camera, Ellipsoid, ImageSize, Intrinsics};

use crate::{
    factor::{Factor, FactorError},
    values::{Key, Values},
};

/// Box error between the projected ellipsoid and a detected box: `predicted − detected` (4 pixels),
/// keys `[T_wc, ellipsoid]` (fix the pose key to optimise the object alone).
///
/// **Border policy.** A box touching the image border is probably truncated. The paper ignores such
/// detections; [`BoxFactor::usable`] is that test (the graph builder counts and logs what it skips).
/// With [`BoundsModel::Clipped`] a truncated box can instead be kept: the prediction is then the exact
/// image-clipped box of the ellipse, which is what the detector saw. When the ellipsoid does not project
/// (behind the camera, camera inside, outside the image) the factor returns
/// [`FactorError::Undefined`]; the solver rejects a trial step that causes it and refuses to start from
/// such a point.
#[derive(Debug, Clone)]
pub struct BoxFactor {
    keys: [Key; 2],
    k: Intrinsics,
    measured: BBox,
    model: BoundsModel,
}

impl BoxFactor {
    /// Detected box `measured` of ellipsoid `object` in the camera at `pose` with intrinsics `k`.
    pub fn new(pose: Key, object: Key, k: Intrinsics, measured: BBox, model: BoundsModel) -> Self {
        Self { keys: [pose, object], k, measured, model }
    }

    /// The paper's policy: use a box only when it is valid and at least `margin` pixels from every image
    /// border.
    pub fn usable(measured: &BBox, image: &ImageSize, margin: f64) -> bool {
        measured.validated().is_ok() && !measured.touches_border(image, margin)
    }
}

impl Factor for BoxFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        4
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let pose = values.require_pose(self.keys[0])?;
        let e = values.require_ellipsoid(self.keys[1])?;
        let cam = Camera::new(self.k, *pose);
        let r =
            box_error(e, &cam, &self.measured, &self.model).map_err(|err| FactorError::Undefined(err.to_string()))?;
        Ok(box_output(&r.error, &r.d_camera, &r.d_quadric, jacobians))
    }
}

/// A box factor's residual, and its Jacobians (camera 4×6, ellipsoid 4×9) when asked for.
fn box_output(
    error: &Vector4<f64>,
    d_camera: &nalgebra::SMatrix<f64, 4, 6>,
    d_object: &nalgebra::SMatrix<f64, 4, 9>,
    jacobians: Option<&mut Vec<DMatrix<f64>>>,
) -> DVector<f64> {
    if let Some(jac) = jacobians {
        jac.clear();
        jac.push(DMatrix::from_column_slice(4, 6, d_camera.as_slice()));
        jac.push(DMatrix::from_column_slice(4, 9, d_object.as_slice()));
    }
    DVector::from_column_slice(error.as_slice())
}

/// Box error of the ellipsoid's circumscribed cuboid: its projected corners' bounds, clamped to the
/// image, minus the detected box (4 pixels), keys `[T_wc, ellipsoid]`. The object model for boxes that
/// bound a box-shaped object (see `slam_quadric::cuboid`). Each side follows one corner, so the
/// prediction is piecewise smooth (like the clipped ellipse's); a side clamped to the border has zero
/// derivative.
#[derive(Debug, Clone)]
pub struct CuboidBoxFactor {
    keys: [Key; 2],
    k: Intrinsics,
    measured: BBox,
    image: ImageSize,
}

impl CuboidBoxFactor {
    /// Detected box `measured` of the object `object` in the camera at `pose`, image `image`.
    pub fn new(pose: Key, object: Key, k: Intrinsics, measured: BBox, image: ImageSize) -> Self {
        Self { keys: [pose, object], k, measured, image }
    }
}

/// The residual of [`CuboidBoxFactor`]: the bounds of the projected corners of `e`'s circumscribed
/// cuboid, clamped to the image, minus `measured`; `None` when a corner is behind the camera.
pub fn cuboid_box_error(camera: &Camera, e: &Ellipsoid, measured: &BBox, image: &ImageSize) -> Option<Vector4<f64>> {
    cuboid_box_prediction(camera, e, image, false).map(|(p, _, _)| p - measured.to_vector())
}

/// Clamped cuboid box and, on request, its Jacobians (4×6 camera `[ω, v]` right perturbation of
/// world-from-camera; 4×9 ellipsoid, see `Ellipsoid::retract`).
fn cuboid_box_prediction(
    camera: &Camera,
    e: &Ellipsoid,
    image: &ImageSize,
    derivatives: bool,
) -> Option<(Vector4<f64>, nalgebra::SMatrix<f64, 4, 6>, nalgebra::SMatrix<f64, 4, 9>)> {
    let cam_from_world = camera.camera_from_world();
    let r_cw = cam_from_world.rotation.to_rotation_matrix().into_inner();
    let r_wo = e.rotation();
    let k = &camera.intrinsics;
    // per corner: own-frame offset q, camera-frame point p, pixel
    let mut corners = Vec::with_capacity(8);
    for s in slam_quadric::cuboid_signs() {
        let q = s.component_mul(&e.semi_axes);
        let p = cam_from_world * nalgebra::Point3::from(e.centre() + r_wo * q);
        if p.z <= 1e-9 || !p.coords.iter().all(|v| v.is_finite()) {
            return None;
        }
        let uv = [k.fx * p.x / p.z + k.skew * p.y / p.z + k.cx, k.fy * p.y / p.z + k.cy];
        corners.push((s, q, p.coords, uv));
    }
    // sides: [xmin, ymin, xmax, ymax] → (corner index, coordinate)
    let pick = |coord: usize, max: bool| {
        (0..8)
            .reduce(|a, b| {
                let (va, vb) = (corners[a].3[coord], corners[b].3[coord]);
                if (max && vb > va) || (!max && vb < va) {
                    b
                } else {
                    a
                }
            })
            .unwrap_or(0)
    };
    let sides = [(pick(0, false), 0), (pick(1, false), 1), (pick(0, true), 0), (pick(1, true), 1)];
    let limits = [image.width, image.height, image.width, image.height];
    let mut predicted = Vector4::zeros();
    let mut d_cam = nalgebra::SMatrix::<f64, 4, 6>::zeros();
    let mut d_obj = nalgebra::SMatrix::<f64, 4, 9>::zeros();
    for (row, &(c, coord)) in sides.iter().enumerate() {
        let raw = corners[c].3[coord];
        predicted[row] = raw.clamp(0.0, limits[row]);
        if !derivatives || raw <= 0.0 || raw >= limits[row] {
            continue;
        }
        let (s, q, p, _) = &corners[c];
        // d pixel / d camera-frame point
        let jp = if coord == 0 {
            nalgebra::RowVector3::new(k.fx / p.z, k.skew / p.z, -(k.fx * p.x + k.skew * p.y) / (p.z * p.z))
        } else {
            nalgebra::RowVector3::new(0.0, k.fy / p.z, -k.fy * p.y / (p.z * p.z))
        };
        // camera: p' = Exp(−ξ) p ≈ p + [p]× ω − v
        let jw = jp * p.cross_matrix();
        let jv = -jp;
        // object: world corner = t + R (q + ω × q + v) with q = s ⊙ (a + δa)
        let jx = jp * r_cw; // d pixel / d world point
        let jo = jx * (-(r_wo * q.cross_matrix()));
        let jt = jx * r_wo;
        let ja = jx * r_wo * nalgebra::Matrix3::from_diagonal(s);
        for j in 0..3 {
            d_cam[(row, j)] = jw[j];
            d_cam[(row, 3 + j)] = jv[j];
            d_obj[(row, j)] = jo[j];
            d_obj[(row, 3 + j)] = jt[j];
            d_obj[(row, 6 + j)] = ja[j];
        }
    }
    Some((predicted, d_cam, d_obj))
}

impl Factor for CuboidBoxFactor {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        4
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let pose = values.require_pose(self.keys[0])?;
        let e = values.require_ellipsoid(self.keys[1])?;
        let (p, d_cam, d_obj) = cuboid_box_prediction(&Camera::new(self.k, *pose), e, &self.image, jacobians.is_some())
            .ok_or_else(|| FactorError::Undefined("a cuboid corner is behind the camera".into()))?;
        Ok(box_output(&(p - self.measured.to_vector()), &d_cam, &d_obj, jacobians))
    }
}

/// Prior on an ellipsoid's semi-axes for its class: residual `a − a_prior` (3), in the ellipsoid's own
/// axis order (for cars: length, height, width along x, y, z).
#[derive(Debug, Clone)]
pub struct AxisPrior {
    keys: [Key; 1],
    prior: Vector3<f64>,
}

impl AxisPrior {
    /// `a ≈ prior`.
    pub fn new(object: Key, prior: Vector3<f64>) -> Self {
        Self { keys: [object], prior }
    }
}

impl Factor for AxisPrior {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        3
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let e = values.require_ellipsoid(self.keys[0])?;
        if let Some(jac) = jacobians {
            let mut j = DMatrix::zeros(3, 9);
            j.view_mut((0, 6), (3, 3)).fill_with_identity();
            jac.clear();
            jac.push(j);
        }
        Ok(DVector::from_column_slice((e.semi_axes - self.prior).as_slice()))
    }
}

/// Texture-plane error (after Ok et al. 2019, used by Tian et al. §V-C): a plane `nᵀx + d = 0` fitted to
/// the object's map points (the visible surface; `n` unit, pointing out of the object towards the
/// camera). The ellipsoid's tangent plane with the same normal on that side is `nᵀx = nᵀt + h(n)` with
/// `h(n) = sqrt(nᵀ S n)`; the residual is their signed distance `nᵀt + h(n) + d` (1, metres).
#[derive(Debug, Clone)]
pub struct TexturePlane {
    keys: [Key; 1],
    plane: Vector4<f64>,
}

impl TexturePlane {
    /// Plane `[n, d]` with `|n| = 1` (normalised here); `None` for a zero normal.
    pub fn new(object: Key, plane: Vector4<f64>) -> Option<Self> {
        let n = Vector3::new(plane[0], plane[1], plane[2]).norm();
        (n > 0.0 && n.is_finite()).then(|| Self { keys: [object], plane: plane / n })
    }
}

impl Factor for TexturePlane {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        1
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let e = values.require_ellipsoid(self.keys[0])?;
        let n = Vector3::new(self.plane[0], self.plane[1], self.plane[2]);
        let r = e.rotation();
        let m = r.transpose() * n;
        let a2 = e.semi_axes.component_mul(&e.semi_axes);
        let h = m.component_mul(&a2).dot(&m).sqrt();
        if h <= 0.0 || !h.is_finite() {
            return Err(FactorError::Undefined("degenerate ellipsoid".into()));
        }
        let res = n.dot(&e.centre()) + h + self.plane[3];
        if let Some(jac) = jacobians {
            let dm = a2.component_mul(&m); // D m
            let dh_dw = dm.cross(&m) / h;
            let dt_dv = r.transpose() * n; // d(nᵀt)/dv = nᵀ R
            let mut j = DMatrix::zeros(1, 9);
            for i in 0..3 {
                j[(0, i)] = dh_dw[i];
                j[(0, 3 + i)] = dt_dv[i];
                j[(0, 6 + i)] = e.semi_axes[i] * m[i] * m[i] / h;
            }
            jac.clear();
            jac.push(j);
        }
        Ok(DVector::from_element(1, res))
    }
}

/// Stereo depth of an object's visible surface: the median of its stereo points, `c`, seen along the
/// unit direction `n` from the object towards the camera. The ellipsoid's surface along that line of
/// sight through its centre lies `δ(n) = 1 / √(Σ mᵢ² / aᵢ²)` (`m = Rᵀn`, the chord's half-length) in
/// front of the centre; the residual is the centre's depth behind the surface, less that chord:
/// `nᵀ(c − t) − δ(n)` (1, metres; positive when the centre lies too far behind the surface).
///
/// Why the chord: over the central part of its silhouette (where the object's points are taken) the
/// visible surface of an ellipsoid lies 0.88 δ in front of the centre (median, seen from afar), that of
/// the box circumscribing it 1.0–1.27 δ (a car or van seen from any side): a real vehicle lies
/// between the two (docs/objects.md, "Stereo depth in the fit").
#[derive(Debug, Clone)]
pub struct SurfaceDepth {
    keys: [Key; 1],
    towards_camera: Vector3<f64>,
    surface: Vector3<f64>,
}

impl SurfaceDepth {
    /// The object's visible surface at `surface` (world), seen from the direction `towards_camera`
    /// (normalised here); `None` for a zero or non-finite direction or a non-finite point.
    pub fn new(object: Key, surface: Vector3<f64>, towards_camera: Vector3<f64>) -> Option<Self> {
        let n = towards_camera.norm();
        (n > 0.0 && n.is_finite() && surface.iter().all(|c| c.is_finite())).then(|| Self {
            keys: [object],
            towards_camera: towards_camera / n,
            surface,
        })
    }
}

impl Factor for SurfaceDepth {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        1
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let e = values.require_ellipsoid(self.keys[0])?;
        let n = self.towards_camera;
        let r = e.rotation();
        let m = r.transpose() * n;
        let inv2 = e.semi_axes.map(|a| 1.0 / (a * a));
        let q = m.component_mul(&inv2).dot(&m);
        if q <= 0.0 || !q.is_finite() {
            return Err(FactorError::Undefined("degenerate ellipsoid".into()));
        }
        let chord = 1.0 / q.sqrt();
        let res = n.dot(&(self.surface - e.centre())) - chord;
        if let Some(jac) = jacobians {
            // m(ω) = Exp(−ω) Rᵀ n, so dm = m × dω; dq = 2 (A⁻² m)ᵀ dm; dδ = −½ q^{−3/2} dq = −½ δ³ dq
            let c3 = chord.powi(3);
            let dchord_dw = -(inv2.component_mul(&m)).cross(&m) * c3;
            let dt_dv = r.transpose() * n; // d(nᵀt)/dv = nᵀ R
            let mut j = DMatrix::zeros(1, 9);
            for i in 0..3 {
                j[(0, i)] = -dchord_dw[i];
                j[(0, 3 + i)] = -dt_dv[i];
                // dq/daᵢ = −2 mᵢ² / aᵢ³, so dδ/daᵢ = δ³ mᵢ² / aᵢ³
                j[(0, 6 + i)] = -c3 * m[i] * m[i] / e.semi_axes[i].powi(3);
            }
            jac.clear();
            jac.push(j);
        }
        Ok(DVector::from_element(1, res))
    }
}

/// A stereo point on an object's visible surface, on one of the visible sides of its box: the box is
/// the cuboid that circumscribes the ellipsoid (semi-axes `a`, own frame; own y is the height), the
/// shape the cuboid box model gives a vehicle. Seen from above (the horizontal plane across `up`), the
/// box is a rectangle, and a camera sees the one or two sides whose outside it stands on; the roof,
/// seen edge-on from a car's height, is left out, and so is the height.
///
/// The point's stereo noise lies along its viewing ray (`σ_z`, growing with the depth squared) with a
/// little across it (`σ_across`, a pixel); a real body's surface lies off its bounding box by
/// `σ_shape` in every direction. In the plane seen from above, whitened by that noise (along the
/// ray by `√(σ_z² + σ_shape²)`, across it by `√(σ_across² + σ_shape²)`), the residual (1) is the
/// point's distance to the nearest visible side, a segment: a point the depth noise put behind a rear
/// face is a σ or two along its ray from it, while a point whose ray passes beside the box is far from
/// every side across the ray, where stereo is precise. Sign: negative inside the footprint. A rear face
/// gives the heading, two faces at a right angle the yaw and their extents; a box too short or beside
/// the points is refused by the points beyond its ends. No visible side (the camera inside the
/// footprint): no residual.
#[derive(Debug, Clone)]
pub struct CuboidSurface {
    keys: [Key; 1],
    /// The point and the camera seen from above (2-D coordinates in the plane across `up`).
    point: nalgebra::Vector2<f64>,
    camera: nalgebra::Vector2<f64>,
    /// The plane's axes (world), rows of the projection.
    plane: nalgebra::Matrix2x3<f64>,
    /// Whitening: rows along the ray / σ_along and across it / σ_across.
    whiten: nalgebra::Matrix2<f64>,
}

impl CuboidSurface {
    /// Point `point` seen from a camera at `camera` (both world), the world's vertical `up`, with depth
    /// σ `sigma_z`, σ across the ray `sigma_across` and shape σ `sigma_shape` (metres); `None` for
    /// non-finite input, a point straight above or below the camera, a zero `up` or σ that are not
    /// positive and finite.
    pub fn new(
        object: Key,
        (point, camera, up): (Vector3<f64>, Vector3<f64>, Vector3<f64>),
        sigma_z: f64,
        sigma_across: f64,
        sigma_shape: f64,
    ) -> Option<Self> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !(ok(sigma_z) && ok(sigma_across) && ok(sigma_shape)) {
            return None;
        }
        let u = up.try_normalize(1e-12)?;
        let seed = if u.x.abs() < 0.9 { Vector3::x() } else { Vector3::z() };
        let h1 = (seed - u * u.dot(&seed)).normalize();
        let h2 = u.cross(&h1);
        let plane = nalgebra::Matrix2x3::from_rows(&[h1.transpose(), h2.transpose()]);
        let (p, c) = (plane * point, plane * camera);
        if !p.iter().chain(c.iter()).all(|v| v.is_finite()) {
            return None;
        }
        let ray = (p - c).try_normalize(1e-9)?;
        let across = nalgebra::Vector2::new(-ray.y, ray.x);
        let (along_s, across_s) = (sigma_z.hypot(sigma_shape), sigma_across.hypot(sigma_shape));
        let whiten = nalgebra::Matrix2::from_rows(&[(ray / along_s).transpose(), (across / across_s).transpose()]);
        Some(Self { keys: [object], point: p, camera: c, plane, whiten })
    }
}

/// The nearest visible side of a [`CuboidSurface`]: the whitened distance to it, the nearest point's
/// offset in the object's frame and its derivatives in the three semi-axes, and the whitened gap.
type NearestSide = (f64, Vector3<f64>, [Vector3<f64>; 3], nalgebra::Vector2<f64>);

impl CuboidSurface {
    /// The residual and, on request, its Jacobian (`[ω, v, δa]`) at ellipsoid `e`, without allocating.
    fn residual(&self, e: &Ellipsoid, jacobian: Option<&mut [f64; 9]>) -> f64 {
        let r = e.rotation();
        let (a, t) = (e.semi_axes, e.centre());
        // the camera in the object's frame decides which sides it sees (only own x and z matter)
        let seen_from = r.transpose() * (self.plane.transpose() * self.camera - t);
        let (pc, pr) = (self.plane * t, self.plane * r);
        let mut best: Option<NearestSide> = None;
        for (i, j) in [(0usize, 2usize), (2, 0)] {
            // the camera stands outside at most one of the two sides across axis i
            let s = if seen_from[i] > a[i] {
                1.0
            } else if seen_from[i] < -a[i] {
                -1.0
            } else {
                continue;
            };
            // the side's ends, own frame: `i` at s a_i, `j` from −a_j to a_j
            let mut e1 = Vector3::zeros();
            e1[i] = s * a[i];
            e1[j] = -a[j];
            let mut e2 = e1;
            e2[j] = a[j];
            let c1 = pc + pr * e1;
            let span = pr * (e2 - e1);
            let (w1, w2) = (self.whiten * (self.point - c1), self.whiten * span);
            let tt = (w1.dot(&w2) / w2.norm_squared().max(1e-300)).clamp(0.0, 1.0);
            let gap = w1 - w2 * tt;
            let d = gap.norm();
            if best.as_ref().is_none_or(|b| d < b.0) {
                // the nearest point's own-frame offset and its derivatives in a_x, a_y, a_z
                let en = e1 * (1.0 - tt) + e2 * tt;
                let mut de = [Vector3::zeros(); 3];
                de[i][i] = s;
                de[j][j] = 2.0 * tt - 1.0;
                best = Some((d, en, de, gap));
            }
        }
        let Some((d, en, de, gap)) = best else {
            if let Some(jac) = jacobian {
                *jac = [0.0; 9];
            }
            return 0.0;
        };
        // inside the footprint: negative
        let q = r.transpose() * (self.plane.transpose() * self.point - t);
        let sign = if q.x.abs() < a.x && q.z.abs() < a.z { -1.0 } else { 1.0 };
        if let Some(jac) = jacobian {
            // d = |W (p − N)|, N = π(t + R e_N): dd = −gᵀ W dN (the nearest point's parameter is at an
            // optimum or a bound: its change does not move d to first order), g = W(p − N) / d;
            // dN = π (R v − R [e_N]× ω + R de_N)
            *jac = [0.0; 9];
            if d > 0.0 {
                let g = (self.whiten.transpose() * gap / d).transpose() * pr; // 1×3: gᵀ W π R
                let dw = g * crate::lie::hat(&en);
                for k in 0..3 {
                    jac[k] = sign * dw[k];
                    jac[3 + k] = -sign * g[k];
                    jac[6 + k] = -sign * g.dot(&de[k].transpose());
                }
            }
        }
        sign * d
    }
}

impl Factor for CuboidSurface {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        1
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let e = values.require_ellipsoid(self.keys[0])?;
        let want = jacobians.is_some();
        let mut j = [0.0; 9];
        let res = self.residual(e, want.then_some(&mut j));
        if let Some(jac) = jacobians {
            jac.clear();
            jac.push(DMatrix::from_row_slice(1, 9, &j));
        }
        Ok(DVector::from_element(1, res))
    }

    fn evaluate_into(
        &self,
        values: &Values,
        residual: &mut [f64],
        jacobians: Option<&mut [f64]>,
    ) -> Result<(), FactorError> {
        let e = values.require_ellipsoid(self.keys[0])?;
        let size = |what: &str, n: usize, want: usize| {
            FactorError::Undefined(format!("{what} buffer of {n} entries, the cuboid surface factor fills {want}"))
        };
        let [r] = residual else { return Err(size("residual", residual.len(), 1)) };
        match jacobians {
            Some(out) => {
                let n = out.len();
                let out: &mut [f64; 9] = out.try_into().map_err(|_| size("Jacobian", n, 9))?;
                *r = self.residual(e, Some(out));
            }
            None => *r = self.residual(e, None),
        }
        Ok(())
    }
}

/// Keeps one of an ellipsoid's axes along a direction: residual `d × (R e_k)` (3; its norm is the sine
/// of the angle between them), e.g. a car's height axis along gravity, the paper's yaw-only assumption
/// as a soft constraint. Without it, a straight drive cannot observe the object's tilt and the
/// optimisation drifts along that unobservable direction.
#[derive(Debug, Clone)]
pub struct AxisDirection {
    keys: [Key; 1],
    axis: usize,
    direction: Vector3<f64>,
}

impl AxisDirection {
    /// Axis `axis` (0, 1, 2 = own x, y, z) of `object` along `direction` (normalised; `None` for a zero
    /// direction or an axis index above 2).
    pub fn new(object: Key, axis: usize, direction: Vector3<f64>) -> Option<Self> {
        let n = direction.norm();
        (axis < 3 && n > 0.0 && n.is_finite()).then(|| Self { keys: [object], axis, direction: direction / n })
    }
}

impl Factor for AxisDirection {
    fn keys(&self) -> &[Key] {
        &self.keys
    }

    fn dim(&self) -> usize {
        3
    }

    fn evaluate(
        &self,
        values: &Values,
        jacobians: Option<&mut Vec<DMatrix<f64>>>,
    ) -> Result<DVector<f64>, FactorError> {
        let e = values.require_ellipsoid(self.keys[0])?;
        let r = e.rotation();
        let mut ek = Vector3::zeros();
        ek[self.axis] = 1.0;
        let a = r * ek;
        let res = self.direction.cross(&a);
        if let Some(jac) = jacobians {
            // R Exp(ω): d(R e_k) = −R [e_k]× ω
            let d = -crate::lie::hat(&self.direction) * r * crate::lie::hat(&ek);
            let mut j = DMatrix::zeros(3, 9);
            j.view_mut((0, 0), (3, 3)).copy_from(&d);
            jac.clear();
            jac.push(j);
        }
        Ok(DVector::from_column_slice(res.as_slice()))
    }
}
