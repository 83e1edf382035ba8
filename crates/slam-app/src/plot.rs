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

/// Most map points drawn on the top-down map.
const MAX_POINTS: usize = 5000;

/// What the top-down map shows (x right, z forward of the first camera; metres).
pub struct TopDown<'a> {
    pub estimate: &'a [[f64; 2]],
    pub truth: Option<&'a [[f64; 2]]>,
    pub points: &'a [[f64; 2]],
    /// Ellipse outline (x, z) of each object, its id and whether it is dynamic.
    pub objects: &'a [(Vec<[f64; 2]>, u64, bool)],
}

fn draw_topdown<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    m: &TopDown<'_>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("{e:?}");
    root.fill(&WHITE).map_err(err)?;
    // frame: the trajectories and objects, plus a margin; points only inside it
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    let mut grow = |p: &[f64; 2]| {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    };
    m.estimate.iter().for_each(&mut grow);
    m.truth.unwrap_or(&[]).iter().for_each(&mut grow);
    m.objects.iter().flat_map(|o| o.0.iter()).for_each(&mut grow);
    if !lo[0].is_finite() {
        lo = [-10.0, -10.0];
        hi = [10.0, 10.0];
    }
    let margin = 15.0;
    let (mut x0, mut x1, mut z0, mut z1) = (lo[0] - margin, hi[0] + margin, lo[1] - margin, hi[1] + margin);
    // equal scale on both axes
    let (w, h) = (x1 - x0, z1 - z0);
    if w < h {
        let c = 0.5 * (x0 + x1);
        (x0, x1) = (c - 0.5 * h, c + 0.5 * h);
    } else {
        let c = 0.5 * (z0 + z1);
        (z0, z1) = (c - 0.5 * w, c + 0.5 * w);
    }
    let mut chart = ChartBuilder::on(&root)
        .caption("Top-down map (x right, z forward; metres)", ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(40)
        .build_cartesian_2d(x0..x1, z0..z1)
        .map_err(err)?;
    chart.configure_mesh().light_line_style(WHITE).x_desc("x (m)").y_desc("z (m)").draw().map_err(err)?;
    let grey = RGBColor(170, 170, 170);
    // at most MAX_POINTS drawn (evenly thinned), so the SVG stays small on long runs
    let inside: Vec<&[f64; 2]> = m.points.iter().filter(|p| p[0] > x0 && p[0] < x1 && p[1] > z0 && p[1] < z1).collect();
    let step = inside.len().div_ceil(MAX_POINTS).max(1);
    chart
        .draw_series(inside.iter().step_by(step).map(|p| Circle::new((p[0], p[1]), 1, grey.filled())))
        .map_err(err)?
        .label("map points")
        .legend(move |(x, y)| Circle::new((x + 8, y), 2, grey.filled()));
    if let Some(t) = m.truth {
        let c = RGBColor(44, 160, 44);
        chart
            .draw_series(LineSeries::new(t.iter().map(|p| (p[0], p[1])), c.stroke_width(2)))
            .map_err(err)?
            .label("ground truth")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
    }
    let c = RGBColor(31, 119, 180);
    chart
        .draw_series(LineSeries::new(m.estimate.iter().map(|p| (p[0], p[1])), c.stroke_width(2)))
        .map_err(err)?
        .label("estimate")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
    for (outline, id, dynamic) in m.objects {
        let colour = if *dynamic { RGBColor(214, 39, 40) } else { RGBColor(255, 127, 14) };
        let mut pts: Vec<(f64, f64)> = outline.iter().map(|p| (p[0], p[1])).collect();
        if let Some(&f) = pts.first() {
            pts.push(f);
        }
        chart.draw_series(std::iter::once(PathElement::new(pts.clone(), colour.stroke_width(2)))).map_err(err)?;
        if let Some(&(x, z)) = pts.iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{id}"),
                    (x, z + 1.0),
                    ("sans-serif", 14).into_font().color(&colour),
                )))
                .map_err(err)?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// Write the top-down map as `<stem>.svg` and `<stem>.png`.
pub fn topdown_figure(m: &TopDown<'_>, out: &Path, stem: &str) -> anyhow::Result<Vec<PathBuf>> {
    register_font();
    let size = (900, 900);
    let svg = out.join(format!("{stem}.svg"));
    let png = out.join(format!("{stem}.png"));
    draw_topdown(SVGBackend::new(&svg, size).into_drawing_area(), m)
        .with_context(|| format!("drawing {}", svg.display()))?;
    draw_topdown(BitMapBackend::new(&png, size).into_drawing_area(), m)
        .with_context(|| format!("drawing {}", png.display()))?;
    Ok(vec![svg, png])
}
