//! The saved-map cases of `track-bench` (issue 38): a map made from odometry 06 frames 0-50 and saved,
//! then runs that start from it: 06 frames 20-50 (the same road again), 06 from frame 50 down to 0 (the
//! road driven back) and odometry 01 localising only (another road, another calibration of the rig:
//! nothing may be placed); the file's size, the time to load it, and the time to place a frame in it
//! from scratch against the time of a tracked frame.

use std::path::{Path, PathBuf};

use slam_core::figure::cell;
use slam_core::figure::median;
use slam_dataset::{kitti::stereo::FrameSelection, layout::Order};
use slam_frontend::{read_image, StereoRig, StereoVo};

use crate::{
    error::{Context, Result, RunnerError},
    in_map::{in_map, unaligned_errors},
    run::{load_map, prepare, Outcome, RunSettings},
};

/// Times each figure of loading is measured, for its median.
const LOAD_REPEATS: usize = 5;

fn play(s: &RunSettings) -> Result<Outcome> {
    prepare(s)?.run(s, &mut |_| {}, || false)
}

/// Run the saved-map cases with `base`'s settings (and detector): `odometry` is odometry 06's
/// sequence folder, `highway` odometry 01's. Prints a table and the file, load and placement lines.
pub fn map_bench(base: &RunSettings, odometry: &Path, highway: &Path, print: &mut dyn FnMut(String)) -> Result<()> {
    let folder = std::env::temp_dir().join(format!("slam-map-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&folder);
    std::fs::create_dir_all(&folder).context_with(|| format!("creating {}", folder.display()))?;
    let result = cases(base, odometry, highway, &folder, print);
    let _ = std::fs::remove_dir_all(&folder);
    result
}

fn cases(
    base: &RunSettings,
    odometry: &Path,
    highway: &Path,
    folder: &Path,
    print: &mut dyn FnMut(String),
) -> Result<()> {
    let mut s = base.clone();
    s.path = odometry.to_path_buf();
    s.selection = FrameSelection { first: Some(0), end: Some(51), stride: 1 };
    let first = play(&s).context_with(|| "the map run (06 frames 0-50)".to_string())?;
    let file = folder.join("map.json");
    first.out.map.save(&file)?;
    let sizes = [file.clone(), slam_pipeline::saved_map::features_path(&file)]
        .map(|p| std::fs::metadata(&p).map(|m| m.len()).unwrap_or(0));
    let kfs = first.out.map.stats().keyframes;
    let max_id = first.out.map.objects.iter().map(|o| o.id).max();
    let rig = StereoRig { k: first.k, baseline: first.seq.baseline };
    let mut load_s: Vec<f64> = (0..LOAD_REPEATS)
        .map(|_| load_map(&file, &rig, first.image, false).map(|(_, info)| info.seconds))
        .collect::<Result<_>>()?;

    let back = folder.join("back");
    let seq06 = slam_dataset::layout::write_layout(odometry, Order::Reversed, &back)?;
    print("\n**Saved map** (06 frames 0-50, then runs that start from it: `run --map`)\n".into());
    print("| case | frames | placed | first placed | ATE in the map's frame m | the map run's, same frames m | keyframes added | objects kept / added |\n|---|---:|---:|---:|---:|---:|---:|---:|".into());
    let cases: [Case<'_>; 3] = [
        ("06 frames 20-50 again", odometry.to_path_buf(), Some((20, 51)), false),
        ("06 driven back, 50 down to 0", seq06, None, false),
        ("01 (another road), localising only", highway.to_path_buf(), Some((0, 51)), true),
    ];
    for case in cases {
        print(case_row(base, &file, (&first, max_id, kfs), case)?);
    }
    let place = placement(&file, &first, base.tracking)?;
    // a map of 50 keyframes (the size): the same frames with a keyframe at every frame
    let mut dense = s.clone();
    dense.tracking.keyframe_max_gap = 1;
    let dense_run = play(&dense).context_with(|| "the dense map run (a keyframe every frame)".to_string())?;
    let dense_file = folder.join("dense.json");
    dense_run.out.map.save(&dense_file)?;
    let dense_place = placement(&dense_file, &first, base.tracking)?;
    print(format!(
        "\nmap file: {:.2} MB ({:.2} MB JSON + {:.2} MB features), {} keyframes: {:.0} KB a keyframe; loading it (read, check, rebuild): {} s median of {LOAD_REPEATS}",
        (sizes[0] + sizes[1]) as f64 / 1e6,
        sizes[0] as f64 / 1e6,
        sizes[1] as f64 / 1e6,
        kfs,
        (sizes[0] + sizes[1]) as f64 / 1e3 / kfs.max(1) as f64,
        cell(median(&mut load_s), 3),
    ));
    let dense_kfs = dense_run.out.map.stats().keyframes;
    print(format!("placing a frame: in the map of {kfs} keyframes {place}; in a map of {dense_kfs} keyframes (a keyframe every frame) {dense_place}"));
    Ok(())
}

/// A case of the table: name, sequence, frame ids (all: None), localising only.
type Case<'a> = (&'a str, PathBuf, Option<(usize, usize)>, bool);

/// One case run from the saved map `file` and its row of the table; `first` is the map run with its
/// largest object id and its keyframe count.
fn case_row(
    base: &RunSettings,
    file: &Path,
    (first, max_id, kfs): (&Outcome, Option<u64>, usize),
    (name, path, range, localise_only): Case<'_>,
) -> Result<String> {
    let mut c = base.clone();
    c.path = path;
    c.selection = FrameSelection { first: range.map(|r| r.0), end: range.map(|r| r.1), stride: 1 };
    (c.map, c.localise_only) = (Some(file.to_path_buf()), localise_only);
    let o = play(&c).context_with(|| format!("case {name}"))?;
    let load = o.loaded.as_ref().ok_or_else(|| RunnerError::Invalid(format!("case {name}: no map loaded")))?;
    let m = in_map(&o.out, &o.seq, load);
    // the map run's frames these frames show: the same ids, or the layout's source frames
    let ids: Vec<usize> = if range.is_some() { o.seq.ids.clone() } else { (0..=50).collect() };
    let same = if localise_only {
        None
    } else {
        let truth = first.seq.truth_from_first().unwrap_or_default();
        unaligned_errors(&first.out, &truth, &first.seq.ids, |id| ids.contains(&id)).map(|e| e.0)
    };
    let objects = &o.out.map.objects;
    let kept = objects.iter().filter(|x| max_id.is_some_and(|m| x.id <= m)).count();
    let added = objects.iter().filter(|x| max_id.is_none_or(|m| x.id > m) && !x.dynamic).count();
    Ok(format!(
        "| {name} | {} | {} | {} | {} | {} | {} | {kept} / {added} |",
        m.frames,
        m.placed,
        m.first_placed.map_or("–".into(), |f| f.to_string()),
        cell(m.errors.map(|e| e.0), 3),
        cell(same, 3),
        o.out.map.stats().keyframes.saturating_sub(kfs),
    ))
}

/// Every frame of 06 frames 0-50 placed in the saved map `file` from scratch ([`StereoVo::place`]: features,
/// stereo matching, retrieval, PnP, the search at the pose found and the refinement), timed, against
/// the map run's tracked frames (features, stereo matching, tracking).
fn placement(file: &Path, first: &Outcome, tracking: slam_frontend::VoConfig) -> Result<String> {
    let rig = StereoRig { k: first.k, baseline: first.seq.baseline };
    let (loaded, _) = load_map(file, &rig, first.image, false)?;
    let optimizer: slam_optim::SharedOptimizer = std::sync::Arc::new(slam_lm::LevenbergMarquardt::default());
    let mut vo = StereoVo::new(rig, tracking, optimizer)?;
    let (mut ms, mut placed, mut errors) = (Vec::new(), 0usize, Vec::new());
    let gt = first.seq.ground_truth.clone().unwrap_or_default();
    for k in 0..first.seq.len() {
        let (l, r) = (read_image(&first.seq.left[k], false)?, read_image(&first.seq.right[k], false)?);
        let t0 = std::time::Instant::now();
        let at = vo.place(&l, &r, &loaded.map)?;
        ms.push(t0.elapsed().as_secs_f64() * 1e3);
        if let Some((_, pose, _)) = at {
            placed += 1;
            if let Some(g) = gt.get(k) {
                errors.push((pose.translation.vector - g.translation.vector).norm());
            }
        }
    }
    let mut tracked: Vec<f64> = first
        .out
        .frames
        .iter()
        .filter(|f| matches!(f.state, Some(slam_core::TrackState::Tracked { .. })))
        .map(|f| f.times.extraction + f.times.stereo + f.times.tracking)
        .collect();
    let (p, t) = (median(&mut ms).unwrap_or(f64::NAN), median(&mut tracked).unwrap_or(f64::NAN));
    let worst = errors.iter().copied().fold(0.0, f64::max);
    if !p.is_finite() || !t.is_finite() {
        return Err(RunnerError::Invalid("placement: no frame timed".into()));
    }
    Ok(format!(
        "{placed} of {} frames of 06 placed from scratch, {p:.1} ms median ({:.2}x a tracked frame's {t:.1} ms: features, stereo, tracking), largest position error {worst:.3} m",
        first.seq.len(),
        p / t
    ))
}
