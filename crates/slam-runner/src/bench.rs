//! `run-bench` (speed of the whole system per detector configuration, medians over repeated runs) and
//! `track-bench` (tracking accuracy on every dev case, without objects): the runs, their medians and the
//! tables' rows; the app prints them.

use std::path::PathBuf;

use slam_core::figure::{cell, median, DASH};
use slam_dataset::{kitti::stereo::TruthSource, layout::Order};
use slam_eval::trajectory_errors::trajectory_errors;

use crate::{
    detector::DetectorChoice,
    error::{Context, Result, RunnerError},
    run::{prepare, ObserverFactory, Outcome, RunSettings},
    run_summary::{median_fps, stage_table, state_counts, STATE_NAMES},
};

/// Run `s` once without printing or progress (followed by the observer `observe` makes, finished after
/// the run).
fn run_quiet(s: &RunSettings, observe: Option<&mut ObserverFactory<'_>>) -> Result<Outcome> {
    let prepared = prepare(s)?;
    let mut observer = observe.map(|make| make(&prepared)).transpose()?;
    let o = prepared.run(
        s,
        &mut |v| {
            if let Some(obs) = &mut observer {
                obs.frame(v);
            }
        },
        || false,
    )?;
    if let Some(obs) = observer {
        obs.finish(&o)?;
    }
    Ok(o)
}

/// The three `run-bench` configurations: no objects, detections from `file`, and the network on every
/// frame.
pub fn bench_configs(file: PathBuf, network: DetectorChoice) -> Vec<(&'static str, DetectorChoice)> {
    vec![
        ("no objects (--detector none)", DetectorChoice::None),
        ("detections from a file", DetectorChoice::File(file)),
        ("shipped detector, every frame", network),
    ]
}

/// The `run-bench` table's header (markdown).
pub const RUN_BENCH_HEADER: &str = "| configuration | frames/s (median) | frames/s (overall) | detection | of which forward pass | extraction | stereo | tracking | flow | association | local BA | objects | ATE m |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|";

/// Medians of one `run-bench` configuration over its repeated runs; a figure of no value (no frame
/// interval, a stage that never ran, no ground truth) is `None`, printed as a dash.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchRow {
    /// Configuration name.
    pub name: String,
    /// Median over runs of 1000 / median frame interval.
    pub fps_median: Option<f64>,
    /// Median over runs of frames / wall time.
    pub fps_overall: Option<f64>,
    /// Median stage times, ms, in `stage_table` order.
    pub stages: Vec<Option<f64>>,
    /// Median ATE, m.
    pub ate: Option<f64>,
}

impl std::fmt::Display for BenchRow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let cells: Vec<String> = self.stages.iter().map(|v| cell(*v, 1)).collect();
        write!(
            f,
            "| {} | {} | {} | {} | {} |",
            self.name,
            cell(self.fps_median, 1),
            cell(self.fps_overall, 1),
            cells.join(" | "),
            cell(self.ate, 3)
        )
    }
}

/// Run `s` `repeat` times, each run followed by the observer `observe` makes, if any; `progress` gets a
/// line after each run.
pub fn bench_row(
    name: &str,
    s: &RunSettings,
    repeat: usize,
    mut observe: Option<&mut ObserverFactory<'_>>,
    progress: &mut dyn FnMut(String),
) -> Result<BenchRow> {
    let (mut fps, mut fps_median, mut ate) = (Vec::new(), Vec::new(), Vec::new());
    let mut stages: Vec<Vec<f64>> = Vec::new();
    for r in 0..repeat {
        let o = run_quiet(s, observe.as_deref_mut())?;
        fps.push(o.out.counts.frames as f64 / o.elapsed);
        fps_median.extend(median_fps(&o.out));
        for (k, (_, ms, _)) in stage_table(&o.out).into_iter().enumerate() {
            if stages.len() <= k {
                stages.push(Vec::new());
            }
            stages[k].extend(ms);
        }
        let scored = o.seq.truth_from_first().map(|g| crate::report::Scored::of(&o.out, &g, &o.seq.ids));
        if let Some(e) = scored.and_then(|s| trajectory_errors(&s.est, &s.truth, &[])) {
            ate.push(e.ate_m);
        }
        progress(format!("{name}: run {} of {repeat}: {:.1} frames/s", r + 1, fps[fps.len() - 1]));
    }
    Ok(BenchRow {
        name: name.to_string(),
        fps_median: median(&mut fps_median),
        fps_overall: median(&mut fps),
        stages: stages.iter_mut().map(|v| median(v)).collect(),
        ate: median(&mut ate),
    })
}

/// The note under the `run-bench` table, with the targets' figures (rows in [`bench_configs`] order).
pub fn run_bench_footer(repeat: usize, rows: &[BenchRow]) -> String {
    let fps = |i: usize| cell(rows.get(i).and_then(|r| r.fps_median), 1);
    let mut text = format!(
        "\nmedians of {repeat} runs each. frames/s (median): 1000 / median interval between consecutive frames; (overall): frames / wall time, start-up and drain included. Stage times: medians over frames (local BA and objects: over keyframes, on the mapping thread), ms; the forward pass is the network's own time within detection. Targets (median): >= 30 frames/s with detections from a file ({}), >= 10 with the detector ({}).",
        fps(1),
        fps(2)
    );
    if let Some(line) = rows.get(2).and_then(processing_line) {
        text.push('\n');
        text.push_str(&line);
    }
    text
}

/// What the detector adds to its network's forward pass on a row (`None` when the row runs no network):
/// the detection stage's median, the forward pass's, and their difference (pre- and post-processing: the
/// letterbox, the input blob, decoding, non-maximum suppression) as a share of the forward pass.
pub fn processing_line(row: &BenchRow) -> Option<String> {
    let (Some(&Some(detection)), Some(&Some(forward))) = (row.stages.first(), row.stages.get(1)) else { return None };
    (forward > 0.0).then(|| {
        format!(
            "{}: detection {detection:.1} ms, of which the forward pass {forward:.1} ms: pre- and post-processing {:.1} ms, {:.0} % of the forward pass (target <= 30 %)",
            row.name,
            detection - forward,
            100.0 * (detection - forward) / forward
        )
    })
}

/// Most runs per `run-bench` configuration: the median of 100 runs moves by well under the spread of
/// one, and 100 runs of the three configurations on the shipped sequence take about half an hour.
pub const MAX_REPEAT: usize = 100;

/// The name of `run-bench`'s row with a recording.
pub const RECORDED_ROW: &str = "shipped detector, every frame, recorded (--rerun)";

/// The whole `run-bench`: the [`bench_configs`] on `base`, `repeat` runs each, and with `record` one more
/// row: the last configuration (the main job's) with the observer it makes following every run (a
/// recording), and the cost of following in the main job's median frame time; every table line goes to
/// `print`, progress lines to `progress`.
pub fn run_bench(
    base: &RunSettings,
    file: PathBuf,
    network: DetectorChoice,
    repeat: usize,
    record: Option<&mut ObserverFactory<'_>>,
    print: &mut dyn FnMut(String),
    progress: &mut dyn FnMut(String),
) -> Result<()> {
    slam_core::check::count("--repeat", repeat, 1, MAX_REPEAT).map_err(RunnerError::other)?;
    print(RUN_BENCH_HEADER.to_string());
    let mut rows = Vec::new();
    let configs = bench_configs(file, network);
    for (name, detector) in &configs {
        let s = RunSettings { detector: detector.clone(), ..base.clone() };
        let row = bench_row(name, &s, repeat, None, progress)?;
        print(row.to_string());
        rows.push(row);
    }
    let recorded = match (record, configs.last()) {
        (Some(make), Some((_, detector))) => {
            let s = RunSettings { detector: detector.clone(), ..base.clone() };
            let row = bench_row(RECORDED_ROW, &s, repeat, Some(make), progress)?;
            print(row.to_string());
            Some(row)
        }
        _ => None,
    };
    print(run_bench_footer(repeat, &rows));
    if let (Some(with), Some(without)) = (&recorded, rows.last()) {
        print(recording_cost(without, with));
    }
    Ok(())
}

/// What following the runs (a recording) cost: the median frame time with and without, and the
/// difference as a share of the time without.
pub fn recording_cost(without: &BenchRow, with: &BenchRow) -> String {
    let Some((a, b)) = without.fps_median.zip(with.fps_median).map(|(a, b)| (1000.0 / a, 1000.0 / b)) else {
        return format!("recording: no median frame time (runs of fewer than two frames): {DASH}");
    };
    format!(
        "recording: median frame time {b:.1} ms against {a:.1} ms without ({:+.1} %; target <= +10 %); runs made one configuration after the other: on a shared machine compare rows made back to back",
        100.0 * (b - a) / a
    )
}

/// One case of `track-bench`: a sequence played at a stride, or its frames in another order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TrackCase {
    /// Name in the table.
    pub name: String,
    /// Sequence folder.
    pub path: PathBuf,
    /// Play every n-th frame id.
    pub stride: u64,
    /// Play the sequence's frames in this order instead (a layout made for the case in a temporary
    /// folder: [`slam_dataset::layout`]).
    pub order: Option<Order>,
}

impl TrackCase {
    /// `PATH` or `PATH:STRIDE` (a `--case` option); a stride of 0 is refused.
    pub fn parse(text: &str) -> Result<Self> {
        let (path, stride) = match text.rsplit_once(':') {
            Some((p, s)) if !p.is_empty() && s.chars().all(|c| c.is_ascii_digit()) && !s.is_empty() => {
                let stride: u64 = s.parse().context_with(|| format!("--case {text}: stride '{s}'"))?;
                if stride == 0 {
                    return Err(RunnerError::Invalid(format!("--case {text}: the stride must be at least 1")));
                }
                (p, stride)
            }
            _ => (text, 1),
        };
        Ok(TrackCase { name: format!("{path}, stride {stride}"), path: PathBuf::from(path), stride, order: None })
    }

    /// The shipped dev cases: odometry 06 (folder `odometry`) at strides 1-4, odometry 01 (`highway`,
    /// a curved on-ramp at 36-46 km/h with most texture far away), raw drive 0005 (`raw`) at strides
    /// 1, 4 and 8 (that drive moves 0.39 m per frame, so every 4th frame is 1.6 m and every 8th 3.1 m per
    /// frame, fast motion on a second drive), and odometry 06 driven there and back over 5 legs and
    /// with a standstill at frame 20 of 2, 30 and 200 frames (map reuse: [`slam_dataset::layout`]).
    pub fn dev_cases(odometry: PathBuf, highway: PathBuf, raw: PathBuf) -> Vec<Self> {
        let case = |name: String, path: &PathBuf, stride: u64, order: Option<Order>| TrackCase {
            name,
            path: path.clone(),
            stride,
            order,
        };
        let mut cases: Vec<Self> = (1..=4)
            .map(|stride| case(format!("odometry 06, frames 0-50, stride {stride}"), &odometry, stride, None))
            .collect();
        cases.push(case("odometry 01, frames 0-50 (highway)".into(), &highway, 1, None));
        cases.push(case("raw drive 0005, frames 0-90 (vs OXTS)".into(), &raw, 1, None));
        for stride in [4, 8] {
            cases.push(case(format!("raw drive 0005, frames 0-88, stride {stride}"), &raw, stride, None));
        }
        let there_and_back = Order::ThereAndBack { legs: 5 };
        cases.push(case("odometry 06 there and back, 5 legs".into(), &odometry, 1, Some(there_and_back)));
        for extra in [2, 30, 200] {
            let order = Order::Standstill { at: 20, extra };
            cases.push(case(format!("odometry 06, standstill at frame 20 (+{extra})"), &odometry, 1, Some(order)));
        }
        cases
    }
}

/// The whole `track-bench` table over `cases` (at least one) with `base`'s settings; every line goes to
/// `print`, the cases' notes after the table. With `objects`, every case runs the full system with
/// `base`'s detector (objects found moving are then masked out of tracking); without, no detector.
pub fn track_bench(
    base: &RunSettings,
    cases: &[TrackCase],
    objects: bool,
    print: &mut dyn FnMut(String),
) -> Result<()> {
    if cases.is_empty() {
        return Err(RunnerError::Invalid("no cases: --only-cases needs at least one --case PATH[:STRIDE]".into()));
    }
    // every case's sequence, calibration and image sizes are checked before the first frame of any
    // (a typo in the last --case is found at once, not after the others ran)
    for c in cases {
        prepare(&case_settings(base, c, objects)).context_with(|| format!("case {}", c.name))?;
    }
    print(if objects {
        "full system: detector on every frame, objects found moving masked out of tracking".to_string()
    } else {
        "tracking only: no detector, no objects".to_string()
    });
    print(track_bench_header());
    let mut notes = Vec::new();
    for c in cases {
        let row = track_row(base, c, objects)?;
        print(row.line);
        notes.extend(row.notes);
    }
    print(TRACK_BENCH_FOOTER.to_string());
    notes.into_iter().for_each(print);
    Ok(())
}

/// The `track-bench` table's header (markdown), with one column per tracking state.
pub fn track_bench_header() -> String {
    format!(
        "| case | frames | ATE aligned m | path error % | end drift % | largest step error m (frame), tracked frames | {} | keyframes | map points | local BA median ms | ATE m | median frames/s |\n|---|---:|---:|---:|---:|---:|{}---:|---:|---:|---:|---:|",
        STATE_NAMES.join(" | "),
        "---:|".repeat(STATE_NAMES.len())
    )
}

/// One `track-bench` row and the notes it adds under the table.
#[derive(Debug, Clone)]
pub struct TrackRow {
    /// The markdown row.
    pub line: String,
    /// Notes on the case's ground truth.
    pub notes: Vec<String>,
}

/// `base`'s settings for `case`: its path and stride; no detector unless `objects`.
fn case_settings(base: &RunSettings, case: &TrackCase, objects: bool) -> RunSettings {
    let mut s = base.clone();
    s.path = case.path.clone();
    s.selection.stride = case.stride as usize;
    if !objects {
        s.detector = DetectorChoice::None;
    }
    s
}

/// Run `case` with `base`'s settings (its path and stride replaced, or its layout made in a temporary
/// folder and removed after; no detector unless `objects`).
pub fn track_row(base: &RunSettings, case: &TrackCase, objects: bool) -> Result<TrackRow> {
    let mut s = case_settings(base, case, objects);
    let layout = match case.order {
        Some(order) => {
            let folder =
                std::env::temp_dir().join(format!("slam-track-bench-{}-{}", std::process::id(), case.name.len()));
            let _ = std::fs::remove_dir_all(&folder);
            let made = slam_dataset::layout::write_layout(&case.path, order, &folder);
            let dir = made.map_err(|e| {
                let _ = std::fs::remove_dir_all(&folder);
                RunnerError::from(e)
            })?;
            s.path = dir;
            Some(folder)
        }
        None => None,
    };
    let run = run_quiet(&s, None).context_with(|| format!("case {}", case.name));
    if let Some(folder) = layout {
        let _ = std::fs::remove_dir_all(folder);
    }
    let o = run?;
    let (out, seq) = (&o.out, &o.seq);
    let truth = seq.truth_from_first();
    let scored = truth.as_ref().map(|g| crate::report::Scored::of(out, g, &seq.ids));
    let errors = scored.as_ref().and_then(|s| trajectory_errors(&s.est, &s.truth, &[]));
    // only frames the tracker marked "tracked" (not initialised, lost, relocalised or any weaker state)
    let step = scored.as_ref().and_then(|s| s.largest_tracked_step_error());
    let states: Vec<String> = state_counts(&out.frames).iter().map(|n| n.to_string()).collect();
    let stats = out.map.stats();
    let mut ba: Vec<f64> = out
        .frames
        .iter()
        .filter(|r| r.keyframe && r.times.bundle_adjustment > 0.0)
        .map(|r| r.times.bundle_adjustment)
        .collect();
    let line = format!(
        "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
        case.name,
        out.frames.len(),
        cell(errors.as_ref().map(|e| e.ate_aligned_m), 3),
        errors.as_ref().map_or(DASH.to_string(), |e| format!("{:+.2}", e.path_error_pct())),
        cell(errors.as_ref().map(|e| e.end_drift_pct), 2),
        step.map_or(DASH.to_string(), |(e, id)| format!("{e:.3} ({id})")),
        states.join(" | "),
        stats.keyframes,
        stats.points,
        cell(median(&mut ba), 1),
        cell(errors.as_ref().map(|e| e.ate_m), 3),
        cell(median_fps(out), 1)
    );
    let mut notes = Vec::new();
    if let Some(TruthSource::Oxts { median_pos_accuracy_m, path }) = seq.truth_source {
        notes.push(format!(
            "{}: ground truth from OXTS (differential GPS + IMU), median pos_accuracy {median_pos_accuracy_m:.2} m: errors below that are not meaningful.",
            case.name
        ));
        if let Some(p) = path {
            notes.push(format!("{}: {}.", case.name, crate::report::oxts_path_line(&p)));
        }
    }
    if let Some(s) = &scored {
        notes.extend(s.note.iter().map(|l| format!("{}: {l}.", case.name)));
        let check = crate::report::interpolation_lines(&s.est, &s.truth, crate::report::PoseNames::Frames(&s.ids));
        notes.extend(check.into_iter().map(|l| format!("{}: {l}.", case.name)));
    }
    if let Some(errors) = crate::report::dead_reckoning_errors(out, seq) {
        notes.push(format!("{}: {}: {errors}.", case.name, crate::report::DEAD_RECKONING));
    }
    if truth.is_none() {
        notes.push(format!("{}: no ground truth, errors not computed.", case.name));
    }
    Ok(TrackRow { line, notes })
}

/// The explanation under the `track-bench` table.
pub const TRACK_BENCH_FOOTER: &str = "\nATE aligned: RMS position error after the best rigid alignment (no scale); ATE: the same with both trajectories starting at the identity. Path error: estimated path length over the true one, minus 1 (a scale error shows here whatever the path's shape). Step error: |t(est step) - t(true step)| over steps ending at a frame marked tracked; the frame id in brackets. State columns: frames per state as tracking.csv names them (each frame in exactly one). Frames/s: 1000 / median interval between frames (machine load matters; accuracy figures are deterministic).";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cases_parse_with_and_without_a_stride() {
        let c = TrackCase::parse("/data/seq:3").expect("stride");
        assert_eq!((c.path, c.stride, c.name.as_str()), (PathBuf::from("/data/seq"), 3, "/data/seq, stride 3"));
        let plain = TrackCase::parse("C:dir").expect("no digits after the colon: a path");
        assert_eq!((plain.path, plain.stride), (PathBuf::from("C:dir"), 1));
        assert!(TrackCase::parse("seq:0").expect_err("zero").to_string().contains("at least 1"));
        assert!(TrackCase::parse("seq:99999999999999999999999").is_err(), "overflow");
        let dev = TrackCase::dev_cases("o".into(), "h".into(), "r".into());
        assert_eq!(dev.iter().map(|c| c.stride).collect::<Vec<_>>(), [1, 2, 3, 4, 1, 1, 4, 8, 1, 1, 1, 1]);
        assert_eq!(dev[8].order, Some(Order::ThereAndBack { legs: 5 }));
        assert_eq!(dev[4].path, PathBuf::from("h"), "the highway case");
    }

    #[test]
    fn tables_have_one_column_per_cell() {
        let header = track_bench_header();
        let mut lines = header.lines();
        let cols = lines.next().expect("head").matches('|').count();
        assert_eq!(lines.next().expect("rule").matches('|').count(), cols);
        assert_eq!(cols, 12 + STATE_NAMES.len());
        let row = BenchRow {
            name: "x".into(),
            fps_median: Some(30.04),
            fps_overall: Some(20.0),
            stages: vec![Some(1.0); 9],
            ate: Some(0.1234),
        };
        assert_eq!(
            row.to_string().matches('|').count(),
            RUN_BENCH_HEADER.lines().next().expect("head").matches('|').count()
        );
        assert!(row.to_string().starts_with("| x | 30.0 | 20.0 | 1.0 |") && row.to_string().ends_with("| 0.123 |"));
        assert!(run_bench_footer(3, &[row.clone(), row.clone(), row.clone()])
            .contains("(30.0), >= 10 with the detector (30.0)"));
        // detection 12 ms of which 10 ms forward: 2 ms of pre- and post-processing, 20 % of the forward pass
        let network =
            BenchRow { stages: [Some(12.0), Some(10.0)].into_iter().chain([Some(1.0); 7]).collect(), ..row.clone() };
        let line = processing_line(&network).expect("a network");
        assert!(line.contains("pre- and post-processing 2.0 ms, 20 % of the forward pass"), "{line}");
        assert!(run_bench_footer(1, &[row.clone(), row.clone(), network]).ends_with("(target <= 30 %)"));
        let file =
            BenchRow { stages: [Some(0.4), Some(0.0)].into_iter().chain([Some(1.0); 7]).collect(), ..row.clone() };
        assert_eq!(processing_line(&file), None, "no network, no line");
        // a run of one frame has no frame interval, a sequence without ground truth no ATE: dashes
        let empty = BenchRow { fps_median: None, stages: vec![None; 9], ate: None, ..row };
        assert!(
            empty.to_string().starts_with("| x | – | 20.0 | – |") && empty.to_string().ends_with("| – |"),
            "{empty}"
        );
        assert!(!empty.to_string().contains("NaN"));
    }
}
