//! Serde helpers of the settings structs: how an optional threshold and the box model are written in a
//! settings file (TOML has no `null`, so "off" is written as 0).

/// `Option<f64>` as a number, 0 meaning `None` (a test switched off).
pub mod zero_is_off {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Write `None` as 0.
    pub fn serialize<S: Serializer>(v: &Option<f64>, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_f64(v.unwrap_or(0.0))
    }

    /// Read 0 as `None`; a negative or non-finite number is an error.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<f64>, D::Error> {
        let v = f64::deserialize(d)?;
        if !v.is_finite() || v < 0.0 {
            return Err(serde::de::Error::custom(format!("{v}: must be 0 (off) or a positive finite number")));
        }
        Ok((v > 0.0).then_some(v))
    }
}

/// `Option<usize>` as a count, 0 meaning `None`.
pub mod zero_is_off_usize {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Write `None` as 0.
    pub fn serialize<S: Serializer>(v: &Option<usize>, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(v.unwrap_or(0) as u64)
    }

    /// Read 0 as `None`.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<usize>, D::Error> {
        let v = usize::deserialize(d)?;
        Ok((v > 0).then_some(v))
    }
}

/// [`slam_optim::object::BoxShape`] as `"ellipse"`, `"cuboid"` or `"two-stage"`.
pub mod box_shape {
    use serde::{de::Error, Deserialize, Deserializer, Serializer};
    use slam_optim::object::BoxShape;

    /// Write the shape's name.
    pub fn serialize<S: Serializer>(v: &BoxShape, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(match v {
            BoxShape::Ellipse => "ellipse",
            BoxShape::Cuboid => "cuboid",
            BoxShape::TwoStage => "two-stage",
        })
    }

    /// Read a shape's name.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<BoxShape, D::Error> {
        match String::deserialize(d)?.as_str() {
            "ellipse" => Ok(BoxShape::Ellipse),
            "cuboid" => Ok(BoxShape::Cuboid),
            "two-stage" => Ok(BoxShape::TwoStage),
            other => Err(D::Error::unknown_variant(other, &["ellipse", "cuboid", "two-stage"])),
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::{objects::MapperConfig, system::SystemConfig};

    #[test]
    fn settings_round_trip_and_zero_switches_a_test_off() {
        let text = serde_json::to_string(&MapperConfig::default()).expect("serialises");
        assert!(text.contains("\"box_shape\":\"ellipse\"") && text.contains("\"dynamic_prior_sigmas\":6.0"), "{text}");
        assert!(!text.contains("tracker") && !text.contains("image"), "caller-set fields stay out: {text}");
        let back: MapperConfig = serde_json::from_str(&text).expect("parses");
        assert_eq!(back, MapperConfig::default());
        let off: MapperConfig =
            serde_json::from_str(r#"{"dynamic_prior_sigmas": 0, "box_shape": "cuboid"}"#).expect("parses");
        assert_eq!(off.dynamic_prior_sigmas, None);
        assert_eq!(off.box_shape, slam_optim::object::BoxShape::Cuboid);
        assert_eq!(off.min_views, MapperConfig::default().min_views, "missing keys keep the defaults");
        assert!(serde_json::from_str::<MapperConfig>(r#"{"box_shape": "sphere"}"#).is_err());
        assert!(serde_json::from_str::<MapperConfig>(r#"{"min_view": 3}"#).is_err(), "unknown keys are errors");
        let sys: SystemConfig = serde_json::from_str(r#"{"projected_gate": 0}"#).expect("parses");
        assert_eq!(sys.projected_gate, None);
        assert_eq!(sys.objects, SystemConfig::default().objects, "stage settings are not keys of [system]");
        assert_eq!(sys.objects.dynamic_rms_px, crate::system::DETECTOR_DYNAMIC_RMS_PX);
    }
}
