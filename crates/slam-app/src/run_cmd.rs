//! `slam-app run`: stereo odometry on a KITTI odometry sequence, trajectory files and errors.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::Args;
use nalgebra::Isometry3;
use slam_dataset::{
    kitti::odometry::OdometrySequence,
    trajectory::{write_kitti_poses, write_tum},
};
use slam_frontend::{read_image, StereoRig, StereoVo, TrackStatus, VoConfig};
use slam_quadric::Intrinsics;

#[derive(Args, Debug)]
pub struct RunArgs {
    /// A KITTI odometry sequence folder (`sequences/NN`, holding calib.txt, image_0, image_1) or a
    /// dataset root holding `sequences/` (its first sequence is used). Default: the shipped sequence 06.
    path: Option<PathBuf>,
    /// Output folder (trajectory.kitti.txt, trajectory.tum.txt)
    #[arg(long, default_value = "out/run")]
    out: PathBuf,
    /// Take a new keyframe after at most this many frames tracked against the current one
    /// (1 = frame-to-frame odometry).
    #[arg(long, default_value_t = VoConfig::default().keyframe_max_gap as u64, value_parser = clap::value_parser!(u64).range(1..))]
    keyframe_gap: u64,
}

fn find_sequence(path: &Path) -> anyhow::Result<PathBuf> {
    if path.join("calib.txt").is_file() && path.join("image_0").is_dir() {
        return Ok(path.to_path_buf());
    }
    let seqs = path.join("sequences");
    if seqs.is_dir() {
        let mut v: Vec<PathBuf> = std::fs::read_dir(&seqs)
            .with_context(|| format!("cannot list {}", seqs.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.join("calib.txt").is_file())
            .collect();
        v.sort();
        if let Some(first) = v.into_iter().next() {
            return Ok(first);
        }
    }
    bail!("{} is not a KITTI odometry sequence (expected calib.txt and image_0/, or sequences/NN/)", path.display())
}

/// Translational and rotational error over all segments of about `length` metres: mean of
/// `|t_err| / length` (%) and `angle_err / length` (deg/100 m), KITTI's relative-pose error.
fn rpe(est: &[Isometry3<f64>], gt: &[Isometry3<f64>], length: f64) -> Option<(f64, f64)> {
    let n = est.len().min(gt.len());
    let mut dist = vec![0.0; n];
    for i in 1..n {
        dist[i] = dist[i - 1] + (gt[i].translation.vector - gt[i - 1].translation.vector).norm();
    }
    let (mut t_sum, mut r_sum, mut count) = (0.0, 0.0, 0usize);
    for i in 0..n {
        let Some(j) = (i..n).find(|&j| dist[j] - dist[i] >= length) else { break };
        let d_gt = gt[i].inverse() * gt[j];
        let d_est = est[i].inverse() * est[j];
        let err = d_gt.inverse() * d_est;
        t_sum += err.translation.vector.norm() / length;
        r_sum += err.rotation.angle().to_degrees() / length;
        count += 1;
    }
    (count > 0).then(|| (100.0 * t_sum / count as f64, 100.0 * r_sum / count as f64))
}

pub fn run(a: &RunArgs) -> anyhow::Result<()> {
    let path = a.path.clone().unwrap_or_else(|| crate::fixture("kitti_odom_06/sequences/06"));
    let seq_dir = find_sequence(&path)?;
    let seq = OdometrySequence::open(&seq_dir)?;
    if seq.left.is_empty() {
        bail!("no images in {}", seq_dir.join("image_0").display());
    }
    let p0 = seq.p0;
    let rig =
        StereoRig { k: Intrinsics::new(p0[(0, 0)], p0[(1, 1)], p0[(0, 2)], p0[(1, 2)]), baseline: seq.baseline() };
    println!(
        "Stereo odometry on {} ({} frames, fx {:.1}, baseline {:.4} m)",
        seq_dir.display(),
        seq.left.len(),
        rig.k.fx,
        rig.baseline
    );
    let mut vo = StereoVo::new(rig, VoConfig { keyframe_max_gap: a.keyframe_gap as usize, ..VoConfig::default() })?;
    let bar = indicatif::ProgressBar::new(seq.left.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames {per_sec} eta {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut poses = Vec::with_capacity(seq.left.len());
    let (mut lost, mut unreadable) = (0usize, 0usize);
    let mut timings: Vec<[f64; 3]> = Vec::new();
    let start = std::time::Instant::now();
    let mut last = Isometry3::identity();
    let mut keyframes = 0usize;
    for (i, (l, r)) in seq.left.iter().zip(&seq.right).enumerate() {
        let pair = read_image(l, false).and_then(|li| read_image(r, false).map(|ri| (li, ri)));
        let (li, ri) = match pair {
            Ok(p) => p,
            Err(e) => {
                // keep one pose per frame: repeat the last pose, and say so
                tracing::warn!("frame {i}: {e}; pose held");
                unreadable += 1;
                poses.push(last);
                bar.inc(1);
                continue;
            }
        };
        let f = vo.process(&li, &ri).with_context(|| format!("frame {i}"))?;
        if f.status == TrackStatus::Lost {
            lost += 1;
            tracing::warn!("frame {i}: tracking lost; constant-velocity pose");
        }
        timings.push(f.timings_ms);
        keyframes += usize::from(f.keyframe);
        last = f.world_from_camera;
        poses.push(last);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let elapsed = start.elapsed().as_secs_f64();
    std::fs::create_dir_all(&a.out).with_context(|| format!("cannot create {}", a.out.display()))?;
    write_kitti_poses(a.out.join("trajectory.kitti.txt"), &poses)?;
    write_tum(
        a.out.join("trajectory.tum.txt"),
        &seq.times[..poses.len().min(seq.times.len())],
        &poses[..poses.len().min(seq.times.len())],
    )?;
    let median = |k: usize| {
        let mut v: Vec<f64> = timings.iter().map(|t| t[k]).collect();
        v.sort_by(|a, b| a.total_cmp(b));
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    println!(
        "{} frames in {:.2} s ({:.1} frames/s incl. image decoding); keyframes {keyframes}, lost {lost}, unreadable {unreadable}",
        poses.len(),
        elapsed,
        poses.len() as f64 / elapsed
    );
    println!(
        "median ms per frame: extraction {:.1}, stereo matching {:.1}, tracking {:.1}",
        median(0),
        median(1),
        median(2)
    );
    if let Some(gt) = &seq.ground_truth {
        let n = gt.len().min(poses.len());
        let ate = (poses[..n]
            .iter()
            .zip(&gt[..n])
            .map(|(e, g)| (e.translation.vector - g.translation.vector).norm_squared())
            .sum::<f64>()
            / n as f64)
            .sqrt();
        let path_len: f64 =
            gt[..n].windows(2).map(|w| (w[1].translation.vector - w[0].translation.vector).norm()).sum();
        let end = (poses[n - 1].translation.vector - gt[n - 1].translation.vector).norm();
        println!(
            "ground truth: path {path_len:.1} m; ATE (RMS, world = first frame) {ate:.3} m; end-point drift {:.2} %",
            100.0 * end / path_len
        );
        for len in [10.0, 20.0, 40.0] {
            if let Some((t, r)) = rpe(&poses[..n], &gt[..n], len) {
                println!("RPE over {len:.0} m segments: {t:.2} % translation, {r:.2} deg/100 m");
            }
        }
    }
    println!(
        "wrote {} and {}",
        a.out.join("trajectory.kitti.txt").display(),
        a.out.join("trajectory.tum.txt").display()
    );
    Ok(())
}
