//! `depth-check`: the tracker's stereo depth against the Velodyne scans of a KITTI raw drive, a depth
//! reference that is not a trajectory. Each stereo keypoint whose neighbourhood the scan covers with a
//! plane is compared with that plane: a plane's disparity is affine in the image coordinates
//! (`d = f b (n·K⁻¹ [u v 1]ᵀ) / c` for the plane `n·X = c`), so an affine fit of the lidar points'
//! disparities around the keypoint gives the lidar's disparity at the keypoint, and the fit's residual
//! tells a plane from a depth edge (keypoints are corners, many of them on object outlines, where the
//! two sensors see different surfaces).

use std::path::{Path, PathBuf};

use slam_dataset::kitti::{
    raw::RawCalib,
    stereo::{open_stereo, Layout, StereoSequence},
    velodyne::{project_into_left, read_scan, ProjectedPoint},
};
use slam_frontend::{
    read_image,
    stereo_vo::{stereo_keypoints, StereoKeypoint},
    StereoRig, VoConfig,
};
use slam_quadric::Intrinsics;

use crate::error::{Result, RunnerError};

/// Half-width and half-height of the neighbourhood fitted around a keypoint, pixels: the HDL-64E's
/// rows are 0.33–0.5° apart (4–6 px at KITTI's 721 px focal length), its columns 0.09° (about 1 px),
/// so ±4 × ±7 px holds two or three scan rows of a few points each.
const WINDOW_PX: (f64, f64) = (4.0, 7.0);

/// Fewest lidar points of a fit, and fewest distinct scan rows among them (an affine model in two
/// image directions needs points off one line).
const MIN_POINTS: usize = 6;

/// Largest RMS of the affine fit, pixels of disparity, at zero depth noise: a tenth of a pixel, the
/// sub-pixel precision stereo matching aims at; the lidar's own range noise (σ ≈ 2 cm for the HDL-64E)
/// is added in disparity (`d² σ_z / (f b)`, three σ).
const PLANE_RMS_PX: f64 = 0.1;
const LIDAR_SIGMA_M: f64 = 0.02;

/// Which pyramid levels a table column takes.
type LevelFilter = fn(i32) -> bool;

/// Ground-truth baseline of the motion reference's frame pairs, metres: ten stereo baselines, so that
/// a point's depth from the two left images is about ten times better determined than from the stereo
/// pair at the same parallax.
pub const MOTION_BASELINE_M: f64 = 5.0;

/// A motion-reference match lies within this of its epipolar line and reprojects within it in both
/// frames, pixels: a few times the keypoint position noise (half a pixel at level 0).
const EPIPOLAR_PX: f64 = 1.5;

/// Least parallax of a motion-reference point, as a multiple of its stereo parallax (baseline over
/// depth): the reference must be better determined than what it checks.
const PARALLAX_RATIO: f64 = 3.0;

/// Depth bins of the table, metres (lower edges; the last bin is open).
pub const DEPTH_BINS: [f64; 7] = [0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 45.0];

/// One keypoint compared: its pyramid level, depth (lidar), our disparity minus the lidar's, and which
/// half of the image it lies in (`true`: left of the principal point).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthSample {
    /// ORB pyramid level.
    pub level: i32,
    /// Depth from the lidar plane, metres.
    pub depth_m: f64,
    /// Our disparity minus the lidar's, pixels.
    pub diff_px: f64,
    /// Left half of the image.
    pub left_half: bool,
}

/// The comparison over every frame with a scan.
#[derive(Debug, Clone)]
pub struct DepthReport {
    /// The drive folder and its rig.
    pub header: String,
    /// Frames compared (ids) with their stereo keypoints and the keypoints compared.
    pub frames: Vec<(usize, usize, usize)>,
    /// Every comparison.
    pub samples: Vec<DepthSample>,
    /// Focal length times baseline, px·m (disparity = `fx_b` / depth).
    pub fx_b: f64,
}

/// Median and robust σ (1.4826 × the median absolute deviation) of `values`; `None` when empty.
pub fn median_sigma(values: &[f64]) -> Option<(f64, f64)> {
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    };
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    let m = median(&mut v);
    let mut dev: Vec<f64> = values.iter().map(|x| (x - m).abs()).collect();
    Some((m, 1.4826 * median(&mut dev)))
}

/// The lidar's disparity at `(u, v)` from an affine fit of the projected points around it (their
/// disparities `fx_b / z`), when the neighbourhood is a plane (see the module text); `None` otherwise.
pub fn lidar_disparity(near: &[ProjectedPoint], (u, v): (f64, f64), fx_b: f64) -> Option<f64> {
    if near.len() < MIN_POINTS {
        return None;
    }
    let mut rows: Vec<i64> = near.iter().map(|p| (p.v / 3.0).round() as i64).collect();
    rows.sort_unstable();
    rows.dedup();
    if rows.len() < 2 {
        return None;
    }
    // least squares d = a + b (u_i − u) + c (v_i − v) via the normal equations
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    for p in near {
        let row = nalgebra::Vector3::new(1.0, p.u - u, p.v - v);
        ata += row * row.transpose();
        atb += row * (fx_b / p.z);
    }
    let x = ata.try_inverse()? * atb;
    let rms = (near
        .iter()
        .map(|p| {
            let r = fx_b / p.z - (x[0] + x[1] * (p.u - u) + x[2] * (p.v - v));
            r * r
        })
        .sum::<f64>()
        / near.len() as f64)
        .sqrt();
    let d = x[0];
    let tolerance = PLANE_RMS_PX + 3.0 * d * d * LIDAR_SIGMA_M / fx_b;
    (d > 0.0 && rms <= tolerance).then_some(d)
}

/// Compare the stereo keypoints of frames of the sequence at `path` (ids `>= first`, every `stride`-th
/// of those with ground truth) with depths triangulated from the left images alone: each frame is paired
/// with the first later frame [`MOTION_BASELINE_M`] away by the ground truth, its stereo keypoints are
/// matched to that frame's along the epipolar line of the ground-truth motion (Hamming ≤ 50, best
/// below 0.8 × second), and each match with enough parallax ([`PARALLAX_RATIO`]) is triangulated with
/// the ground-truth poses. The reference is as good as the ground truth's relative poses: it needs
/// measured, not interpolated, ground truth.
/// With `external`, the stereo keypoints are read from that folder instead (`NNNNNN.csv` per frame id,
/// [`read_keypoints`]): another front end's keypoints checked against the same reference.
pub fn motion_check(
    path: &Path,
    tracking: &VoConfig,
    (first, stride): (usize, usize),
    external: Option<&Path>,
) -> Result<DepthReport> {
    if let Some(dir) = external.filter(|d| !d.is_dir()) {
        return Err(RunnerError::Invalid(format!("--keypoints {}: not a folder", dir.display())));
    }
    let seq = open_stereo(path)?;
    crate::run::checked_size(&seq)?;
    let truth = seq.truth_from_first().ok_or_else(|| {
        RunnerError::Invalid(format!("{}: depth-check --motion needs ground-truth poses", path.display()))
    })?;
    let [fx, fy, cx, cy] = seq.intrinsics;
    let k = Intrinsics::new(fx, fy, cx, cy);
    let rig = StereoRig { k, baseline: seq.baseline };
    let fx_b = fx * seq.baseline;
    let header = format!(
        "{}: fx {fx:.1} px, baseline {:.4} m; reference: the left images of frame pairs {MOTION_BASELINE_M} m apart by the ground truth",
        seq.dir.display(),
        seq.baseline
    );
    let mut cache: std::collections::HashMap<usize, Vec<slam_frontend::stereo_vo::StereoKeypoint>> = Default::default();
    let mut keypoints_of = |i: usize| -> Result<Vec<slam_frontend::stereo_vo::StereoKeypoint>> {
        if let Some(k) = cache.get(&i) {
            return Ok(k.clone());
        }
        let kp = match external {
            Some(dir) => read_keypoints(&dir.join(format!("{:06}.csv", seq.ids[i])))?,
            None => {
                let left = read_image(&seq.left[i], false).map_err(RunnerError::other)?;
                let right = read_image(&seq.right[i], false).map_err(RunnerError::other)?;
                stereo_keypoints(rig, tracking, &left, &right).map_err(RunnerError::other)?
            }
        };
        cache.insert(i, kp.clone());
        Ok(kp)
    };
    let (mut frames, mut samples) = (Vec::new(), Vec::new());
    let n = seq.ids.len().min(truth.len());
    for i in (0..n).filter(|&i| seq.ids[i] >= first).step_by(stride.max(1)) {
        let Some(j) = (i + 1..n)
            .find(|&j| (truth[j].translation.vector - truth[i].translation.vector).norm() >= MOTION_BASELINE_M)
        else {
            break;
        };
        let (a, b) = (keypoints_of(i)?, keypoints_of(j)?);
        let j_from_i = truth[j].inverse() * truth[i];
        let before = samples.len();
        for p in &a {
            let Some((z, _)) = motion_depth(p, &b, &j_from_i, &k, seq.baseline) else { continue };
            samples.push(DepthSample {
                level: p.level,
                depth_m: z,
                diff_px: p.disparity - fx_b / z,
                left_half: p.u < cx,
            });
        }
        frames.push((seq.ids[i], a.len(), samples.len() - before));
    }
    if frames.is_empty() {
        return Err(RunnerError::Invalid(format!(
            "{}: no frame pair {MOTION_BASELINE_M} m apart with ground truth",
            seq.dir.display()
        )));
    }
    Ok(DepthReport { header, frames, samples, fx_b })
}

/// Stereo keypoints of one frame from a CSV file with a header naming at least the columns `u`, `v`,
/// `octave`, `ur` (right-image column; negative: no stereo match, skipped) and `desc` (the 256-bit
/// descriptor as 64 hex digits); errors name the file and line.
pub fn read_keypoints(path: &Path) -> Result<Vec<slam_frontend::stereo_vo::StereoKeypoint>> {
    let bad = |line: usize, what: String| RunnerError::Invalid(format!("{}:{line}: {what}", path.display()));
    let text = slam_core::files::read_text(path, &slam_core::files::TABLE).map_err(RunnerError::other)?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').map(str::trim).collect();
    let col = |name: &str| header.iter().position(|h| *h == name).ok_or_else(|| bad(1, format!("no column {name}")));
    let (cu, cv, co, cr, cd) = (col("u")?, col("v")?, col("octave")?, col("ur")?, col("desc")?);
    let mut out = Vec::new();
    for (n, line) in lines.enumerate() {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let get = |c: usize| f.get(c).copied().ok_or_else(|| bad(n + 2, format!("only {} fields", f.len())));
        let num = |c: usize| -> Result<f64> {
            get(c)?
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(n + 2, format!("field {} is not a number", c + 1)))
        };
        let (u, v, level, ur) = (num(cu)?, num(cv)?, num(co)? as i32, num(cr)?);
        if ur < 0.0 {
            continue;
        }
        let hex = get(cd)?;
        let mut descriptor = [0u8; 32];
        if hex.len() != 64 {
            return Err(bad(n + 2, "the descriptor is not 64 hex digits".into()));
        }
        for (k, byte) in descriptor.iter_mut().enumerate() {
            *byte = u8::from_str_radix(&hex[2 * k..2 * k + 2], 16)
                .map_err(|_| bad(n + 2, "the descriptor is not hex".into()))?;
        }
        out.push(slam_frontend::stereo_vo::StereoKeypoint { u, v, disparity: u - ur, level, descriptor });
    }
    Ok(out)
}

/// The depth in frame `a` of keypoint `p` of frame `a` from its match among frame `b`'s keypoints
/// along the epipolar line of `b_from_a`, and the match's index; `None` without a clear match, with
/// too little parallax or a reprojection error above [`EPIPOLAR_PX`].
fn motion_depth(
    p: &slam_frontend::stereo_vo::StereoKeypoint,
    b: &[slam_frontend::stereo_vo::StereoKeypoint],
    b_from_a: &nalgebra::Isometry3<f64>,
    k: &Intrinsics,
    baseline: f64,
) -> Option<(f64, usize)> {
    use nalgebra::{Point3, Vector3};
    let ray = |u: f64, v: f64| Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
    let (r, t) = (b_from_a.rotation.to_rotation_matrix().into_inner(), b_from_a.translation.vector);
    // x_bᵀ [t]× R x_a = 0 in normalised coordinates: the line in b of a's ray
    let line_n = t.cross(&(r * ray(p.u, p.v)));
    let line =
        Vector3::new(line_n.x / k.fx, line_n.y / k.fy, line_n.z - line_n.x * k.cx / k.fx - line_n.y * k.cy / k.fy);
    let norm = line.x.hypot(line.y);
    if norm < 1e-12 {
        return None;
    }
    let (mut best, mut second, mut arg) = (u32::MAX, u32::MAX, usize::MAX);
    for (j, q) in b.iter().enumerate() {
        if (line.x * q.u + line.y * q.v + line.z).abs() / norm > EPIPOLAR_PX {
            continue;
        }
        let h = slam_frontend::hamming(&p.descriptor, &q.descriptor);
        if h < best {
            (second, best, arg) = (best, h, j);
        } else if h < second {
            second = h;
        }
    }
    if arg == usize::MAX || best > 50 || (second != u32::MAX && best as f64 >= 0.8 * second as f64) {
        return None;
    }
    let q = &b[arg];
    // midpoint of the two rays in a's frame: a's ray from the origin, b's from its centre
    let da = ray(p.u, p.v).normalize();
    let a_from_b = b_from_a.inverse();
    let centre_b = a_from_b.translation.vector;
    let db = (a_from_b.rotation * ray(q.u, q.v)).normalize();
    let cos = da.dot(&db);
    let den = 1.0 - cos * cos;
    if den < 1e-12 {
        return None;
    }
    let (w_a, w_b) = (da.dot(&centre_b), db.dot(&centre_b));
    let s = (w_a - cos * w_b) / den;
    let u = (cos * w_a - w_b) / den;
    if s <= 0.0 || u <= 0.0 {
        return None;
    }
    let x = 0.5 * (s * da + centre_b + u * db);
    let parallax = cos.clamp(-1.0, 1.0).acos();
    let z = x.z;
    if z <= 1.0 || parallax < PARALLAX_RATIO * baseline / z {
        return None;
    }
    let project = |c: &Point3<f64>| (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
    let (pa, pb) = (project(&Point3::from(x)), project(&(b_from_a * Point3::from(x))));
    if (pa.0 - p.u).hypot(pa.1 - p.v) > EPIPOLAR_PX || (pb.0 - q.u).hypot(pb.1 - q.v) > EPIPOLAR_PX {
        return None;
    }
    Some((z, arg))
}

/// Compare the stereo keypoints of every frame of the raw drive at `path` that has a Velodyne scan,
/// with `tracking`'s stereo settings.
pub fn depth_check(path: &Path, tracking: &VoConfig) -> Result<DepthReport> {
    let seq = open_raw_drive(path)?;
    let date: PathBuf = seq.dir.parent().map(Path::to_path_buf).unwrap_or_default();
    let calib = RawCalib::read(&date)?;
    let [fx, fy, cx, cy] = seq.intrinsics;
    let rig = StereoRig { k: Intrinsics::new(fx, fy, cx, cy), baseline: seq.baseline };
    let fx_b = fx * seq.baseline;
    let mut header = format!("{}: fx {fx:.1} px, baseline {:.4} m", seq.dir.display(), seq.baseline);
    let (mut frames, mut samples) = (Vec::new(), Vec::new());
    // frames without a readable scan (none, or a scan that is no file: a link to /dev/zero) are
    // skipped, each logged with the reason and counted in the header
    let mut no_scan = Vec::new();
    let mut in_image = 0usize;
    for (i, &id) in seq.ids.iter().enumerate() {
        let scan = seq.dir.join("velodyne_points").join("data").join(format!("{id:010}.bin"));
        if let Err(e) = slam_core::files::regular_file(&scan) {
            tracing::warn!(frame = id, "skipped: no Velodyne scan: {e}");
            no_scan.push(id);
            continue;
        }
        let left = read_image(&seq.left[i], false).map_err(RunnerError::other)?;
        let right = read_image(&seq.right[i], false).map_err(RunnerError::other)?;
        let size = (left.width as f64, left.height as f64);
        let keypoints = stereo_keypoints(rig, tracking, &left, &right).map_err(RunnerError::other)?;
        let lidar = project_into_left(&read_scan(&scan)?, &calib, size, 1.0);
        in_image += lidar.len();
        let before = samples.len();
        sample_keypoints(&keypoints, &lidar, size.0, (fx_b, cx), &mut samples);
        frames.push((id, keypoints.len(), samples.len() - before));
    }
    if frames.is_empty() {
        return Err(RunnerError::Invalid(format!(
            "{}: no frame has a Velodyne scan (velodyne_points/data/NNNNNNNNNN.bin)",
            seq.dir.display()
        )));
    }
    if samples.is_empty() {
        // nothing to compare is no result: a table of dashes would read as one
        return Err(RunnerError::Invalid(format!(
            "{}: no stereo keypoint of the {} frames with a scan lies on a lidar plane ({in_image} lidar points fell \
             inside the images in all): nothing to compare; check calib_velo_to_cam.txt (where the lidar is) and \
             calib_cam_to_cam.txt",
            seq.dir.display(),
            frames.len()
        )));
    }
    if let Some(first) = no_scan.first() {
        header.push_str(&format!(
            "; {} of {} frames skipped without a readable Velodyne scan (first: frame {first}; reasons in the log)",
            no_scan.len(),
            seq.ids.len()
        ));
    }
    Ok(DepthReport { header, frames, samples, fx_b })
}

/// The KITTI raw drive at `path` (refused when it is another layout), its images checked for size.
fn open_raw_drive(path: &Path) -> Result<StereoSequence> {
    let seq = open_stereo(path)?;
    if seq.layout != Layout::Raw {
        return Err(RunnerError::Invalid(format!(
            "{}: depth-check needs a KITTI raw drive (…/YYYY_MM_DD_drive_NNNN_sync with velodyne_points/)",
            path.display()
        )));
    }
    crate::run::checked_size(&seq)?;
    Ok(seq)
}

/// One frame's samples: each stereo keypoint against the lidar points projected near it (an image
/// `width` pixels wide; `fx_b` is `fx` times the baseline, `cx` splits the image in halves).
fn sample_keypoints(
    keypoints: &[StereoKeypoint],
    lidar: &[ProjectedPoint],
    width: f64,
    (fx_b, cx): (f64, f64),
    samples: &mut Vec<DepthSample>,
) {
    // bucket the lidar points by pixel column for the window queries
    let mut by_col: Vec<Vec<ProjectedPoint>> = vec![Vec::new(); width as usize + 1];
    for p in lidar {
        by_col[p.u as usize].push(*p);
    }
    for k in keypoints {
        let (lo, hi) = ((k.u - WINDOW_PX.0).max(0.0) as usize, ((k.u + WINDOW_PX.0) as usize).min(by_col.len() - 1));
        let near: Vec<ProjectedPoint> = by_col[lo..=hi]
            .iter()
            .flatten()
            .filter(|p| (p.u - k.u).abs() <= WINDOW_PX.0 && (p.v - k.v).abs() <= WINDOW_PX.1)
            .copied()
            .collect();
        if let Some(d) = lidar_disparity(&near, (k.u, k.v), fx_b) {
            samples.push(DepthSample {
                level: k.level,
                depth_m: fx_b / d,
                diff_px: k.disparity - d,
                left_half: k.u < cx,
            });
        }
    }
}

impl DepthReport {
    /// A cell: median difference and count of the samples `keep` selects.
    fn cell(&self, keep: &dyn Fn(&DepthSample) -> bool) -> String {
        let v: Vec<f64> = self.samples.iter().filter(|s| keep(s)).map(|s| s.diff_px).collect();
        match median_sigma(&v) {
            Some((m, _)) if v.len() >= 5 => format!("{m:+.3} ({})", v.len()),
            _ => format!("– ({})", v.len()),
        }
    }

    /// The header and a line per frame compared: its stereo keypoints and how many were compared with
    /// the reference (`motion`: a motion-triangulated depth, else a lidar plane).
    pub fn frames_text(&self, motion: bool) -> String {
        let what = if motion { "with a motion-triangulated depth" } else { "on a lidar plane" };
        let mut out = self.header.clone();
        for (id, keypoints, compared) in &self.frames {
            out.push_str(&format!("\nframe {id}: {keypoints} stereo keypoints, {compared} {what}"));
        }
        out
    }

    /// The tables: by depth bin and pyramid level (median of our disparity − the lidar's, px, and the
    /// count), then by depth bin with the robust σ, each image half, and the relative depth error.
    pub fn tables(&self) -> String {
        let levels: [(&str, LevelFilter); 6] = [
            ("0", |l| l == 0),
            ("1", |l| l == 1),
            ("2", |l| l == 2),
            ("3", |l| l == 3),
            ("4-7", |l| l >= 4),
            ("all", |_| true),
        ];
        let bin = |b: usize| (DEPTH_BINS[b], DEPTH_BINS.get(b + 1).copied().unwrap_or(f64::INFINITY));
        let in_bin = |s: &DepthSample, b: usize| s.depth_m >= bin(b).0 && s.depth_m < bin(b).1;
        let name = |b: usize| match bin(b).1 {
            e if e.is_finite() => format!("{:.0}-{e:.0} m", bin(b).0),
            _ => format!(">= {:.0} m", bin(b).0),
        };
        let mut out = vec![
            "our disparity − the reference's, px: median (count), by depth and ORB pyramid level".to_string(),
            format!(
                "| depth | {} |\n|---|{}",
                levels.iter().map(|l| format!("level {}", l.0)).collect::<Vec<_>>().join(" | "),
                "---:|".repeat(levels.len())
            ),
        ];
        for b in 0..DEPTH_BINS.len() {
            let cells: Vec<String> = levels.iter().map(|(_, lv)| self.cell(&|s| in_bin(s, b) && lv(s.level))).collect();
            out.push(format!("| {} | {} |", name(b), cells.join(" | ")));
        }
        let all: Vec<String> = levels.iter().map(|(_, lv)| self.cell(&|s| lv(s.level))).collect();
        out.push(format!("| all | {} |", all.join(" | ")));
        out.push(String::new());
        out.push(
            "by depth: median and robust σ of the difference, px; each image half; depth error of the median, %".into(),
        );
        out.push("| depth | count | median px | σ px | left half | right half | depth error % |\n|---|---:|---:|---:|---:|---:|---:|".into());
        for b in 0..DEPTH_BINS.len() {
            let v: Vec<&DepthSample> = self.samples.iter().filter(|s| in_bin(s, b)).collect();
            let diffs: Vec<f64> = v.iter().map(|s| s.diff_px).collect();
            // as in the first table: fewer than five samples say nothing about a bias
            let Some((m, sigma)) = median_sigma(&diffs).filter(|_| diffs.len() >= 5) else { continue };
            let mid: Vec<f64> = v.iter().map(|s| s.depth_m).collect();
            let z = median_sigma(&mid).map_or(f64::NAN, |x| x.0);
            // depth ∝ 1/disparity: a disparity error e at disparity d = f b / z is a depth error −e/d
            out.push(format!(
                "| {} | {} | {m:+.3} | {sigma:.3} | {} | {} | {:+.2} |",
                name(b),
                v.len(),
                self.cell(&|s| in_bin(s, b) && s.left_half),
                self.cell(&|s| in_bin(s, b) && !s.left_half),
                -100.0 * m * z / self.fx_b
            ));
        }
        out.join("\n")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lidar points of the plane `n·X = c` seen through `k`, on three scan rows around `(u0, v0)`.
    fn plane_points(n: [f64; 3], c: f64, (u0, v0): (f64, f64), k: &Intrinsics) -> Vec<ProjectedPoint> {
        let mut out = Vec::new();
        for dv in [-5.0, 0.5, 5.5] {
            for du in [-3.5, -2.0, -0.5, 1.0, 2.5, 3.5] {
                let (u, v) = (u0 + du, v0 + dv);
                let ray = [(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0];
                let z = c / (n[0] * ray[0] + n[1] * ray[1] + n[2] * ray[2]);
                out.push(ProjectedPoint { u, v, z });
            }
        }
        out
    }

    /// A plane's disparity is affine in the image: the fit returns it at the keypoint exactly, for a
    /// wall seen obliquely and for the road; a depth edge (two planes) is refused.
    #[test]
    fn the_affine_fit_gives_a_planes_disparity_and_refuses_an_edge() {
        let k = Intrinsics::new(721.5, 721.5, 609.6, 172.9);
        let fx_b = 721.5 * 0.537;
        for (n, c, at) in [([0.6, 0.0, 0.8], 12.0, (800.0, 150.0)), ([0.0, 1.0, 0.0], 1.65, (500.0, 300.0))] {
            let pts = plane_points(n, c, at, &k);
            let ray = [(at.0 - k.cx) / k.fx, (at.1 - k.cy) / k.fy, 1.0];
            let z = c / (n[0] * ray[0] + n[1] * ray[1] + n[2] * ray[2]);
            let d = lidar_disparity(&pts, at, fx_b).expect("a plane");
            assert!((d - fx_b / z).abs() < 1e-9, "{d} vs {}", fx_b / z);
        }
        // the left half at 10 m, the right half at 25 m
        let mut edge = plane_points([0.0, 0.0, 1.0], 10.0, (600.0, 150.0), &k);
        for p in edge.iter_mut().filter(|p| p.u > 600.0) {
            p.z = 25.0;
        }
        assert!(lidar_disparity(&edge, (600.0, 150.0), fx_b).is_none());
        // one scan row is not enough to fit a plane
        let row: Vec<ProjectedPoint> =
            (0..8).map(|i| ProjectedPoint { u: 600.0 + i as f64, v: 150.0, z: 10.0 }).collect();
        assert!(lidar_disparity(&row, (603.0, 150.0), fx_b).is_none());
    }

    #[test]
    fn median_and_robust_sigma() {
        assert_eq!(median_sigma(&[]), None);
        let (m, s) = median_sigma(&[1.0, 2.0, 3.0, 4.0, 100.0]).expect("values");
        assert_eq!(m, 3.0);
        assert!((s - 1.4826).abs() < 1e-12, "{s}");
        assert_eq!(median_sigma(&[1.0, 3.0]).map(|x| x.0), Some(2.0));
    }

    /// The shipped drive: every scan frame compared, hundreds of keypoints on lidar planes, and our
    /// disparities within a pixel of the lidar's in the median of every populated depth bin.
    #[test]
    fn the_shipped_drive_is_compared_frame_by_frame() {
        let drive = PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../fixtures/kitti_raw_0005/2011_09_26/2011_09_26_drive_0005_sync"
        ));
        let r = depth_check(&drive, &VoConfig::default()).expect("compared");
        assert_eq!(r.frames.iter().map(|f| f.0).collect::<Vec<_>>(), [0, 1, 2, 3, 4]);
        assert!(r.samples.len() > 300, "{}", r.samples.len());
        let (m, _) = median_sigma(&r.samples.iter().map(|s| s.diff_px).collect::<Vec<_>>()).expect("samples");
        assert!(m.abs() < 0.5, "median {m}");
        let t = r.tables();
        assert!(t.contains("| 10-15 m |") && t.contains("level 4-7"), "{t}");
        let odometry = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/kitti_odom_06/sequences/06"));
        let e = depth_check(&odometry, &VoConfig::default()).expect_err("no lidar there");
        assert!(e.to_string().contains("raw drive"), "{e}");
    }
}
