//! How some settings are written in a settings file: numbers where 0 switches a test off, and the
//! box model's name. Used by the settings' types with `#[serde(with = ...)]`; a file of its own so that
//! the types' modules and the settings file's reader (`crate::settings`) do not import each other.

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
