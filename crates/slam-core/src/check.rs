//! Range checks of settings and options: a value against its valid interval ([`number`], [`count`]),
//! failing with an [`InvalidValue`] that names the key, the value given and what is valid. The settings
//! structs of the library crates check themselves with these (`validate()` methods); the front ends add
//! where the key came from (a file and table, or a command-line flag).

/// A value outside its valid range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key} {value}: must be {valid}")]
pub struct InvalidValue {
    /// The key (a settings field such as `ransac_px`, or an option such as `--noise`).
    pub key: String,
    /// The value given, as printed.
    pub value: String,
    /// What is valid, e.g. `a finite number in (0, 1000] px`.
    pub valid: String,
}

impl InvalidValue {
    /// The same error under another key name (e.g. a table prefix).
    pub fn rename(self, key: impl Into<String>) -> Self {
        Self { key: key.into(), ..self }
    }

    /// The same error under the command-line flag of its key (`min_frames` → `--min-frames`).
    pub fn as_flag(self) -> Self {
        let key = format!("--{}", self.key.replace('_', "-"));
        self.rename(key)
    }
}

/// An interval of valid values, printed in messages as `[lo, hi]`, `(lo, hi]`, ….
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    lo: f64,
    hi: f64,
    lo_open: bool,
    hi_open: bool,
}

impl Range {
    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64) -> Self {
        Self { lo, hi, lo_open: false, hi_open: false }
    }
    /// `(lo, hi]`.
    pub const fn above(lo: f64, hi: f64) -> Self {
        Self { lo, hi, lo_open: true, hi_open: false }
    }
    /// `(lo, hi)`.
    pub const fn open(lo: f64, hi: f64) -> Self {
        Self { lo, hi, lo_open: true, hi_open: true }
    }
    /// The same range without its upper end: `[lo, hi)`.
    pub const fn with_hi_open(mut self) -> Self {
        self.hi_open = true;
        self
    }

    /// Whether `v` is finite and inside.
    pub fn contains(&self, v: f64) -> bool {
        v.is_finite()
            && (if self.lo_open { v > self.lo } else { v >= self.lo })
            && (if self.hi_open { v < self.hi } else { v <= self.hi })
    }
}

impl std::fmt::Display for Range {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // a bound computed from others (`--range / 10000`) carries float noise (5.9999999999999995e-5):
        // shown to 12 significant digits, which no setting needs more of
        let num = |v: f64| {
            if v.is_infinite() {
                "∞".to_string()
            } else {
                format!("{}", format!("{v:.11e}").parse::<f64>().unwrap_or(v))
            }
        };
        write!(
            f,
            "{}{}, {}{}",
            if self.lo_open { "(" } else { "[" },
            num(self.lo),
            num(self.hi),
            if self.hi_open || self.hi.is_infinite() { ")" } else { "]" }
        )
    }
}

/// A command-line value that must be a finite number of at least 0 (a `clap` value parser's shape:
/// the message names the text and what is wrong with it).
pub fn non_negative_text(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        Ok(v) => Err(format!("{v} is not a finite number at least 0")),
        Err(e) => Err(format!("'{text}': {e}")),
    }
}

/// A number as a message shows it: as Rust writes it, but in exponent form beyond 16 digits or below
/// 1e-6 (`1e300`, not three hundred digits).
pub fn number_text(v: f64) -> String {
    if v.is_finite() && v != 0.0 && (v.abs() >= 1e16 || v.abs() < 1e-6) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// `key` must be a finite number in `range`; `unit` is appended to the range in the message.
pub fn number(key: &str, v: f64, range: Range, unit: &str) -> Result<(), InvalidValue> {
    if range.contains(v) {
        return Ok(());
    }
    let unit = if unit.is_empty() { String::new() } else { format!(" {unit}") };
    Err(InvalidValue {
        key: key.to_string(),
        value: number_text(v),
        valid: format!("a finite number in {range}{unit}"),
    })
}

/// A count `key` must lie in `[lo, hi]` (`hi = usize::MAX`: no upper bound).
pub fn count(key: &str, v: usize, lo: usize, hi: usize) -> Result<(), InvalidValue> {
    if (lo..=hi).contains(&v) {
        return Ok(());
    }
    let valid = if hi == usize::MAX { format!("at least {lo}") } else { format!("an integer in [{lo}, {hi}]") };
    Err(InvalidValue { key: key.to_string(), value: v.to_string(), valid })
}

/// Largest distance of a camera's principal point from its image's centre, as a share of the image's
/// width (for `cx`) or height (for `cy`). A lens sits on the middle of its sensor to within a few per
/// cent and rectification keeps the principal point near the middle of the common view (KITTI: 1 % on
/// the odometry pair, 4 % vertically on the raw pair); 20 % still lets a user crop a few hundred pixels
/// off one side, but images of half the calibrated size put the principal point at their corner (48 %)
/// and images of twice the size at their first quarter (25 %).
pub const PRINCIPAL_POINT_OFF_CENTRE: f64 = 0.2;

/// Widest and narrowest field of view of a camera the system takes, degrees: a rectified pinhole
/// image cannot show 180° (170° leaves the fisheyes out), and under 1° is a telescope.
pub const FIELD_OF_VIEW_DEG: (f64, f64) = (1.0, 170.0);

/// Largest side of an image, pixels: what the image readers take (an 8-bit colour image of 8192 ×
/// 8192 is 192 MiB decoded).
pub const MAX_IMAGE_SIDE_PX: f64 = 8192.0;

/// A rectified stereo camera that can be right, as a calibration or a saved map states it: the image
/// `width` and `height` whole pixels in [1, [`MAX_IMAGE_SIDE_PX`]]; `fx` giving a field of view within
/// [`FIELD_OF_VIEW_DEG`] over the width; `fy` within a factor 2 of `fx` (pixels no more than twice as
/// tall as wide); the principal point inside the image and within [`PRINCIPAL_POINT_OFF_CENTRE`] of
/// its centre; a baseline in (0, 10] m (the right camera to the right of the left one; no vehicle is
/// wider than 10 m). Keys: `fx`, `fy`, `cx`, `cy`, `baseline`, `width`, `height`.
pub fn stereo_camera([fx, fy, cx, cy]: [f64; 4], baseline: f64, (w, h): (f64, f64)) -> Result<(), InvalidValue> {
    for (key, side) in [("width", w), ("height", h)] {
        number(key, side, Range::closed(1.0, MAX_IMAGE_SIDE_PX), "px")?;
        if side.fract() != 0.0 {
            return Err(InvalidValue {
                key: key.into(),
                value: side.to_string(),
                valid: "a whole number of pixels".into(),
            });
        }
    }
    let focal = |fov_deg: f64| w / (2.0 * (fov_deg.to_radians() / 2.0).tan());
    let (narrow, wide) = FIELD_OF_VIEW_DEG;
    let fov = |f: f64| 2.0 * (w / (2.0 * f)).atan().to_degrees();
    number(
        "fx",
        fx,
        Range::closed(focal(wide), focal(narrow)),
        &format!("px (a field of view of {narrow}°–{wide}° over an image {w} px wide; given: {:.1}°)", fov(fx)),
    )?;
    number("fy", fy, Range::closed(fx / 2.0, fx * 2.0), "px (within a factor 2 of fx)")?;
    let off = PRINCIPAL_POINT_OFF_CENTRE;
    let near_centre = |side: f64| Range::closed(side * (0.5 - off), side * (0.5 + off));
    let why = format!("px (inside the image and within {:.0} % of its size from its centre)", 100.0 * off);
    number("cx", cx, near_centre(w), &why)?;
    number("cy", cy, near_centre(h), &why)?;
    number("baseline", baseline, Range::above(0.0, 10.0), "m")
}

#[cfg(test)]
mod tests {

    #[test]
    fn non_negative_text_takes_finite_numbers_from_zero() {
        assert_eq!(non_negative_text(" 0.25 "), Ok(0.25));
        assert_eq!(non_negative_text("0"), Ok(0.0));
        assert!(non_negative_text("-0.1").unwrap_err().contains("not a finite number at least 0"));
        assert!(non_negative_text("inf").unwrap_err().contains("not a finite number"));
        assert!(non_negative_text("ten").unwrap_err().starts_with("'ten'"));
    }
    use super::*;

    #[test]
    fn a_key_becomes_its_flag() {
        let e = count("min_frames", 0, 1, 10).expect_err("out of range").as_flag();
        assert_eq!(e.to_string(), "--min-frames 0: must be an integer in [1, 10]");
    }

    #[test]
    fn messages_name_the_key_the_value_and_the_range() {
        let e = number("ransac_px", f64::NAN, Range::above(0.0, 1000.0), "px").expect_err("NaN");
        assert_eq!(e.to_string(), "ransac_px NaN: must be a finite number in (0, 1000] px");
        assert_eq!(e.clone().rename("[tracking] ransac_px").key, "[tracking] ransac_px");
        let e = number("x", 1.0, Range::closed(0.0, 1.0).with_hi_open(), "").expect_err("open end");
        assert_eq!(e.valid, "a finite number in [0, 1)");
        assert!(number("x", 1.0, Range::closed(0.0, f64::INFINITY), "").is_ok());
        assert_eq!(
            number("x", -1.0, Range::closed(0.0, f64::INFINITY), "m").expect_err("neg").valid,
            "a finite number in [0, ∞) m"
        );
        assert_eq!(count("n", 0, 1, usize::MAX).expect_err("zero").to_string(), "n 0: must be at least 1");
        assert_eq!(count("n", 7, 1, 5).expect_err("big").to_string(), "n 7: must be an integer in [1, 5]");
        assert!(count("n", 5, 1, 5).is_ok() && number("x", 0.0, Range::open(0.0, 1.0), "").is_err());
        // a bound computed from another carries no float noise into the message
        let e = number("--step", 0.0, Range::above(0.6 / 10_000.0, 0.6), "px").expect_err("zero");
        assert_eq!(e.valid, "a finite number in (0.00006, 0.6] px");
        assert_eq!(Range::closed(0.1 + 0.2, 1000.0).to_string(), "[0.3, 1000]");
    }

    /// A camera block that cannot be right is refused naming the value: KITTI's odometry camera
    /// passes; a focal length of 1e300 px or 0, a negative one, a baseline of 0 or below, a fractional
    /// or empty image are each refused.
    #[test]
    fn impossible_cameras_are_refused_naming_the_value() {
        let kitti = ([707.0912, 707.0912, 601.8873, 183.1104], 0.5372, (1226.0, 370.0));
        stereo_camera(kitti.0, kitti.1, kitti.2).expect("KITTI's odometry camera");
        let with = |i: usize, v: f64| {
            let mut k = kitti.0;
            k[i] = v;
            stereo_camera(k, kitti.1, kitti.2).expect_err("refused").to_string()
        };
        assert!(with(0, 1e300).starts_with("fx 1e300: must be"), "{}", with(0, 1e300));
        assert!(with(0, 0.0).contains("field of view"), "{}", with(0, 0.0));
        assert!(with(0, -707.0).starts_with("fx -707"));
        assert!(with(1, 100.0).starts_with("fy 100"));
        assert!(with(2, 20.0).starts_with("cx 20"));
        assert!(with(3, f64::NAN).starts_with("cy NaN"));
        for b in [0.0, -0.537, f64::INFINITY] {
            let e = stereo_camera(kitti.0, b, kitti.2).expect_err("baseline").to_string();
            assert!(e.starts_with("baseline") && e.contains("(0, 10] m"), "{e}");
        }
        assert!(stereo_camera(kitti.0, kitti.1, (1226.5, 370.0))
            .expect_err("half pixel")
            .to_string()
            .starts_with("width"));
        assert!(stereo_camera(kitti.0, kitti.1, (1226.0, 0.0)).expect_err("empty").to_string().starts_with("height 0"));
    }
}
