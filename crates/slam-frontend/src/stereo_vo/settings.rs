//! The valid ranges of the tracker's settings ([`VoConfig::validate`]), checked before a run starts.

use slam_core::check::{count, number, InvalidValue, Range};

use super::config::VoConfig;

impl VoConfig {
    /// Check every range-limited setting; the error names the field (e.g. `ransac_px`, or
    /// `depth_range (far)` for one end of a pair).
    pub fn validate(&self) -> Result<(), InvalidValue> {
        let pos = Range::above(0.0, f64::INFINITY);
        if !(1..=100_000).contains(&self.features) {
            let valid = "an integer in [1, 100000]".to_string();
            return Err(InvalidValue { key: "features".into(), value: self.features.to_string(), valid });
        }
        // ORB descriptors have 256 bits: a larger Hamming bound accepts everything
        count("stereo_hamming", self.stereo_hamming as usize, 0, 256)?;
        count("track_hamming", self.track_hamming as usize, 0, 256)?;
        // rectified rows agree to a pixel or two; 50 px of slack is no longer stereo matching along a row
        number("row_tolerance", self.row_tolerance, Range::closed(0.0, 50.0), "px")?;
        number("depth_range (near)", self.depth_range.0, pos, "m")?;
        let far = Range::above(self.depth_range.0.max(0.0), f64::INFINITY);
        number("depth_range (far)", self.depth_range.1, far, "m (beyond near)")?;
        number("search_radius", self.search_radius, Range::above(0.0, 10_000.0), "px")?;
        number("ransac_px", self.ransac_px as f64, Range::above(0.0, 1000.0), "px")?;
        // a pose has 6 degrees of freedom: PnP needs at least 4 points
        count("min_inliers", self.min_inliers, 4, usize::MAX)?;
        // a weak frame has fewer inliers than a tracked one, still enough for PnP
        count("weak_inliers", self.weak_inliers, 4, self.min_inliers.max(4)).map_err(|e| InvalidValue {
            valid: format!(
                "an integer in [4, min_inliers ({})] (lowering min_inliers below it, lower weak_inliers too)",
                self.min_inliers
            ),
            ..e
        })?;
        // cells of a 4 × 4 grid
        count("min_spread_cells", self.min_spread_cells, 0, 16)?;
        number("max_rms_px", self.max_rms_px, Range::above(0.0, 1000.0), "px")?;
        // 0: from the sequence's times; a frame period of minutes is no longer video
        number("frame_period_s", self.frame_period_s, Range::closed(0.0, 60.0), "s (0: from the sequence)")?;
        // limits of a road vehicle's motion, with room for any vehicle a camera rides on (10 g, 1000 km/h)
        number("max_acceleration", self.max_acceleration, Range::above(0.0, 100.0), "m/s²")?;
        number("max_angular_acceleration", self.max_angular_acceleration, Range::above(0.0, 100.0), "rad/s²")?;
        number("max_speed", self.max_speed, Range::above(0.0, 300.0), "m/s")?;
        number("step_tolerance_m", self.step_tolerance_m, Range::closed(0.0, 100.0), "m")?;
        number("rotation_tolerance_rad", self.rotation_tolerance_rad, Range::closed(0.0, std::f64::consts::PI), "rad")?;
        // `1e9` (a finite number) weights every point alike
        number("far_baselines", self.far_baselines, pos, "baselines")?;
        number("max_lost_s", self.max_lost_s, Range::closed(0.0, 3600.0), "s")?;
        let share = "(share of the reference keyframe's points)";
        number("keyframe_tracked_ratio", self.keyframe_tracked_ratio, Range::closed(0.0, 1.0), share)?;
        // a view holds a few thousand keypoints at most
        count("keyframe_near_points (tracked)", self.keyframe_near_points.0, 0, 100_000)?;
        count("keyframe_near_points (not in the map)", self.keyframe_near_points.1, 0, 100_000)?;
        count("keyframe_max_gap", self.keyframe_max_gap, 0, usize::MAX)?;
        count("flow_points_per_region", self.flow_points_per_region, 0, 100_000)?;
        // the local map needs the reference keyframe at least
        count("local_keyframes", self.local_keyframes, 1, 1000)?;
        count("local_neighbours", self.local_neighbours, 0, 1000)?;
        number("local_radius", self.local_radius, Range::above(0.0, 10_000.0), "px")?;
        // a rectification error of more than a few pixels is a wrong calibration, not a correction
        number("disparity_offset", self.disparity_offset, Range::closed(-10.0, 10.0), "px")?;
        // a slip angle beyond 0.5 rad (29°) is a car spinning, not driving
        number("vehicle_slip_rad", self.vehicle_slip_rad, Range::closed(0.0, 0.5), "rad (0: no prior)")?;
        number("vehicle_lever_m (mean)", self.vehicle_lever_m.0, Range::closed(-10.0, 10.0), "m")?;
        number("vehicle_lever_m (σ)", self.vehicle_lever_m.1, Range::closed(0.0, 10.0), "m")?;
        number("vehicle_height_m", self.vehicle_height_m, Range::closed(-5.0, 5.0), "m")?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_pass_and_each_bad_value_is_named() {
        VoConfig::default().validate().expect("defaults valid");
        type Case = (fn(&mut VoConfig), &'static str);
        let cases: [Case; 11] = [
            (|c| c.features = 0, "features 0: must be an integer in [1, 100000]"),
            (|c| c.ransac_px = f32::NAN, "ransac_px NaN: must be a finite number in (0, 1000] px"),
            (|c| c.depth_range = (5.0, 2.0), "depth_range (far) 2: must be a finite number in (5, ∞) m (beyond near)"),
            (|c| c.min_inliers = 2, "min_inliers 2: must be at least 4"),
            (|c| c.stereo_hamming = 300, "stereo_hamming 300: must be an integer in [0, 256]"),
            (|c| c.local_keyframes = 0, "local_keyframes 0: must be an integer in [1, 1000]"),
            (
                |c| c.weak_inliers = 40,
                "weak_inliers 40: must be an integer in [4, min_inliers (30)] (lowering min_inliers below it, lower weak_inliers too)",
            ),
            (|c| c.max_rms_px = f64::NAN, "max_rms_px NaN: must be a finite number in (0, 1000] px"),
            (|c| c.max_speed = -5.0, "max_speed -5: must be a finite number in (0, 300] m/s"),
            (
                |c| c.keyframe_tracked_ratio = 7.0,
                "keyframe_tracked_ratio 7: must be a finite number in [0, 1] (share of the reference keyframe's points)",
            ),
            (
                |c| c.frame_period_s = -1.0,
                "frame_period_s -1: must be a finite number in [0, 60] s (0: from the sequence)",
            ),
        ];
        for (corrupt, want) in cases {
            let mut c = VoConfig::default();
            corrupt(&mut c);
            assert_eq!(c.validate().expect_err(want).to_string(), want);
        }
    }
}
