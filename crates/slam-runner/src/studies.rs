//! `slam-app eval` over tracking sequences: the image-free study's table as the command prints it,
//! with progress and the optional CSV (the study itself is `slam_eval::study::eval_study`).

use std::path::{Path, PathBuf};

use slam_dataset::output::{refuse_overwriting_inputs, AtomicFile, Written};
use slam_eval::{
    labelled::{study_title, table_header, LabelNoise, VehicleCriteria, SEQUENCE_FILES},
    study::eval_study,
};
use slam_pipeline::objects::ObjectMapper;
use slam_quadric::ImageSize;

use crate::{console::Progress, error::Result};

/// The names printed in the study's title.
pub struct StudyNames<'a> {
    /// The associator.
    pub associator: &'a str,
    /// The ellipsoid method.
    pub method: &'a str,
}

/// The study over the sequence folders of `dir`, each through a fresh `mapper()`: the title, the table
/// row by row as sequences finish (with a progress bar on stderr), the closing lines; the table as CSV
/// into `csv` when given (refused before any work when it would overwrite a sequence file).
pub fn eval_table(
    dir: &Path,
    mapper: &dyn Fn() -> ObjectMapper,
    (noise, criteria): (&LabelNoise, &VehicleCriteria),
    names: StudyNames<'_>,
    csv: Option<&Path>,
    print: &mut dyn FnMut(&str),
) -> Result<()> {
    let seqs = slam_dataset::folders::tracking_sequences(dir)?;
    let files: Vec<PathBuf> = seqs.iter().flat_map(|s| SEQUENCE_FILES.map(|f| s.join(f))).collect();
    let inputs: Vec<(&str, &Path)> = files.iter().map(|f| ("the sequence file", f.as_path())).collect();
    let written: Vec<Written> = csv.iter().map(|p| Written::File("--csv", p)).collect();
    refuse_overwriting_inputs(&inputs, &written)?;
    let csv_out = csv.map(AtomicFile::new).transpose()?;
    print(&study_title(noise, names.associator, names.method, criteria));
    print(&table_header());
    let mut bar = Progress::new("eval", seqs.len() as u64, "sequences", false);
    let image = ImageSize::new(1242.0, 375.0);
    let (study, table) = eval_study(&seqs, mapper, noise, criteria, &image, &mut |name, score| {
        bar.println(&score.row.table_line(name));
        bar.inc();
    })?;
    bar.finish();
    print(study.report(criteria.moving_m).trim_end_matches('\n'));
    if let Some(f) = csv_out {
        f.write_with(|tmp| std::fs::write(tmp, table))?;
    }
    Ok(())
}
