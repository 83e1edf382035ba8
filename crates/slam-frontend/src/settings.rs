//! The valid ranges of the tracker's settings ([`VoConfig::validate`]), checked before a run starts.

use slam_core::check::{count, number, InvalidValue, Range};

use crate::VoConfig;

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
        number("keyframe_inlier_ratio", self.keyframe_inlier_ratio, Range::closed(0.0, 1.0), "")?;
        count("keyframe_max_gap", self.keyframe_max_gap, 1, usize::MAX)?;
        count("local_keyframes", self.local_keyframes, 0, 1000)?;
        number("local_radius", self.local_radius, Range::above(0.0, 10_000.0), "px")?;
        // a rectification error of more than a few pixels is a wrong calibration, not a correction
        number("disparity_offset", self.disparity_offset, Range::closed(-10.0, 10.0), "px")?;
        // a slip angle beyond 0.5 rad (29°) is a car spinning, not driving
        number("vehicle_slip_rad", self.vehicle_slip_rad, Range::closed(0.0, 0.5), "rad (0: no prior)")?;
        number("vehicle_lever_m (mean)", self.vehicle_lever_m.0, Range::closed(-10.0, 10.0), "m")?;
        number("vehicle_lever_m (σ)", self.vehicle_lever_m.1, Range::closed(0.0, 10.0), "m")?;
        number("vehicle_height_m", self.vehicle_height_m, Range::closed(-5.0, 5.0), "m")?;
        number("triangulate_parallax_deg", self.triangulate_parallax_deg, Range::open(0.0, 90.0), "degrees")?;
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
        let cases: [Case; 6] = [
            (|c| c.features = 0, "features 0: must be an integer in [1, 100000]"),
            (|c| c.ransac_px = f32::NAN, "ransac_px NaN: must be a finite number in (0, 1000] px"),
            (|c| c.depth_range = (5.0, 2.0), "depth_range (far) 2: must be a finite number in (5, ∞) m (beyond near)"),
            (|c| c.min_inliers = 2, "min_inliers 2: must be at least 4"),
            (|c| c.stereo_hamming = 300, "stereo_hamming 300: must be an integer in [0, 256]"),
            (
                |c| c.triangulate_parallax_deg = 90.0,
                "triangulate_parallax_deg 90: must be a finite number in (0, 90) degrees",
            ),
        ];
        for (corrupt, want) in cases {
            let mut c = VoConfig::default();
            corrupt(&mut c);
            assert_eq!(c.validate().expect_err(want).to_string(), want);
        }
    }
}
