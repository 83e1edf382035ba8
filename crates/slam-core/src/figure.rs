//! Figures of sets that may be empty. A mean, share or median over nothing is no figure: these
//! functions give `None` for it (never NaN, never a 0 that reads as a perfect score), and the table and
//! CSV writers of every study print such a figure as [`DASH`] (a table cell) or an empty field (CSV).
//! One rule for every report: `eval`, `track-bench`, `run-bench`, `detect-recall` and a run's summary.

/// How a table shows a figure that does not exist (the mean of no vehicle, the median of no frame).
pub const DASH: &str = "–";

/// `sum / n`, or `None` when `n` is 0.
pub fn mean(sum: f64, n: usize) -> Option<f64> {
    (n > 0).then(|| sum / n as f64)
}

/// `part / whole` as counts, or `None` when `whole` is 0 (a share of nothing).
pub fn share(part: usize, whole: usize) -> Option<f64> {
    (whole > 0).then(|| part as f64 / whole as f64)
}

/// The upper median (the element at `len / 2` after sorting), or `None` for no values. Sorts `v`.
pub fn median(v: &mut [f64]) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied()
}

/// A table cell: the figure with `digits` decimals, or [`DASH`] when there is none (or it is not
/// finite: a figure computed from a set that was empty in part).
pub fn cell(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}"),
        _ => DASH.to_string(),
    }
}

/// [`cell`] with a unit after the number (`0.453 m`); the dash goes without it.
pub fn cell_unit(v: Option<f64>, digits: usize, unit: &str) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.digits$}{unit}"),
        _ => DASH.to_string(),
    }
}

/// A CSV field: the figure in full precision, or an empty field when there is none.
pub fn csv(v: Option<f64>) -> String {
    match v {
        Some(x) if x.is_finite() => x.to_string(),
        _ => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_set_has_no_figure_and_prints_a_dash() {
        assert_eq!(mean(3.0, 2), Some(1.5));
        assert_eq!(mean(0.0, 0), None, "the mean of nothing is not 0");
        assert_eq!(share(1, 4), Some(0.25));
        assert_eq!(share(0, 0), None);
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&mut []), None);
        assert_eq!(cell(Some(0.12345), 3), "0.123");
        assert_eq!(cell(None, 3), DASH);
        assert_eq!(cell(Some(f64::NAN), 3), DASH, "NaN never reaches a table");
        assert_eq!(cell_unit(Some(2.0), 1, " m"), "2.0 m");
        assert_eq!(cell_unit(None, 1, " m"), DASH);
        assert_eq!(csv(Some(0.5)), "0.5");
        assert_eq!(csv(None), "");
        assert_eq!(csv(Some(f64::INFINITY)), "");
    }
}
