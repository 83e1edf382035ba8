//! `stereo-check`: the rig's disparity offset estimated from the sequence itself
//! (`slam_frontend::disparity`). The scan's response to an offset is below one on real images (about 0.7
//! on KITTI 06, docs/system.md), so the offset is found in rounds: track with the offset found so far,
//! estimate the residual, add it, until the residual is below [`DONE_PX`].

use std::path::PathBuf;

use slam_dataset::kitti::stereo::{open_stereo, Layout, StereoSequence};
use slam_frontend::{disparity::OffsetEstimate, read_image, StereoRig, VoConfig};
use slam_quadric::Intrinsics;

use crate::{
    error::{Context, Result, RunnerError},
    run::OptimizerFactory,
};

/// A residual below this (px) ends the rounds: a hundredth of the offsets KITTI rigs show (0.1-0.3 px)
/// changes depths at 20 m by well under 0.1 %.
pub const DONE_PX: f64 = 0.02;

/// What `stereo-check` is asked to do.
#[derive(Clone)]
pub struct StereoCheck {
    /// The sequence folder.
    pub path: PathBuf,
    /// Frames tracked to collect frame pairs (at least 2).
    pub frames: usize,
    /// Largest residual offset scanned either side of zero, px.
    pub range: f64,
    /// Scan step, px.
    pub step: f64,
    /// Most rounds.
    pub rounds: usize,
    /// Tracking settings; its `disparity_offset` is the starting point.
    pub tracking: VoConfig,
    /// The optimiser backend.
    pub optimizer: OptimizerFactory,
}

/// Arguments of `slam-app stereo-check` (a `clap` group with the feature `clap`).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "clap", derive(clap::Args))]
pub struct StereoCheckArgs {
    /// KITTI stereo sequence folder (odometry, raw or tracking layout); default: the shipped sequence.
    pub path: Option<PathBuf>,
    /// Frames tracked to collect frame pairs, from the first (a count, as `run --max-frames`).
    #[cfg_attr(feature = "clap", arg(long = "max-frames", default_value_t = 51))]
    pub frames: usize,
    /// Largest residual offset scanned either side of zero, pixels.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.6))]
    pub range: f64,
    /// Scan step, pixels.
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 0.05))]
    pub step: f64,
    /// Most rounds of (track with the offset found so far, estimate the residual).
    #[cfg_attr(feature = "clap", arg(long, default_value_t = 4))]
    pub rounds: usize,
    /// Print the cost curve of the last round.
    #[cfg_attr(feature = "clap", arg(long))]
    pub curve: bool,
    /// Settings file (its `[tracking]` table is used; its `disparity_offset` is the starting point).
    #[cfg_attr(feature = "clap", arg(long))]
    pub config: Option<PathBuf>,
}

impl StereoCheckArgs {
    /// The whole command: the check of these options on `path` (else `default`), its rounds and its
    /// conclusion, each line given to `print` as it is made.
    pub fn run(&self, default: PathBuf, print: &mut dyn FnMut(&str)) -> Result<()> {
        let cfg = crate::RunConfig::load(self.config.as_deref())?;
        let check = StereoCheck {
            path: self.path.clone().unwrap_or(default),
            frames: self.frames,
            range: self.range,
            step: self.step,
            rounds: self.rounds,
            tracking: cfg.tracking,
            optimizer: std::sync::Arc::new(|| crate::OptimizerKind::default().build()),
        };
        check.validate()?;
        // both callbacks print as the check goes
        let print = std::cell::RefCell::new(print);
        let mut number = 0;
        let report = stereo_check(
            &check,
            &mut |header: &str| (print.borrow_mut())(&format!("{header}\n{ROUND_HEADER}")),
            &mut |round| {
                number += 1;
                (print.borrow_mut())(&round.row(number));
            },
        )?;
        (print.borrow_mut())(&report.conclusion(self.curve));
        Ok(())
    }
}

/// One round: the offset applied while tracking and the residual estimated from its frame pairs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Round {
    /// Offset applied, px.
    pub applied: f64,
    /// Frame pairs used.
    pub pairs: usize,
    /// Correspondences used.
    pub points: usize,
    /// Residual offset estimated, px.
    pub residual: f64,
}

/// The result of `stereo-check`.
#[derive(Debug, Clone)]
pub struct StereoReport {
    /// The sequence's description line (folder, frames, unreadable, fx, baseline).
    pub header: String,
    /// Every round, in order.
    pub rounds: Vec<Round>,
    /// The last round's estimate (with its cost curve).
    pub last: OffsetEstimate,
    /// The offset found, px.
    pub offset: f64,
    /// Focal length times baseline, px·m (for the depth error at 20 m).
    pub fx_baseline: f64,
}

/// The checked sequence and the frames (positions) that can be read.
/// The sequence, its rig, the positions of the frames to use (readable, not repeating an earlier frame's
/// images), the frames looked at, and how many of them repeated an earlier frame.
fn open_checked(c: &StereoCheck) -> Result<(StereoSequence, StereoRig, Vec<usize>, usize, usize)> {
    let seq = open_stereo(&c.path)?;
    crate::run::checked_size(&seq)?;
    let [fx, fy, cx, cy] = seq.intrinsics;
    let rig = StereoRig { k: Intrinsics::new(fx, fy, cx, cy), baseline: seq.baseline };
    let n = c.frames.min(seq.len());
    // stereo-check computes no ATE: a missing ground truth is no news to its user
    for w in seq.warnings.iter().filter(|w| !slam_dataset::kitti::stereo::is_no_truth_warning(w)) {
        tracing::warn!("{w}");
    }
    let colour = seq.layout != Layout::Odometry;
    // a frame whose two images repeat an earlier frame's is no new evidence: the offset's interval comes
    // from the spread over frame pairs, and copies of one view would make it zero (14 copies of one
    // frame gave ± 0.000 px)
    let mut seen = std::collections::HashSet::new();
    let mut repeats = 0usize;
    let readable: Vec<usize> = (0..n)
        .filter(|&i| match read_pair(&seq, i, colour) {
            Ok((l, r)) => {
                use std::hash::{Hash, Hasher};
                let mut h = std::collections::hash_map::DefaultHasher::new();
                (l.width, l.height, &l.data, &r.data).hash(&mut h);
                let new = seen.insert(h.finish());
                repeats += usize::from(!new);
                new
            }
            Err(e) => {
                tracing::warn!(frame = seq.ids[i], "skipped: {e}");
                false
            }
        })
        .collect();
    if repeats > 0 {
        tracing::warn!(
            "{repeats} of {n} frames repeat an earlier frame's images exactly: skipped (a copy is no independent evidence)"
        );
    }
    Ok((seq, rig, readable, n, repeats))
}

fn read_pair(
    seq: &StereoSequence,
    i: usize,
    colour: bool,
) -> std::result::Result<(slam_core::Image, slam_core::Image), slam_frontend::FrontendError> {
    read_image(&seq.left[i], colour).and_then(|l| read_image(&seq.right[i], colour).map(|r| (l, r)))
}

impl StereoCheck {
    /// Range checks, the keys named as the command line names them (`--range`).
    pub fn validate(&self) -> std::result::Result<(), slam_core::check::InvalidValue> {
        use slam_core::check::{count, number, Range};
        count("--max-frames", self.frames, 2, usize::MAX)?;
        // a rectification error of more than 10 px is a wrong calibration, not an offset to estimate
        number("--range", self.range, Range::above(0.0, 10.0), "px")?;
        let step = Range::above(self.range / 10_000.0, self.range);
        number("--step", self.step, step, "px (at most --range, at least --range / 10000)")?;
        count("--rounds", self.rounds, 1, 100)
    }
}

/// Run the rounds; `on_round` sees each round as it finishes (the header first, once).
pub fn stereo_check(
    c: &StereoCheck,
    on_header: &mut dyn FnMut(&str),
    on_round: &mut dyn FnMut(&Round),
) -> Result<StereoReport> {
    c.validate()?;
    let (seq, rig, readable, n, repeats) = open_checked(c)?;
    let header = format!(
        "{}: {n} frames ({} unreadable{}), fx {:.1} px, baseline {:.4} m",
        seq.dir.display(),
        n - readable.len() - repeats,
        if repeats > 0 { format!(", {repeats} repeating an earlier frame's images") } else { String::new() },
        rig.k.fx,
        seq.baseline
    );
    on_header(&header);
    let colour = seq.layout != Layout::Odometry;
    let (mut applied, mut rounds, mut last) = (c.tracking.disparity_offset, Vec::new(), None);
    for _ in 0..c.rounds {
        let mut tracking = c.tracking;
        tracking.keep_disparity_pairs = usize::MAX;
        tracking.disparity_offset = applied;
        // far points carry most of what the disparities say about an offset: the calibration tracks
        // with their disparity at full weight (tracking.far_baselines off)
        tracking.far_baselines = f64::INFINITY;
        let optimizer = (c.optimizer)();
        let mut vo = slam_frontend::Odometry::new(rig, tracking, optimizer.clone())?;
        // images are read again in every round rather than held: a whole sequence would not fit
        for &i in &readable {
            let (l, r) = read_pair(&seq, i, colour).context_with(|| format!("frame {i} became unreadable"))?;
            vo.track(seq.ids[i], &l, &r, &[]).map_err(RunnerError::other)?;
        }
        let e = slam_frontend::disparity::estimate_disparity_offset(
            &rig,
            vo.vo.disparity_pairs(),
            (-c.range, c.range),
            c.step,
            &*optimizer,
        )
        .ok_or_else(|| {
            RunnerError::Invalid(format!("no tracked frame pairs in {n} frames of {}", seq.dir.display()))
        })?;
        if e.pairs < slam_frontend::disparity::MIN_OFFSET_PAIRS {
            return Err(RunnerError::Invalid(format!(
                "{} frame pairs tracked in {n} frames of {}: an offset needs at least {} to say how sure it is (give more frames: --max-frames)",
                e.pairs,
                seq.dir.display(),
                slam_frontend::disparity::MIN_OFFSET_PAIRS
            )));
        }
        let round = Round { applied, pairs: e.pairs, points: e.points, residual: e.offset };
        on_round(&round);
        rounds.push(round);
        let done = e.offset.abs() < DONE_PX || !e.interior;
        applied += e.offset;
        last = Some(e);
        if done {
            break;
        }
    }
    let last = last.ok_or_else(|| RunnerError::Invalid("no rounds ran".into()))?;
    Ok(StereoReport { header, rounds, last, offset: applied, fx_baseline: rig.k.fx * seq.baseline })
}

/// The `stereo-check` table's header (markdown).
pub const ROUND_HEADER: &str =
    "| round | offset applied (px) | frame pairs | correspondences | residual estimate (px) |\n|---:|---:|---:|---:|---:|";

impl Round {
    /// The round's table row (`number` counts from 1).
    pub fn row(&self, number: usize) -> String {
        format!("| {number} | {:+.3} | {} | {} | {:+.3} |", self.applied, self.pairs, self.points, self.residual)
    }
}

impl StereoReport {
    /// What follows the rounds' table: the cost curve when asked, a note when the residual lay at the
    /// end of the scanned range, and the offset found.
    pub fn conclusion(&self, curve: bool) -> String {
        let mut lines = Vec::new();
        if curve {
            let min = self.last.curve.iter().map(|c| c.1).fold(f64::INFINITY, f64::min);
            lines.push("\n| residual offset (px) | robust cost − least |\n|---:|---:|".to_string());
            for (o, c) in &self.last.curve {
                lines.push(format!("| {o:+.3} | {:.2} |", c - min));
            }
        }
        if !self.last.interior {
            lines.push("(the last residual lay at the end of the scanned range: widen --range)".to_string());
        }
        // 95 %: 1.96 standard errors of the last round's residual (the offsets applied before are exact)
        let half = 1.96 * self.last.standard_error;
        lines.push(format!(
            "estimated rig disparity offset: {:+.3} ± {half:.3} px (95 %, from the spread over the last round's {} frame pairs) (tracking.disparity_offset); without it, depths at 20 m err by {:+.2} %",
            self.offset,
            self.last.pairs,
            100.0 * self.offset / (self.fx_baseline / 20.0)
        ));
        if self.offset.abs() < half {
            lines.push(format!(
                "the offset is within its 95 % interval of zero: these frames do not show one (|{:+.3}| < {half:.3} px)",
                self.offset
            ));
        }
        lines.join("\n")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_and_conclusion_read_as_the_table_says() {
        let r = Round { applied: 0.1, pairs: 40, points: 5000, residual: -0.034 };
        assert_eq!(r.row(2), "| 2 | +0.100 | 40 | 5000 | -0.034 |");
        let last = OffsetEstimate {
            offset: -0.034,
            pairs: 40,
            points: 5000,
            interior: false,
            curve: vec![(-0.1, 12.0), (0.0, 10.0), (0.1, 11.5)],
            standard_error: 0.05,
        };
        // fx·b = 386 px·m: at 20 m a disparity of 19.3 px; an offset of 0.193 px is 1 %
        let rep = StereoReport { header: String::new(), rounds: vec![r], last, offset: 0.193, fx_baseline: 386.0 };
        let text = rep.conclusion(true);
        assert!(text.contains("| -0.100 | 2.00 |") && text.contains("| +0.000 | 0.00 |"), "{text}");
        assert!(text.contains("widen --range"), "{text}");
        assert!(text.ends_with("err by +1.00 %"), "{text}");
        assert!(
            text.contains("+0.193 ± 0.098 px (95 %, from the spread over the last round's 40 frame pairs)"),
            "{text}"
        );
        // an offset inside its interval of zero is said to be no offset these frames show
        let unsure = StereoReport { offset: 0.05, ..rep.clone() };
        assert!(unsure.conclusion(false).contains("do not show one"), "{}", unsure.conclusion(false));
        assert!(!rep.conclusion(false).contains("do not show one"));
        assert!(!rep.conclusion(false).contains("robust cost"));
    }
}
