//! `slam-app objects` and `slam-app eval`: image-free object mapping on KITTI tracking labels + poses,
//! and the paper's object metrics.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use slam_core::check::InvalidValue;
use slam_eval::{
    labelled::{LabelNoise, VehicleCriteria},
    study::map_to_file,
};
use slam_pipeline::objects::{MapperConfig, ObjectMapper};
use slam_runner::{AssociatorKind, Method, OptimizerKind, Shape};

#[derive(Args, Debug, Clone)]
pub struct InputArgs {
    /// Box noise: σ of each coordinate as a fraction of the box width/height
    #[arg(long, default_value_t = 0.0)]
    noise: f64,
    /// Probability of dropping a label box
    #[arg(long, default_value_t = 0.0)]
    dropout: f64,
    /// Seed of the noise and dropout
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Ellipsoid method
    #[arg(long, value_enum, default_value_t = Method::Refine)]
    method: Method,
    /// Object associator
    #[arg(long, value_enum, default_value_t = AssociatorKind::Oda)]
    associator: AssociatorKind,
    /// Optimiser backend of the object fits
    #[arg(long, value_enum, default_value_t = OptimizerKind::Lm)]
    optimizer: OptimizerKind,
    /// Also fit objects seen without parallax (a standing camera) once they have this many boxes: depth
    /// from the class's size prior (off by default, as in the paper)
    #[arg(long)]
    without_parallax_after: Option<usize>,
    /// Least angle between an object's first and latest ray through its box centres before it is fitted,
    /// degrees
    #[arg(long, default_value_t = 3.0)]
    min_parallax_deg: f64,
    /// Flag an object dynamic when its fitted semi-axes lie this many prior σ from its class prior
    /// (Mahalanobis; 0: off)
    #[arg(long, default_value_t = 6.0)]
    dynamic_prior_sigmas: f64,
    /// What a box bounds in the object optimisation: the ellipsoid (the paper), its circumscribed cuboid,
    /// or two stages (yaw from the cuboid, then the ellipse with that yaw held)
    #[arg(long, value_enum, default_value_t = Shape::Cuboid)]
    box_shape: Shape,
    /// Remove an ellipsoid visible but not detected in this many frames in a row (0: never)
    #[arg(long, default_value_t = 5)]
    max_misses: usize,
}

impl InputArgs {
    /// Range checks (before any file is read).
    fn check(&self) -> anyhow::Result<()> {
        use slam_core::check::{count, number, Range};
        self.noise().validate().map_err(InvalidValue::as_flag)?;
        number("--min-parallax-deg", self.min_parallax_deg, Range::closed(0.0, 90.0), "degrees")?;
        number("--dynamic-prior-sigmas", self.dynamic_prior_sigmas, Range::closed(0.0, 1.0e6), "(0: off)")?;
        if let Some(n) = self.without_parallax_after {
            count("--without-parallax-after", n, 1, usize::MAX)?;
        }
        Ok(())
    }

    fn noise(&self) -> LabelNoise {
        LabelNoise { noise: self.noise, dropout: self.dropout, seed: self.seed }
    }
}

#[derive(Args, Debug)]
pub struct ObjectsArgs {
    /// Folder with label_02.txt, poses_orbslam3.txt and calib.txt
    dir: PathBuf,
    /// Labels file (default: DIR/label_02.txt)
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Poses file, camera-to-world of the left colour camera, one line per frame (default: DIR/poses_orbslam3.txt)
    #[arg(long)]
    poses: Option<PathBuf>,
    /// Calibration with P2 (default: DIR/calib.txt)
    #[arg(long)]
    calib: Option<PathBuf>,
    /// Output object-map JSON
    #[arg(long, default_value = "out/objects.json")]
    out: PathBuf,
    #[command(flatten)]
    input: InputArgs,
}

/// The object mapper the options describe.
fn mapper(input: &InputArgs) -> ObjectMapper {
    let config = MapperConfig {
        min_views_without_parallax: input.without_parallax_after,
        box_shape: input.box_shape.shape(),
        min_parallax_deg: input.min_parallax_deg,
        dynamic_prior_sigmas: (input.dynamic_prior_sigmas > 0.0).then_some(input.dynamic_prior_sigmas),
        max_misses: (input.max_misses > 0).then_some(input.max_misses),
        ..MapperConfig::default()
    };
    ObjectMapper::new(input.associator.build(None), config, input.optimizer.build()).with_method(input.method.fit())
}

pub fn objects(a: &ObjectsArgs) -> anyhow::Result<()> {
    a.input.check()?;
    let file = |given: &Option<PathBuf>, name: &str| given.clone().unwrap_or_else(|| a.dir.join(name));
    let (labels, poses, calib) =
        (file(&a.labels, "label_02.txt"), file(&a.poses, "poses_orbslam3.txt"), file(&a.calib, "calib.txt"));
    let files = (labels.as_path(), poses.as_path(), calib.as_path());
    println!("{}", map_to_file(files, &a.input.noise(), mapper(&a.input), &a.out)?);
    Ok(())
}

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// One sequence folder (label_02.txt, poses_orbslam3.txt, calib.txt), a folder of them (default: the
    /// shipped fixtures/kitti_tracking), or the output folder of `slam-app run` (objects.json,
    /// trajectory.kitti.txt, camera.json) to score against --labels
    dir: Option<PathBuf>,
    /// With a run's output folder: the labels to score it against (label_02.txt format)
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Fewest labelled frames of a ground-truth vehicle
    #[arg(long, default_value_t = 10)]
    min_frames: usize,
    /// Largest spread (max distance from its mean) of a vehicle's world centre to count as static, metres
    #[arg(long, default_value_t = 1.0)]
    static_m: f64,
    /// Smallest spread of a vehicle's world centre to count as moving (the dynamic-object check), metres
    #[arg(long, default_value_t = 3.0)]
    moving_m: f64,
    /// Also write the table as CSV
    #[arg(long)]
    csv: Option<PathBuf>,
    #[command(flatten)]
    input: InputArgs,
}

/// `slam-app eval <run folder> --labels <label_02.txt>`: score a finished run's object map.
fn eval_run_folder(dir: &std::path::Path, a: &EvalArgs, criteria: VehicleCriteria) -> anyhow::Result<()> {
    let labels = a.labels.as_ref().context("scoring a run folder needs --labels <label_02.txt>")?;
    if a.csv.is_some() {
        bail!("--csv writes the table of a study over sequence folders; scoring a run folder writes objects_score.json into it");
    }
    println!("{}", slam_eval::study::score_run_folder_to_file(dir, labels, &criteria.into())?);
    Ok(())
}

pub fn eval(a: &EvalArgs) -> anyhow::Result<()> {
    a.input.check()?;
    let criteria = VehicleCriteria { min_frames: a.min_frames, static_m: a.static_m, moving_m: a.moving_m };
    match criteria.validate() {
        // the ranges passed: only the order of the two spreads is wrong
        Err(e) if e.key == "static_m" && e.valid.starts_with("at most moving_m") => bail!(
            "--static-m {} exceeds --moving-m {}: a vehicle would count as static and moving",
            a.static_m,
            a.moving_m
        ),
        r => r.map_err(InvalidValue::as_flag)?,
    }
    let dir = a.dir.clone().unwrap_or_else(|| crate::fixture("kitti_tracking"));
    if slam_eval::study::is_run_folder(&dir)? {
        return eval_run_folder(&dir, a, criteria);
    }
    let method = a.input.method.fit();
    let names = slam_runner::studies::StudyNames { associator: a.input.associator.name(), method: method.name() };
    let (noise, csv) = (a.input.noise(), a.csv.as_deref());
    slam_runner::studies::eval_table(&dir, &|| mapper(&a.input), (&noise, &criteria), names, csv, &mut |l| {
        println!("{l}")
    })?;
    Ok(())
}

#[derive(Args, Debug)]
pub struct ObjectsBenchArgs {
    /// Settings file used for every case (TOML, as for `run --config`; its `[objects] box_shape` also
    /// sets the image-free study's box model)
    #[arg(long)]
    config: Option<PathBuf>,
    /// Strides at which the labelled drive is played, comma-separated
    #[arg(long, value_delimiter = ',', default_value = "1,2,3", value_parser = clap::value_parser!(u64).range(1..=100))]
    strides: Vec<u64>,
    /// Leave out the image-free study on the 17 tracking sequences (about a minute)
    #[arg(long)]
    no_image_free: bool,
}

/// `slam-app objects-bench`: the object map of every dev case in one table (issue 45): drive 0005 at
/// each stride scored against its labels, the image-free study, the main job's cars against the street.
pub fn objects_bench(b: &ObjectsBenchArgs) -> anyhow::Result<()> {
    let config = slam_runner::RunConfig::load(b.config.as_deref())?;
    let mut base = slam_runner::RunSettings::odometry_only(crate::fixture(crate::SHIPPED), &config, None);
    base.detector = slam_runner::DetectorChoice::Network(crate::detect_cmd::ModelArgs::default().loader());
    let strides = b.strides.iter().map(|&s| s as usize).collect();
    let cases = slam_runner::objects_bench::ObjectsBenchCases::shipped(&crate::fixture(""), strides, !b.no_image_free);
    let bench = slam_runner::objects_bench::objects_bench(&base, &cases, &mut |c| eprintln!("objects-bench: {c}"))?;
    bench.lines().iter().for_each(|l| println!("{l}"));
    Ok(())
}
