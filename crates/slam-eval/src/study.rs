//! The steps of `slam-app eval`: one image-free sequence scored with a given object mapper
//! ([`eval_sequence`]), and a finished run's output folder scored against labels
//! ([`score_run_folder`], with the played frame ids of its `tracking.csv`, [`played_frame_ids`]); and
//! the valid ranges of the study's settings ([`LabelNoise::validate`], [`VehicleCriteria::validate`]).

use std::path::{Path, PathBuf};

use slam_core::check::{count, number, InvalidValue, Range};
use slam_dataset::kitti::{poses::read_kitti_poses, tracking::read_tracking_labels};
use slam_pipeline::objects::ObjectMapper;
use slam_quadric::ImageSize;

use crate::{
    labelled::{
        run_mapper, score_sequence, LabelNoise, LabelledSequence, SequenceScore, Study, VehicleCriteria, CSV_COLUMNS,
    },
    read_object_map, score_run, EvalError, LabelGeometry, RunScore, ScoreConfig,
};

/// The frame id of each line of a run's trajectory: the `frame` column of its `tracking.csv` (one row
/// per played frame, in the trajectory's order, after a header line). A run with `--frames 20..60`
/// starts at id 20, so the line number is not the id. Errors name the file and line; a row count that
/// differs from `poses` is an error (the files are not of the same run).
pub fn played_frame_ids(path: &Path, poses: usize) -> Result<Vec<usize>, EvalError> {
    let text = slam_core::files::read_text(path, &slam_core::files::TABLE)?;
    let ids = text
        .lines()
        .enumerate()
        .skip(1)
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            l.split(',').next().and_then(|f| f.trim().parse::<usize>().ok()).ok_or_else(|| {
                EvalError::Invalid(format!("{}:{}: no frame id in the first column: {l:?}", path.display(), i + 1))
            })
        })
        .collect::<Result<Vec<usize>, EvalError>>()?;
    if ids.len() != poses {
        return Err(EvalError::Invalid(format!(
            "{} has {} frames, the trajectory {poses} poses: not the same run",
            path.display(),
            ids.len()
        )));
    }
    Ok(ids)
}

/// The files of a run's output folder that scoring reads.
pub const RUN_FOLDER_FILES: [&str; 4] = ["trajectory.kitti.txt", "camera.json", "objects.json", "tracking.csv"];

/// Whether `dir` is the output folder of a run (`objects.json` and `trajectory.kitti.txt` in it) rather
/// than sequence folders for a study; an error naming what is missing when it holds part of a run's
/// files (`objects.json`, `trajectory.kitti.txt`, `camera.json`) and no labels of its own.
pub fn is_run_folder(dir: &Path) -> Result<bool, EvalError> {
    if dir.join("objects.json").is_file() && dir.join("trajectory.kitti.txt").is_file() {
        return Ok(true);
    }
    let run_files = ["objects.json", "trajectory.kitti.txt", "camera.json"];
    let present: Vec<&str> = run_files.iter().copied().filter(|f| dir.join(f).is_file()).collect();
    if present.is_empty() || dir.join("label_02.txt").is_file() {
        return Ok(false);
    }
    let missing: Vec<&str> = run_files.iter().copied().filter(|f| !present.contains(f)).collect();
    let missing = match missing.as_slice() {
        [one] => format!("{one} is"),
        more => format!("{} are", more.join(", ")),
    };
    Err(EvalError::Invalid(format!(
        "{}: looks like the output of `slam-app run` ({} present) but {missing} missing: scoring a run needs objects.json, trajectory.kitti.txt and camera.json",
        dir.display(),
        present.join(", "),
    )))
}

/// Score the output folder of a run (`trajectory.kitti.txt`, `camera.json`, `objects.json`,
/// `tracking.csv`) against the tracking labels at `labels`.
pub fn score_run_folder(dir: &Path, labels: &Path, config: &ScoreConfig) -> Result<RunScore, EvalError> {
    let labels = read_tracking_labels(labels)?;
    let poses = read_kitti_poses(dir.join("trajectory.kitti.txt"))?;
    let geometry = LabelGeometry::read(&dir.join("camera.json"))?;
    let objects = read_object_map(&dir.join("objects.json"))?;
    let ids = played_frame_ids(&dir.join("tracking.csv"), poses.len())?;
    // an object seen in a frame the run did not play is not of this run
    let played: std::collections::BTreeSet<usize> = ids.iter().copied().collect();
    for o in &objects {
        if let Some(f) = o.frames.iter().find(|f| !played.contains(f)) {
            return Err(EvalError::Invalid(format!(
                "{}: object {} is seen in frame {f}, which the run did not play ({} frames, ids {}..={}): not the objects of this run",
                dir.join("objects.json").display(),
                o.id,
                ids.len(),
                ids.first().copied().unwrap_or(0),
                ids.last().copied().unwrap_or(0)
            )));
        }
    }
    Ok(score_run(&labels, &poses, &ids, &geometry, &objects, config))
}

/// [`score_run_folder`], its score written to `dir/objects_score.json`; returns the printed report and
/// the line naming the file.
pub fn score_run_folder_to_file(dir: &Path, labels: &Path, config: &ScoreConfig) -> Result<String, EvalError> {
    // nothing the score reads may be the file it writes
    let read: Vec<PathBuf> = RUN_FOLDER_FILES.iter().map(|f| dir.join(f)).collect();
    let mut inputs: Vec<(&str, &Path)> = read.iter().map(|f| ("the run's", f.as_path())).collect();
    inputs.push(("--labels", labels));
    let score_file = dir.join("objects_score.json");
    slam_dataset::output::refuse_overwriting_inputs(
        &inputs,
        &[slam_dataset::output::Written::File("the score", &score_file)],
    )?;
    // checked first: a user's own objects_score.json in the folder is not replaced; a run writes this
    // file too, so once written it is listed in the folder's marker and the folder stays the run's
    let into = slam_dataset::output::FilesInto::new(dir, &["objects_score.json"], "the score", "eval")?;
    let score = score_run_folder(dir, labels, config)?;
    let out = dir.join("objects_score.json");
    into.write_with(|tmp| score.write_json(&tmp.join("objects_score.json")))?;
    Ok(format!("{}wrote {}", score.report(), out.display()))
}

/// Load the image-free sequence in `dir` ([`LabelledSequence::load_dir`]), play its label boxes
/// (perturbed by `noise`) through `mapper` and score the objects against the vehicles that meet
/// `criteria`; `name` names the sequence in the score.
pub fn eval_sequence(
    dir: &Path,
    name: &str,
    mapper: ObjectMapper,
    noise: &LabelNoise,
    criteria: &VehicleCriteria,
    image: &ImageSize,
) -> Result<SequenceScore, EvalError> {
    let seq = LabelledSequence::load_dir(dir)?;
    let (mapper, truth) = run_mapper(&seq, noise, mapper);
    Ok(score_sequence(name, &seq, &mapper, &truth, criteria, image))
}

/// `slam-app objects`: the image-free sequence of `labels`, `poses` and `calib` played through `mapper`
/// (label boxes perturbed by `noise`), its object map written to `out` (checked writable first, never
/// over one of the inputs, put in place whole); returns the summary line.
pub fn map_to_file(
    (labels, poses, calib): (&Path, &Path, &Path),
    noise: &LabelNoise,
    mapper: ObjectMapper,
    out: &Path,
) -> Result<String, EvalError> {
    slam_dataset::output::refuse_overwriting_inputs(
        &[("the labels", labels), ("the poses", poses), ("the calibration", calib)],
        &[slam_dataset::output::Written::File("--out", out)],
    )?;
    let file = slam_dataset::output::AtomicFile::new(out)?;
    let seq = LabelledSequence::load(labels, poses, calib)?;
    let (mapper, _) = run_mapper(&seq, noise, mapper);
    let objs: Vec<_> = mapper.objects().collect();
    // the file was made writable before the work: its temporary gets the text, then takes its place
    let text = slam_pipeline::objects::object_map_text(&objs, slam_pipeline::objects::INPUT_POSES_WORLD)
        .map_err(|e| EvalError::Io(format!("cannot write {}", out.display()), e))?;
    file.write_with(|tmp| std::fs::write(tmp, text))?;
    let with = objs.iter().filter(|o| o.ellipsoid.is_some()).count();
    let dynamic = objs.iter().filter(|o| o.ellipsoid.is_some() && o.dynamic).count();
    Ok(format!(
        "{} frames, {} tracks, {with} objects with an ellipsoid ({dynamic} flagged dynamic), {} fits; wrote {}",
        seq.poses.len(),
        objs.len(),
        mapper.fits(),
        out.display()
    ))
}

/// The image-free study over the sequence folders `seqs`: each played through a fresh mapper from
/// `mapper` ([`eval_sequence`]); `on_sequence` sees each score as it is made (for the table and
/// progress). Returns the study and the per-sequence table as CSV ([`CSV_COLUMNS`]).
pub fn eval_study(
    seqs: &[PathBuf],
    mapper: &dyn Fn() -> ObjectMapper,
    noise: &LabelNoise,
    criteria: &VehicleCriteria,
    image: &ImageSize,
    on_sequence: &mut dyn FnMut(&str, &SequenceScore),
) -> Result<(Study, String), EvalError> {
    let csv_error = |e: csv::Error| EvalError::Invalid(format!("writing the study's CSV: {e}"));
    let mut csv = csv::Writer::from_writer(Vec::new());
    csv.write_record(CSV_COLUMNS).map_err(csv_error)?;
    let mut study = Study::default();
    for dir in seqs {
        let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let score = eval_sequence(dir, &name, mapper(), noise, criteria, image)?;
        csv.write_record(score.row.csv_record(&name)).map_err(csv_error)?;
        on_sequence(&name, &score);
        study.add(&score);
    }
    let bytes = csv.into_inner().map_err(|e| csv_error(e.into_error().into()))?;
    Ok((study, String::from_utf8_lossy(&bytes).into_owned()))
}

impl LabelNoise {
    /// Check the noise (a share of the box size) and the dropout (a probability); errors name the field.
    pub fn validate(&self) -> Result<(), InvalidValue> {
        number("noise", self.noise, Range::closed(0.0, 1.0), "(σ as a share of the box size)")?;
        number("dropout", self.dropout, Range::closed(0.0, 1.0), "(a probability)")
    }
}

impl VehicleCriteria {
    /// Check the criteria: at least one frame, spreads within a kilometre, and the static spread not
    /// above the moving one (a vehicle would count as both); errors name the field.
    pub fn validate(&self) -> Result<(), InvalidValue> {
        count("min_frames", self.min_frames, 1, usize::MAX)?;
        number("static_m", self.static_m, Range::closed(0.0, 1000.0), "m")?;
        number("moving_m", self.moving_m, Range::above(0.0, 1000.0), "m")?;
        if self.static_m > self.moving_m {
            let valid = format!("at most moving_m ({}): a vehicle would count as static and moving", self.moving_m);
            return Err(InvalidValue { key: "static_m".into(), value: self.static_m.to_string(), valid });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn study_settings_name_their_bad_field() {
        let noise = LabelNoise { noise: 0.05, dropout: 0.2, seed: 1 };
        noise.validate().expect("valid");
        let e = LabelNoise { noise: f64::NAN, ..noise }.validate().expect_err("NaN");
        assert_eq!(e.to_string(), "noise NaN: must be a finite number in [0, 1] (σ as a share of the box size)");
        assert_eq!(LabelNoise { dropout: 2.0, ..noise }.validate().expect_err("dropout").key, "dropout");
        let c = VehicleCriteria { min_frames: 10, static_m: 1.0, moving_m: 3.0 };
        c.validate().expect("valid");
        assert_eq!(VehicleCriteria { min_frames: 0, ..c }.validate().expect_err("frames").key, "min_frames");
        assert_eq!(VehicleCriteria { moving_m: 0.0, ..c }.validate().expect_err("moving").key, "moving_m");
        let e = VehicleCriteria { static_m: 5.0, ..c }.validate().expect_err("static above moving");
        assert!(e.key == "static_m" && e.valid.starts_with("at most moving_m (3)"), "{e}");
    }

    fn write(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("slam-eval-study-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let p = dir.join(name);
        std::fs::write(&p, text).expect("write");
        p
    }

    #[test]
    fn played_frame_ids_read_the_first_column_and_name_bad_lines() {
        let ok = write("ok.csv", "frame,state\n20,tracking\n21,lost\n\n22,tracking\n");
        assert_eq!(played_frame_ids(&ok, 3).expect("reads"), [20, 21, 22]);
        let e = played_frame_ids(&ok, 4).expect_err("count differs").to_string();
        assert!(e.contains("has 3 frames, the trajectory 4 poses"), "{e}");
        let bad = write("bad.csv", "frame,state\n20,tracking\nx,lost\n");
        let e = played_frame_ids(&bad, 2).expect_err("bad id").to_string();
        assert!(e.contains("bad.csv:3: no frame id"), "{e}");
        let e = played_frame_ids(Path::new("/no/such/tracking.csv"), 1).expect_err("missing").to_string();
        assert!(e.starts_with("cannot read /no/such/tracking.csv: "), "{e}");
    }
}
