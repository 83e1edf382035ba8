//! Plots of the simulation study (SVG and PNG through plotters, text with an embedded font).

use std::path::{Path, PathBuf};

use anyhow::Context;
use plotters::prelude::*;
use slam_sim::{CellStats, Geometry, Method, NoiseKind};

const COLORS: [RGBColor; 6] = [
    RGBColor(214, 39, 40),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(31, 119, 180),
    RGBColor(148, 103, 189),
    RGBColor(0, 0, 0),
];

fn register_font() {
    // The font ships inside a crates.io package (epaint_default_fonts, Ubuntu Light, Ubuntu Font Licence).
    let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, epaint_default_fonts::UBUNTU_LIGHT);
}

type Metric = (&'static str, fn(&CellStats) -> f64);

const METRICS: [Metric; 4] = [
    ("success rate", |c| c.success),
    ("median e_trans (m)", |c| c.e_trans_median),
    ("median e_axe (m)", |c| c.e_axe_median),
    ("mean IoU2D", |c| c.iou_mean),
];

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    cells: &[CellStats],
    g: Geometry,
    kinds: &[NoiseKind],
    methods: &[Method],
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let title = format!("Initialisation under noise, {} geometry", g.name());
    let root = root.titled(&title, ("sans-serif", 26)).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let panels = root.split_evenly((kinds.len(), METRICS.len()));
    for (pi, panel) in panels.iter().enumerate() {
        let kind = kinds[pi / METRICS.len()];
        let (mname, metric) = METRICS[pi % METRICS.len()];
        let levels = kind.levels();
        let xmax = levels.last().copied().unwrap_or(1.0);
        let mut ymax: f64 = if mname.contains("success") || mname.contains("IoU") { 1.0 } else { 0.0 };
        if ymax == 0.0 {
            for c in cells.iter().filter(|c| c.geometry == g && c.noise == kind) {
                let v = metric(c);
                if v.is_finite() {
                    ymax = ymax.max(v);
                }
            }
            ymax = (ymax * 1.1).clamp(0.05, 5.0);
        }
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("{} noise: {}", kind.name(), mname), ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(28)
            .y_label_area_size(40)
            .build_cartesian_2d(0f64..xmax, 0f64..ymax)
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        chart
            .configure_mesh()
            .x_desc("noise %")
            .light_line_style(WHITE)
            .draw()
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        for (mi, &m) in methods.iter().enumerate() {
            let color = COLORS[mi % COLORS.len()];
            let pts: Vec<(f64, f64)> = levels
                .iter()
                .filter_map(|&l| {
                    let c =
                        cells.iter().find(|c| c.geometry == g && c.noise == kind && c.level == l && c.method == m)?;
                    let v = metric(c);
                    v.is_finite().then_some((l, v.min(ymax)))
                })
                .collect();
            let series = chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
            if pi == 0 {
                series
                    .label(m.name())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
            }
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        }
        if pi == 0 {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::LowerLeft)
                .draw()
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        }
    }
    root.present().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    Ok(())
}

/// Write `sim_<geometry>.svg` and `.png` (a panel per noise kind and metric, a curve per method).
pub fn simulation_figure(
    cells: &[CellStats],
    g: Geometry,
    kinds: &[NoiseKind],
    methods: &[Method],
    out: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    register_font();
    let size = (1600, 300 * kinds.len() as u32 + 60);
    let stem = format!("sim_{}", g.name());
    let svg = out.join(format!("{stem}.svg"));
    let png = out.join(format!("{stem}.png"));
    draw(SVGBackend::new(&svg, size).into_drawing_area(), cells, g, kinds, methods)
        .with_context(|| format!("drawing {}", svg.display()))?;
    draw(BitMapBackend::new(&png, size).into_drawing_area(), cells, g, kinds, methods)
        .with_context(|| format!("drawing {}", png.display()))?;
    Ok(vec![svg, png])
}
