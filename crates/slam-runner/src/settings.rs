//! The settings of a run from TOML: one table per stage, each the library's own settings struct (its
//! `Default` is the one source of the defaults), every key optional, unknown keys rejected with the
//! file's name and line; every value range-checked by the library that defines it. The app's
//! `--print-config` prints [`RunConfig::to_commented_toml`].

use std::path::Path;

use serde::{Deserialize, Serialize};
use slam_core::check::InvalidValue;
use slam_frontend::VoConfig;
use slam_pipeline::{
    mapping::MappingConfig, objects::MapperConfig, settings::commented_table, system::SystemConfig,
    texture::TextureConfig,
};

use crate::error::{Context, Result, RunnerError};

/// All settings of a run.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    /// Visual odometry (slam-frontend `VoConfig`).
    pub tracking: VoConfig,
    /// Local mapping, bundle adjustment (slam-pipeline `MappingConfig`).
    pub mapping: MappingConfig,
    /// Objects (slam-pipeline `MapperConfig`; the associator keeps its defaults).
    pub objects: MapperConfig,
    /// Texture planes (slam-pipeline `TextureConfig`).
    pub texture: TextureConfig,
    /// Threads and their hand-over (slam-pipeline `SystemConfig`).
    pub system: SystemConfig,
}

impl Default for RunConfig {
    /// The running system's defaults, as the libraries define them.
    fn default() -> Self {
        let system = SystemConfig::default();
        Self {
            tracking: VoConfig::default(),
            mapping: system.mapping,
            objects: system.objects,
            texture: system.texture,
            system,
        }
    }
}

impl RunConfig {
    /// The settings file at `path` over the library defaults, or the defaults when there is none.
    pub fn load(path: Option<&Path>) -> Result<Self> {
        path.map_or_else(|| Ok(Self::default()), Self::read)
    }

    /// The command line's overrides of single keys: `tracking.keyframe_max_gap`, `mapping.bundle_adjustment`
    /// off, `system.detect_every`.
    pub fn with_overrides(mut self, keyframe_gap: Option<usize>, no_ba: bool, detect_every: Option<usize>) -> Self {
        self.tracking.keyframe_max_gap = keyframe_gap.unwrap_or(self.tracking.keyframe_max_gap);
        self.mapping.bundle_adjustment &= !no_ba;
        self.system.detect_every = detect_every.unwrap_or(self.system.detect_every);
        self
    }

    /// Read a settings file; every value is checked ([`RunConfig::validate`]).
    pub fn read(path: &Path) -> Result<Self> {
        let text = slam_core::files::read_text(path, &slam_core::files::SMALL).map_err(RunnerError::other)?;
        let c = Self::parse(&text).context_with(|| format!("{}: invalid configuration", path.display()))?;
        c.validate(&path.display().to_string())?;
        Ok(c)
    }

    /// Settings from TOML text, overlaid key by key on the defaults (a table that sets one key keeps
    /// the running system's defaults for the others).
    pub fn parse(text: &str) -> std::result::Result<Self, slam_pipeline::settings::SettingsError> {
        slam_pipeline::settings::parse_over_defaults(text, &RunConfig::default())
    }

    /// Every table checked by its library's `validate()`; `source` names the file (or "defaults") and
    /// the table in messages (`x.toml: [tracking] ransac_px = NaN: must be …`).
    pub fn validate(&self, source: &str) -> Result<()> {
        let at = |table: &'static str| {
            move |e: InvalidValue| {
                let key = format!("{source}: [{table}] {} =", e.key);
                RunnerError::other(e.rename(key))
            }
        };
        self.tracking.validate().map_err(at("tracking"))?;
        self.mapping.validate().map_err(at("mapping"))?;
        self.objects.validate().map_err(at("objects"))?;
        self.texture.validate().map_err(at("texture"))?;
        self.system.validate().map_err(at("system"))?;
        Ok(())
    }

    /// The settings as TOML, with every key's doc comment from the library that defines it.
    pub fn to_commented_toml(self) -> String {
        [
            "# slam-app run: effective settings (the defaults of the library crates, overlaid by --config and\n\
             # the command-line options). Every key is optional in a settings file.\n"
                .to_string(),
            commented_table("tracking", "slam-frontend VoConfig", &self.tracking),
            commented_table("mapping", "slam-pipeline MappingConfig", &self.mapping),
            commented_table("objects", "slam-pipeline MapperConfig", &self.objects),
            commented_table("texture", "slam-pipeline TextureConfig", &self.texture),
            commented_table("system", "slam-pipeline SystemConfig", &self.system),
        ]
        .join("\n")
    }

    /// The system's settings: the file's tables put together, the image size from the sequence.
    pub fn system(&self, image: slam_quadric::ImageSize) -> SystemConfig {
        SystemConfig {
            mapping: self.mapping,
            objects: MapperConfig { image, ..self.objects },
            texture: self.texture,
            ..self.system
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_round_trip_through_toml_and_unknown_keys_fail() {
        let text = RunConfig::default().to_commented_toml();
        assert!(text.contains("[tracking]") && text.contains("keyframe_max_gap = 0") && text.contains("[mapping]"));
        // every key carries its library doc comment
        assert!(text.contains("# ORB features per image.\nfeatures = 2000"), "{text}");
        assert!(text.contains("dynamic_rms_px = 25.0"), "the running system's default (library): {text}");
        let back = RunConfig::parse(&text).expect("parses");
        assert_eq!(back.tracking, VoConfig::default());
        assert_eq!(back.objects, SystemConfig::default().objects);
        assert_eq!(back.system(MapperConfig::default().image), SystemConfig::default());
        // a table with one key keeps the running system's defaults for the others
        let one = RunConfig::parse("[objects]\nmin_views = 4\n").expect("parses");
        assert_eq!(one.objects.min_views, 4);
        assert_eq!(one.objects.dynamic_rms_px, slam_pipeline::system::DETECTOR_DYNAMIC_RMS_PX);
        let partial = RunConfig::parse("[mapping]\nwindow = 9\n").expect("partial");
        assert_eq!(partial.mapping.window, 9);
        assert_eq!(partial.tracking.features, 2000);
        let e = RunConfig::parse("[tracking]\nfeatures_typo = 3\n").expect_err("unknown key");
        assert!(e.to_string().contains("features_typo"), "{e}");
        // the box model and the disparity offset reach the stages they configure
        let c = RunConfig::parse("[objects]\nbox_shape = \"cuboid\"\n[tracking]\ndisparity_offset = 0.1\n")
            .expect("parses");
        let sys = c.system(slam_quadric::ImageSize::new(1242.0, 375.0));
        assert_eq!(sys.objects.box_shape, slam_optim::object::BoxShape::Cuboid);
        assert_eq!(c.tracking.disparity_offset, 0.1);
        assert!(toml::from_str::<RunConfig>("[objects]\nbox_shape = \"sphere\"\n").is_err());
        assert!(toml::from_str::<RunConfig>("[tracking]\nkeep_disparity_pairs = 5\n").is_err());
        assert!(toml::from_str::<RunConfig>("[objects]\nimage = 5\n").is_err(), "caller-set fields are not keys");
    }

    #[test]
    fn the_defaults_pass_and_every_table_is_checked() {
        RunConfig::default().validate("defaults").expect("defaults valid");
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
            let e = c.validate("x.toml").expect_err(text).to_string();
            assert!(e.contains("x.toml") && e.contains(want), "{text}: {e}");
        }
    }

    #[test]
    fn a_file_names_itself_in_every_error() {
        let dir = std::env::temp_dir().join(format!("slam-runner-settings-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("tmp");
        let missing = dir.join("missing.toml");
        let e = RunConfig::load(Some(&missing)).expect_err("missing");
        assert!(e.to_string().contains("missing.toml"), "{e}");
        let bad = dir.join("bad.toml");
        std::fs::write(&bad, "[tracking]\nransac_px = -2.0\n").expect("write");
        let e = RunConfig::load(Some(&bad)).expect_err("bad value");
        assert!(e.to_string().contains("bad.toml: [tracking] ransac_px"), "{e}");
        std::fs::write(&bad, "[tracking]\nnope = 1\n").expect("write");
        let e = RunConfig::load(Some(&bad)).expect_err("unknown key");
        assert!(e.to_string().contains("bad.toml: invalid configuration"), "{e}");
        assert_eq!(RunConfig::load(None).expect("defaults").tracking, VoConfig::default());
        let o = RunConfig::default().with_overrides(Some(7), true, Some(3));
        assert_eq!((o.tracking.keyframe_max_gap, o.mapping.bundle_adjustment, o.system.detect_every), (7, false, 3));
        let kept = RunConfig::default().with_overrides(None, false, None);
        assert_eq!(kept.system(MapperConfig::default().image), SystemConfig::default(), "nothing overridden");
        std::fs::remove_dir_all(&dir).ok();
    }
}
