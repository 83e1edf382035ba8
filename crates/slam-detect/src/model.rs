//! A detector model as a user names it ([`ModelSpec`]): a shipped model by name (default: YOLOX-nano),
//! or model files with their family, how to feed it and (ONNX models) where ONNX Runtime runs it, every
//! field optional. [`ModelSpec::check`] range-checks the settings before anything is loaded;
//! [`ModelSpec::load`] builds the [`DnnDetector`].

use std::path::{Path, PathBuf};

use slam_core::check::{count, number, InvalidValue, Range};

use crate::{
    onnx::{Device, RuntimeOptions, DEFAULT_THREADS, MAX_THREADS},
    DetectorConfig, DetectorError, DnnDetector, InputMode, ModelFamily,
};

/// Largest network input side accepted, pixels. Memory and time grow with the input's area (the input
/// blob and every activation map): 2048 keeps a CPU forward pass within a few hundred megabytes; an
/// input of 32000 once asked for 23.8 GB.
pub const MAX_INPUT_SIZE: i32 = 2048;

/// More tiles than this across a KITTI frame would be narrower than the objects they should hold.
pub const MAX_TILES: u32 = 16;

/// How frames are fed to the network, by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ModeName {
    /// Resize to the input, ignoring the aspect ratio.
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

/// The detector models shipped in `fixtures/`, by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ShippedModel {
    /// YOLOX-nano (COCO, ONNX, Apache-2.0; `fixtures/yolox_nano`): the default.
    #[default]
    YoloxNano,
    /// Yolo-Fastest 1.1 (COCO, Darknet, public domain; `fixtures/detector`).
    YoloFastest,
}

impl ShippedModel {
    /// Name, as on a command line.
    pub fn name(self) -> &'static str {
        match self {
            ShippedModel::YoloxNano => "yolox-nano",
            ShippedModel::YoloFastest => "yolo-fastest",
        }
    }

    /// Its family's settings ([`DetectorConfig::yolox`], [`DetectorConfig::yolo_fastest`]).
    pub fn config(self) -> DetectorConfig {
        match self {
            ShippedModel::YoloxNano => DetectorConfig::yolox(),
            ShippedModel::YoloFastest => DetectorConfig::yolo_fastest(),
        }
    }
}

/// A network's output layout by name (the `--family` of an ONNX model).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum FamilyName {
    /// YOLOX: grid cells of strides 8, 16, 32, input BGR 0–255 ([`ModelFamily::Yolox`]).
    Yolox,
    /// Darknet-style YOLO rows, normalised boxes, input RGB 0–1 ([`ModelFamily::Rows`]).
    Rows,
}

impl FamilyName {
    /// The family.
    pub fn family(self) -> ModelFamily {
        match self {
            FamilyName::Yolox => ModelFamily::Yolox,
            FamilyName::Rows => ModelFamily::Rows,
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
    /// A family given for a Darknet model (Darknet's YOLO layers always give rows).
    #[error("family is a setting of an ONNX model; a Darknet model (cfg and weights) always gives rows")]
    FamilyWithoutOnnx,
    /// A shipped model named together with model files.
    #[error("model names a shipped model; with model files (onnx, or cfg and weights) give no model")]
    ModelWithFiles,
    /// A runtime setting (`device`, `detector_threads`) given for a Darknet model, which runs on OpenCV's CPU backend.
    #[error("{0} is a setting of ONNX models (ONNX Runtime); a Darknet model (cfg and weights) runs on OpenCV's dnn module on the CPU")]
    RuntimeWithDarknet(&'static str),
    /// The model files could not be loaded.
    #[error(transparent)]
    Load(#[from] DetectorError),
}

/// A [`ModelError`] in a command line's words, where each setting is an option (`tiles` is `--tiles`,
/// `threads` is `--detector-threads`): what `slam-app detect`, `run` and `detect-recall` print.
#[derive(Debug, thiserror::Error)]
pub enum OptionError {
    /// An option out of its range, named as an option.
    #[error(transparent)]
    Invalid(InvalidValue),
    /// Options that do not go together.
    #[error("{0}")]
    Conflict(String),
    /// The model files could not be loaded.
    #[error(transparent)]
    Load(DetectorError),
}

impl ModelError {
    /// The error with the settings named as command-line options.
    pub fn as_options(self) -> OptionError {
        let conflict = |s: String| OptionError::Conflict(s);
        match self {
            ModelError::Invalid(v) => OptionError::Invalid(v.as_flag()),
            ModelError::TilesWithoutTiling(m) => {
                conflict(format!("--tiles is an option of --mode tiles, but --mode {m} was given"))
            }
            ModelError::FamilyWithoutOnnx => conflict("--family is an option of --onnx".into()),
            ModelError::ModelWithFiles => {
                conflict("--model names a shipped model: give it without --onnx/--cfg/--weights".into())
            }
            ModelError::RuntimeWithDarknet(key) => conflict(format!(
                "--{} is an option of ONNX models (ONNX Runtime); a Darknet model runs on OpenCV's CPU backend",
                key.replace('_', "-")
            )),
            ModelError::Load(e) => OptionError::Load(e),
        }
    }
}

/// A detector model and its settings; `None` fields take the defaults of the model's family.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ModelSpec {
    /// A shipped model by name (default: YOLOX-nano, unless model files are given).
    pub model: Option<ShippedModel>,
    /// Darknet .cfg (the rows family; default: the shipped Yolo-Fastest's).
    pub cfg: Option<PathBuf>,
    /// Darknet .weights (default: the shipped Yolo-Fastest's).
    pub weights: Option<PathBuf>,
    /// An ONNX model.
    pub onnx: Option<PathBuf>,
    /// The ONNX model's output layout (default: YOLOX).
    pub family: Option<FamilyName>,
    /// Input mode (default: the family's: letterbox for YOLOX, tiles for rows).
    pub mode: Option<ModeName>,
    /// Tiles across the width (mode tiles only; default 3).
    pub tiles: Option<u32>,
    /// Network input `[width, height]`, multiples of 32 (default: 736 × 224 for YOLOX, 320 × 320 for
    /// rows).
    pub input_size: Option<InputSize>,
    /// Smallest score kept (default: 0.4 for YOLOX, 0.2 for rows).
    pub score: Option<f32>,
    /// Where ONNX Runtime runs an ONNX model (default: the CPU).
    pub device: Option<Device>,
    /// ONNX Runtime's intra-op threads on the CPU (default [`DEFAULT_THREADS`]).
    pub threads: Option<usize>,
}

/// A network input size as the user wrote it: `W`x`H`, or one number for a square input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputSize {
    /// `[width, height]`, pixels.
    pub size: [i32; 2],
    /// Written as one number (`320`) rather than as `WxH`.
    pub square: bool,
}

impl InputSize {
    /// A square input of `n` pixels a side, written `n`.
    pub fn square(n: i32) -> Self {
        Self { size: [n, n], square: true }
    }

    /// An input of `w × h` pixels, written `WxH`.
    pub fn wide(w: i32, h: i32) -> Self {
        Self { size: [w, h], square: false }
    }
}

impl std::fmt::Display for InputSize {
    /// As written: `320`, `736x224`, `0x0`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.square {
            write!(f, "{}", self.size[0])
        } else {
            write!(f, "{}x{}", self.size[0], self.size[1])
        }
    }
}

/// Parse an input size: `W` x `H` (`736x224`) or one number for a square input (`320`).
pub fn parse_input_size(s: &str) -> Result<InputSize, String> {
    let num =
        |t: &str| t.trim().parse::<i32>().map_err(|_| format!("'{s}': expected WIDTHxHEIGHT (736x224) or N (320)"));
    match s.split_once(['x', 'X']) {
        Some((w, h)) => Ok(InputSize::wide(num(w)?, num(h)?)),
        None => num(s).map(InputSize::square),
    }
}

impl ModelSpec {
    /// A shipped model with its own settings.
    pub fn shipped(model: ShippedModel) -> Self {
        Self { model: Some(model), ..Self::default() }
    }

    /// The first setting given, as its command-line option (`--model`, …, `--detector-threads`): these
    /// options only make sense with a network.
    pub fn first_given(&self) -> Option<&'static str> {
        [
            (self.model.is_some(), "--model"),
            (self.cfg.is_some(), "--cfg"),
            (self.weights.is_some(), "--weights"),
            (self.onnx.is_some(), "--onnx"),
            (self.family.is_some(), "--family"),
            (self.mode.is_some(), "--mode"),
            (self.tiles.is_some(), "--tiles"),
            (self.input_size.is_some(), "--input-size"),
            (self.score.is_some(), "--score"),
            (self.device.is_some(), "--device"),
            (self.threads.is_some(), "--detector-threads"),
        ]
        .into_iter()
        .find_map(|(given, flag)| given.then_some(flag))
    }

    /// The detectors `slam-app detect-recall` compares by default: both shipped models with their own
    /// settings; with `all`, also their other input modes (YOLOX-nano in 3 tiles and squashed,
    /// Yolo-Fastest squashed and letterboxed).
    pub fn recall_candidates(all: bool) -> Vec<ModelSpec> {
        let (yolox, fastest) = (ShippedModel::YoloxNano, ShippedModel::YoloFastest);
        let mut v = vec![ModelSpec::shipped(yolox), ModelSpec::shipped(fastest)];
        if all {
            let with = |model, mode, tiles| ModelSpec { mode: Some(mode), tiles, ..ModelSpec::shipped(model) };
            v.extend([
                with(yolox, ModeName::Tiles, Some(3)),
                with(yolox, ModeName::Squash, None),
                with(fastest, ModeName::Squash, None),
                with(fastest, ModeName::Letterbox, None),
            ]);
        }
        v
    }

    /// Range checks and the settings' consistency (before any model is loaded).
    pub fn check(&self) -> Result<(), ModelError> {
        self.config().map(drop)
    }

    /// The family of the model this specification names.
    fn base(&self) -> Result<DetectorConfig, ModelError> {
        if self.family.is_some() && self.onnx.is_none() {
            return Err(ModelError::FamilyWithoutOnnx);
        }
        if self.model.is_some() && (self.onnx.is_some() || self.cfg.is_some() || self.weights.is_some()) {
            return Err(ModelError::ModelWithFiles);
        }
        Ok(match (&self.onnx, &self.cfg, &self.weights) {
            (Some(_), _, _) => match self.family.unwrap_or(FamilyName::Yolox) {
                FamilyName::Yolox => DetectorConfig::yolox(),
                FamilyName::Rows => DetectorConfig::yolo_fastest(),
            },
            (None, Some(_), _) | (None, _, Some(_)) => DetectorConfig::yolo_fastest(),
            (None, None, None) => self.model.unwrap_or_default().config(),
        })
    }

    /// The detector settings this specification describes.
    pub fn config(&self) -> Result<DetectorConfig, ModelError> {
        let base = self.base()?;
        let input = self.input_size.map_or(base.input, |s| s.size);
        for v in input {
            if !(32..=MAX_INPUT_SIZE).contains(&v) || v % 32 != 0 {
                let valid =
                    format!("multiples of 32 in [32, {MAX_INPUT_SIZE}], each side (memory grows with the area)");
                // the value as written (`0x0` stays `0x0`)
                let value = self.input_size.map_or_else(|| format!("{}x{}", input[0], input[1]), |s| s.to_string());
                return Err(InvalidValue { key: "input_size".into(), value, valid }.into());
            }
        }
        count("tiles", self.tiles.unwrap_or(3) as usize, 1, MAX_TILES as usize)?;
        count("detector_threads", self.threads.unwrap_or(DEFAULT_THREADS), 1, MAX_THREADS)?;
        if !self.on_onnx_runtime() {
            if self.device.is_some() {
                return Err(ModelError::RuntimeWithDarknet("device"));
            }
            if self.threads.is_some() {
                return Err(ModelError::RuntimeWithDarknet("detector_threads"));
            }
        }
        let score = self.score.unwrap_or(base.score_threshold);
        number("score", score as f64, Range::closed(0.0, 1.0), "")?;
        let mode = match (self.mode, self.tiles) {
            (None, None) => base.mode,
            (None | Some(ModeName::Tiles), t) => InputMode::Tiles(t.unwrap_or(3)),
            (Some(m), Some(_)) => return Err(ModelError::TilesWithoutTiling(m.name())),
            (Some(ModeName::Squash), None) => InputMode::Squash,
            (Some(ModeName::Letterbox), None) => InputMode::Letterbox,
        };
        Ok(DetectorConfig { input, mode, score_threshold: score, ..base })
    }

    /// Whether the model is an ONNX model (run on ONNX Runtime), not a Darknet one (run on OpenCV).
    pub fn on_onnx_runtime(&self) -> bool {
        match (&self.onnx, &self.cfg, &self.weights) {
            (Some(_), _, _) => true,
            (None, Some(_), _) | (None, _, Some(_)) => false,
            (None, None, None) => self.model.unwrap_or_default() == ShippedModel::YoloxNano,
        }
    }

    /// How ONNX Runtime runs the model: the device and threads given (or their defaults), the runtime
    /// library recorded in `setup_dir` (unless `ORT_DYLIB_PATH` names one).
    pub fn runtime(&self, setup_dir: &Path) -> RuntimeOptions {
        RuntimeOptions {
            device: self.device.unwrap_or_default(),
            threads: self.threads.unwrap_or(DEFAULT_THREADS),
            setup_dir: setup_dir.to_path_buf(),
        }
    }

    /// A short description: the model and its settings (`yolox-nano, letterbox 736x224, score 0.4`).
    pub fn describe(&self) -> Result<String, ModelError> {
        let c = self.config()?;
        let name = match (&self.onnx, &self.cfg, &self.weights) {
            (Some(m), _, _) => format!("{} ({})", m.display(), c.family.name()),
            (None, Some(_), _) | (None, _, Some(_)) => "darknet model (rows)".to_string(),
            (None, None, None) => self.model.unwrap_or_default().name().to_string(),
        };
        let mode = match c.mode {
            InputMode::Squash => "squash".to_string(),
            InputMode::Letterbox => "letterbox".to_string(),
            InputMode::Tiles(n) => format!("whole frame + {n} tiles"),
        };
        let runtime = match (self.on_onnx_runtime(), self.device.unwrap_or_default()) {
            (false, _) => String::new(),
            (true, Device::Cpu) => {
                let asked = self.threads.unwrap_or(DEFAULT_THREADS);
                match crate::onnx::capped_threads(asked) {
                    Some(cores) => {
                        format!(", cpu {cores} threads ({asked} asked: as many as the cores this process may use)")
                    }
                    None => format!(", cpu {asked} thread{}", if asked == 1 { "" } else { "s" }),
                }
            }
            (true, Device::Cuda) => ", cuda".to_string(),
        };
        Ok(format!("{name}, {mode} {}x{}, score {}{runtime}", c.input[0], c.input[1], c.score_threshold))
    }

    /// Load the network; `fixtures` is the folder holding the shipped models (`yolox_nano/` and
    /// `detector/`), used for a shipped model and for whichever Darknet file is not given; `setup_dir` the
    /// folder where `tools/setup.sh` records ONNX Runtime's library ([`RuntimeOptions::setup_dir`]).
    pub fn load(&self, fixtures: &Path, setup_dir: &Path) -> Result<DnnDetector, ModelError> {
        let config = self.config()?;
        let runtime = self.runtime(setup_dir);
        let darknet = |cfg: &Option<PathBuf>, weights: &Option<PathBuf>, config| {
            let shipped = fixtures.join("detector");
            let cfg = cfg.clone().unwrap_or_else(|| shipped.join("yolo-fastest-1.1.cfg"));
            let weights = weights.clone().unwrap_or_else(|| shipped.join("yolo-fastest-1.1.weights"));
            DnnDetector::from_darknet(cfg, weights, config)
        };
        Ok(match (&self.onnx, &self.cfg, &self.weights) {
            (Some(m), _, _) => DnnDetector::from_onnx(m, config, &runtime)?,
            (None, Some(_), _) | (None, _, Some(_)) => darknet(&self.cfg, &self.weights, config)?,
            (None, None, None) => match self.model.unwrap_or_default() {
                ShippedModel::YoloxNano => {
                    DnnDetector::from_onnx(fixtures.join("yolox_nano/yolox_nano.onnx"), config, &runtime)?
                }
                ShippedModel::YoloFastest => darknet(&None, &None, config)?,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_are_checked_and_mapped() {
        let c = ModelSpec::default().config().expect("defaults");
        assert_eq!(c, DetectorConfig::yolox());
        assert_eq!((c.input, c.mode, c.family), ([736, 224], InputMode::Letterbox, ModelFamily::Yolox));
        let fastest = ModelSpec::shipped(ShippedModel::YoloFastest).config().expect("yolo-fastest");
        assert_eq!(fastest, DetectorConfig::yolo_fastest());
        // a Darknet file alone selects the rows family and its defaults
        let darknet = ModelSpec { cfg: Some("m.cfg".into()), ..Default::default() }.config().expect("darknet");
        assert_eq!((darknet.family, darknet.mode), (ModelFamily::Rows, InputMode::Tiles(3)));
        let rows = ModelSpec { onnx: Some("m.onnx".into()), family: Some(FamilyName::Rows), ..Default::default() };
        assert_eq!(rows.config().expect("rows").family, ModelFamily::Rows);
        let s = ModelSpec {
            model: Some(ShippedModel::YoloFastest),
            mode: Some(ModeName::Letterbox),
            input_size: Some(InputSize::square(416)),
            score: Some(0.5),
            ..Default::default()
        };
        let c = s.config().expect("valid");
        assert_eq!((c.mode, c.input, c.score_threshold), (InputMode::Letterbox, [416, 416], 0.5));
        assert_eq!(
            ModelSpec { tiles: Some(5), ..Default::default() }.config().expect("tiles").mode,
            InputMode::Tiles(5)
        );
        for (bad, want) in [
            (
                ModelSpec { input_size: Some(InputSize::square(100)), ..Default::default() },
                "input_size 100: must be multiples of 32",
            ),
            (ModelSpec { input_size: Some(InputSize::wide(736, 230)), ..Default::default() }, "input_size 736x230"),
            (ModelSpec { input_size: Some(InputSize::square(4096)), ..Default::default() }, "input_size 4096"),
            (ModelSpec { input_size: Some(InputSize::wide(0, 0)), ..Default::default() }, "input_size 0x0: must be"),
            (ModelSpec { tiles: Some(0), ..Default::default() }, "tiles 0: must be an integer in [1, 16]"),
            (ModelSpec { score: Some(f32::NAN), ..Default::default() }, "score NaN"),
            (ModelSpec { mode: Some(ModeName::Squash), tiles: Some(2), ..Default::default() }, "mode squash was given"),
            (
                ModelSpec { family: Some(FamilyName::Yolox), ..Default::default() },
                "family is a setting of an ONNX model",
            ),
            (
                ModelSpec { model: Some(ShippedModel::YoloxNano), onnx: Some("m.onnx".into()), ..Default::default() },
                "give no model",
            ),
        ] {
            let e = bad.check().expect_err(want).to_string();
            assert!(e.contains(want), "{e}");
        }
        let missing = ModelSpec { onnx: Some("/nonexistent/model.onnx".into()), ..Default::default() };
        assert!(matches!(missing.load(Path::new("/nonexistent"), Path::new("/nonexistent")), Err(ModelError::Load(_))));
        assert_eq!(
            ModelSpec::default().describe().expect("valid"),
            "yolox-nano, letterbox 736x224, score 0.4, cpu 1 thread"
        );
        let two = ModelSpec { threads: Some(2), ..Default::default() };
        assert_eq!(two.describe().expect("valid"), "yolox-nano, letterbox 736x224, score 0.4, cpu 2 threads");
        let cuda = ModelSpec { device: Some(Device::Cuda), ..Default::default() };
        assert!(cuda.describe().expect("valid").ends_with(", cuda"));
        let fastest = ModelSpec::shipped(ShippedModel::YoloFastest).describe().expect("valid");
        assert_eq!(fastest, "yolo-fastest, whole frame + 3 tiles 320x320, score 0.2", "OpenCV: no runtime settings");
        // the runtime's settings are an ONNX model's; a thread count is range-checked
        for (bad, want) in [
            (
                ModelSpec { model: Some(ShippedModel::YoloFastest), device: Some(Device::Cuda), ..Default::default() },
                "device is a setting of ONNX models",
            ),
            (
                ModelSpec { cfg: Some("m.cfg".into()), threads: Some(2), ..Default::default() },
                "detector_threads is a setting",
            ),
            (ModelSpec { threads: Some(0), ..Default::default() }, "detector_threads 0: must be an integer in [1, 64]"),
        ] {
            let e = bad.check().expect_err(want).to_string();
            assert!(e.contains(want), "{e}");
        }
        let rt = ModelSpec { threads: Some(2), ..Default::default() }.runtime(Path::new("/setup"));
        assert_eq!((rt.device, rt.threads, rt.setup_dir), (Device::Cpu, 2, PathBuf::from("/setup")));
    }

    #[test]
    fn input_sizes_parse_as_width_by_height_or_one_side() {
        assert_eq!(parse_input_size("736x224"), Ok(InputSize::wide(736, 224)));
        assert_eq!(parse_input_size("320"), Ok(InputSize::square(320)));
        assert_eq!(parse_input_size("640X192").map(|s| s.size), Ok([640, 192]));
        assert_eq!(parse_input_size("0x0").map(|s| s.to_string()), Ok("0x0".to_string()));
        assert!(parse_input_size("736x").is_err() && parse_input_size("wide").is_err());
    }
}
