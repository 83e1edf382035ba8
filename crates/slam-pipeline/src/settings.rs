//! The settings structs of the pipeline in a settings file: serde helpers for how an optional threshold
//! and the box model are written (TOML has no `null`, so "off" is written as 0), and the valid range of
//! every range-limited setting (`validate()` of [`MappingConfig`], [`MapperConfig`], [`TextureConfig`]
//! and [`SystemConfig`], each over its own fields; errors name the field). A settings file is read
//! key by key over the defaults ([`parse_over_defaults`]) and written with every key's doc comment
//! ([`commented_table`]).

use slam_core::check::{count, number, InvalidValue, Range};

/// The settings-file forms of some settings, where they were before they moved to [`crate::serde_forms`].
pub use crate::serde_forms::{box_shape, zero_is_off, zero_is_off_usize};
use crate::{mapping::MappingConfig, objects::MapperConfig, system::SystemConfig, texture::TextureConfig};

/// Errors of reading settings from TOML.
#[derive(Debug, thiserror::Error)]
pub enum SettingsError {
    /// The text is not valid TOML or has a wrong or unknown key (the message names the line).
    #[error(transparent)]
    Parse(#[from] toml::de::Error),
    /// The defaults could not be written as TOML.
    #[error(transparent)]
    Defaults(#[from] toml::ser::Error),
    /// A finite number beyond what its (32-bit) setting can hold.
    #[error("{key} = {value:e}: beyond the range of this setting (a 32-bit number: at most ±3.4e38)")]
    Narrowed {
        /// The key, `[table] key`.
        key: String,
        /// The number as written.
        value: f64,
    },
}

/// Settings from TOML text, overlaid key by key on `defaults`: a table that sets one key keeps the
/// defaults of the others. The text is first read as written, so that errors name its line.
pub fn parse_over_defaults<T>(text: &str, defaults: &T) -> Result<T, SettingsError>
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    toml::from_str::<T>(text)?;
    let mut merged = toml::Value::try_from(defaults)?;
    let given = toml::from_str::<toml::Value>(text)?;
    overlay(&mut merged, given.clone());
    let value: T = merged.try_into()?;
    // a 32-bit setting turns a finite number beyond its range (1e308) into infinity on the way in: say
    // so with the number as written, not as "inf"
    if let Some((key, v)) = narrowed(&given, &toml::Value::try_from(&value)?, "") {
        return Err(SettingsError::Narrowed { key, value: v });
    }
    Ok(value)
}

/// The first finite number of `given` that reads back as a non-finite one in `read` (the same keys),
/// with its key (`[tracking] ransac_px`).
fn narrowed(given: &toml::Value, read: &toml::Value, table: &str) -> Option<(String, f64)> {
    match (given, read) {
        (toml::Value::Table(g), toml::Value::Table(r)) => g.iter().find_map(|(k, v)| {
            let name = if table.is_empty() { k.clone() } else { format!("{table}.{k}") };
            r.get(k).and_then(|rv| narrowed(v, rv, &name))
        }),
        (toml::Value::Array(g), toml::Value::Array(r)) => g.iter().zip(r).find_map(|(a, b)| narrowed(a, b, table)),
        (toml::Value::Float(g), toml::Value::Float(r)) if g.is_finite() && !r.is_finite() => {
            let key = match table.split_once('.') {
                Some((t, k)) => format!("[{t}] {k}"),
                None => table.to_string(),
            };
            Some((key, *g))
        }
        _ => None,
    }
}

/// Put `over`'s keys onto `base`, table by table.
fn overlay(base: &mut toml::Value, over: toml::Value) {
    match (base, over) {
        (toml::Value::Table(b), toml::Value::Table(o)) => {
            for (k, v) in o {
                match b.get_mut(&k) {
                    Some(slot) => overlay(slot, v),
                    None => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (slot, v) => *slot = v,
    }
}

/// One table of a settings file, `[name]  # what`, each key preceded by its doc comment as `#` lines
/// (rustdoc links as plain code names).
pub fn commented_table<T: serde::Serialize + documented::DocumentedFieldsOpt>(
    name: &str,
    what: &str,
    value: &T,
) -> String {
    let body = toml::to_string(value).unwrap_or_default();
    let mut s = format!("[{name}]  # {what}\n");
    for line in body.lines() {
        let key = line.split('=').next().unwrap_or("").trim();
        if let Ok(doc) = T::get_field_docs(key) {
            for d in doc.lines() {
                let d = d.trim().replace("[`", "`").replace("`]", "`");
                s.push_str(&format!("# {d}\n").replace("# \n", "#\n"));
            }
        }
        s.push_str(line);
        s.push('\n');
    }
    s
}

const POSITIVE: Range = Range::above(0.0, f64::INFINITY);

impl MappingConfig {
    /// Check the local-mapping settings.
    pub fn validate(&self) -> Result<(), InvalidValue> {
        count("window", self.window, 1, usize::MAX)?;
        number("huber_px", self.huber_px, POSITIVE, "px")?;
        number("cull_chi2", self.cull_chi2, POSITIVE, "px²")?;
        number("cull_chi2_mono", self.cull_chi2_mono, POSITIVE, "px²")?;
        count("iterations", self.iterations, 1, 100_000)
    }
}

impl MapperConfig {
    /// Check the object settings the file sets (the image size is the caller's).
    pub fn validate(&self) -> Result<(), InvalidValue> {
        count("min_views", self.min_views, 1, usize::MAX)?;
        let min_views = self.min_views.max(1);
        count("max_views", self.max_views, min_views, usize::MAX)
            .map_err(|e| InvalidValue { valid: format!("at least min_views ({min_views})"), ..e })?;
        number("min_parallax_deg", self.min_parallax_deg, Range::closed(0.0, 90.0).with_hi_open(), "degrees")?;
        number("border_margin_px", self.border_margin_px, Range::closed(0.0, 10_000.0), "px")?;
        count("refit_every", self.refit_every, 1, usize::MAX)?;
        number("dynamic_rms_px", self.dynamic_rms_px, POSITIVE, "px")?;
        number("dynamic_motion_sigmas", self.dynamic_motion_sigmas, POSITIVE, "σ")?;
        let prior = self.dynamic_prior_sigmas.unwrap_or(0.0);
        number("dynamic_prior_sigmas", prior, Range::closed(0.0, f64::INFINITY), "(0: off)")?;
        number("max_depth_m", self.max_depth_m, POSITIVE, "m")?;
        number("visible_depth_m", self.visible_depth_m, POSITIVE, "m")?;
        number("merge_distance_m", self.merge_distance_m, Range::closed(0.0, f64::INFINITY), "m")
    }
}

impl TextureConfig {
    /// Check the texture-plane settings.
    pub fn validate(&self) -> Result<(), InvalidValue> {
        number("max_edge_m", self.max_edge_m, POSITIVE, "m")?;
        number("min_facing", self.min_facing, Range::closed(0.0, 1.0), "(|cos|)")?;
        // a Delaunay triangulation needs three points
        count("min_points", self.min_points, 3, usize::MAX)
    }
}

impl SystemConfig {
    /// Check the system's own settings (the stage settings it holds check themselves).
    pub fn validate(&self) -> Result<(), InvalidValue> {
        count("correction_lag", self.correction_lag, 0, 1000)?;
        count("detect_every", self.detect_every, 1, usize::MAX)?;
        number("object_core", self.object_core, Range::above(0.0, 1.0), "(share of the box)")?;
        // a matcher's disparity error: a fraction of a pixel to a few pixels; 100 px is no measurement
        number("disparity_sigma_px", self.disparity_sigma_px, Range::above(0.0, 100.0), "px")?;
        let gate = self.projected_gate.unwrap_or(0.0);
        number("projected_gate", gate, Range::closed(0.0, 1.0), "(IoU; 0: off)")?;
        count("max_detections", self.max_detections, 1, 10_000)
    }
}

#[cfg(test)]
mod validate_tests {
    use super::*;

    #[test]
    fn a_file_overlays_the_defaults_key_by_key_and_comments_name_each_key() {
        let defaults = TextureConfig { max_planes: 7, ..TextureConfig::default() };
        let t: TextureConfig = parse_over_defaults("min_points = 9\n", &defaults).expect("parses");
        assert_eq!((t.min_points, t.max_planes), (9, 7), "unset keys keep the given defaults");
        let e = parse_over_defaults::<TextureConfig>("min_points = 9\nmin_pints = 3\n", &defaults).expect_err("typo");
        assert!(e.to_string().contains("min_pints") && e.to_string().contains("line 2"), "{e}");
        let text = commented_table("texture", "slam-pipeline TextureConfig", &defaults);
        assert!(text.starts_with("[texture]  # slam-pipeline TextureConfig\n#"), "{text}");
        assert!(text.contains("\nmax_planes = 7\n"), "{text}");
        let back: TextureConfig = toml::from_str(text.split_once('\n').expect("header").1).expect("reads back");
        assert_eq!(back, defaults);
    }

    #[test]
    fn the_defaults_pass_and_each_table_names_its_bad_field() {
        let s = SystemConfig::default();
        s.validate().and(s.mapping.validate()).and(s.objects.validate()).and(s.texture.validate()).expect("defaults");
        let m = MappingConfig { huber_px: -1.0, ..MappingConfig::default() };
        assert_eq!(m.validate().expect_err("huber").to_string(), "huber_px -1: must be a finite number in (0, ∞) px");
        let mut o = MapperConfig { min_views: 5, max_views: 3, ..MapperConfig::default() };
        assert_eq!(o.validate().expect_err("views").to_string(), "max_views 3: must be at least min_views (5)");
        o.max_views = 5;
        o.dynamic_prior_sigmas = Some(-2.0);
        assert_eq!(o.validate().expect_err("prior").key, "dynamic_prior_sigmas");
        let t = TextureConfig { min_facing: 1.5, ..TextureConfig::default() };
        assert_eq!(t.validate().expect_err("facing").key, "min_facing");
        let t = TextureConfig { min_points: 2, ..TextureConfig::default() };
        assert_eq!(t.validate().expect_err("points").to_string(), "min_points 2: must be at least 3");
        let sys = SystemConfig { object_core: 0.0, ..SystemConfig::default() };
        assert_eq!(sys.validate().expect_err("core").key, "object_core");
        let sys = SystemConfig { disparity_sigma_px: -1.0, ..SystemConfig::default() };
        assert_eq!(sys.validate().expect_err("disparity σ").key, "disparity_sigma_px");
        let objects = MapperConfig { visible_depth_m: f64::NAN, ..MapperConfig::default() };
        assert_eq!(objects.validate().expect_err("visible depth").key, "visible_depth_m");
        let sys = SystemConfig { max_detections: 0, ..SystemConfig::default() };
        assert_eq!(sys.validate().expect_err("max").to_string(), "max_detections 0: must be an integer in [1, 10000]");
    }
}

#[cfg(test)]
mod tests {
    use crate::{objects::MapperConfig, system::SystemConfig};

    #[test]
    fn settings_round_trip_and_zero_switches_a_test_off() {
        let text = serde_json::to_string(&MapperConfig::default()).expect("serialises");
        assert!(text.contains("\"box_shape\":\"cuboid\"") && text.contains("\"dynamic_prior_sigmas\":6.0"), "{text}");
        assert!(!text.contains("tracker") && !text.contains("image"), "caller-set fields stay out: {text}");
        let back: MapperConfig = serde_json::from_str(&text).expect("parses");
        assert_eq!(back, MapperConfig::default());
        let off: MapperConfig =
            serde_json::from_str(r#"{"dynamic_prior_sigmas": 0, "box_shape": "ellipse"}"#).expect("parses");
        assert_eq!(off.dynamic_prior_sigmas, None);
        assert_eq!(off.box_shape, slam_optim::object::BoxShape::Ellipse);
        assert_eq!(off.min_views, MapperConfig::default().min_views, "missing keys keep the defaults");
        assert!(serde_json::from_str::<MapperConfig>(r#"{"box_shape": "sphere"}"#).is_err());
        assert!(serde_json::from_str::<MapperConfig>(r#"{"min_view": 3}"#).is_err(), "unknown keys are errors");
        let sys: SystemConfig = serde_json::from_str(r#"{"projected_gate": 0}"#).expect("parses");
        assert_eq!(sys.projected_gate, None);
        assert_eq!(sys.objects, SystemConfig::default().objects, "stage settings are not keys of [system]");
        assert_eq!(sys.objects.dynamic_rms_px, crate::system::DETECTOR_DYNAMIC_RMS_PX);
    }
}
