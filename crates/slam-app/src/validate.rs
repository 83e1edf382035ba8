//! Validation at the edge: command-line numbers, settings-file values, calibration and image sizes are
//! checked before any work starts, and every message names the value, what was given and the valid
//! range. Inside the libraries these values are trusted.

use std::path::Path;

use anyhow::{bail, Context};

use crate::config::RunConfig;

pub use slam_dataset::check::{calibration, count, declared_size, first_pair, number, Range};

/// Largest square network input accepted, pixels. Memory and time grow with its square (the input blob
/// and every activation map): 320 is the shipped model's size, 2048 keeps a CPU forward pass within a few
/// hundred megabytes; `--input-size 32000` once asked for 23.8 GB.
pub const MAX_INPUT_SIZE: i32 = 2048;

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
