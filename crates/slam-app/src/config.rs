//! `slam-app run` settings from TOML: one table per stage, every key optional (defaults below, printed
//! by `slam-app run --print-config`), unknown keys rejected with the file's name.

use std::path::Path;

use anyhow::Context;
use serde::{Deserialize, Serialize};
use slam_frontend::VoConfig;
use slam_pipeline::{mapping::MappingConfig, objects::MapperConfig, system::SystemConfig, texture::TextureConfig};

/// Object mapping (slam-pipeline `MapperConfig`; the associator keeps its defaults).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ObjectsToml {
    /// Fewest border-free boxes before an ellipsoid is fitted.
    pub min_views: usize,
    /// Smallest angle between the first and latest ray through the box centres, degrees.
    pub min_parallax_deg: f64,
    /// Boxes this close to the border are not used for fitting, pixels.
    pub border_margin_px: f64,
    /// Refit after this many new boxes.
    pub refit_every: usize,
    /// Most views in one fit.
    pub max_views: usize,
    /// RMS box misfit above which an object is flagged dynamic, pixels (25 here: detector boxes are
    /// noisier than the labels the image-free mode's 12 px was set on; moving map points are the main cue).
    pub dynamic_rms_px: f64,
    /// Centroid motion above which an object is moving, metres (+5 % of depth).
    pub dynamic_motion_m: f64,
    /// Fitted semi-axes this many prior σ from the class prior flag an object dynamic (0: off).
    pub dynamic_prior_sigmas: f64,
    /// Ellipsoids farther than this from their latest camera are discarded, metres.
    pub max_depth_m: f64,
    /// Static objects of one class closer than this are merged, metres.
    pub merge_distance_m: f64,
    /// What a box bounds in the object optimisation: "ellipse" (the paper) or "cuboid".
    pub box_shape: crate::objects_cmd::Shape,
}

impl Default for ObjectsToml {
    fn default() -> Self {
        let m = MapperConfig::default();
        Self {
            min_views: m.min_views,
            min_parallax_deg: m.min_parallax_deg,
            border_margin_px: m.border_margin_px,
            refit_every: m.refit_every,
            max_views: m.max_views,
            // detector boxes (partial, jittery) miss more than label boxes; the motion test is the main cue
            dynamic_rms_px: 25.0,
            dynamic_motion_m: m.dynamic_motion_m,
            dynamic_prior_sigmas: m.dynamic_prior_sigmas.unwrap_or(0.0),
            max_depth_m: m.max_depth_m,
            merge_distance_m: m.merge_distance_m,
            box_shape: crate::objects_cmd::Shape::Ellipse,
        }
    }
}

/// Threads and their hand-over (slam-pipeline `SystemConfig`).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SystemToml {
    /// Frames between a keyframe and the use of the mapper's reply.
    pub correction_lag: usize,
    /// Run the detector on every n-th frame.
    pub detect_every: usize,
    /// Keep keypoints of moving objects out of tracking.
    pub exclude_moving: bool,
    /// Central fraction of a box whose map points belong to the object.
    pub object_core: f64,
    /// ODA gate: never give a detection to an object whose projected ellipsoid overlaps it by less than
    /// this IoU (0: the paper's cost alone).
    pub projected_gate: f64,
    /// Most detections kept per frame (the highest scores; the rest are dropped and counted). The busiest
    /// labelled frame of the KITTI tracking fixtures has 25 boxes; association cost grows with the cube of
    /// the count (1,000 boxes per frame once took 297 s for 51 frames).
    pub max_detections: usize,
}

impl Default for SystemToml {
    fn default() -> Self {
        let s = SystemConfig::default();
        Self {
            correction_lag: s.correction_lag,
            detect_every: s.detect_every,
            exclude_moving: s.exclude_moving,
            object_core: s.object_core,
            projected_gate: s.projected_gate.unwrap_or(0.0),
            max_detections: 100,
        }
    }
}

/// All settings of a run.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    /// Visual odometry.
    pub tracking: VoConfig,
    /// Local mapping (bundle adjustment).
    pub mapping: MappingConfig,
    /// Objects.
    pub objects: ObjectsToml,
    /// Texture planes.
    pub texture: TextureConfig,
    /// Threads.
    pub system: SystemToml,
}

impl RunConfig {
    /// Read a settings file; every value is checked ([`crate::validate::run_config`]).
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let c: Self = toml::from_str(&text).with_context(|| format!("{}: invalid configuration", path.display()))?;
        crate::validate::run_config(&c, &path.display().to_string())?;
        Ok(c)
    }

    pub fn to_toml(self) -> String {
        toml::to_string(&self).unwrap_or_default()
    }

    pub fn system(&self, image: slam_quadric::ImageSize) -> SystemConfig {
        let o = self.objects;
        SystemConfig {
            mapping: self.mapping,
            objects: MapperConfig {
                image,
                min_views: o.min_views,
                min_parallax_deg: o.min_parallax_deg,
                border_margin_px: o.border_margin_px,
                refit_every: o.refit_every,
                max_views: o.max_views,
                dynamic_rms_px: o.dynamic_rms_px,
                dynamic_motion_m: o.dynamic_motion_m,
                dynamic_prior_sigmas: (o.dynamic_prior_sigmas > 0.0).then_some(o.dynamic_prior_sigmas),
                max_depth_m: o.max_depth_m,
                merge_distance_m: o.merge_distance_m,
                box_shape: o.box_shape.shape(),
                ..MapperConfig::default()
            },
            texture: self.texture,
            correction_lag: self.system.correction_lag,
            detect_every: self.system.detect_every,
            exclude_moving: self.system.exclude_moving,
            object_core: self.system.object_core,
            projected_gate: (self.system.projected_gate > 0.0).then_some(self.system.projected_gate),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_round_trip_through_toml_and_unknown_keys_fail() {
        let text = RunConfig::default().to_toml();
        assert!(text.contains("[tracking]") && text.contains("keyframe_max_gap = 4") && text.contains("[mapping]"));
        let back: RunConfig = toml::from_str(&text).expect("parses");
        assert_eq!(back.tracking, VoConfig::default());
        let partial: RunConfig = toml::from_str("[mapping]\nwindow = 9\n").expect("partial");
        assert_eq!(partial.mapping.window, 9);
        assert_eq!(partial.tracking.features, 2000);
        let e = toml::from_str::<RunConfig>("[tracking]\nfeatures_typo = 3\n").expect_err("unknown key");
        assert!(e.to_string().contains("features_typo"), "{e}");
        // the box model and the disparity offset reach the stages they configure
        let c: RunConfig =
            toml::from_str("[objects]\nbox_shape = \"cuboid\"\n[tracking]\ndisparity_offset = 0.1\n").expect("parses");
        let sys = c.system(slam_quadric::ImageSize::new(1242.0, 375.0));
        assert_eq!(sys.objects.box_shape, slam_optim::object::BoxShape::Cuboid);
        assert_eq!(c.tracking.disparity_offset, 0.1);
        assert!(toml::from_str::<RunConfig>("[objects]\nbox_shape = \"sphere\"\n").is_err());
        assert!(toml::from_str::<RunConfig>("[tracking]\nkeep_disparity_pairs = 5\n").is_err());
    }
}
