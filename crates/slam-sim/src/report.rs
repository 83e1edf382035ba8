//! The study's tables and CSV as text (`slam-app sim` prints and writes them): per geometry and noise
//! kind a table of every method's success, median errors and IoU2D over the noise levels; the breakdown
//! levels; and one CSV row per cell.

use std::fmt::Write as _;

use crate::{breakdown_level, CellStats, Geometry, Method, NoiseKind, SweepConfig};

/// `x` with `prec` decimals, `-` for NaN (no successful trial).
fn fmt(x: f64, prec: usize) -> String {
    if x.is_nan() {
        "-".into()
    } else {
        format!("{x:.prec$}")
    }
}

/// The table of one geometry and noise kind: a blank line, a title, a header and a row per noise level
/// (per method: success %, median e_trans m, median e_axe m, mean IoU2D); each line ends with a newline.
pub fn noise_table(cells: &[CellStats], g: Geometry, k: NoiseKind, methods: &[Method]) -> String {
    let mut out = format!(
        "\n== {} geometry, {} noise (per method: success %, median e_trans m, median e_axe m, mean IoU2D) ==\n",
        g.name(),
        k.name()
    );
    let mut header = format!("{:>6}", "p%");
    for m in methods {
        header.push_str(&format!(" | {:^26}", m.name()));
    }
    out += &header;
    out.push('\n');
    for &level in k.levels() {
        let mut row = format!("{:>6}", level);
        for &m in methods {
            if let Some(c) = cells.iter().find(|c| c.geometry == g && c.noise == k && c.level == level && c.method == m)
            {
                row.push_str(&format!(
                    " | {:>4.0} {:>6} {:>6} {:>6}",
                    100.0 * c.success,
                    fmt(c.e_trans_median, 3),
                    fmt(c.e_axe_median, 3),
                    fmt(c.iou_mean, 3)
                ));
            }
        }
        out += &row;
        out.push('\n');
    }
    out
}

/// The breakdown levels ([`breakdown_level`]) of every geometry, noise kind and method of `config`: a
/// blank line, a title, a header and a row per geometry and noise kind.
pub fn breakdown_table(cells: &[CellStats], config: &SweepConfig) -> String {
    let mut out =
        String::from("\nBreakdown level (smallest noise level with success < 50 %; '-' = never within the sweep):\n");
    let _ = writeln!(
        out,
        "{:<9} {:<12} {}",
        "geometry",
        "noise",
        config.methods.iter().map(|m| format!("{:>15}", m.name())).collect::<String>()
    );
    for &g in &config.geometries {
        for &k in &config.noise {
            let row: String = config
                .methods
                .iter()
                .map(|&m| {
                    format!("{:>15}", breakdown_level(cells, g, k, m).map(|l| format!("{l}%")).unwrap_or("-".into()))
                })
                .collect();
            let _ = writeln!(out, "{:<9} {:<12} {row}", g.name(), k.name());
        }
    }
    out
}

/// The study's title line.
pub fn title(config: &SweepConfig) -> String {
    format!(
        "Simulation study: master seed {} ({} objects x {} noise seeds = {} trials per cell)",
        config.seed,
        config.objects,
        config.noise_seeds,
        config.objects * config.noise_seeds
    )
}

/// Every table of the study: one per geometry and noise kind, then the breakdown.
pub fn tables(cells: &[CellStats], config: &SweepConfig) -> String {
    let mut text = String::new();
    for &g in &config.geometries {
        for &k in &config.noise {
            text.push_str(&noise_table(cells, g, k, &config.methods));
        }
    }
    text + &breakdown_table(cells, config)
}

/// The cells as CSV (a header, one row per cell).
pub fn csv(cells: &[CellStats]) -> Result<String, csv::Error> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record([
        "geometry",
        "noise",
        "level_percent",
        "method",
        "trials",
        "success",
        "e_trans_mean",
        "e_trans_median",
        "e_axe_mean",
        "e_axe_median",
        "iou_mean",
        "iou_median",
    ])?;
    for c in cells {
        w.write_record([
            c.geometry.name().to_string(),
            c.noise.name().to_string(),
            c.level.to_string(),
            c.method.name().to_string(),
            c.trials.to_string(),
            c.success.to_string(),
            c.e_trans_mean.to_string(),
            c.e_trans_median.to_string(),
            c.e_axe_mean.to_string(),
            c.e_axe_median.to_string(),
            c.iou_mean.to_string(),
            c.iou_median.to_string(),
        ])?;
    }
    let bytes = w.into_inner().map_err(|e| e.into_error())?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cell(level: f64, method: Method, success: f64) -> CellStats {
        CellStats {
            geometry: Geometry::Arc,
            noise: NoiseKind::Box,
            level,
            method,
            trials: 10,
            success,
            e_trans_mean: 0.5,
            e_trans_median: 0.25,
            e_axe_mean: 0.2,
            e_axe_median: f64::NAN,
            iou_mean: 0.75,
            iou_median: 0.8,
        }
    }

    #[test]
    fn tables_and_csv_show_every_cell() {
        let methods = [Method::TriYawRefine];
        let cells: Vec<CellStats> = NoiseKind::Box
            .levels()
            .iter()
            .enumerate()
            .map(|(i, &l)| cell(l, Method::TriYawRefine, if i < 2 { 1.0 } else { 0.2 }))
            .collect();
        let t = noise_table(&cells, Geometry::Arc, NoiseKind::Box, &methods);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 3 + NoiseKind::Box.levels().len(), "{t}");
        assert!(lines[1].starts_with("== arc geometry"), "{t}");
        // success in %, NaN median shown as '-'
        assert!(lines[3].ends_with(" |  100  0.250      -  0.750"), "{t}");
        let config = SweepConfig {
            geometries: vec![Geometry::Arc],
            noise: vec![NoiseKind::Box],
            methods: methods.to_vec(),
            ..SweepConfig::default()
        };
        let b = breakdown_table(&cells, &config);
        let third = NoiseKind::Box.levels()[2];
        assert!(b.lines().nth(3).expect("row").trim_end().ends_with(&format!("{third}%")), "{b}");
        let c = csv(&cells).expect("csv");
        assert_eq!(c.lines().count(), 1 + cells.len());
        assert!(c.lines().nth(1).expect("row").contains(",NaN,"), "{c}");
    }
}
