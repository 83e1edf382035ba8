//! Validation at the edge: command-line numbers, settings-file values, calibration and image sizes are
//! checked before any work starts, and every message names the value, what was given and the valid
//! range. Inside the libraries these values are trusted.

use anyhow::{bail, Context};

use crate::config::RunConfig;

pub use slam_dataset::check::{count, number, Range};

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
    number(&at("[objects] dynamic_motion_sigmas"), o.dynamic_motion_sigmas, pos, "σ")?;
    number(
        &at("[objects] dynamic_prior_sigmas"),
        o.dynamic_prior_sigmas.unwrap_or(0.0),
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
    number(&at("[system] projected_gate"), s.projected_gate.unwrap_or(0.0), Range::closed(0.0, 1.0), "(IoU; 0: off)")?;
    count(&at("[system] max_detections"), s.max_detections, 1, 10_000)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
