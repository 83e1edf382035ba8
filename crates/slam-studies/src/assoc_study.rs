//! The association studies of `slam-app assoc`: totals over simulated scenes ([`simulated_totals`],
//! the scene variants of [`sim_variants`]), and ID switches on labelled boxes played as detections, with
//! box noise and dropout ([`id_switches_on_labels`]), under the study's [`CONDITIONS`]
//! ([`label_study`]). The two associators compared are [`compared_associators`].

use std::collections::BTreeMap;

use slam_core::{geometry::BBox, Associator, Detection};

use slam_assoc::{IouAssociator, ObjectTracker, Oda, TrackerConfig, TrackerInput};

use crate::assoc_sim::{run, simulate, IdSwitchCounter, MotCounts, SimConfig, SimRng};

/// Builds a fresh associator.
pub type MakeAssociator = fn() -> Box<dyn Associator>;

/// The associators the studies compare, with their column names: ODA (the paper's) and IoU-only (the
/// baseline), each with its default settings.
pub fn compared_associators() -> [(&'static str, MakeAssociator); 2] {
    [("ODA", || Box::new(Oda::default())), ("IoU", || Box::new(IouAssociator::default()))]
}

/// The simulated scene variants of the study, each `frames` long: the default scene (masks, 5-12
/// px/frame), boxes without masks, slower objects, and a scene without dropout and clutter.
pub fn sim_variants(frames: usize) -> [(&'static str, SimConfig); 4] {
    [
        ("masks, 5-12 px/frame", SimConfig { frames, ..SimConfig::default() }),
        ("boxes only", SimConfig { frames, masks: false, ..SimConfig::default() }),
        ("slow, 2-7 px/frame", SimConfig { frames, speed: (2.0, 7.0), ..SimConfig::default() }),
        ("no dropout, no clutter", SimConfig { frames, dropout: 0.0, clutter: 0.0, ..SimConfig::default() }),
    ]
}

/// CLEAR-MOT counts summed over the simulated scenes of seeds `0..scenes`, each tracked by a fresh
/// tracker around `make()`.
pub fn simulated_totals(config: &SimConfig, scenes: u64, make: impl Fn() -> Box<dyn Associator>) -> MotCounts {
    let mut total = MotCounts::default();
    for seed in 0..scenes {
        let frames = simulate(config, seed);
        let mut tracker = ObjectTracker::new(make(), TrackerConfig::default());
        let c = run(&mut tracker, &frames);
        total.ground_truth += c.ground_truth;
        total.misses += c.misses;
        total.false_positives += c.false_positives;
        total.id_switches += c.id_switches;
    }
    total
}

/// Labelled boxes per frame: `(true object id, detection)`.
pub type LabelledFrames = BTreeMap<usize, Vec<(u64, Detection)>>;

/// How labelled boxes are perturbed before they are played as detections.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxNoise {
    /// σ of each box coordinate as a fraction of the box width / height.
    pub noise_frac: f64,
    /// Probability of dropping a box.
    pub dropout: f64,
}

/// What [`id_switches_on_labels`] counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LabelRun {
    /// ID switches.
    pub id_switches: usize,
    /// Detections played (after the dropout).
    pub detections: usize,
}

/// The simulated study's table (`slam-app assoc sim`): every [`sim_variants`] scene type over
/// `scenes` seeds of `frames` frames, ID switches and MOTA of both [`compared_associators`]; each line
/// goes to `print`.
pub fn simulated_table(scenes: u64, frames: usize, print: &mut dyn FnMut(String)) {
    print(format!("Simulated association, {scenes} scenes x {frames} frames, 8 objects of one class in two lanes"));
    print(format!("{:<24} {:>10} {:>8} {:>10} {:>8}", "scene", "ODA IDSW", "ODA MOTA", "IoU IDSW", "IoU MOTA"));
    for (name, cfg) in sim_variants(frames) {
        let [oda, iou] = compared_associators().map(|(_, make)| simulated_totals(&cfg, scenes, make));
        print(format!(
            "{name:<24} {:>10} {:>8.4} {:>10} {:>8.4}",
            oda.id_switches,
            oda.mota(),
            iou.id_switches,
            iou.mota()
        ));
    }
}

/// Play frames `0..n_frames` of labelled boxes (perturbed by `noise`, from one random stream seeded by
/// `seed`) through a fresh tracker around `associator`, with the true ids hidden, and count ID switches.
/// Only the Kalman prediction is available as a cue (no images: no flow, no ellipsoids).
pub fn id_switches_on_labels(
    frames: &LabelledFrames,
    n_frames: usize,
    noise: BoxNoise,
    seed: u64,
    associator: Box<dyn Associator>,
) -> LabelRun {
    let mut rng = SimRng::new(seed);
    let mut tracker = ObjectTracker::new(associator, TrackerConfig::default());
    let mut ids = IdSwitchCounter::default();
    let mut n_det = 0;
    let projected = BTreeMap::new();
    let mut f = 0;
    while f < n_frames {
        // a frame without labels while no track is alive changes nothing: go to the next labelled frame,
        // so the cost follows the labels, not the largest frame id
        if tracker.tracks().is_empty() && !frames.contains_key(&f) {
            f = frames.range(f..).next().map_or(n_frames, |(&next, _)| next);
            continue;
        }
        let mut truth = Vec::new();
        let mut dets = Vec::new();
        for (id, d) in frames.get(&f).map(|v| v.as_slice()).unwrap_or(&[]) {
            if rng.unit() < noise.dropout {
                continue;
            }
            let b = d.bbox;
            let (sx, sy) = (noise.noise_frac * b.width(), noise.noise_frac * b.height());
            let nb = BBox::new(
                b.xmin + sx * rng.normal(),
                b.ymin + sy * rng.normal(),
                b.xmax + sx * rng.normal(),
                b.ymax + sy * rng.normal(),
            );
            let nb = if nb.validated().is_ok() { nb } else { b };
            dets.push(Detection::new(d.class, 1.0, nb));
            truth.push(*id);
        }
        n_det += dets.len();
        let out = tracker.step(&TrackerInput {
            detections: &dets,
            projected: &projected,
            predicted: &projected,
            flow: &[],
            keyframe: true,
        });
        ids.frame(truth.iter().zip(&out.tracks).filter_map(|(t, k)| Some((*t, (*k)?))));
        f += 1;
    }
    LabelRun { id_switches: ids.switches, detections: n_det }
}

/// One perturbation of the labelled-boxes study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Condition {
    /// Column name.
    pub name: &'static str,
    /// The perturbation.
    pub noise: BoxNoise,
}

/// The conditions of the labelled-boxes study: clean boxes, 5 % box noise, and 5 % noise with 20 %
/// of the boxes dropped.
pub const CONDITIONS: [Condition; 3] = [
    Condition { name: "clean", noise: BoxNoise { noise_frac: 0.0, dropout: 0.0 } },
    Condition { name: "noise 5%", noise: BoxNoise { noise_frac: 0.05, dropout: 0.0 } },
    Condition { name: "noise 5% + drop 20%", noise: BoxNoise { noise_frac: 0.05, dropout: 0.2 } },
];

/// Labelled boxes grouped by frame from `(frame, track id, class, box)` rows; rows without a class or
/// with a negative track id (KITTI's DontCare) are left out. Returns the frames, the frame count
/// (one past the last labelled frame) and the number of distinct objects.
pub fn labelled_frames(
    rows: impl IntoIterator<Item = (usize, i64, Option<slam_core::ClassId>, BBox)>,
) -> (LabelledFrames, usize, usize) {
    let mut frames = LabelledFrames::new();
    let (mut n_frames, mut objects) = (0, std::collections::BTreeSet::new());
    for (frame, track, class, bbox) in rows {
        n_frames = n_frames.max(frame.saturating_add(1));
        if let (Some(class), true) = (class, track >= 0) {
            frames.entry(frame).or_default().push((track as u64, Detection::new(class, 1.0, bbox)));
            objects.insert(track);
        }
    }
    (frames, n_frames, objects.len())
}

/// One sequence of labelled boxes under every [`CONDITIONS`] entry and with every
/// [`compared_associators`] entry: `[condition][associator]`. Condition `i` draws its noise from seed
/// `seed * 1000 + i`, the same stream for both associators.
pub fn label_study(frames: &LabelledFrames, n_frames: usize, seed: u64) -> Vec<[LabelRun; 2]> {
    CONDITIONS
        .iter()
        .enumerate()
        .map(|(ci, cond)| {
            let seed = seed.wrapping_mul(1000).wrapping_add(ci as u64);
            compared_associators().map(|(_, make)| id_switches_on_labels(frames, n_frames, cond.noise, seed, make()))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use slam_assoc::{IouAssociator, Oda};
    use slam_core::ClassId;

    /// Two cars driving apart, one box each per frame.
    fn two_cars(n: usize) -> LabelledFrames {
        (0..n)
            .map(|f| {
                let x = 4.0 * f as f64;
                let a = Detection::new(ClassId(2), 1.0, BBox::new(100.0 + x, 100.0, 160.0 + x, 150.0));
                let b = Detection::new(ClassId(2), 1.0, BBox::new(700.0 - x, 120.0, 770.0 - x, 170.0));
                (f, vec![(1, a), (2, b)])
            })
            .collect()
    }

    #[test]
    fn clean_separate_tracks_keep_their_ids_and_dropout_drops_boxes() {
        let frames = two_cars(30);
        let clean = BoxNoise { noise_frac: 0.0, dropout: 0.0 };
        for make in [|| Box::new(Oda::default()) as Box<dyn Associator>, || Box::new(IouAssociator::default()) as _] {
            let r = id_switches_on_labels(&frames, 30, clean, 1, make());
            assert_eq!(r, LabelRun { id_switches: 0, detections: 60 });
        }
        let dropped =
            id_switches_on_labels(&frames, 30, BoxNoise { noise_frac: 0.0, dropout: 0.5 }, 1, Box::new(Oda::default()));
        assert!(dropped.detections > 10 && dropped.detections < 50, "{dropped:?}");
        // the same seed gives the same run
        assert_eq!(
            dropped,
            id_switches_on_labels(&frames, 30, BoxNoise { noise_frac: 0.0, dropout: 0.5 }, 1, Box::new(Oda::default()))
        );
    }

    #[test]
    fn simulated_totals_sum_the_scenes() {
        let config = SimConfig { frames: 40, ..SimConfig::default() };
        let make = || Box::new(Oda::default()) as Box<dyn Associator>;
        let one = simulated_totals(&config, 1, make);
        let two = simulated_totals(&config, 2, make);
        let second = run(&mut ObjectTracker::new(make(), TrackerConfig::default()), &simulate(&config, 1));
        assert_eq!(two.ground_truth, one.ground_truth + second.ground_truth);
        assert_eq!(two.id_switches, one.id_switches + second.id_switches);
        assert!(one.ground_truth > 0);
    }

    #[test]
    fn labelled_frames_drop_unclassed_and_dontcare_rows_and_count_objects() {
        let b = BBox::new(10.0, 10.0, 50.0, 40.0);
        let rows =
            [(0, 1, Some(ClassId(2)), b), (0, -1, Some(ClassId(2)), b), (3, 2, None, b), (4, 1, Some(ClassId(2)), b)];
        let (frames, n_frames, objects) = labelled_frames(rows);
        assert_eq!(n_frames, 5, "the last frame counts even when its row is dropped");
        assert_eq!(objects, 1);
        assert_eq!(frames.keys().copied().collect::<Vec<_>>(), [0, 4]);
        assert_eq!(frames[&0].len(), 1);
    }

    #[test]
    fn the_label_study_runs_every_condition_with_both_associators_on_their_own_seeds() {
        let frames = two_cars(30);
        let runs = label_study(&frames, 30, 7);
        assert_eq!(runs.len(), CONDITIONS.len());
        // clean boxes: every box played, no switch, for both associators
        assert_eq!(runs[0], [LabelRun { id_switches: 0, detections: 60 }; 2]);
        // the dropout condition draws from seed 7 * 1000 + 2, the same for both associators
        let direct = id_switches_on_labels(&frames, 30, CONDITIONS[2].noise, 7002, Box::new(IouAssociator::default()));
        assert_eq!(runs[2][1], direct);
        assert!(runs[2][0].detections < 60 && runs[2][0].detections == direct.detections);
    }
}
