//! Validation at the edge: command-line numbers, settings-file values, calibration and image sizes are
//! checked before any work starts, and every message names the value, what was given and the valid
//! range. Inside the libraries these values are trusted.

use crate::config::RunConfig;

pub use slam_dataset::check::{count, number, Range};

/// Largest square network input accepted, pixels. Memory and time grow with its square (the input blob
/// and every activation map): 320 is the shipped model's size, 2048 keeps a CPU forward pass within a few
/// hundred megabytes; `--input-size 32000` once asked for 23.8 GB.
pub const MAX_INPUT_SIZE: i32 = 2048;

/// A library setting's error under its command-line flag (`min_frames` → `--min-frames`).
pub fn flag(e: slam_core::check::InvalidValue) -> slam_core::check::InvalidValue {
    let key = format!("--{}", e.key.replace('_', "-"));
    e.rename(key)
}

/// Settings values, checked table by table by the libraries' `validate()`; `source` names the file (or
/// "defaults") and the table in messages.
pub fn run_config(c: &RunConfig, source: &str) -> anyhow::Result<()> {
    let at = |table: &'static str| {
        move |e: slam_core::check::InvalidValue| {
            let key = format!("{source}: [{table}] {} =", e.key);
            e.rename(key)
        }
    };
    c.tracking.validate().map_err(at("tracking"))?;
    c.mapping.validate().map_err(at("mapping"))?;
    c.objects.validate().map_err(at("objects"))?;
    c.texture.validate().map_err(at("texture"))?;
    c.system.validate().map_err(at("system"))?;
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
