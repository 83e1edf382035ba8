//! A detector model as a user names it ([`ModelSpec`]): the network files (default: the shipped
//! Yolo-Fastest 1.1) and how to feed it, every field optional. [`ModelSpec::check`] range-checks the
//! settings before anything is loaded; [`ModelSpec::load`] builds the [`DnnDetector`].

use std::path::{Path, PathBuf};

use slam_core::check::{count, number, InvalidValue, Range};

use crate::{DetectorConfig, DnnDetector, FrontendError, InputMode};

/// Largest square network input accepted, pixels. Memory and time grow with its square (the input blob
/// and every activation map): 320 is the shipped model's size, 2048 keeps a CPU forward pass within a few
/// hundred megabytes; an input of 32000 once asked for 23.8 GB.
pub const MAX_INPUT_SIZE: i32 = 2048;

/// More tiles than this across a KITTI frame would be narrower than the objects they should hold.
pub const MAX_TILES: u32 = 16;

/// How frames are fed to the network, by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ModeName {
    /// Resize to the square input, ignoring the aspect ratio.
    Squash,
    /// Keep the aspect ratio, pad.
    Letterbox,
    /// Overlapping tiles across the width plus the whole frame.
    Tiles,
}

impl ModeName {
    /// Lower-case name, as on a command line.
    pub fn name(self) -> &'static str {
        match self {
            ModeName::Squash => "squash",
            ModeName::Letterbox => "letterbox",
            ModeName::Tiles => "tiles",
        }
    }
}

/// Errors of a model specification.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A setting out of its range (the key is the field name: `input_size`, `tiles`, `score`).
    #[error(transparent)]
    Invalid(#[from] InvalidValue),
    /// `tiles` given with another mode than tiles.
    #[error("tiles is a setting of mode tiles, but mode {0} was given")]
    TilesWithoutTiling(&'static str),
    /// The model files could not be loaded.
    #[error(transparent)]
    Load(#[from] FrontendError),
}

/// A detector model and its settings; `None` fields take the shipped model's defaults.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ModelSpec {
    /// Darknet .cfg (default: the shipped one).
    pub cfg: Option<PathBuf>,
    /// Darknet .weights (default: the shipped ones).
    pub weights: Option<PathBuf>,
    /// An ONNX model instead of Darknet.
    pub onnx: Option<PathBuf>,
    /// Input mode (default: tiles).
    pub mode: Option<ModeName>,
    /// Tiles across the width (mode tiles only; default 3).
    pub tiles: Option<u32>,
    /// Network input size, a multiple of 32 (default 320).
    pub input_size: Option<i32>,
    /// Smallest score kept (default 0.2).
    pub score: Option<f32>,
}

impl ModelSpec {
    /// The shipped model in one input mode, every other setting at its default.
    pub fn shipped(mode: ModeName) -> Self {
        Self { mode: Some(mode), ..Self::default() }
    }

    /// Range checks and the mode's consistency (before any model is loaded).
    pub fn check(&self) -> Result<(), ModelError> {
        self.config().map(drop)
    }

    /// The detector settings this specification describes.
    pub fn config(&self) -> Result<DetectorConfig, ModelError> {
        let input_size = self.input_size.unwrap_or(320);
        if !(32..=MAX_INPUT_SIZE).contains(&input_size) || input_size % 32 != 0 {
            let valid = format!("a multiple of 32 in [32, {MAX_INPUT_SIZE}] (memory grows with its square)");
            return Err(InvalidValue { key: "input_size".into(), value: input_size.to_string(), valid }.into());
        }
        count("tiles", self.tiles.unwrap_or(3) as usize, 1, MAX_TILES as usize)?;
        number("score", self.score.unwrap_or(0.2) as f64, Range::closed(0.0, 1.0), "")?;
        let mode = match (self.mode, self.tiles) {
            (None | Some(ModeName::Tiles), t) => InputMode::Tiles(t.unwrap_or(3)),
            (Some(m), Some(_)) => return Err(ModelError::TilesWithoutTiling(m.name())),
            (Some(ModeName::Squash), None) => InputMode::Squash,
            (Some(ModeName::Letterbox), None) => InputMode::Letterbox,
        };
        Ok(DetectorConfig { input_size, mode, score_threshold: self.score.unwrap_or(0.2), ..DetectorConfig::default() })
    }

    /// Load the network; `shipped` is the folder of the shipped Darknet files (`yolo-fastest-1.1.cfg`
    /// and `.weights`), used for whichever of the two is not given.
    pub fn load(&self, shipped: &Path) -> Result<DnnDetector, ModelError> {
        let config = self.config()?;
        Ok(match &self.onnx {
            Some(m) => DnnDetector::from_onnx(m, config)?,
            None => {
                let cfg = self.cfg.clone().unwrap_or_else(|| shipped.join("yolo-fastest-1.1.cfg"));
                let weights = self.weights.clone().unwrap_or_else(|| shipped.join("yolo-fastest-1.1.weights"));
                DnnDetector::from_darknet(cfg, weights, config)?
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_are_checked_and_mapped() {
        let c = ModelSpec::default().config().expect("defaults");
        assert_eq!(c, DetectorConfig::default());
        let s = ModelSpec {
            mode: Some(ModeName::Letterbox),
            input_size: Some(416),
            score: Some(0.5),
            ..Default::default()
        };
        let c = s.config().expect("valid");
        assert_eq!((c.mode, c.input_size, c.score_threshold), (InputMode::Letterbox, 416, 0.5));
        assert_eq!(
            ModelSpec { tiles: Some(5), ..Default::default() }.config().expect("tiles").mode,
            InputMode::Tiles(5)
        );
        for (bad, want) in [
            (ModelSpec { input_size: Some(100), ..Default::default() }, "input_size 100: must be a multiple of 32"),
            (ModelSpec { input_size: Some(4096), ..Default::default() }, "input_size 4096"),
            (ModelSpec { tiles: Some(0), ..Default::default() }, "tiles 0: must be an integer in [1, 16]"),
            (ModelSpec { score: Some(f32::NAN), ..Default::default() }, "score NaN"),
            (ModelSpec { mode: Some(ModeName::Squash), tiles: Some(2), ..Default::default() }, "mode squash was given"),
        ] {
            let e = bad.check().expect_err(want).to_string();
            assert!(e.contains(want), "{e}");
        }
        let missing = ModelSpec { onnx: Some("/nonexistent/model.onnx".into()), ..Default::default() };
        assert!(matches!(missing.load(Path::new("/nonexistent")), Err(ModelError::Load(_))));
    }
}
