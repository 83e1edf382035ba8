//! `--rerun FILE`: a rerun recording of a run (`run`, `run-bench`) or of a saved map (`map`), written by
//! `slam-rerun` when this program is built with the feature `rerun`; without it the option is refused
//! before any work, saying how to build with it.

use std::path::Path;
#[cfg(feature = "rerun")]
use std::path::PathBuf;

use slam_pipeline::saved_map::SavedMap;
use slam_runner::{Prepared, RunObserver};

/// How to get a program that records.
const BUILD_WITH_RERUN: &str = "this slam-app was built without rerun recordings: build it with the `rerun` feature \
     (`cargo run --release -p slam-app --features rerun -- …`; rerun's SDK adds 15-17 minutes to a first build on two cores)";

/// Refuse `--rerun` (given as `option`) when this program cannot record; refuse a recording inside the
/// output folder `out`, which a run replaces as a whole at its end.
pub fn check(path: Option<&Path>, out: Option<&Path>) -> anyhow::Result<()> {
    let Some(path) = path else { return Ok(()) };
    if !cfg!(feature = "rerun") {
        anyhow::bail!("--rerun {}: {BUILD_WITH_RERUN}", path.display());
    }
    if let Some(out) = out {
        slam_dataset::output::refuse_inside_replaced("--rerun", path, "--out", out)?;
    }
    Ok(())
}

/// A run's recording at `path`, started for a prepared run.
#[cfg(feature = "rerun")]
pub fn recorder(path: &Path, p: &Prepared) -> slam_runner::Result<Box<dyn RunObserver>> {
    let seq = &p.seq;
    let setup = slam_rerun::SceneSetup {
        k: p.k,
        image: p.image,
        times: seq.ids.iter().copied().zip(seq.times.iter().copied()).collect(),
        truth: seq.truth_from_first(),
    };
    let recorder = slam_rerun::Recorder::create(path, setup).map_err(slam_runner::RunnerError::other)?;
    Ok(Box::new(Recording { recorder, path: path.to_path_buf() }))
}

/// A run's recording: cannot be made without the feature ([`check`] refuses the option first).
#[cfg(not(feature = "rerun"))]
pub fn recorder(path: &Path, _: &Prepared) -> slam_runner::Result<Box<dyn RunObserver>> {
    Err(slam_runner::RunnerError::Invalid(format!("--rerun {}: {BUILD_WITH_RERUN}", path.display())))
}

#[cfg(feature = "rerun")]
struct Recording {
    recorder: slam_rerun::Recorder,
    path: PathBuf,
}

#[cfg(feature = "rerun")]
impl RunObserver for Recording {
    fn frame(&mut self, view: &slam_pipeline::system::FrameView<'_>) {
        self.recorder.frame(view);
    }

    fn finish(self: Box<Self>, o: &slam_runner::Outcome) -> slam_runner::Result<String> {
        let stats = self.recorder.finish(&o.out.poses, &o.out.objects).map_err(slam_runner::RunnerError::other)?;
        Ok(stats.summary(&self.path))
    }
}

/// The line saying what a recording holds.
/// Write a saved map as a recording; returns the line saying what it holds.
pub fn record_map(map: &SavedMap, path: &Path) -> anyhow::Result<String> {
    #[cfg(feature = "rerun")]
    {
        let stats = slam_rerun::record_map(map, path)?;
        Ok(stats.summary(path))
    }
    #[cfg(not(feature = "rerun"))]
    {
        let _ = map;
        anyhow::bail!("--rerun {}: {BUILD_WITH_RERUN}", path.display())
    }
}
