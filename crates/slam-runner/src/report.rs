//! What `slam-app run` writes into its output folder and prints: the files of a finished run, its summary
//! (counts, map, stage times, errors against ground truth, detection guard, unused detections), the
//! object score against labels, and the pictures.

use std::path::Path;

use nalgebra::Isometry3;
use slam_core::TrackState;
use slam_dataset::{
    kitti::{
        raw::OxtsPath,
        stereo::{StereoSequence, TruthSource},
    },
    trajectory::{write_kitti_poses, write_tum},
};
use slam_eval::{
    trajectory_errors::{
        errors_from, interpolated_stretches, largest_step_error, trajectory_errors, INTERPOLATED_TURN_DEG,
    },
    LabelGeometry,
};
use slam_pipeline::{objects::MappedObject, system::RunOutput};

/// The world of a rectified run's trajectory and object files.
pub const RAW_LEFT_WORLD: &str = "world = the raw (unrectified) left camera of the first frame: x right, y down, z forward, metres; poses world from camera";

use crate::{
    error::{Context, Result, RunnerError},
    run::{played_ids, Outcome},
    run_summary::{median_fps, stages_run, tracking_csv},
};

/// Overlay images to draw: every `every`-th frame, as `format` (`png` or `jpg`).
#[derive(Debug, Clone)]
pub struct OverlayChoice {
    /// Draw every n-th frame.
    pub every: u64,
    /// Image format, `png` or `jpg`.
    pub format: String,
}

/// Most frames after the first are not tracked when fewer than this share of them is (tracked, weak or
/// relocalised): then the run looks at its images and says what it saw.
pub const MOSTLY_LOST_SHARE: f64 = 0.5;

impl Outcome {
    /// Frames after the first readable one, and how many of them were tracked (tracked, weak or
    /// relocalised; not lost, predicted or unreadable).
    pub fn tracked_after_first(&self) -> (usize, usize) {
        let c = self.out.counts;
        (c.frames.saturating_sub(c.unreadable + 1), c.tracked + c.weak + c.relocalised)
    }

    /// When most frames after the first were not tracked ([`MOSTLY_LOST_SHARE`]): what the images show
    /// (`slam_frontend::diagnosis`, over up to three readable pairs spread over the run), one sentence
    /// each; empty when the run tracked most frames.
    /// In a loaded map frames not placed are the map's answer (another place), not a fault of the
    /// images: nothing to diagnose.
    pub fn diagnosis(&self) -> Vec<String> {
        let (after, tracked) = self.tracked_after_first();
        if after == 0 || self.loaded.is_some() || tracked as f64 >= MOSTLY_LOST_SHARE * after as f64 {
            return Vec::new();
        }
        let n = self.seq.len();
        let mut positions = vec![0, n / 2, n.saturating_sub(1)];
        positions.dedup();
        let looked: Vec<slam_frontend::diagnosis::PairDiagnosis> = match &self.seq.recording {
            None => positions
                .into_iter()
                .filter_map(|i| slam_frontend::diagnosis::diagnose_pair(&self.seq.left[i], &self.seq.right[i]).ok())
                .collect(),
            Some(_) => {
                // the images as tracked (decoded, rectified), the bit depth of their source
                let mut reader = crate::source::FrameReader::new(&self.seq, self.colour, self.rectifier.clone());
                positions
                    .into_iter()
                    .filter_map(|i| {
                        let (l, r) = reader.pair(i).ok()?;
                        let header = slam_frontend::image_size::image_header(&self.seq.left[i]).unwrap_or(
                            slam_frontend::image_size::ImageHeader {
                                width: l.width,
                                height: l.height,
                                bit_depth: self.source_bit_depth(),
                                format: "ROS image message",
                            },
                        );
                        slam_frontend::diagnosis::diagnose_images(&l, &r, header).ok()
                    })
                    .collect()
            }
        };
        let head = format!("most frames were not tracked ({tracked} of the {after} after the first)");
        let Some(first) = looked.first().copied() else {
            return vec![format!("{head}; no pair of images could be read to say why")];
        };
        // the evidence of every pair looked at: matches summed, the value range the widest seen
        let all = looked.iter().skip(1).fold(first, |mut a, d| {
            a.matches += d.matches;
            a.negative += d.negative;
            a.positive += d.positive;
            a.percentiles = (a.percentiles.0.min(d.percentiles.0), a.percentiles.1.max(d.percentiles.1));
            a
        });
        let findings = all.findings();
        if findings.is_empty() {
            return vec![format!(
                "{head}; the images look usable ({} matches along the rows of {} pairs, {} at positive disparity; grey \
                 values {}-{} of 255): check the calibration (focal length, baseline) and whether consecutive frames \
                 overlap",
                all.matches,
                looked.len(),
                all.positive,
                all.percentiles.0,
                all.percentiles.1
            )];
        }
        findings.into_iter().map(|f| format!("{head}: {f}")).collect()
    }

    /// An error when frames after the first were played and none of them was tracked: the run's output is
    /// written (tracking.csv shows every frame's state), but the run failed. Not for a run in a loaded
    /// map: frames it cannot place there are its answer (the summary says so).
    pub fn nothing_tracked(&self) -> Option<RunnerError> {
        let (after, tracked) = self.tracked_after_first();
        (after > 0 && tracked == 0 && self.loaded.is_none()).then(|| {
            RunnerError::Invalid(format!(
                "no frame after the first of {} was tracked ({after} lost, predicted or relocalising; the diagnosis \
                 above says what the images show)",
                self.seq.dir.display()
            ))
        })
    }

    /// Write the trajectory (KITTI and TUM: one pose per played frame, TUM with the frames' own times),
    /// tracking.csv, map.json and objects.json into `dir`; `shown` is the folder's name in messages.
    pub fn write_files(&self, dir: &Path, shown: &Path) -> Result<()> {
        let out = &self.out;
        // a frame not placed in a loaded map has no pose: left out of both files
        let placed = |k: &usize| out.placed.get(*k).copied().unwrap_or(true);
        let keep: Vec<usize> = (0..out.poses.len()).filter(placed).collect();
        let poses: Vec<Isometry3<f64>> = keep.iter().map(|&k| self.raw_left(&out.poses[k])).collect();
        let times: Vec<f64> = keep.iter().filter_map(|&k| self.seq.times.get(k).copied()).collect();
        write_kitti_poses(dir.join("trajectory.kitti.txt"), &poses)?;
        write_tum(
            dir.join("trajectory.tum.txt"),
            if times.len() == poses.len() { &times } else { &self.seq.times },
            &poses,
        )?;
        let csv = tracking_csv(out).map_err(RunnerError::other)?;
        std::fs::write(dir.join("tracking.csv"), csv)
            .context_with(|| format!("writing {}", dir.join("tracking.csv").display()))?;
        out.map.save(&dir.join("map.json"))?;
        let objects: Vec<MappedObject> = self.objects_in_raw_left();
        let objects: Vec<&MappedObject> = objects.iter().collect();
        let world = if self.rectifier.is_some() { RAW_LEFT_WORLD } else { slam_pipeline::saved_map::MAP_WORLD };
        slam_pipeline::objects::write_object_map_in(&dir.join("objects.json"), &objects, world)
            .context_with(|| format!("writing {}", shown.join("objects.json").display()))?;
        Ok(())
    }

    /// The world from raw-left-camera frame change of a rectified run: `x_raw = Rᵀ x_rectified`, `R` the
    /// rectification's rotation of the left camera (identity without one).
    fn raw_from_rectified(&self) -> Isometry3<f64> {
        match &self.rectifier {
            Some(r) => {
                let rot = nalgebra::Rotation3::from_matrix_unchecked(r.left_rotation.transpose());
                Isometry3::from_parts(
                    nalgebra::Translation3::identity(),
                    nalgebra::UnitQuaternion::from_rotation_matrix(&rot),
                )
            }
            None => Isometry3::identity(),
        }
    }

    /// A tracked camera pose (world from rectified left camera, world = the rectified left camera of the
    /// first frame) as written: the raw left camera's, in the raw left camera of the first frame. The
    /// pose itself without a rectification.
    pub fn raw_left(&self, pose: &Isometry3<f64>) -> Isometry3<f64> {
        if self.rectifier.is_none() {
            return *pose;
        }
        let c = self.raw_from_rectified();
        c * pose * c.inverse()
    }

    /// The objects with their ellipsoids in the world of [`Outcome::raw_left`].
    pub fn objects_in_raw_left(&self) -> Vec<MappedObject> {
        let c = self.raw_from_rectified();
        self.out
            .objects
            .iter()
            .map(|o| {
                let mut o = o.clone();
                if let Some(e) = &mut o.ellipsoid {
                    e.world_from_quadric = c * e.world_from_quadric;
                }
                o
            })
            .collect()
    }

    /// A map point in the world of [`Outcome::raw_left`].
    pub fn point_in_raw_left(&self, p: &nalgebra::Point3<f64>) -> nalgebra::Point3<f64> {
        self.raw_from_rectified() * p
    }

    /// Bits per sample of the images as recorded (16 for a bag of `mono16` images, else 8).
    fn source_bit_depth(&self) -> u8 {
        let deep = self
            .seq
            .recording
            .as_ref()
            .and_then(|r| r.bag.as_ref())
            .is_some_and(|b| b.bag.topic(&b.topics.0).is_some_and(|t| t.layouts.contains("mono16")));
        if deep {
            16
        } else {
            8
        }
    }

    /// The run's summary as printed: speed, counts, tracking states, map, stage table, errors against
    /// ground truth, the detection guard's changes (`max_detections` a frame) and unused detections.
    pub fn summary(&self, max_detections: usize) -> String {
        let (out, c) = (&self.out, self.out.counts);
        let mut lines = vec![
            format!(
                "{} frames in {:.2} s: {:.1} frames/s overall, {} (all threads, incl. image decoding)",
                c.frames,
                self.elapsed,
                c.frames as f64 / self.elapsed,
                match median_fps(out) {
                    Some(f) => format!("{f:.1} frames/s median"),
                    None => "no median frames/s (it needs two tracked frames)".to_string(),
                }
            ),
            format!(
                "keyframes {}, lost {}, relocalised {}, new map segments {}, unreadable {}, detector errors {}, culled observations {}, duplicate or part boxes suppressed {}, ellipsoids of impossible size refused {}, removed for free space seen through them {}",
                c.keyframes, c.lost, c.relocalised, c.new_segments, c.unreadable, c.detector_errors, c.culled_observations, c.suppressed_boxes, c.implausible_fits, c.free_space_removals
            ),
            format!(
                "tracking states: tracked {}, weak {}, relocalised {}, lost {}, predicted {}, unreadable {} (tracking.csv has one row per frame)",
                c.tracked, c.weak, c.relocalised, c.lost, c.predicted, c.unreadable
            ),
        ];
        // what the images show, when most frames were not tracked, goes with the states it explains
        for line in self.diagnosis() {
            tracing::warn!("{line}");
            if let Some(states) = lines.last_mut() {
                states.push_str(&format!("; {line}"));
            }
        }
        let st = out.map.stats();
        let dets: usize = out.frames.iter().map(|f| f.detections.len()).sum();
        lines.push(format!(
            "map: {} keyframes, {} points, {} observations; objects: {} with an ellipsoid ({} dynamic) from {dets} detections",
            st.keyframes, st.points, st.observations, st.objects, st.dynamic_objects
        ));
        lines.push(format!(
            "local mapping: {} points triangulated between keyframes, {} fused into another, {} young points culled, {} keyframes culled as redundant",
            c.triangulated_points, c.fused_points, c.culled_points, c.culled_keyframes
        ));
        lines.push("\n| stage | median ms | frames |\n|---|---:|---:|".into());
        for (name, ms, count) in stages_run(out, self.stages) {
            lines.push(format!("| {name} | {} | {count} |", slam_core::figure::cell(ms, 1)));
        }
        if self.loaded.is_some() {
            lines.extend(self.map_lines());
        } else {
            lines.extend(self.truth_lines());
        }
        if let Some(d) = &self.detections {
            lines.push(d.summary(max_detections));
        }
        for note in &self.notes {
            lines.push(note.clone());
        }
        lines.join("\n")
    }

    /// Errors against the sequence's ground truth (none without it).
    fn truth_lines(&self) -> Vec<String> {
        let mut lines = Vec::new();
        let Some(gt) = self.seq.truth_from_first() else {
            lines.push(
                "\nground truth: none for this sequence, so no ATE/RPE (the odometry layout's poses/NN.txt beside \
                 sequences/, a raw drive's oxts/; the log says what was missing)"
                    .into(),
            );
            return lines;
        };
        let s = Scored::of(&self.out, &gt, &self.seq.ids);
        let Some(e) = trajectory_errors(&s.est, &s.truth, &[10.0, 20.0, 40.0]) else {
            lines.push(format!(
                "\nground truth: no ATE/RPE: {} frame(s) with an estimate to compare (it needs two: unreadable frames \
                 and frames before tracking started are left out)",
                s.est.len().min(s.truth.len())
            ));
            return lines;
        };
        if let Some(TruthSource::Oxts { median_pos_accuracy_m, path }) = self.seq.truth_source {
            lines.push(format!(
                "\nground truth from the drive's OXTS packets (differential GPS + IMU; median position accuracy {median_pos_accuracy_m:.2} m from the packets' pos_accuracy): position errors below that are not meaningful"
            ));
            if let Some(p) = path {
                lines.push(oxts_path_line(&p));
            }
        }
        // drift needs a ground-truth path, the scale an estimate that moves too
        let drift = drift_text(e.end_drift_pct);
        let scale = match e.scale {
            x if x.is_finite() => format!("{x:.4}"),
            _ if e.frames < 3 => format!("– (the alignment needs 3 poses, {} here)", e.frames),
            _ => "– (a path does not move)".to_string(),
        };
        lines.push(format!(
            "\nground truth: path {:.1} m over {} frames; ATE {:.3} m (aligned {:.3} m); end-point drift {drift}; scale {scale}",
            e.path_m, e.frames, e.ate_m, e.ate_aligned_m
        ));
        lines.extend(s.note.clone());
        for (len, t, r, count) in e.rpe {
            lines.push(format!("RPE over {len:.0} m segments ({count}): {t:.2} % translation, {r:.2} deg/100 m"));
        }
        if let Some((err, id)) = s.largest_tracked_step_error() {
            lines.push(format!("largest step error of a frame marked tracked: {err:.3} m (frame {id})"));
        }
        lines.extend(interpolation_lines(&s.est, &s.truth, PoseNames::Frames(&s.ids)));
        lines.extend(self.dead_reckoning_line());
        lines
    }

    /// Errors against a raw drive's INS dead reckoning (its velocities and orientation, no GPS
    /// position), when the sequence has it.
    fn dead_reckoning_line(&self) -> Option<String> {
        Some(format!("{}: {}", DEAD_RECKONING, dead_reckoning_errors(&self.out, &self.seq)?))
    }

    /// Write camera.json (the run's camera, for scoring the objects later).
    pub fn write_camera(&self, dir: &Path) -> Result<()> {
        LabelGeometry::of_sequence(&self.seq, self.image)?.write(&dir.join("camera.json"))?;
        Ok(())
    }

    /// Score the run's objects against its labels, if any: writes objects_score.json and returns the
    /// printed report.
    pub fn score(&self, dir: &Path) -> Result<Option<String>> {
        let Some(score) = self.run_score() else { return Ok(None) };
        score.write_json(&dir.join("objects_score.json"))?;
        Ok(Some(score.report()))
    }

    /// The run's objects scored against its labels (`None` without labels), the association's figures
    /// included.
    pub fn run_score(&self) -> Option<slam_eval::RunScore> {
        let (labels, geometry) = self.labels.as_ref()?;
        let out = &self.out;
        let objects: Vec<slam_eval::ScoredInput> = out
            .objects
            .iter()
            .filter_map(|o| {
                Some(slam_eval::ScoredInput {
                    id: o.id.0,
                    class: o.class.0,
                    ellipsoid: o.ellipsoid?,
                    // this run's detections (a loaded map's object brings earlier runs' first)
                    frames: o.observations[o.earlier.min(o.observations.len())..].iter().map(|x| x.frame).collect(),
                    dynamic: o.dynamic,
                })
            })
            .collect();
        // frames without a pose in the map (a loaded map's, before the run was placed) are not scored
        let (poses, ids) = self.placed_poses(|k| out.frames.get(k).map(|r| r.index));
        let mut score =
            slam_eval::score_run(labels, &poses, &ids, geometry, &objects, &slam_eval::ScoreConfig::default());
        let boxes: Vec<slam_eval::FrameBoxes> = out
            .frames
            .iter()
            .map(|r| (r.index, r.detections.iter().zip(&r.tracks).map(|(d, t)| (d.bbox, t.map(|t| t.0))).collect()))
            .collect();
        score.association = Some(slam_eval::association_score(labels, geometry, &boxes));
        Some(score)
    }

    /// The poses of the frames placed in the map (all frames but a loaded map's unplaced ones), with
    /// `tag(k)` of each (its position `k` among the played frames, mapped).
    fn placed_poses<T>(&self, tag: impl Fn(usize) -> Option<T>) -> (Vec<nalgebra::Isometry3<f64>>, Vec<T>) {
        let out = &self.out;
        (0..out.poses.len())
            .filter(|&k| out.placed.get(k).copied().unwrap_or(true))
            .filter_map(|k| tag(k).map(|t| (out.poses[k], t)))
            .unzip()
    }

    /// The top-down map picture and, when asked, overlay images into `dir/overlays`; returns what was
    /// written, for the summary line.
    pub fn pictures(&self, dir: &Path, overlays: Option<&OverlayChoice>) -> Result<String> {
        let out = &self.out;
        // a map that cannot be drawn is said so; the run's trajectory and maps are written all the same
        // in a loaded map the poses are in the map's frame: the ground truth expressed in the map's world
        // (or none, said why), frames without a pose left out
        let (poses, truth) = match &self.loaded {
            Some(load) => {
                let (poses, ks) = self.placed_poses(Some);
                let gt = match crate::in_map::truth_in_map(&self.seq, load) {
                    Ok((g, _)) => Some(ks.iter().filter_map(|&k| g.get(k).copied()).collect()),
                    Err(why) => {
                        tracing::info!("the map picture draws no ground truth: {why}");
                        None
                    }
                };
                (poses, gt)
            }
            None => (out.poses.clone(), self.seq.truth_from_first()),
        };
        let mut written = match slam_viz::map_picture(&out.map, &poses, truth.as_deref(), dir) {
            Ok(_) => "map.svg, map.png".to_string(),
            Err(slam_viz::VizError::NotDrawable { message }) => {
                tracing::warn!("no map picture: {message}");
                format!("no map picture ({message})")
            }
            Err(e) => return Err(e.into()),
        };
        let Some(o) = overlays else { return Ok(written) };
        let reader =
            std::cell::RefCell::new(crate::source::FrameReader::new(&self.seq, self.colour, self.rectifier.clone()));
        let left = |k: usize| reader.borrow_mut().pair(k).map(|p| p.0);
        let opts =
            slam_viz::OverlayOptions { left: &left, k: self.k, image: self.image, every: o.every, format: &o.format };
        let count = slam_viz::write_overlays(out, &opts, &dir.join("overlays"))?;
        written.push_str(&format!(", {count} overlays in overlays/"));
        Ok(written)
    }

    /// Everything a finished run writes into `dir` (`shown` in messages), in order: the files, camera.json,
    /// the object score, the pictures. The summary and the score report go to `print` as they are made;
    /// returns the last line (what was written, which frames).
    pub fn write_all(
        &self,
        dir: &Path,
        shown: &Path,
        max_detections: usize,
        overlays: Option<&OverlayChoice>,
        print: &mut dyn FnMut(&str),
    ) -> Result<String> {
        self.write_files(dir, shown)?;
        print(&self.summary(max_detections));
        self.write_camera(dir)?;
        let score = self.score(dir)?;
        if let Some(report) = &score {
            print(&format!("\n{report}"));
        }
        let pictures = self.pictures(dir, overlays)?;
        Ok(self.wrote_line(shown, score.is_some(), &pictures))
    }

    /// The last line of a run: what was written where, and which frames.
    pub fn wrote_line(&self, shown: &Path, scored: bool, pictures: &str) -> String {
        format!(
            "\nwrote {}: trajectory.kitti.txt (one line per {}), trajectory.tum.txt (frame times), tracking.csv (one row per played frame), map.json, {}objects.json, camera.json, {}{pictures}; {}",
            shown.display(),
            if self.out.placed.iter().all(|p| *p) { "played frame" } else { "frame placed in the map" },
            if self.out.map.keyframe_features.is_empty() { "" } else { "map.features, " },
            if scored { "objects_score.json, " } else { "" },
            played_ids(&self.seq, &self.selection)
        )
    }
}

/// What the second reference of a raw drive is, for the output.
pub(crate) const DEAD_RECKONING: &str = "against the INS's dead reckoning (its velocity over ground integrated, no GPS position: steadier than the positions over a short stretch, but its direction of travel can differ from the packets' yaw by a few degrees, so the aligned ATE is the figure to read)";

/// Errors of a run against its sequence's INS dead reckoning (none without one): ATE, aligned ATE,
/// end-point drift and the largest step error of a frame marked tracked, as one phrase.
pub(crate) fn dead_reckoning_errors(out: &RunOutput, seq: &StereoSequence) -> Option<String> {
    let dr = seq.dead_reckoned_from_first()?;
    let s = Scored::of(out, &dr, &seq.ids);
    let e = trajectory_errors(&s.est, &s.truth, &[])?;
    let step = s
        .largest_tracked_step_error()
        .map(|(err, id)| format!("; largest step error of a frame marked tracked {err:.3} m (frame {id})"))
        .unwrap_or_default();
    // how far the two references disagree on the same steps: a step error below that cannot be told
    // from the references' own
    let refs = seq
        .truth_from_first()
        .and_then(|gt| {
            let all = vec![true; gt.len().min(dr.len())];
            let (max, k) = largest_step_error(&gt, &dr, &all)?;
            Some(format!(
                "; the GPS positions and this reference differ by up to {max:.3} m on one step of this run (frame {}): step errors below that cannot be told from the references' own",
                seq.ids.get(k).copied().unwrap_or(k)
            ))
        })
        .unwrap_or_default();
    Some(format!(
        "path {:.1} m; ATE {:.3} m (aligned {:.3} m); end-point drift {:.2} %{step}{refs}",
        e.path_m, e.ate_m, e.ate_aligned_m, e.end_drift_pct
    ))
}

/// What names the poses compared in the ground-truth check's lines: their frame ids, or (TUM files,
/// which carry no frame ids) their times.
#[derive(Debug, Clone, Copy)]
pub enum PoseNames<'a> {
    /// Frame id of each pose.
    Frames(&'a [usize]),
    /// Time of each pose, seconds.
    Times(&'a [f64]),
}

impl PoseNames<'_> {
    /// Poses `a` to `b`: `frames 3-11`, `the poses at 0.300-1.100 s`.
    fn span(&self, a: usize, b: usize) -> String {
        match self {
            PoseNames::Frames(ids) => {
                let id = |k: usize| ids.get(k).copied().unwrap_or(k);
                format!("frames {}-{}", id(a), id(b))
            }
            PoseNames::Times(t) => {
                let at = |k: usize| t.get(k).copied().unwrap_or(f64::NAN);
                format!("the poses at {:.3}-{:.3} s", at(a), at(b))
            }
        }
    }

    /// Pose `k`: `frame 11`, `the pose at 1.100 s`.
    fn one(&self, k: usize) -> String {
        match self {
            PoseNames::Frames(ids) => format!("frame {}", ids.get(k).copied().unwrap_or(k)),
            PoseNames::Times(t) => format!("the pose at {:.3} s", t.get(k).copied().unwrap_or(f64::NAN)),
        }
    }
}

/// What the ground-truth check says ([`interpolated_stretches`]): one line per stretch of ground truth
/// that turns by the same rotation every step, and the errors from the end of the last one on.
pub fn interpolation_lines(est: &[Isometry3<f64>], gt: &[Isometry3<f64>], names: PoseNames<'_>) -> Vec<String> {
    let stretches = interpolated_stretches(gt);
    let mut lines: Vec<String> = stretches
        .iter()
        .map(|&(a, b)| {
            format!(
                "ground-truth check: {} turn by the same rotation every step (successive steps differ by less than the test's bound of {INTERPOLATED_TURN_DEG}°; measured driving changes by 0.015° or more from step to step): an interpolated stretch, not a measurement",
                names.span(a, b)
            )
        })
        .collect();
    if let Some(e) = stretches.last().and_then(|&(_, b)| errors_from(est, gt, b, &[]).map(|e| (b, e))) {
        let drift = drift_text(e.1.end_drift_pct);
        lines.push(format!(
            "from {} on (both re-anchored there): path {:.1} m; ATE {:.3} m (aligned {:.3} m); end-point drift {drift}",
            names.one(e.0),
            e.1.path_m,
            e.1.ate_m,
            e.1.ate_aligned_m,
        ));
    }
    lines
}

/// An end-point drift as printed: a percentage, or a dash when the ground truth has no path to divide by.
pub(crate) fn drift_text(pct: f64) -> String {
    if pct.is_finite() {
        format!("{pct:.2} %")
    } else {
        "– (the ground truth does not move)".to_string()
    }
}

/// A run's poses as they are scored against a reference (ground truth, dead reckoning): from the
/// first frame tracking started at (initialised) on, without the unreadable frames (their pose is the
/// frame before's, held, not a measurement), the estimate and the reference both re-anchored at that
/// first frame when it is not the sequence's first. Lost and predicted frames stay: their pose is the
/// run's estimate.
#[derive(Debug, Clone)]
pub struct Scored {
    /// Frame id of each scored pose.
    pub ids: Vec<usize>,
    /// The run's poses scored.
    pub est: Vec<Isometry3<f64>>,
    /// The reference's poses of the same frames.
    pub truth: Vec<Isometry3<f64>>,
    /// Whether each scored frame was marked tracked (the step-error figure).
    pub tracked: Vec<bool>,
    /// What was left out and where both start, when anything was.
    pub note: Option<String>,
}

impl Scored {
    /// The scored poses of `out` against `truth` (one per played frame, from the sequence's first), the
    /// frames named by `ids`.
    pub fn of(out: &RunOutput, truth: &[Isometry3<f64>], ids: &[usize]) -> Self {
        let n = out.poses.len().min(truth.len()).min(out.frames.len());
        let state = |k: usize| out.frames[k].state;
        let first = (0..n).find(|&k| state(k) == Some(TrackState::Initialised)).unwrap_or(0);
        let keep: Vec<usize> = (first..n).filter(|&k| state(k).is_some()).collect();
        let id = |k: usize| ids.get(k).copied().unwrap_or(k);
        let tracked = keep.iter().map(|&k| matches!(state(k), Some(TrackState::Tracked { .. }))).collect();
        let ids_kept: Vec<usize> = keep.iter().map(|&k| id(k)).collect();
        if keep.len() == n {
            // nothing left out: the poses as they are
            return Self {
                ids: ids_kept,
                est: out.poses[..n].to_vec(),
                truth: truth[..n].to_vec(),
                tracked,
                note: None,
            };
        }
        let anchored = |v: &[Isometry3<f64>]| -> Vec<Isometry3<f64>> {
            let origin = v[first].inverse();
            keep.iter().map(|&k| origin * v[k]).collect()
        };
        let unreadable = (first..n).filter(|&k| state(k).is_none()).count();
        let mut left_out = Vec::new();
        if first > 0 {
            left_out.push(format!(
                "the {first} frame{} before frame {}, where tracking started (both trajectories start there)",
                if first == 1 { "" } else { "s" },
                id(first)
            ));
        }
        if unreadable > 0 {
            left_out.push(format!(
                "{unreadable} unreadable frame{}{} (a held pose, not a measurement)",
                if unreadable == 1 { "" } else { "s" },
                if first > 0 { " after it" } else { "" }
            ));
        }
        let note =
            format!("scored over the {} frames tracking estimated; left out: {}", keep.len(), left_out.join(", and "));
        Self { ids: ids_kept, est: anchored(&out.poses), truth: anchored(truth), tracked, note: Some(note) }
    }

    /// The largest translation error of one step between scored frames ending at a frame marked
    /// tracked, and that frame's id (`None` without such a step).
    pub fn largest_tracked_step_error(&self) -> Option<(f64, usize)> {
        largest_step_error(&self.est, &self.truth, &self.tracked).map(|(e, k)| (e, self.ids[k]))
    }
}

/// What the OXTS path check says ([`slam_dataset::kitti::raw::oxts_path_lengths`]), in one line.
pub fn oxts_path_line(p: &OxtsPath) -> String {
    format!(
        "OXTS path check: the GPS positions trace {:.1} m, the INS's velocities {:.1} m ({:+.1} %): scale and end-point drift against these positions are uncertain by about that much",
        p.positions_m,
        p.velocities_m,
        p.position_excess_pct()
    )
}
