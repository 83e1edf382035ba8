//! `slam-app objects` and `slam-app eval`: image-free object mapping on KITTI tracking labels + poses,
//! and the paper's object metrics.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use slam_core::check::InvalidValue;
use slam_dataset::output::Written;
use slam_eval::{
    labelled::{study_title, table_header, LabelNoise, VehicleCriteria},
    study::{eval_study, map_to_file},
};
use slam_pipeline::objects::{MapperConfig, ObjectMapper};
use slam_quadric::ImageSize;
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
    #[arg(long, value_enum, default_value_t = Shape::Ellipse)]
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
fn eval_run_folder(dir: &std::path::Path, a: &EvalArgs) -> anyhow::Result<()> {
    let labels = a.labels.as_ref().context("scoring a run folder needs --labels <label_02.txt>")?;
    if a.csv.is_some() {
        bail!("--csv writes the table of a study over sequence folders; scoring a run folder writes objects_score.json into it");
    }
    let config = slam_eval::ScoreConfig {
        min_frames: a.min_frames,
        static_m: a.static_m,
        moving_m: a.moving_m,
        ..Default::default()
    };
    println!("{}", slam_eval::study::score_run_folder_to_file(dir, labels, &config)?);
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
        return eval_run_folder(&dir, a);
    }
    let seqs = slam_dataset::folders::tracking_sequences(&dir)?;
    let files: Vec<PathBuf> =
        seqs.iter().flat_map(|s| slam_eval::labelled::SEQUENCE_FILES.map(|f| s.join(f))).collect();
    let inputs: Vec<(&str, &std::path::Path)> = files.iter().map(|f| ("the sequence file", f.as_path())).collect();
    let csv: Vec<Written> = a.csv.iter().map(|p| Written::File("--csv", p)).collect();
    slam_dataset::output::refuse_overwriting_inputs(&inputs, &csv)?;
    let csv_out = a.csv.as_deref().map(slam_dataset::output::AtomicFile::new).transpose()?;
    let (associator, method) = (a.input.associator.name(), a.input.method.fit());
    println!("{}", study_title(&a.input.noise(), associator, method.name(), &criteria));
    println!("{}", table_header());
    let mut bar = slam_runner::console::Progress::new("eval", seqs.len() as u64, "sequences", false);
    let image = ImageSize::new(1242.0, 375.0);
    let (study, csv) =
        eval_study(&seqs, &|| mapper(&a.input), &a.input.noise(), &criteria, &image, &mut |name, score| {
            bar.println(&score.row.table_line(name));
            bar.inc();
        })?;
    bar.finish();
    print!("{}", study.report(a.moving_m));
    if let Some(f) = csv_out {
        f.write_with(|tmp| std::fs::write(tmp, csv))?;
    }
    Ok(())
}
