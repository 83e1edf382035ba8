//! Simulated multi-object scenes and CLEAR-MOT style counting, to compare associators.
//!
//! The simulator moves boxes across a KITTI-sized image at constant velocity, bouncing off the
//! sides, so same-class objects at similar heights cross each other many times. Nearer objects occlude
//! farther ones: an object less than 30 % visible is not detected, and keypoints are only drawn on the
//! visible part of each object. Detections get Gaussian box noise, random dropouts and clutter
//! (false boxes). Keypoints are "tracked" from the previous frame (every frame is a reference keyframe)
//! with sub-pixel noise and a share of outliers, as a forward-backward-checked optical flow would give.

use std::collections::BTreeMap;

use slam_core::{geometry::BBox, ClassId, Detection, Mask, PointPair, TrackId};

use slam_assoc::{ObjectTracker, TrackerInput};

/// The seeded generator used by the simulations (from `slam-core`).
pub use slam_core::rng::SimRng;

/// Settings of [`simulate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimConfig {
    /// Number of objects.
    pub objects: usize,
    /// Number of frames.
    pub frames: usize,
    /// Box noise, standard deviation in pixels per coordinate.
    pub box_noise_px: f64,
    /// Probability that a visible object is not detected in a frame.
    pub dropout: f64,
    /// Expected number of clutter detections per frame.
    pub clutter: f64,
    /// Keypoints drawn per object (before occlusion).
    pub flow_points: usize,
    /// Share of tracked keypoints whose reference position is wrong.
    pub flow_outliers: f64,
    /// Range of horizontal speeds, pixels per frame.
    pub speed: (f64, f64),
    /// Give each detection an instance mask of the object's visible pixels (as a segmenting detector
    /// does); without masks the inlier cue sees the points of occluders inside a box.
    pub masks: bool,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            objects: 8,
            frames: 300,
            box_noise_px: 2.0,
            dropout: 0.05,
            clutter: 0.3,
            flow_points: 40,
            flow_outliers: 0.1,
            masks: true,
            speed: (5.0, 12.0),
        }
    }
}

/// One simulated frame.
#[derive(Debug, Clone)]
pub struct SimFrame {
    /// Detections.
    pub detections: Vec<Detection>,
    /// True object of each detection (`None` for clutter).
    pub truth: Vec<Option<u64>>,
    /// Keypoints tracked from the previous frame.
    pub flow: Vec<PointPair>,
    /// Number of objects present (visible or not) this frame.
    pub objects_present: usize,
}

struct Obj {
    x: f64,
    y: f64,
    w: f64,
    h: f64,
    vx: f64,
    depth: f64,
}

impl Obj {
    fn bbox(&self) -> BBox {
        BBox::new(self.x, self.y, self.x + self.w, self.y + self.h)
    }
}

const WIDTH: f64 = 1242.0;
const HEIGHT: f64 = 375.0;

/// Simulate a scene. All objects are of one class, and lie in two horizontal lanes, so boxes overlap
/// and cross often: the hard case for association.
pub fn simulate(config: &SimConfig, seed: u64) -> Vec<SimFrame> {
    let mut rng = SimRng::new(seed);
    let mut objs = initial_objects(config, &mut rng);
    let class = ClassId(2);
    let mut frames = Vec::with_capacity(config.frames);
    for _ in 0..config.frames {
        let prev: Vec<BBox> = objs.iter().map(|o| o.bbox()).collect();
        move_objects(&mut objs);
        let boxes: Vec<BBox> = objs.iter().map(|o| o.bbox()).collect();
        let occluded_by = |i: usize, x: f64, y: f64| {
            boxes.iter().enumerate().any(|(j, b)| {
                j != i && objs[j].depth < objs[i].depth && x >= b.xmin && x <= b.xmax && y >= b.ymin && y <= b.ymax
            })
        };
        let mut detections = Vec::new();
        let mut truth = Vec::new();
        let mut flow = Vec::new();
        for (i, b) in boxes.iter().enumerate() {
            let occluded = |x: f64, y: f64| occluded_by(i, x, y);
            if visible_share(b, &occluded) >= 0.3 && rng.unit() >= config.dropout {
                detections.push(noisy_detection(config, &mut rng, class, b, &occluded));
                truth.push(Some(i as u64));
            }
            track_points(config, &mut rng, b, &prev[i], &occluded, &mut flow);
        }
        add_clutter(config, &mut rng, class, &mut detections, &mut truth);
        frames.push(SimFrame { detections, truth, flow, objects_present: objs.len() });
    }
    frames
}

/// The scene's objects at the start: random boxes in two lanes, each with a speed and a depth.
fn initial_objects(config: &SimConfig, rng: &mut SimRng) -> Vec<Obj> {
    (0..config.objects)
        .map(|k| {
            let w = rng.uniform(60.0, 130.0);
            let lane = (k % 2) as f64;
            Obj {
                x: rng.uniform(0.0, WIDTH - w),
                y: 150.0 + 40.0 * lane + rng.uniform(-10.0, 10.0),
                w,
                h: w * rng.uniform(0.5, 0.8),
                vx: rng.uniform(config.speed.0, config.speed.1) * if rng.unit() < 0.5 { -1.0 } else { 1.0 },
                depth: rng.uniform(5.0, 40.0),
            }
        })
        .collect()
}

/// Move each object one frame on, bouncing it off the image's sides.
fn move_objects(objs: &mut [Obj]) {
    for o in objs {
        o.x += o.vx;
        if o.x < 0.0 || o.x + o.w > WIDTH {
            o.vx = -o.vx;
            o.x = o.x.clamp(0.0, WIDTH - o.w);
        }
    }
}

/// The share of box `b` not hidden by nearer objects (`occluded` at a point), sampled on a 10 × 10 grid.
fn visible_share(b: &BBox, occluded: &impl Fn(f64, f64) -> bool) -> f64 {
    let (mut vis, mut tot) = (0, 0);
    for gx in 0..10 {
        for gy in 0..10 {
            let x = b.xmin + (gx as f64 + 0.5) * b.width() / 10.0;
            let y = b.ymin + (gy as f64 + 0.5) * b.height() / 10.0;
            tot += 1;
            if !occluded(x, y) {
                vis += 1;
            }
        }
    }
    (vis as f64) / (tot as f64)
}

/// The detection of box `b`: corners with Gaussian noise, and the mask of its visible pixels if asked.
fn noisy_detection(
    config: &SimConfig,
    rng: &mut SimRng,
    class: ClassId,
    b: &BBox,
    occluded: &impl Fn(f64, f64) -> bool,
) -> Detection {
    let n = config.box_noise_px;
    let nb = BBox::new(
        b.xmin + n * rng.normal(),
        b.ymin + n * rng.normal(),
        b.xmax + n * rng.normal(),
        b.ymax + n * rng.normal(),
    );
    let mut det = Detection::new(class, 0.9, nb);
    if config.masks {
        det.mask = Some(visible_mask(b, |x, y| !occluded(x, y)));
    }
    det
}

/// Keypoints on the visible part of box `b`, tracked from `prev` with noise and outliers, onto `flow`.
fn track_points(
    config: &SimConfig,
    rng: &mut SimRng,
    b: &BBox,
    prev: &BBox,
    occluded: &impl Fn(f64, f64) -> bool,
    flow: &mut Vec<PointPair>,
) {
    for _ in 0..config.flow_points {
        let x = rng.uniform(b.xmin, b.xmax);
        let y = rng.uniform(b.ymin, b.ymax);
        if occluded(x, y) {
            continue;
        }
        let (dx, dy) = (b.xmin - prev.xmin, b.ymin - prev.ymin);
        let reference = if rng.unit() < config.flow_outliers {
            [rng.uniform(0.0, WIDTH), rng.uniform(0.0, HEIGHT)]
        } else {
            [x - dx + 0.5 * rng.normal(), y - dy + 0.5 * rng.normal()]
        };
        flow.push(PointPair { reference, current: [x, y] });
    }
}

/// The frame's clutter: about `config.clutter` false boxes at random, pushed with no true object.
fn add_clutter(
    config: &SimConfig,
    rng: &mut SimRng,
    class: ClassId,
    detections: &mut Vec<Detection>,
    truth: &mut Vec<Option<u64>>,
) {
    let n_clutter = (config.clutter + rng.uniform(-0.5, 0.5)).round().max(0.0) as usize;
    for _ in 0..n_clutter {
        let w = rng.uniform(40.0, 120.0);
        let x = rng.uniform(0.0, WIDTH - w);
        let y = rng.uniform(100.0, 250.0);
        detections.push(Detection::new(class, 0.4, BBox::new(x, y, x + w, y + 0.6 * w)));
        truth.push(None);
    }
}

/// The mask of the pixels of `b` (pixel centres) for which `visible` holds.
fn visible_mask(b: &BBox, visible: impl Fn(f64, f64) -> bool) -> Mask {
    let mut m = Mask::from_box(b);
    for v in 0..m.height as usize {
        for u in 0..m.width as usize {
            let (x, y) = (m.x0 as f64 + u as f64 + 0.5, m.y0 as f64 + v as f64 + 0.5);
            m.bits[v * m.width as usize + u] = visible(x, y);
        }
    }
    m
}

/// CLEAR-MOT style counts over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MotCounts {
    /// Ground-truth object instances over all frames.
    pub ground_truth: usize,
    /// Objects present but not detected.
    pub misses: usize,
    /// Detections of no object.
    pub false_positives: usize,
    /// Times an object's track differs from the track it had when last detected.
    pub id_switches: usize,
}

impl MotCounts {
    /// `MOTA = 1 − (misses + false positives + ID switches) / ground truth`.
    pub fn mota(&self) -> f64 {
        if self.ground_truth == 0 {
            return 1.0;
        }
        1.0 - (self.misses + self.false_positives + self.id_switches) as f64 / self.ground_truth as f64
    }
}

/// Counts ID switches frame by frame: call [`IdSwitchCounter::frame`] with each detection's true id and
/// assigned track.
#[derive(Debug, Clone, Default)]
pub struct IdSwitchCounter {
    last: BTreeMap<u64, TrackId>,
    /// Switches so far.
    pub switches: usize,
}

impl IdSwitchCounter {
    /// Record one frame: pairs `(true id, assigned track)`.
    pub fn frame(&mut self, pairs: impl IntoIterator<Item = (u64, TrackId)>) {
        for (truth, track) in pairs {
            if let Some(prev) = self.last.insert(truth, track) {
                if prev != track {
                    self.switches += 1;
                }
            }
        }
    }
}

/// Run a tracker over simulated frames and count.
pub fn run(tracker: &mut ObjectTracker, frames: &[SimFrame]) -> MotCounts {
    let mut counts = MotCounts::default();
    let mut ids = IdSwitchCounter::default();
    let projected = BTreeMap::new();
    for f in frames {
        let out = tracker.step(&TrackerInput {
            detections: &f.detections,
            projected: &projected,
            predicted: &projected,
            flow: &f.flow,
            keyframe: true,
        });
        let detected = f.truth.iter().filter(|t| t.is_some()).count();
        counts.ground_truth += f.objects_present;
        counts.misses += f.objects_present - detected;
        counts.false_positives += f.truth.len() - detected;
        ids.frame(f.truth.iter().zip(&out.tracks).filter_map(|(t, k)| Some(((*t)?, (*k)?))));
    }
    counts.id_switches = ids.switches;
    counts
}
