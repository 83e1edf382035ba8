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

/// The cells the targets name for Tri+Yaw+refine (docs/simulation.md): geometry, noise kind, level (%).
pub const TARGET_CELLS: [(Geometry, NoiseKind, f64); 4] = [
    (Geometry::Arc, NoiseKind::Box, 6.0),
    (Geometry::DriveBy, NoiseKind::Translation, 2.0),
    (Geometry::DriveBy, NoiseKind::Rotation, 2.0),
    (Geometry::DriveBy, NoiseKind::Box, 3.0),
];

/// Mean, sample standard deviation, least and largest of `x` (NaN for a mean of none; the deviation is
/// 0 for one value).
fn spread(x: &[f64]) -> (f64, f64, f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = if x.len() > 1 { x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0) } else { 0.0 };
    let (lo, hi) = x.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
    (mean, var.sqrt(), lo, hi)
}

/// How Tri+Yaw+refine's target cells ([`TARGET_CELLS`]) vary with the master seed: one sweep's cells
/// per seed (`runs`: seed and cells); per cell the success and the mean e_trans and e_axe of each seed,
/// as mean ± standard deviation over the seeds, with the least and largest. A cell's figure is a mean
/// over its 100 trials (10 objects × 10 noise seeds), whose own spread makes it move from seed to seed.
pub fn seed_spread(runs: &[(u64, Vec<CellStats>)]) -> String {
    let mut s = format!(
        "\n== Tri+Yaw+refine's target cells over {} master seeds ({}): mean ± sd [least, largest] of each seed's figure ==\n",
        runs.len(),
        runs.iter().map(|r| r.0.to_string()).collect::<Vec<_>>().join(", ")
    );
    let _ = writeln!(s, "{:<26} | {:<28} | {:<28} | {:<28}", "cell", "success", "e_trans mean (m)", "e_axe mean (m)");
    for (g, k, level) in TARGET_CELLS {
        let of = |f: fn(&CellStats) -> f64| -> Vec<f64> {
            runs.iter()
                .filter_map(|(_, cells)| {
                    cells.iter().find(|c| {
                        c.geometry == g && c.noise == k && c.level == level && c.method == Method::TriYawRefine
                    })
                })
                .map(f)
                .collect()
        };
        let col = |v: Vec<f64>, prec: usize| {
            if v.is_empty() {
                return "-".to_string();
            }
            let (m, sd, lo, hi) = spread(&v);
            format!("{} ± {} [{}, {}]", fmt(m, prec), fmt(sd, prec), fmt(lo, prec), fmt(hi, prec))
        };
        let _ = writeln!(
            s,
            "{:<26} | {:<28} | {:<28} | {:<28}",
            format!("{}, {} {}%", g.name(), k.name(), level),
            col(of(|c| c.success), 2),
            col(of(|c| c.e_trans_mean), 3),
            col(of(|c| c.e_axe_mean), 3)
        );
    }
    s
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

    #[test]
    fn the_seed_spread_gives_mean_deviation_and_range_per_target_cell() {
        let at = |e_trans: f64| CellStats {
            geometry: Geometry::DriveBy,
            noise: NoiseKind::Translation,
            level: 2.0,
            method: Method::TriYawRefine,
            trials: 100,
            success: 1.0,
            e_trans_mean: e_trans,
            e_trans_median: e_trans,
            e_axe_mean: 0.15,
            e_axe_median: 0.15,
            iou_mean: 0.9,
            iou_median: 0.9,
        };
        let runs = vec![(1, vec![at(0.4)]), (2, vec![at(0.5)]), (3, vec![at(0.6)])];
        let t = seed_spread(&runs);
        let line = t.lines().find(|l| l.starts_with("drive-by, translation 2%")).expect("the cell");
        // mean 0.5, sample sd 0.1, range 0.4-0.6
        assert!(line.contains("0.500 ± 0.100 [0.400, 0.600]") && line.contains("1.00 ± 0.00"), "{t}");
        // cells no run has print a dash
        assert!(t.lines().find(|l| l.starts_with("arc, box 6%")).is_some_and(|l| l.contains(" - ")), "{t}");
    }

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
