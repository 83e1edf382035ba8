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

/// `key` must be a finite number in `range`; `unit` is appended to the range in the message.
pub fn number(key: &str, v: f64, range: Range, unit: &str) -> Result<(), InvalidValue> {
    if range.contains(v) {
        return Ok(());
    }
    let unit = if unit.is_empty() { String::new() } else { format!(" {unit}") };
    Err(InvalidValue { key: key.to_string(), value: v.to_string(), valid: format!("a finite number in {range}{unit}") })
}

/// A count `key` must lie in `[lo, hi]` (`hi = usize::MAX`: no upper bound).
pub fn count(key: &str, v: usize, lo: usize, hi: usize) -> Result<(), InvalidValue> {
    if (lo..=hi).contains(&v) {
        return Ok(());
    }
    let valid = if hi == usize::MAX { format!("at least {lo}") } else { format!("an integer in [{lo}, {hi}]") };
    Err(InvalidValue { key: key.to_string(), value: v.to_string(), valid })
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
}
