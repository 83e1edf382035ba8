//! One run of the whole system on a KITTI stereo sequence: the settings the app fills, the checks before
//! the first frame ([`prepare`]), the wiring of `SystemBuilder` and the frame source ([`Prepared::run`]),
//! and what is needed to report on the run ([`Outcome`]).

use std::{path::PathBuf, sync::Arc};

use slam_core::{Associator, DetectionSource, Image};
use slam_dataset::{
    check::{calibration, calibration_file, declared_size, first_pair},
    kitti::{
        stereo::{FrameSelection, Layout, StereoSequence},
        tracking::{read_tracking_labels, TrackingLabel},
    },
    recording::{open_sequence, SourceOptions},
};
use slam_detect::detectors::{DetectionCounts, DetectionGuard};
use slam_eval::LabelGeometry;
use slam_frontend::{rectify::Rectifier, StereoRig, StereoVo, VoConfig};
use slam_optim::SharedOptimizer;
use slam_pipeline::{
    objects::FitMethod,
    system::{FrameInput, FrameView, RunOutput, SystemBuilder, SystemConfig},
};
use slam_quadric::{ImageSize, Intrinsics};

use slam_frontend::image_size::stereo_pair;

use crate::{
    detector::DetectorChoice,
    error::{Result, RunnerError},
    run_summary::frame_period,
    source::{rectifier_of, FrameReader},
};

/// The world of a rectified run's map file: the frame the tracker worked in (a later `run --map` tracks
/// in it again).
pub const RECTIFIED_WORLD: &str = "world = the rectified left camera of the first frame (the run rectified its images; trajectory and objects files are in the raw left camera's frame): x right, y down, z forward, metres; poses world from rectified camera";

/// A fresh optimiser backend for each run.
pub type OptimizerFactory = Arc<dyn Fn() -> SharedOptimizer + Send + Sync>;
/// A fresh associator for each run, given ODA's projected-ellipsoid gate (`SystemConfig::projected_gate`).
pub type AssociatorFactory = Arc<dyn Fn(Option<f64>) -> Box<dyn Associator> + Send + Sync>;

/// Everything a run needs, filled by the app from its options and settings file.
#[derive(Clone)]
pub struct RunSettings {
    /// The sequence: a KITTI folder (odometry, raw or tracking layout), a ROS 2 bag, or a folder of
    /// `left/` and `right/` images.
    pub path: PathBuf,
    /// How to read a recording that is not KITTI's (calibration file, a bag's topics, a folder's rate).
    pub source: SourceOptions,
    /// Frame ids to play.
    pub selection: FrameSelection,
    /// Play at most this many frames (after the selection); `Some(0)` is refused.
    pub max_frames: Option<usize>,
    /// Visual odometry settings (a `frame_period_s` of 0 or less is taken from the sequence's times).
    pub tracking: VoConfig,
    /// The system's settings; `objects.image` is replaced by the sequence's image size.
    pub system: SystemConfig,
    /// The optimiser backend.
    pub optimizer: OptimizerFactory,
    /// The object associator.
    pub associator: AssociatorFactory,
    /// How objects' ellipsoids are fitted.
    pub method: FitMethod,
    /// Names of the associator and the method, for the header.
    pub names: (String, String),
    /// Where the boxes come from.
    pub detector: DetectorChoice,
    /// KITTI tracking labels to score the run against (else the tracking layout's own, if any).
    pub labels: Option<PathBuf>,
    /// A map file of an earlier run to localise in and extend (`run --map`).
    pub map: Option<PathBuf>,
    /// With `map`: localise only, add nothing (`run --localise-only`).
    pub localise_only: bool,
}

/// The map a run started from: its file, what it held, and how long loading it took.
#[derive(Debug, Clone, PartialEq)]
pub struct MapLoad {
    /// The map file.
    pub path: PathBuf,
    /// Keyframes, points and objects loaded.
    pub counts: (usize, usize, usize),
    /// Reading, checking and rebuilding it, seconds.
    pub seconds: f64,
    /// Its keyframes were re-expressed in the run's camera (another calibration, localising only).
    pub reexpressed: bool,
    /// Localising only.
    pub localise_only: bool,
    /// The frame whose camera is the map's world (its first keyframe's).
    pub first_frame: Option<usize>,
    /// The map's world in the ground truth of the run that made it, when the map records it.
    pub ground_truth_world: Option<slam_pipeline::saved_map::GroundTruthWorld>,
}

/// Read a map file and rebuild it as the live map of a run with `rig` and images of `image` size;
/// a map made with another camera is refused unless `localise_only` (then re-expressed, logged).
pub fn load_map(
    path: &std::path::Path,
    rig: &StereoRig,
    image: ImageSize,
    localise_only: bool,
) -> Result<(slam_pipeline::saved_map::LoadedMap, MapLoad)> {
    let t0 = std::time::Instant::now();
    let file = slam_pipeline::saved_map::SavedMap::load(path)?;
    let camera = slam_pipeline::saved_map::MapCamera::of(rig, (image.width, image.height));
    let loaded = file.to_live(&camera, localise_only).map_err(|e| {
        let hint = if matches!(e, slam_pipeline::saved_map::ToLiveError::Camera(_)) {
            " (a map is extended only with the camera it was made with; --localise-only re-expresses its keyframes in this camera)"
        } else {
            ""
        };
        RunnerError::Invalid(format!("{}: {e}{hint}", path.display()))
    })?;
    if loaded.reexpressed {
        tracing::warn!("{}: made with another camera; its keyframes re-expressed in this run's camera", path.display());
    }
    let counts = (loaded.map.keyframe_count(), loaded.map.point_count(), loaded.objects.len());
    let seconds = t0.elapsed().as_secs_f64();
    tracing::info!(keyframes = counts.0, points = counts.1, objects = counts.2, seconds, "map loaded");
    let info = MapLoad {
        path: path.to_path_buf(),
        counts,
        seconds,
        reexpressed: loaded.reexpressed,
        localise_only,
        first_frame: loaded.first_frame,
        ground_truth_world: loaded.ground_truth_world,
    };
    Ok((loaded, info))
}

/// A sequence checked and ready to play: the frames, calibration and image size.
pub struct Prepared {
    /// The played frames.
    pub seq: StereoSequence,
    /// Camera intrinsics of the left camera.
    pub k: Intrinsics,
    /// Whether the images are read in colour (every layout but odometry).
    pub colour: bool,
    /// Image size most frames have (every frame's, or it is played as unreadable).
    pub image: ImageSize,
    /// The same, with the frames of another size.
    pub sizes: SequenceSize,
    /// The rectification of a rig whose images are not a rectified pair, computed once.
    pub rectifier: Option<Arc<Rectifier>>,
    selection: FrameSelection,
}

/// Something that follows a run frame by frame and is finished with the run's outcome: a recording.
pub trait RunObserver {
    /// One frame, as soon as it is tracked (on the tracking thread: keep it short).
    fn frame(&mut self, view: &FrameView<'_>);
    /// The run ended with `outcome`; returns a line saying what was written.
    fn finish(self: Box<Self>, outcome: &Outcome) -> Result<String>;
}

/// Makes the observer of a prepared run (a recording needs the run's camera, frames and ground truth).
pub type ObserverFactory<'f> = dyn FnMut(&Prepared) -> Result<Box<dyn RunObserver>> + 'f;

/// A finished run and what is needed to report on it.
pub struct Outcome {
    /// What the system produced.
    pub out: RunOutput,
    /// The labels (`--labels`, or the tracking layout's own) and their geometry in the run's camera.
    pub labels: Option<(Vec<TrackingLabel>, LabelGeometry)>,
    /// The played frames.
    pub seq: StereoSequence,
    /// Wall time of the run, seconds.
    pub elapsed: f64,
    /// Camera intrinsics.
    pub k: Intrinsics,
    /// Image size.
    pub image: ImageSize,
    /// Whether the images were read in colour.
    pub colour: bool,
    /// What the detection guard changed.
    pub detections: Option<Arc<DetectionCounts>>,
    /// Reports of detections no frame used.
    pub notes: Vec<String>,
    /// The frame selection, for the summary.
    pub selection: FrameSelection,
    /// The optional stages the run switched on (for the timing table).
    pub stages: crate::run_summary::StagesOn,
    /// The map the run started from (`run --map`).
    pub loaded: Option<MapLoad>,
    /// The rectification the images went through (raw cameras), if any.
    pub rectifier: Option<Arc<Rectifier>>,
}

/// Open the sequence, apply the selection and `max_frames`, and check image sizes and calibration before
/// the first frame (a right camera of another size would make every frame unreadable). The sequence's
/// input warnings are logged.
pub fn prepare(s: &RunSettings) -> Result<Prepared> {
    let full = open_sequence(&s.path, &s.source)?;
    for w in &full.warnings {
        tracing::warn!("{w}");
    }
    let mut seq = full.select(&s.selection)?;
    if let Some(n) = s.max_frames {
        if n == 0 {
            return Err(RunnerError::Invalid("nothing to run: --max-frames 0".into()));
        }
        seq.truncate(n);
    }
    let rectifier = rectifier_of(&mut seq)?;
    let colour = seq.layout != Layout::Odometry;
    let sizes = match &seq.recording {
        Some(_) => recording_size(&seq, colour, rectifier.clone())?,
        None => checked_size(&seq)?,
    };
    let [fx, fy, cx, cy] = seq.intrinsics;
    let image = ImageSize::new(f64::from(sizes.size.0), f64::from(sizes.size.1));
    Ok(Prepared { seq, k: Intrinsics::new(fx, fy, cx, cy), colour, image, sizes, rectifier, selection: s.selection })
}

/// The image size of a recording that is not KITTI's, checked before the run: the first pair decoded
/// (and rectified) must be one size, the calibration's size when it says one, and fit the calibration
/// ([`calibration`]); a bag's raw images of another size (their headers say) are played as unreadable.
pub fn recording_size(seq: &StereoSequence, colour: bool, rectifier: Option<Arc<Rectifier>>) -> Result<SequenceSize> {
    let recording = seq.recording.as_ref().ok_or_else(|| RunnerError::Invalid("not a recording".into()))?;
    let mut reader = FrameReader::new(seq, colour, None);
    let (l, r) =
        reader.pair(0).map_err(|e| RunnerError::Invalid(format!("{}: the first frame: {e}", seq.dir.display())))?;
    if (l.width, l.height) != (r.width, r.height) {
        return Err(RunnerError::Invalid(format!(
            "{}: the first frame's left image is {}×{} and its right image {}×{}: a stereo pair has one size",
            seq.dir.display(),
            l.width,
            l.height,
            r.width,
            r.height
        )));
    }
    let size = (l.width, l.height);
    if let Some(c) = recording.calibrated_size.filter(|c| *c != size) {
        return Err(RunnerError::Invalid(format!(
            "{}: the calibration is for {}×{} images, and the first frame's are {}×{} ({})",
            recording.calibration.display(),
            c.0,
            c.1,
            size.0,
            size.1,
            seq.dir.display()
        )));
    }
    if let Some(rect) = &rectifier {
        debug_assert_eq!(rect.size(), size);
    }
    let odd: Vec<usize> = match recording.bag.as_ref() {
        Some(b) => (0..b.frames.len())
            .filter(|&k| [b.frames[k].left.size, b.frames[k].right.size].iter().flatten().any(|s| *s != size))
            .collect(),
        None => Vec::new(),
    };
    if let Some(&i) = odd.first() {
        tracing::warn!(
            "{} of {} frames have images of another size than the first frame's {}×{} (first: frame {}): played as unreadable",
            odd.len(),
            seq.len(),
            size.0,
            size.1,
            seq.ids[i]
        );
    }
    let reference = seq.left.first().cloned().unwrap_or_else(|| seq.dir.clone());
    calibration(&calibration_file(seq), seq.intrinsics, seq.baseline, &reference, size)?;
    Ok(SequenceSize { size, odd })
}

/// The image size of a sequence and the frames that do not have it.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceSize {
    /// The size most frames have (width, height).
    pub size: (u32, u32),
    /// Frames (positions) whose images, read from their headers, have another size: played as
    /// unreadable.
    pub odd: Vec<usize>,
}

/// The image size of `seq`, checked before any frame is decoded: the first frame with both images must
/// be a readable pair of one size ([`stereo_pair`]); the size is the one most frames' headers declare (a
/// first frame of its own size, a crop, does not make every other frame unreadable); the calibration
/// must fit it ([`calibration`]: focal length, principal point near the centre; a raw drive's declared
/// `S_rect`). Every command that tracks a sequence (`run`, `track-bench`, `run-bench`, `stereo-check`,
/// `depth-check`) checks it this way.
pub fn checked_size(seq: &StereoSequence) -> Result<SequenceSize> {
    let (l0, r0) = first_pair(&seq.left, &seq.right)?;
    let first = stereo_pair(l0, r0)?;
    let of = |p: &std::path::Path| slam_frontend::image_size::image_size(p).ok();
    let frames: Vec<Option<(u32, u32)>> =
        seq.left.iter().zip(&seq.right).map(|(l, r)| of(l).filter(|s| of(r) == Some(*s))).collect();
    let mut counts: std::collections::BTreeMap<(u32, u32), usize> = std::collections::BTreeMap::new();
    for s in frames.iter().flatten() {
        *counts.entry(*s).or_default() += 1;
    }
    // the most common size; a tie goes to the first frame's
    let most = counts.values().copied().max().unwrap_or(0);
    let size = if counts.get(&first) == Some(&most) {
        first
    } else {
        counts.iter().find(|(_, &n)| n == most).map_or(first, |(s, _)| *s)
    };
    let odd: Vec<usize> = (0..frames.len()).filter(|&i| frames[i].is_some_and(|s| s != size)).collect();
    if let Some(&i) = odd.first() {
        let (w, h) = frames[i].unwrap_or_default();
        tracing::warn!(
            "{} of {} frames have images of another size than the others' {}×{} (first: frame {}, {w}×{h}): played as unreadable",
            odd.len(),
            frames.len(),
            size.0,
            size.1,
            seq.ids[i]
        );
    }
    let reference = frames.iter().position(|s| *s == Some(size)).map_or(l0, |i| seq.left[i].as_path());
    calibration(&calibration_file(seq), seq.intrinsics, seq.baseline, reference, size)?;
    declared_size(&calibration_file(seq), reference, size)?;
    Ok(SequenceSize { size, odd })
}

/// Which frames a run played, e.g. `frame ids 0..=50 every 2 ids`.
pub fn played_ids(seq: &StereoSequence, sel: &FrameSelection) -> String {
    let (first, last) = (seq.ids[0], seq.ids[seq.ids.len() - 1]);
    let stride = if sel.stride > 1 { format!(" every {} ids", sel.stride) } else { String::new() };
    format!("frame ids {first}..={last}{stride}")
}

impl Prepared {
    /// Number of frames to play.
    pub fn len(&self) -> usize {
        self.seq.len()
    }

    /// Whether no frame is played.
    pub fn is_empty(&self) -> bool {
        self.seq.len() == 0
    }

    /// The run's header: sequence, layout, frames, calibration, detector, association and method, and a
    /// line on missing images if any.
    pub fn header(&self, s: &RunSettings) -> String {
        let seq = &self.seq;
        let mut text = format!(
            "quadric SLAM on {} ({:?} layout, {} frames: {}, fx {:.1} px, baseline {:.4} m, detector: {}, \
             association: {}, ellipsoids: {})",
            seq.dir.display(),
            seq.layout,
            seq.len(),
            played_ids(seq, &self.selection),
            self.k.fx,
            seq.baseline,
            if s.localise_only { "none (localising only)".to_string() } else { s.detector.describe() },
            s.names.0,
            s.names.1,
        );
        if let Some(r) = &seq.recording {
            text.push_str(&format!("\ninput: {}", r.source));
        }
        if let Some(r) = &self.rectifier {
            text.push_str(&format!(
                "\nrectified once for the run: fx {:.2} px, baseline {:.4} m (the tracked pair's; outputs in the raw left camera's frame)",
                r.intrinsics[0], r.baseline
            ));
        }
        if let Some(&i) = self.sizes.odd.first() {
            text.push_str(&format!(
                "\ninput: {} frame(s) of another image size than the others' {}×{} (first: frame {}), played as unreadable",
                self.sizes.odd.len(),
                self.sizes.size.0,
                self.sizes.size.1,
                seq.ids[i]
            ));
        }
        if !(seq.gaps.is_empty() && seq.one_camera.is_empty()) {
            text.push_str(&format!(
                "\ninput: {} frame(s) missing in both cameras (skipped, ids kept), {} with one image missing (played as unreadable); see the warnings",
                seq.gaps.count(),
                seq.one_camera.len()
            ));
        }
        text
    }

    /// Run the system over the frames. `on_frame` sees every frame as soon as it is tracked (progress, a
    /// recording); `stop` is polled before each frame is read (Ctrl-C: the input ends, the system
    /// finishes what it has).
    pub fn run(self, s: &RunSettings, on_frame: &mut dyn FnMut(&FrameView<'_>), stop: fn() -> bool) -> Result<Outcome> {
        let Prepared { seq, k, colour, selection, image, sizes, rectifier, .. } = self;
        let mut tracking = s.tracking;
        tracking.frame_period_s = frame_period_of(&tracking, &seq);
        let optimizer = (s.optimizer)();
        let rig = StereoRig { k, baseline: seq.baseline };
        let (map, loaded) = starting_map(s, &rig, image)?;
        tracking.localise_only = s.localise_only;
        let tracker = Box::new(StereoVo::new(rig, tracking, optimizer.clone())?);
        let labels = run_labels(s, &seq, image)?;
        let mut notes = unused_label_notes(s, &seq, labels.as_ref());
        let mut unused_detections = Vec::new();
        // localising only maps no objects: no detector runs
        let (det, detections) = match s.localise_only {
            true => (None, None),
            false => guarded(s, &seq, image, labels.as_ref(), &mut unused_detections)?,
        };
        notes.extend(unused_detections.into_iter().map(|n| format!("unused detections: {n}")));
        for note in &notes {
            tracing::warn!("{note}");
        }
        let frames = frame_source(FrameReader::new(&seq, colour, rectifier.clone()), &seq, sizes, stop);
        let start = std::time::Instant::now();
        let sys = system_config(s, image, &tracking);
        let mut out = SystemBuilder::new(k, seq.baseline)
            .map(map)
            .config(sys)
            .source(frames)
            .tracker(tracker)
            .detector(det)
            .associator((s.associator)(sys.projected_gate))
            .optimizer(optimizer)
            .method(s.method.clone())
            .build()?
            .run(on_frame)?;
        let elapsed = start.elapsed().as_secs_f64();
        if rectifier.is_some() {
            out.map.frame = RECTIFIED_WORLD.to_string();
        }
        // the map's world in the ground truth: the loaded map's, else this run's first frame's
        out.map.ground_truth_world = match &loaded {
            Some(l) => l.ground_truth_world,
            None => ground_truth_world(&out.map, &seq),
        };
        let stages = crate::run_summary::StagesOn {
            objects: detections.is_some(),
            bundle_adjustment: sys.mapping.bundle_adjustment,
        };
        Ok(Outcome {
            out,
            labels,
            seq,
            elapsed,
            k,
            image,
            colour,
            detections,
            notes,
            selection,
            stages,
            loaded,
            rectifier,
        })
    }
}

/// Where a map made by a run over `seq` lies in the sequence's ground truth: its first frame and that
/// frame's ground-truth pose (none without ground truth or keyframes).
/// The tracker's frame period: the settings' own, else (when 0 or less) the one the sequence's times give.
fn frame_period_of(tracking: &VoConfig, seq: &StereoSequence) -> f64 {
    if tracking.frame_period_s <= 0.0 {
        let n = seq.len().min(seq.times.len());
        let stamped: Vec<(usize, f64)> = (0..n).map(|i| (seq.ids[i], seq.times[i])).collect();
        return frame_period(&stamped);
    }
    tracking.frame_period_s
}

/// The map the run starts from (`--map`, rebuilt for `rig`) and what loading it found; none without one.
fn starting_map(
    s: &RunSettings,
    rig: &StereoRig,
    image: ImageSize,
) -> Result<(Option<slam_pipeline::saved_map::LoadedMap>, Option<MapLoad>)> {
    Ok(match &s.map {
        Some(path) => {
            let (m, info) = load_map(path, rig, image, s.localise_only)?;
            (Some(m), Some(info))
        }
        None => (None, None),
    })
}

/// Notes on `--labels` files' frames the run does not play (they score nothing); said as unused
/// detections are, except with `--detector labels`, where they are those detections (reported later).
fn unused_label_notes(
    s: &RunSettings,
    seq: &StereoSequence,
    labels: Option<&(Vec<TrackingLabel>, LabelGeometry)>,
) -> Vec<String> {
    let mut notes = Vec::new();
    if let (Some(path), Some((l, _))) = (&s.labels, labels) {
        if !matches!(s.detector, DetectorChoice::Labels { .. }) {
            let mut per_frame: std::collections::BTreeMap<usize, usize> = Default::default();
            for label in l.iter().filter(|l| !l.is_dont_care()) {
                *per_frame.entry(label.frame).or_default() += 1;
            }
            let source = path.display().to_string();
            let unused = slam_detect::detectors::unused_frames(&source, per_frame.into_iter(), &seq.ids);
            notes.extend(unused.map(|n| format!("unused labels: {}", n.replace(" boxes)", " labels)"))));
        }
    }
    notes
}

/// The system's settings for this run: the sequence's image size, the tracker's near bound for the
/// map's points and local BA's disparity weights, and whether it only localises.
fn system_config(s: &RunSettings, image: ImageSize, tracking: &VoConfig) -> SystemConfig {
    let mut sys = s.system;
    sys.objects.image = image;
    // the map makes points and local BA weighs disparities by the tracker's near bound
    sys.mapping.near_baselines = tracking.far_baselines;
    sys.localise_only = s.localise_only;
    sys
}

fn ground_truth_world(
    map: &slam_pipeline::saved_map::SavedMap,
    seq: &StereoSequence,
) -> Option<slam_pipeline::saved_map::GroundTruthWorld> {
    let frame = map.first_frame()?;
    let k = seq.ids.iter().position(|&id| id == frame)?;
    let pose = seq.ground_truth.as_ref()?.get(k)?;
    Some(slam_pipeline::saved_map::GroundTruthWorld { frame, pose: slam_pipeline::saved_map::pose_to_array(pose) })
}

/// The run's labels: the `--labels` file, else the tracking layout's own; with their camera geometry.
fn run_labels(
    s: &RunSettings,
    seq: &StereoSequence,
    image: ImageSize,
) -> Result<Option<(Vec<TrackingLabel>, LabelGeometry)>> {
    let labels = match (&s.labels, &seq.labels) {
        (Some(p), _) => Some(read_tracking_labels(p)?),
        (None, Some(l)) => Some(l.clone()),
        (None, None) => None,
    };
    Ok(match labels {
        Some(l) => Some((l, LabelGeometry::of_sequence(seq, image)?)),
        None => None,
    })
}

/// The chosen detector behind the class filter and the detection guard (at most
/// `system.max_detections` boxes a frame, boxes clipped to the image), and the guard's counts.
type Guarded = (Option<Box<dyn DetectionSource>>, Option<Arc<DetectionCounts>>);

fn guarded(
    s: &RunSettings,
    seq: &StereoSequence,
    image: ImageSize,
    labels: Option<&(Vec<TrackingLabel>, LabelGeometry)>,
    notes: &mut Vec<String>,
) -> Result<Guarded> {
    let mut counts = None;
    let det = s.detector.build(seq, image, labels, notes)?.map(|d| {
        // the guard keeps the mapped classes and counts the rest
        let (g, c) = DetectionGuard::new(d, [image.width, image.height], s.system.max_detections);
        counts = Some(c);
        Box::new(g) as Box<dyn DetectionSource>
    });
    Ok((det, counts))
}

/// Both images of a frame, of one size and of the size most of the sequence's frames have.
fn checked_pair(
    (li, ri): (Image, Image),
    (l, r): (&std::path::Path, &std::path::Path),
    first: &SequenceSize,
) -> std::result::Result<(Image, Image), String> {
    if (li.width, li.height) != (ri.width, ri.height) {
        Err(format!(
            "left {} is {}×{}, right {} is {}×{}",
            l.display(),
            li.width,
            li.height,
            r.display(),
            ri.width,
            ri.height
        ))
    } else if (li.width, li.height) != first.size {
        Err(format!(
            "{} is {}×{}, {} {}×{}",
            l.display(),
            li.width,
            li.height,
            if first.odd.first() == Some(&0) { "most of the sequence's frames" } else { "the sequence's first frame" },
            first.size.0,
            first.size.1
        ))
    } else {
        Ok((li, ri))
    }
}

/// The frames as the system reads them (through `reader`: files or a bag, rectified when the rig needs
/// it); the input ends early when `stop()` turns true.
fn frame_source(
    mut reader: FrameReader,
    seq: &StereoSequence,
    first: SequenceSize,
    stop: fn() -> bool,
) -> Box<dyn Iterator<Item = FrameInput> + Send> {
    let entries: Vec<(usize, PathBuf, PathBuf)> =
        (0..seq.len()).map(|k| (seq.ids[k], seq.left[k].clone(), seq.right[k].clone())).collect();
    Box::new(entries.into_iter().enumerate().take_while(move |_| !stop()).map(move |(k, (i, l, r))| FrameInput {
        index: i,
        images: reader.pair(k).and_then(|p| checked_pair(p, (&l, &r), &first)),
    }))
}
