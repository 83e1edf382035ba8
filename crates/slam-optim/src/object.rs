//! Object optimisation of one ellipsoid from its box observations (Tian et al. §V), robust enough to
//! start from any of the initialisers: used by the simulation study and by the object mapper.
//!
//! See [`refine`] for the stages (starts, re-weighted passes, joint camera-object stage).

use nalgebra::{Matrix3, UnitQuaternion, Vector3, Vector4};
use slam_quadric::{
    init::{triangulate_box_centres, BoxView, Dqp, InitError, Initializer, TriangulationConfig},
    se3, BoundsModel, Ellipsoid, ImageSize,
};

use crate::{
    factors::{
        AxisDirection, AxisPrior, BoxFactor, CuboidBoxFactor, CuboidSurface, PosePrior, SurfaceDepth, TexturePlane,
    },
    Graph, Huber, NoiseModel, Optimizer, Options, Values, Var, L2,
};

/// Class prior of an object's semi-axes (own x = length, y = height, z = width) with standard deviations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectPrior {
    /// Mean semi-axes, metres.
    pub axes: Vector3<f64>,
    /// Standard deviation of each, metres.
    pub sigma: Vector3<f64>,
}

impl ObjectPrior {
    /// The car prior of the study: the middle of the sampled ranges, σ = the uniform ranges' widths / 2.
    pub fn car() -> Self {
        Self { axes: Vector3::new(2.1, 0.8, 0.85), sigma: Vector3::new(0.3, 0.1, 0.1) }
    }
}

/// What a detected box is taken to bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BoxShape {
    /// The ellipsoid itself: the exact image-clipped bounds of its projected ellipse (the paper's model).
    #[default]
    Ellipse,
    /// The cuboid circumscribing the ellipsoid (a car is box-shaped): the clamped bounds of its projected
    /// corners ([`CuboidBoxFactor`]).
    Cuboid,
    /// Two stages: the orientation (and a first centre and size) from the cuboid model, which is the
    /// right model of a box-shaped car's silhouette and so decides its yaw; then the paper's ellipse
    /// model from there with that yaw held (σ `hold_yaw_sigma_deg`), which sizes and places the
    /// ellipsoid to fill the boxes. Its box error is the ellipse model's.
    TwoStage,
}

impl BoxShape {
    /// The box model of the final ellipsoid (the one its box error is measured with).
    pub fn final_model(self) -> BoxShape {
        match self {
            BoxShape::Cuboid => BoxShape::Cuboid,
            BoxShape::Ellipse | BoxShape::TwoStage => BoxShape::Ellipse,
        }
    }
}

/// A soft prior on an object's yaw: its length axis (own x) along a horizontal direction, either way
/// (the residual is sign-free), with standard deviation `sigma_rad` (the angle's sine, radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawCue {
    /// Direction of the length axis, world frame (need not be unit).
    pub direction: Vector3<f64>,
    /// Standard deviation, radians.
    pub sigma_rad: f64,
}

/// The stereo depth of an object's visible surface ([`SurfaceDepth`]): the ellipsoid's centre lies
/// one chord half-length behind it along the line of sight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceCue {
    /// Median of the object's stereo points, world frame.
    pub surface: Vector3<f64>,
    /// Direction from the object towards the cameras that saw those points (need not be unit).
    pub towards_camera: Vector3<f64>,
    /// Standard deviation, metres: the points' depth noise and how far a real object's visible surface
    /// may lie from its ellipsoid's.
    pub sigma_m: f64,
}

/// A stereo point on an object's visible surface ([`CuboidSurface`]): where it is and the camera it
/// was seen from (world), and its noise along and across its viewing ray, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// World position, metres.
    pub point: Vector3<f64>,
    /// The camera's centre, world, metres.
    pub camera: Vector3<f64>,
    /// Stereo depth σ along the ray, metres.
    pub sigma_z: f64,
    /// σ across the ray (a pixel at the point's depth), metres.
    pub sigma_across: f64,
}

/// What a fit may use besides the boxes and the class prior; every stage after the starts uses them.
#[derive(Debug, Clone, Copy, Default)]
pub struct Cues<'a> {
    /// Texture planes `[n, d]` of the object's map points ([`TexturePlane`]; `n` unit, pointing out of
    /// the object towards the cameras), σ `plane_sigma_m` with Huber.
    pub planes: &'a [Vector4<f64>],
    /// A soft prior on the yaw (e.g. from the object's stereo points, or a first stage's).
    pub yaw: Option<YawCue>,
    /// The stereo depth of the object's visible surface.
    pub surface: Option<SurfaceCue>,
    /// The object's own stereo points, on the faces of its box ([`CuboidSurface`], with the cuboid box
    /// model and its stage of a two-stage fit), σ from each point's noise and
    /// [`RefineConfig::surface_shape_sigma_m`], with Huber at [`RefineConfig::surface_huber`].
    pub surface_points: &'a [SurfacePoint],
}

/// Settings of [`refine`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefineConfig {
    /// The box model of the box error.
    pub box_shape: BoxShape,
    /// Box noise σ of the first pass, pixels (whitening of the box error).
    pub box_sigma_px: f64,
    /// Huber threshold in pixels (converted to σ units for each pass, so re-estimating σ does not
    /// change which residuals count as outliers).
    pub huber_px: f64,
    /// Passes; after each, every view's σ is re-estimated as its RMS box residual, times each side's
    /// share of the misfit as the first pass measured it (at least half the overall RMS, clamped to
    /// `[min_sigma_px, max_sigma_px]`), so the axis prior weighs as much as the boxes' actual misfit
    /// warrants (little when they fit: no bias at zero noise) and views whose pose or box is off count
    /// less.
    pub passes: usize,
    /// Lower clamp of the re-estimated σ, pixels.
    pub min_sigma_px: f64,
    /// Upper clamp of the re-estimated σ, pixels.
    pub max_sigma_px: f64,
    /// Final joint stage: camera poses become variables (the first view stays fixed) with a prior at
    /// their given values whose translation σ grows with the distance from the first camera,
    /// `σ_t = pose_drift · distance` (odometry drift per metre), and rotation σ `pose_rot_sigma_deg`.
    /// `None` keeps the poses fixed.
    pub pose_drift: Option<f64>,
    /// Rotation σ of the pose prior in the joint stage, degrees.
    pub pose_rot_sigma_deg: f64,
    /// Below this RMS box misfit (pixels) after the fixed-pose passes, the data count as consistent
    /// and the joint stage is skipped.
    pub consistent_rms_px: f64,
    /// The joint stage runs only when the shift part of the misfit exceeds this multiple of its size
    /// part (see [`refine`]).
    pub shift_ratio: f64,
    /// Standard deviation of the texture-plane error, metres (only with planes, [`refine_with_planes`]).
    pub plane_sigma_m: f64,
    /// Huber threshold of the texture-plane error, metres.
    pub plane_huber_m: f64,
    /// With texture planes, the re-estimated box σ is at least this, pixels.
    pub plane_box_floor_px: f64,
    /// [`BoxShape::TwoStage`]: σ of the prior holding the first stage's yaw in the second, degrees.
    pub hold_yaw_sigma_deg: f64,
    /// How far a real body's surface lies from its bounding box (σ, metres): a car's panels are curved
    /// and its corners rounded (a plan-view corner radius of about a quarter of its width, 0.4 m, puts
    /// its surface up to 0.12 m inside the box there), its glass slopes inward; 0.1 m.
    pub surface_shape_sigma_m: f64,
    /// Huber threshold of the surface points, in σ: a point beyond it (the road or a wall inside the
    /// object's depth window, a mismatch on glass) counts linearly. 2 σ (95 % of a normal noise below it).
    pub surface_huber: f64,
    /// Fewest surface points a fit uses at all: fewer say nothing (no opinion rather than one a stray
    /// point or two could make). 10: the points an object's depth needs in each of two frames (a
    /// centroid takes five, so that one stray point of the background cannot move it).
    pub min_surface_points: usize,
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self {
            box_shape: BoxShape::Ellipse,
            box_sigma_px: 1.0,
            huber_px: 3.0,
            passes: 8,
            min_sigma_px: 1e-4,
            max_sigma_px: 20.0,
            pose_drift: Some(0.03),
            pose_rot_sigma_deg: 0.2,
            consistent_rms_px: 0.2,
            shift_ratio: 2.0,
            plane_sigma_m: 0.25,
            plane_huber_m: 0.5,
            plane_box_floor_px: 2.0,
            hold_yaw_sigma_deg: 0.5,
            surface_shape_sigma_m: 0.1,
            surface_huber: 2.0,
            min_surface_points: 10,
        }
    }
}

/// Box error (predicted − detected, pixels) of an ellipsoid in a view under a box model; `None` when it
/// does not project.
pub fn box_residual(v: &BoxView, image: &ImageSize, e: &Ellipsoid, shape: BoxShape) -> Option<Vector4<f64>> {
    match shape.final_model() {
        BoxShape::Ellipse | BoxShape::TwoStage => {
            Some(slam_quadric::box_error(e, &v.camera, &v.bbox, &BoundsModel::Clipped(*image)).ok()?.error)
        }
        BoxShape::Cuboid => crate::factors::cuboid_box_error(&v.camera, e, &v.bbox, image),
    }
}

/// An ellipsoid's box residual in each view and their mean square over all sides of all views
/// (pixels²); `None` when it does not project into a view.
fn box_misfit(
    views: &[BoxView],
    image: &ImageSize,
    e: &Ellipsoid,
    shape: BoxShape,
) -> Option<(Vec<Vector4<f64>>, f64)> {
    let r: Vec<Vector4<f64>> = views.iter().map(|v| box_residual(v, image, e, shape)).collect::<Option<_>>()?;
    let all = r.iter().map(|x| x.norm_squared()).sum::<f64>() / (4.0 * r.len().max(1) as f64);
    Some((r, all))
}

/// Each box side's share of an ellipsoid's misfit: side `s`'s mean square over the views divided by
/// the overall mean square (1 each when the misfit is zero). It measures the detector's bias on that
/// side of this object (e.g. a part of a large vehicle it leaves out, a neighbour it merges in) and is
/// taken once, from the first pass, whose boxes were all weighed alike. Re-measured after passes that
/// used it, it would also take up the object's own misfit along that side (a class prior too small for
/// the object shows as the same one-sided misfit in every view): the side's σ would grow from pass to
/// pass and free the extent it should hold. On drive 0005 at every 3rd frame that turned the parked
/// van's bottom σ from 5 to 20 px over 9 passes while its height shrank from 1.11 to 0.70 m, and the
/// 10th pass lifted it 5 m off the road. `None` when the ellipsoid does not project into a view.
fn side_shares(views: &[BoxView], image: &ImageSize, e: &Ellipsoid, shape: BoxShape) -> Option<[f64; 4]> {
    let (r, all) = box_misfit(views, image, e, shape)?;
    let n = r.len().max(1) as f64;
    let mut out = [1.0; 4];
    if all > 0.0 {
        for (k, o) in out.iter_mut().enumerate() {
            *o = r.iter().map(|x| x[k] * x[k]).sum::<f64>() / n / all;
        }
    }
    Some(out)
}

/// Box noise σ of each view's four sides (pixels) from an ellipsoid's misfit, for the re-weighted
/// passes: a view's error (its pose, a partial box) and a side's ([`side_shares`], measured once)
/// multiply, so side `s` of view `v` gets `σ² = σ_v² · share_s` (the view's mean square over its
/// sides), never below half the overall RMS (one view or side cannot claim to be much better than the
/// data as a whole), clamped to `[min_sigma, max_sigma_px]`. `None` when the ellipsoid does not
/// project into a view.
fn side_sigmas(
    views: &[BoxView],
    image: &ImageSize,
    e: &Ellipsoid,
    config: &RefineConfig,
    min_sigma: f64,
    shares: &[f64; 4],
) -> Option<Vec<[f64; 4]>> {
    let (r, all) = box_misfit(views, image, e, config.box_shape)?;
    let floor = 0.5 * all.sqrt();
    Some(
        r.iter()
            .map(|x| {
                let view = x.norm_squared() / 4.0;
                let mut out = [0.0; 4];
                for k in 0..4 {
                    out[k] = (view * shares[k]).sqrt().max(floor).clamp(min_sigma, config.max_sigma_px);
                }
                out
            })
            .collect(),
    )
}

/// RMS box error (pixels) of an ellipsoid in each view; `None` when it does not project into a view.
fn box_rms(views: &[BoxView], image: &ImageSize, e: &Ellipsoid, shape: BoxShape) -> Option<Vec<f64>> {
    views.iter().map(|v| Some((box_residual(v, image, e, shape)?.norm_squared() / 4.0).sqrt())).collect()
}

/// Re-order an ellipsoid's axes (permuting rotation columns, keeping a proper rotation) to match the
/// prior's order best; the ellipsoid is unchanged as a set.
fn align_to_prior(e: &Ellipsoid, prior: &Vector3<f64>) -> Ellipsoid {
    const PERMS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    let r = e.rotation();
    let best = PERMS
        .iter()
        .min_by(|p, q| {
            let err =
                |p: &[usize; 3]| (Vector3::new(e.semi_axes[p[0]], e.semi_axes[p[1]], e.semi_axes[p[2]]) - prior).norm();
            err(p).total_cmp(&err(q))
        })
        .copied()
        .unwrap_or([0, 1, 2]);
    let mut cols = [r.column(best[0]).into_owned(), r.column(best[1]).into_owned(), r.column(best[2]).into_owned()];
    if cols[0].cross(&cols[1]).dot(&cols[2]) < 0.0 {
        cols[2] = -cols[2];
    }
    let rot = Matrix3::from_columns(&cols);
    Ellipsoid::new(
        se3::isometry_from_parts(&rot, &e.centre()),
        Vector3::new(e.semi_axes[best[0]], e.semi_axes[best[1]], e.semi_axes[best[2]]),
    )
}

/// Object optimisation of one ellipsoid over fixed (noisy) cameras: box error on the exact clipped
/// bounds (Huber), plus the class prior on the semi-axes; returns the optimised ellipsoid and its cost.
pub fn optimise_object(
    views: &[BoxView],
    image: &ImageSize,
    prior: &ObjectPrior,
    config: &RefineConfig,
    start: Ellipsoid,
    optimizer: &dyn Optimizer,
) -> Option<(Ellipsoid, f64)> {
    let sigmas = vec![[config.box_sigma_px; 4]; views.len()];
    optimise_object_weighted(
        views,
        image,
        prior,
        config,
        start,
        Stage { sigmas: &sigmas, drift: None, cues: Cues::default(), optimizer, tolerance: FINE },
    )
}

/// What one optimisation stage uses besides the views: one box σ per view (pixels), the pose drift
/// (`None`: cameras fixed), the cues and the optimiser.
struct Stage<'a> {
    /// Box noise σ of each view's four sides, pixels.
    sigmas: &'a [[f64; 4]],
    drift: Option<f64>,
    cues: Cues<'a>,
    optimizer: &'a dyn Optimizer,
    /// Relative cost decrease (and step) below which the stage stops: [`FINE`], or [`COARSE`] for the
    /// starts, which only need to be ranked.
    tolerance: f64,
}

/// Stop when a step lowers the cost by less than this share: the final passes, converged to the
/// solver's precision so that exact data give exact results.
const FINE: f64 = 1e-12;
/// The starts' first pass stops at a millionth of the cost (the tolerance Ceres uses by default):
/// enough to rank the starts, the best of which is then polished to [`FINE`].
const COARSE: f64 = 1e-6;

/// [`optimise_object`] with one box σ per view (pixels); with `drift`, the cameras other than the
/// first become variables with a prior at their given poses (translation σ = `drift` × distance to the
/// first camera, rotation σ = `pose_rot_sigma_deg`), else they are fixed.
fn optimise_object_weighted(
    views: &[BoxView],
    image: &ImageSize,
    prior: &ObjectPrior,
    config: &RefineConfig,
    start: Ellipsoid,
    Stage { sigmas, drift, cues, optimizer, tolerance }: Stage<'_>,
) -> Option<(Ellipsoid, f64)> {
    let mut values = Values::new();
    let mut graph = Graph::new();
    let ko = values.add(Var::Ellipsoid(start));
    let options = Options {
        function_tolerance: tolerance,
        parameter_tolerance: tolerance,
        max_iterations: 200,
        ..Options::default()
    };
    let first = views.first()?.camera.world_from_camera;
    let rot_sigma = config.pose_rot_sigma_deg.to_radians();
    for (i, (v, sigma)) in views.iter().zip(sigmas).enumerate() {
        let pose = v.camera.world_from_camera;
        let kp = values.add(Var::Pose(pose));
        match drift {
            Some(k) if i > 0 => {
                let st = (k * (pose.translation.vector - first.translation.vector).norm()).max(1e-4);
                let noise = NoiseModel::Diagonal(vec![rot_sigma, rot_sigma, rot_sigma, st, st, st]);
                graph.add(PosePrior::new(kp, pose), noise, L2).ok()?;
            }
            _ => {
                graph.fix(kp);
            }
        }
        // Huber at `huber_px` of the view's mean σ (its four sides whitened by their own σ)
        let mean = (sigma.iter().map(|s| s * s).sum::<f64>() / 4.0).sqrt();
        let (noise, huber) = (NoiseModel::Diagonal(sigma.to_vec()), Huber(config.huber_px / mean));
        match config.box_shape.final_model() {
            BoxShape::Ellipse | BoxShape::TwoStage => graph.add(
                BoxFactor::new(kp, ko, v.camera.intrinsics, v.bbox, BoundsModel::Clipped(*image)),
                noise,
                huber,
            ),
            BoxShape::Cuboid => {
                graph.add(CuboidBoxFactor::new(kp, ko, v.camera.intrinsics, v.bbox, *image), noise, huber)
            }
        }
        .ok()?;
    }
    graph.add(AxisPrior::new(ko, prior.axes), NoiseModel::Diagonal(prior.sigma.as_slice().to_vec()), L2).ok()?;
    for plane in cues.planes {
        if let Some(f) = TexturePlane::new(ko, *plane) {
            graph
                .add(f, NoiseModel::Isotropic(config.plane_sigma_m), Huber(config.plane_huber_m / config.plane_sigma_m))
                .ok()?;
        }
    }
    // The paper's assumption: the object only yaws; its height axis (own y) stays along the reference
    // camera's y axis (gravity for a level camera), 0.5° σ.
    let up = first.rotation * Vector3::y();
    graph.add(AxisDirection::new(ko, 1, up)?, NoiseModel::Isotropic(0.5f64.to_radians()), L2).ok()?;
    if let Some(cue) = cues.yaw {
        // only the cue's horizontal part: the height axis is held by the factor above
        let horizontal = cue.direction - up * up.dot(&cue.direction);
        if let Some(f) = AxisDirection::new(ko, 0, horizontal) {
            graph.add(f, NoiseModel::Isotropic(cue.sigma_rad), L2).ok()?;
        }
    }
    if let Some(cue) = cues.surface {
        if let Some(f) = SurfaceDepth::new(ko, cue.surface, cue.towards_camera) {
            graph.add(f, NoiseModel::Isotropic(cue.sigma_m), L2).ok()?;
        }
    }
    if config.box_shape == BoxShape::Cuboid && cues.surface_points.len() >= config.min_surface_points {
        for p in cues.surface_points {
            let at = (p.point, p.camera, up);
            let f = CuboidSurface::new(ko, at, p.sigma_z, p.sigma_across, config.surface_shape_sigma_m);
            if let Some(f) = f {
                // the factor whitens itself (σ from the point's noise along the face's normal)
                graph.add(f, NoiseModel::Isotropic(1.0), Huber(config.surface_huber)).ok()?;
            }
        }
    }
    let summary = optimizer.optimize(&graph, &mut values, &options, None).ok()?;
    let e = *values.ellipsoid(ko)?;
    let in_front = views.iter().all(|v| slam_quadric::classify(&e, &v.camera) == slam_quadric::Visibility::InFront);
    (e.is_valid() && in_front).then_some((e, summary.final_cost))
}

/// RMS over views of the box misfit's shift part (`(e_min + e_max)/2` per axis) and size part
/// (`(e_max − e_min)/2`), pixels.
fn shift_and_size_rms(views: &[BoxView], image: &ImageSize, e: &Ellipsoid, shape: BoxShape) -> Option<(f64, f64)> {
    let (mut shift, mut size) = (0.0, 0.0);
    for v in views {
        let r = box_residual(v, image, e, shape)?;
        for (lo, hi) in [(r[0], r[2]), (r[1], r[3])] {
            shift += (0.5 * (lo + hi)).powi(2);
            size += (0.5 * (hi - lo)).powi(2);
        }
    }
    let n = (2 * views.len().max(1)) as f64;
    Some(((shift / n).sqrt(), (size / n).sqrt()))
}

/// The point on a view's ray through its box centre at the depth where an object of the prior's height
/// (2 × the own-y semi-axis) spans the box's height.
fn depth_from_height(view: &BoxView, prior: &ObjectPrior) -> Option<Vector3<f64>> {
    let k = &view.camera.intrinsics;
    let h = view.bbox.height();
    if h.is_nan() || h <= 1.0 {
        return None;
    }
    let depth = k.fy * 2.0 * prior.axes.y / h;
    let [u, v] = view.bbox.centre();
    let y = (v - k.cy) / k.fy;
    let x = (u - k.cx - k.skew * y) / k.fx;
    let p = view.camera.world_from_camera * nalgebra::Point3::new(x * depth, y * depth, depth);
    p.coords.iter().all(|c| c.is_finite()).then_some(p.coords)
}

/// Tri+Yaw followed by object optimisation, then (with `pose_drift`) a joint stage that lets the
/// cameras move under a drift prior. Starts: the DQP ellipsoid (axes re-ordered to the prior),
/// and, always, the triangulated box-centre point with the prior's axes at the reference camera's heading
/// and at that heading turned by 90° (a car seen side-on or along the road). The lowest-cost result that
/// is in front of every camera wins.
pub fn refine(
    views: &[BoxView],
    image: &ImageSize,
    prior: &ObjectPrior,
    config: &RefineConfig,
    optimizer: &dyn Optimizer,
) -> Result<Ellipsoid, InitError> {
    refine_with_planes(views, image, prior, config, &[], optimizer)
}

/// [`refine`] with the paper's texture-plane error: each plane `[n, d]` (`n` unit, pointing out of the
/// object towards the cameras, see [`TexturePlane`]) comes from a triangle of the object's map points;
/// the ellipsoid's tangent plane with that normal should coincide with it (σ `plane_sigma_m`, Huber).
/// The planes enter every optimisation stage after the starts.
pub fn refine_with_planes(
    views: &[BoxView],
    image: &ImageSize,
    prior: &ObjectPrior,
    config: &RefineConfig,
    planes: &[Vector4<f64>],
    optimizer: &dyn Optimizer,
) -> Result<Ellipsoid, InitError> {
    refine_with_cues(&Dqp::default(), views, image, prior, config, &Cues { planes, ..Cues::default() }, optimizer)
}

/// [`refine_with_planes`] with another initialiser for the first start (in place of the plain DQP; the
/// other starts, DQP with centre correction and the triangulated centre at two headings, stay) and
/// any [`Cues`]: texture planes, a soft yaw prior (e.g. from the object's stereo points) and the stereo
/// depth of the object's surface, in every stage after the starts.
/// With [`BoxShape::TwoStage`] the cues enter the first (cuboid) stage, whose yaw the second then holds
/// (the planes and the surface depth enter both).
pub fn refine_with_cues(
    initializer: &dyn Initializer,
    views: &[BoxView],
    image: &ImageSize,
    prior: &ObjectPrior,
    config: &RefineConfig,
    cues: &Cues<'_>,
    optimizer: &dyn Optimizer,
) -> Result<Ellipsoid, InitError> {
    let cues = *cues;
    if config.box_shape == BoxShape::TwoStage {
        let first = RefineConfig { box_shape: BoxShape::Cuboid, ..*config };
        let e1 = refine_with_cues(initializer, views, image, prior, &first, &cues, optimizer)?;
        let held =
            YawCue { direction: e1.rotation() * Vector3::x(), sigma_rad: config.hold_yaw_sigma_deg.to_radians() };
        let second = RefineConfig { box_shape: BoxShape::Ellipse, ..*config };
        let held = Cues { yaw: Some(held), ..cues };
        let sigmas = vec![[config.box_sigma_px; 4]; views.len()];
        let started = optimise_object_weighted(
            views,
            image,
            prior,
            &second,
            e1,
            Stage { sigmas: &sigmas, drift: None, cues: held, optimizer, tolerance: FINE },
        );
        return Ok(match started {
            Some((e, _)) if in_front_of_all(views, &e) => polish(views, image, prior, &second, held, e, optimizer),
            _ => e1,
        });
    }
    let mut starts = Vec::new();
    if let Ok(e) = initializer.initialize(views) {
        starts.push(align_to_prior(&e, &prior.axes));
    }
    if let Ok(e) = Dqp::with_centre_correction().initialize(views) {
        starts.push(align_to_prior(&e, &prior.axes));
    }
    let mut centre = triangulate_box_centres(views, &TriangulationConfig::default());
    if centre.is_err() {
        // no parallax (a standing camera): the class's height puts the object at the depth its boxes'
        // height implies, along the middle view's ray
        if let Some(c) = views.get(views.len() / 2).and_then(|v| depth_from_height(v, prior)) {
            centre = Ok(c);
        }
    }
    if let (Ok(c), Some(first)) = (centre, views.first()) {
        let heading = first.camera.world_from_camera.rotation;
        for turn in [0.0, std::f64::consts::FRAC_PI_2] {
            let rot = heading * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), turn);
            starts.push(Ellipsoid::new(
                nalgebra::Isometry3::from_parts(nalgebra::Translation3::from(c), rot),
                prior.axes,
            ));
        }
    }
    // Pass 1 from every start at the configured σ; the best result goes on to the re-weighted passes.
    let mut best: Option<(Ellipsoid, f64)> = None;
    for s in starts {
        let sigmas = vec![[config.box_sigma_px; 4]; views.len()];
        if let Some((e, cost)) = optimise_object_weighted(
            views,
            image,
            prior,
            config,
            s,
            Stage { sigmas: &sigmas, drift: None, cues, optimizer, tolerance: COARSE },
        ) {
            if in_front_of_all(views, &e) && best.as_ref().is_none_or(|b| cost < b.1) {
                best = Some((e, cost));
            }
        }
    }
    match (best, centre) {
        (Some((e, _)), _) => Ok(polish(views, image, prior, config, cues, e, optimizer)),
        (None, Err(err)) => Err(err),
        (None, Ok(_)) => Err(InitError::Degenerate(slam_quadric::init::Degeneracy::RankDeficient)),
    }
}

fn in_front_of_all(views: &[BoxView], e: &Ellipsoid) -> bool {
    views.iter().all(|v| slam_quadric::classify(e, &v.camera) == slam_quadric::Visibility::InFront)
}

/// The re-weighted passes and the joint camera-object stage from a first-pass ellipsoid.
fn polish(
    views: &[BoxView],
    image: &ImageSize,
    prior: &ObjectPrior,
    config: &RefineConfig,
    cues: Cues<'_>,
    mut e: Ellipsoid,
    optimizer: &dyn Optimizer,
) -> Ellipsoid {
    // Boxes that fit perfectly may still be biased (a drive-by cannot tell a shifted car from a
    // shifted box); with planes, a box is never trusted below `plane_box_floor_px`.
    let min_sigma =
        if cues.planes.is_empty() { config.min_sigma_px } else { config.min_sigma_px.max(config.plane_box_floor_px) };
    let Some(shares) = side_shares(views, image, &e, config.box_shape) else { return e };
    for _ in 1..config.passes {
        let Some(sigmas) = side_sigmas(views, image, &e, config, min_sigma, &shares) else { break };
        match optimise_object_weighted(
            views,
            image,
            prior,
            config,
            e,
            Stage { sigmas: &sigmas, drift: None, cues, optimizer, tolerance: FINE },
        ) {
            Some((next, _)) if in_front_of_all(views, &next) => e = next,
            _ => break,
        }
    }
    if let (Some(drift), Some(rms)) = (config.pose_drift, box_rms(views, image, &e, config.box_shape)) {
        let all = (rms.iter().map(|r| r * r).sum::<f64>() / rms.len().max(1) as f64).sqrt();
        // Free the cameras only when the boxes disagree with the given poses. With the cameras free,
        // boxes no longer fix the scene's scale about the first camera; the pose and axis priors
        // share it, which would bias data that are already consistent.
        // Pose errors move a whole box (its two x edges, or its two y edges, together); box noise moves
        // the edges independently. Free the cameras only when the misfit is mostly such shifts.
        let (shift, size) = shift_and_size_rms(views, image, &e, config.box_shape).unwrap_or((0.0, 0.0));
        if all > config.consistent_rms_px && shift > config.shift_ratio * size {
            let Some(sigmas) = side_sigmas(views, image, &e, config, min_sigma, &shares) else { return e };
            if let Some(j) = optimise_object_weighted(
                views,
                image,
                prior,
                config,
                e,
                Stage { sigmas: &sigmas, drift: Some(drift), cues, optimizer, tolerance: FINE },
            ) {
                e = j.0;
            }
        }
    }
    e
}
