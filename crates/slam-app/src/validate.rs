//! Validation at the edge: command-line numbers, settings-file values, calibration and image sizes are
//! checked before any work starts, and every message names the value, what was given and the valid
//! range. Inside the libraries these values are trusted.

use std::path::Path;

use anyhow::{bail, Context};

use crate::config::RunConfig;

/// An interval of valid values, printed in messages as `[lo, hi]`, `(lo, hi]`, ….
#[derive(Debug, Clone, Copy)]
pub struct Range {
    lo: f64,
    hi: f64,
    lo_open: bool,
    hi_open: bool,
}

impl Range {
    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64) -> Self {
        Self { lo, hi, lo_open: false, hi_open: false }
    }
    /// `(lo, hi]`.
    pub const fn above(lo: f64, hi: f64) -> Self {
        Self { lo, hi, lo_open: true, hi_open: false }
    }
    /// `(lo, hi)`.
    pub const fn open(lo: f64, hi: f64) -> Self {
        Self { lo, hi, lo_open: true, hi_open: true }
    }

    fn contains(&self, v: f64) -> bool {
        v.is_finite()
            && (if self.lo_open { v > self.lo } else { v >= self.lo })
            && (if self.hi_open { v < self.hi } else { v <= self.hi })
    }
}

impl std::fmt::Display for Range {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let num = |v: f64| if v.is_infinite() { "∞".to_string() } else { format!("{v}") };
        write!(
            f,
            "{}{}, {}{}",
            if self.lo_open { "(" } else { "[" },
            num(self.lo),
            num(self.hi),
            if self.hi_open || self.hi.is_infinite() { ")" } else { "]" }
        )
    }
}

/// `what` (e.g. `--noise`) must be a finite number in `range`; `unit` is appended to the range.
pub fn number(what: &str, v: f64, range: Range, unit: &str) -> anyhow::Result<()> {
    if range.contains(v) {
        return Ok(());
    }
    let unit = if unit.is_empty() { String::new() } else { format!(" {unit}") };
    bail!("{what} {v}: must be a finite number in {range}{unit}")
}

/// A count `what` must lie in `[lo, hi]`.
pub fn count(what: &str, v: usize, lo: usize, hi: usize) -> anyhow::Result<()> {
    if (lo..=hi).contains(&v) {
        return Ok(());
    }
    if hi == usize::MAX {
        bail!("{what} {v}: must be at least {lo}")
    }
    bail!("{what} {v}: must be an integer in [{lo}, {hi}]")
}

/// Largest square network input accepted, pixels. Memory and time grow with its square (the input blob
/// and every activation map): 320 is the shipped model's size, 2048 keeps a CPU forward pass within a few
/// hundred megabytes; `--input-size 32000` once asked for 23.8 GB.
pub const MAX_INPUT_SIZE: i32 = 2048;

/// Settings values, checked together; `source` names the file (or "defaults") in messages.
pub fn run_config(c: &RunConfig, source: &str) -> anyhow::Result<()> {
    let at = |key: &str| format!("{source}: {key} =");
    let pos = Range::above(0.0, f64::INFINITY);
    let t = &c.tracking;
    // ORB descriptors have 256 bits: a larger Hamming bound accepts everything
    if !(1..=100_000).contains(&t.features) {
        bail!("{} {}: must be an integer in [1, 100000]", at("[tracking] features"), t.features);
    }
    count(&at("[tracking] stereo_hamming"), t.stereo_hamming as usize, 0, 256)?;
    count(&at("[tracking] track_hamming"), t.track_hamming as usize, 0, 256)?;
    // rectified rows agree to a pixel or two; 50 px of slack is no longer stereo matching along a row
    number(&at("[tracking] row_tolerance"), t.row_tolerance, Range::closed(0.0, 50.0), "px")?;
    number(&at("[tracking] depth_range (near)"), t.depth_range.0, pos, "m")?;
    number(
        &at("[tracking] depth_range (far)"),
        t.depth_range.1,
        Range::above(t.depth_range.0.max(0.0), f64::INFINITY),
        "m (beyond near)",
    )?;
    number(&at("[tracking] search_radius"), t.search_radius, Range::above(0.0, 10_000.0), "px")?;
    number(&at("[tracking] ransac_px"), t.ransac_px as f64, Range::above(0.0, 1000.0), "px")?;
    // a pose has 6 degrees of freedom: PnP needs at least 4 points
    count(&at("[tracking] min_inliers"), t.min_inliers, 4, usize::MAX)?;
    number(&at("[tracking] keyframe_inlier_ratio"), t.keyframe_inlier_ratio, Range::closed(0.0, 1.0), "")?;
    count(&at("[tracking] keyframe_max_gap"), t.keyframe_max_gap, 1, usize::MAX)?;
    count(&at("[tracking] local_keyframes"), t.local_keyframes, 0, 1000)?;
    number(&at("[tracking] local_radius"), t.local_radius, Range::above(0.0, 10_000.0), "px")?;
    // a rectification error of more than a few pixels is a wrong calibration, not a correction
    number(&at("[tracking] disparity_offset"), t.disparity_offset, Range::closed(-10.0, 10.0), "px")?;
    number(&at("[tracking] triangulate_parallax_deg"), t.triangulate_parallax_deg, Range::open(0.0, 90.0), "degrees")?;
    let m = &c.mapping;
    count(&at("[mapping] window"), m.window, 1, usize::MAX)?;
    number(&at("[mapping] huber_px"), m.huber_px, pos, "px")?;
    number(&at("[mapping] cull_chi2"), m.cull_chi2, pos, "px²")?;
    number(&at("[mapping] cull_chi2_mono"), m.cull_chi2_mono, pos, "px²")?;
    count(&at("[mapping] iterations"), m.iterations, 1, 100_000)?;
    let o = &c.objects;
    count(&at("[objects] min_views"), o.min_views, 1, usize::MAX)?;
    count(&at("[objects] max_views"), o.max_views, o.min_views.max(1), usize::MAX)
        .context("max_views must be at least min_views")?;
    number(&at("[objects] min_parallax_deg"), o.min_parallax_deg, Range::closed(0.0, 90.0).with_hi_open(), "degrees")?;
    number(&at("[objects] border_margin_px"), o.border_margin_px, Range::closed(0.0, 10_000.0), "px")?;
    count(&at("[objects] refit_every"), o.refit_every, 1, usize::MAX)?;
    number(&at("[objects] dynamic_rms_px"), o.dynamic_rms_px, pos, "px")?;
    number(&at("[objects] dynamic_motion_m"), o.dynamic_motion_m, pos, "m")?;
    number(
        &at("[objects] dynamic_prior_sigmas"),
        o.dynamic_prior_sigmas,
        Range::closed(0.0, f64::INFINITY),
        "(0: off)",
    )?;
    number(&at("[objects] max_depth_m"), o.max_depth_m, pos, "m")?;
    number(&at("[objects] merge_distance_m"), o.merge_distance_m, Range::closed(0.0, f64::INFINITY), "m")?;
    let x = &c.texture;
    number(&at("[texture] max_edge_m"), x.max_edge_m, pos, "m")?;
    number(&at("[texture] min_facing"), x.min_facing, Range::closed(0.0, 1.0), "(|cos|)")?;
    // a Delaunay triangulation needs three points
    count(&at("[texture] min_points"), x.min_points, 3, usize::MAX)?;
    let s = &c.system;
    count(&at("[system] correction_lag"), s.correction_lag, 0, 1000)?;
    count(&at("[system] detect_every"), s.detect_every, 1, usize::MAX)?;
    number(&at("[system] object_core"), s.object_core, Range::above(0.0, 1.0), "(share of the box)")?;
    number(&at("[system] projected_gate"), s.projected_gate, Range::closed(0.0, 1.0), "(IoU; 0: off)")?;
    count(&at("[system] max_detections"), s.max_detections, 1, 10_000)?;
    Ok(())
}

impl Range {
    const fn with_hi_open(mut self) -> Self {
        self.hi_open = true;
        self
    }
}

/// The width and height of an image file, read from its header (PNG) or by decoding it.
pub fn image_size(path: &Path) -> anyhow::Result<(u32, u32)> {
    let mut head = [0u8; 24];
    use std::io::Read;
    let n = std::fs::File::open(path)
        .and_then(|mut f| f.read(&mut head))
        .with_context(|| format!("cannot read image {}", path.display()))?;
    if n == 24 && head[..8] == *b"\x89PNG\r\n\x1a\n" && head[12..16] == *b"IHDR" {
        let w = u32::from_be_bytes([head[16], head[17], head[18], head[19]]);
        let h = u32::from_be_bytes([head[20], head[21], head[22], head[23]]);
        return Ok((w, h));
    }
    let img = slam_frontend::read_image(path, false)?;
    Ok((img.width, img.height))
}

/// Calibration sanity against the image it describes: focal lengths that give a field of view between
/// 1° and 170° (a rectified pinhole image cannot show more; less is a telescope), pixels no more than
/// twice as tall as wide, the principal point inside the image, a baseline in (0, 10] m.
pub fn calibration(
    calib: &Path,
    intrinsics: [f64; 4],
    baseline: f64,
    image: &Path,
    size: (u32, u32),
) -> anyhow::Result<()> {
    let [fx, fy, cx, cy] = intrinsics;
    let (w, h) = (size.0 as f64, size.1 as f64);
    let at = |what: &str| format!("{}: {what}", calib.display());
    let img = format!("{} is {}×{}", image.display(), size.0, size.1);
    let fov = |f: f64, side: f64| 2.0 * (side / (2.0 * f)).atan().to_degrees();
    let f_lo = w / (2.0 * 85f64.to_radians().tan());
    let f_hi = w / (2.0 * 0.5f64.to_radians().tan());
    number(
        &at("focal length fx"),
        fx,
        Range::closed(f_lo, f_hi),
        &format!("px (a field of view of 1°–170° over {img}; given: {:.1}°)", fov(fx, w)),
    )?;
    number(&at("focal length fy"), fy, Range::closed(fx / 2.0, fx * 2.0), "px (within a factor 2 of fx)")?;
    number(&at("principal point cx"), cx, Range::open(0.0, w), &format!("px (inside the image: {img})"))?;
    number(&at("principal point cy"), cy, Range::open(0.0, h), &format!("px (inside the image: {img})"))?;
    number(&at("baseline"), baseline, Range::above(0.0, 10.0), "m")?;
    Ok(())
}

/// A raw drive's calibration declares each camera's rectified image size (`S_rect_0N`): the image must
/// have it. Files without the key (other layouts) are not checked.
pub fn declared_size(calib: &Path, image: &Path, size: (u32, u32)) -> anyhow::Result<()> {
    let Some(cam) = image
        .components()
        .filter_map(|c| c.as_os_str().to_str())
        .find_map(|c| c.strip_prefix("image_").filter(|n| n.len() == 2))
    else {
        return Ok(());
    };
    let Ok(c) = slam_dataset::kitti::calib::Calib::read(calib) else { return Ok(()) };
    let key = format!("S_rect_{cam}");
    if !c.has(&key) {
        return Ok(());
    }
    let v = c.numbers(&key, Some(2))?;
    if (v[0], v[1]) != (size.0 as f64, size.1 as f64) {
        bail!(
            "{}: {key} declares {}×{} images, but {} is {}×{}",
            calib.display(),
            v[0],
            v[1],
            image.display(),
            size.0,
            size.1
        );
    }
    Ok(())
}

/// The first frame with both images on disk (a frame missing in one camera is played as unreadable, so
/// sizes are checked on the first complete pair).
pub fn first_pair<'a>(
    left: &'a [std::path::PathBuf],
    right: &'a [std::path::PathBuf],
) -> anyhow::Result<(&'a Path, &'a Path)> {
    left.iter()
        .zip(right)
        .find(|(l, r)| l.is_file() && r.is_file())
        .map(|(l, r)| (l.as_path(), r.as_path()))
        .with_context(|| {
            let dir = left.first().and_then(|p| p.parent()).map(|p| p.display().to_string()).unwrap_or_default();
            format!("{dir}: no frame has both its left and its right image")
        })
}

/// A stereo pair: both images readable and of the same size (a mismatch names both files).
pub fn stereo_pair(left: &Path, right: &Path) -> anyhow::Result<(u32, u32)> {
    let l = image_size(left)?;
    let r = image_size(right)?;
    if l != r {
        bail!(
            "image sizes differ: left {} is {}×{}, right {} is {}×{} (a stereo pair must have one size)",
            left.display(),
            l.0,
            l.1,
            right.display(),
            r.0,
            r.1
        );
    }
    if l.0 == 0 || l.1 == 0 {
        bail!("{}: empty image ({}×{})", left.display(), l.0, l.1);
    }
    Ok(l)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_print_and_reject_non_finite_values() {
        let e = number("--noise", f64::NAN, Range::closed(0.0, 1.0), "").expect_err("nan").to_string();
        assert_eq!(e, "--noise NaN: must be a finite number in [0, 1]");
        let e = number("x", f64::INFINITY, Range::above(0.0, f64::INFINITY), "m").expect_err("inf").to_string();
        assert_eq!(e, "x inf: must be a finite number in (0, ∞) m");
        assert!(number("x", 0.0, Range::above(0.0, 1.0), "").is_err());
        assert!(number("x", 1.0, Range::open(0.0, 1.0), "").is_err());
        assert!(number("x", 1.0, Range::closed(0.0, 1.0), "").is_ok());
        assert_eq!(count("n", 0, 1, usize::MAX).expect_err("0").to_string(), "n 0: must be at least 1");
        assert_eq!(count("n", 9, 1, 5).expect_err("9").to_string(), "n 9: must be an integer in [1, 5]");
    }

    #[test]
    fn the_defaults_pass_and_every_table_is_checked() {
        run_config(&RunConfig::default(), "defaults").expect("defaults valid");
        let bad: [(&str, &str); 8] = [
            ("[tracking]\nransac_px = nan\n", "[tracking] ransac_px = NaN"),
            ("[tracking]\ndepth_range = [5.0, 2.0]\n", "depth_range (far) = 2"),
            ("[tracking]\nmin_inliers = 2\n", "min_inliers = 2"),
            ("[mapping]\nhuber_px = -1.0\n", "huber_px = -1"),
            ("[objects]\nmin_views = 5\nmax_views = 3\n", "max_views"),
            ("[texture]\nmin_facing = 1.5\n", "min_facing = 1.5"),
            ("[system]\nobject_core = 0.0\n", "object_core = 0"),
            ("[system]\nmax_detections = 0\n", "max_detections = 0"),
        ];
        for (text, want) in bad {
            let c: RunConfig = toml::from_str(text).expect("parses");
            let e = format!("{:#}", run_config(&c, "x.toml").expect_err(text));
            assert!(e.contains("x.toml") && e.contains(want), "{text}: {e}");
        }
    }

    #[test]
    fn calibration_checks_focal_length_principal_point_and_baseline() {
        let (c, i) = (Path::new("calib.txt"), Path::new("000000.png"));
        let size = (1241, 376);
        calibration(c, [718.856, 718.856, 607.19, 185.22], 0.537, i, size).expect("KITTI 06");
        let e = calibration(c, [0.001, 0.001, 607.0, 185.0], 0.5, i, size).expect_err("fx").to_string();
        assert!(e.contains("focal length fx 0.001") && e.contains("field of view"), "{e}");
        let e = calibration(c, [718.0, 718.0, 1500.0, 185.0], 0.5, i, size).expect_err("cx").to_string();
        assert!(e.contains("principal point cx 1500") && e.contains("(0, 1241)"), "{e}");
        let e = calibration(c, [718.0, 718.0, 600.0, 185.0], 0.0, i, size).expect_err("baseline").to_string();
        assert!(e.contains("baseline 0"), "{e}");
        let e = calibration(c, [718.0, 100.0, 600.0, 185.0], 0.5, i, size).expect_err("fy").to_string();
        assert!(e.contains("focal length fy 100"), "{e}");
    }
}
