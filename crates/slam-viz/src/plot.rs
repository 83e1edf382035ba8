//! Plots through plotters (SVG and PNG, text with an embedded font): the simulation study's figure
//! ([`simulation_figure`]) and the top-down map of a run ([`topdown_figure`]).

use std::path::{Path, PathBuf};

use plotters::prelude::*;
use slam_sim::{CellStats, Geometry, Method, NoiseKind};

use crate::VizError;

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
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(|e| format!("{e:?}"))?;
    let title = format!("Initialisation under noise, {} geometry", g.name());
    let root = root.titled(&title, ("sans-serif", 26)).map_err(|e| format!("{e:?}"))?;
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
            .map_err(|e| format!("{e:?}"))?;
        chart.configure_mesh().x_desc("noise %").light_line_style(WHITE).draw().map_err(|e| format!("{e:?}"))?;
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
            let series =
                chart.draw_series(LineSeries::new(pts.clone(), color.stroke_width(2))).map_err(|e| format!("{e:?}"))?;
            if pi == 0 {
                series
                    .label(m.name())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
            }
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled()))).map_err(|e| format!("{e:?}"))?;
        }
        if pi == 0 {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::LowerLeft)
                .draw()
                .map_err(|e| format!("{e:?}"))?;
        }
    }
    root.present().map_err(|e| format!("{e:?}"))?;
    Ok(())
}

/// Write `sim_<geometry>.svg` and `.png` (a panel per noise kind and metric, a curve per method).
pub fn simulation_figure(
    cells: &[CellStats],
    g: Geometry,
    kinds: &[NoiseKind],
    methods: &[Method],
    out: &Path,
) -> Result<Vec<PathBuf>, VizError> {
    register_font();
    let size = (1600, 300 * kinds.len() as u32 + 60);
    let stem = format!("sim_{}", g.name());
    let svg = out.join(format!("{stem}.svg"));
    let png = out.join(format!("{stem}.png"));
    draw(SVGBackend::new(&svg, size).into_drawing_area(), cells, g, kinds, methods)
        .map_err(|message| VizError::Draw { path: svg.clone(), message })?;
    draw(BitMapBackend::new(&png, size).into_drawing_area(), cells, g, kinds, methods)
        .map_err(|message| VizError::Draw { path: png.clone(), message })?;
    Ok(vec![svg, png])
}

/// Most map points drawn on the top-down map.
const MAX_POINTS: usize = 5000;

/// What an object is, for pictures: one colour and one legend entry per state (add a state here and
/// every picture shows it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectState {
    /// A mapped, static object.
    Static,
    /// Mapped but flagged dynamic (box misfit or a size unlike its class).
    Dynamic,
    /// Its map points moved: not mapped.
    Moving,
}

impl ObjectState {
    /// All states, in legend order.
    pub const ALL: [ObjectState; 3] = [ObjectState::Static, ObjectState::Dynamic, ObjectState::Moving];

    /// The state of a stored object.
    pub fn of(dynamic: bool, moving: bool) -> Self {
        match (dynamic, moving) {
            (_, true) => ObjectState::Moving,
            (true, false) => ObjectState::Dynamic,
            (false, false) => ObjectState::Static,
        }
    }

    /// Colour, RGB.
    pub fn rgb(self) -> [u8; 3] {
        match self {
            ObjectState::Static => [40, 170, 60],
            ObjectState::Dynamic => [240, 140, 20],
            ObjectState::Moving => [220, 30, 40],
        }
    }

    /// Colour, BGR (OpenCV overlays).
    pub fn bgr(self) -> [u8; 3] {
        let [r, g, b] = self.rgb();
        [b, g, r]
    }

    /// Legend text.
    pub fn meaning(self) -> &'static str {
        match self {
            ObjectState::Static => "static object (mapped)",
            ObjectState::Dynamic => "dynamic object (flagged)",
            ObjectState::Moving => "moving object (not mapped)",
        }
    }
}

/// An object on the top-down map.
pub struct MapShape {
    /// Ellipse outline (x, z).
    pub outline: Vec<[f64; 2]>,
    /// "#id class".
    pub label: String,
    /// Its state (moving objects are not drawn).
    pub state: ObjectState,
}

/// What the top-down map shows (x right, z forward of the first camera; metres).
pub struct TopDown<'a> {
    /// The estimated positions, one per frame.
    pub estimate: &'a [[f64; 2]],
    /// Ground truth, one position per estimated pose (the first ones when shorter).
    pub truth: Option<&'a [[f64; 2]]>,
    /// Map points.
    pub points: &'a [[f64; 2]],
    /// Objects.
    pub objects: &'a [MapShape],
}

/// Blue (0) → yellow (0.5) → red (1).
fn error_colour(f: f64) -> RGBColor {
    let f = f.clamp(0.0, 1.0);
    let lerp = |a: f64, b: f64, t: f64| (a + (b - a) * t).round() as u8;
    if f < 0.5 {
        let t = f / 0.5;
        RGBColor(lerp(40.0, 240.0, t), lerp(90.0, 200.0, t), lerp(220.0, 30.0, t))
    } else {
        let t = (f - 0.5) / 0.5;
        RGBColor(lerp(240.0, 210.0, t), lerp(200.0, 20.0, t), lerp(30.0, 30.0, t))
    }
}

/// The frame of a top-down map (lowest and highest x, z): the estimate, the ground truth and the
/// outlines of the objects shown, finite points only; an error when a trajectory holds a non-finite
/// position or the frame spans more than [`MAX_SPAN_M`].
fn frame_of(m: &TopDown<'_>) -> Result<([f64; 2], [f64; 2]), String> {
    let shown: Vec<&MapShape> = m.objects.iter().filter(|o| o.state != ObjectState::Moving).collect();
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for (what, path) in [("estimate", Some(m.estimate)), ("ground truth", m.truth)] {
        if let Some(k) = path.and_then(|p| p.iter().position(|q| !q.iter().all(|v| v.is_finite()))) {
            return Err(format!("position {k} of the {what} is not finite: {:?}", path.map(|p| p[k])));
        }
    }
    // non-finite outlines cannot be drawn (and make the axes' ticks loop): left out of the frame
    let mut grow = |p: &[f64; 2]| {
        if p.iter().all(|v| v.is_finite()) {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    };
    m.estimate.iter().for_each(&mut grow);
    m.truth.unwrap_or(&[]).iter().for_each(&mut grow);
    shown.iter().flat_map(|o| o.outline.iter()).for_each(&mut grow);
    if !lo[0].is_finite() {
        lo = [-10.0, -10.0];
        hi = [10.0, 10.0];
    }
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if span.is_nan() || span > MAX_SPAN_M {
        return Err(format!(
            "the trajectories and objects span {span:.3e} m; a top-down map is drawn up to {MAX_SPAN_M:.0e} m (a pose in the wrong units?)"
        ));
    }
    Ok((lo, hi))
}

fn draw_topdown<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    m: &TopDown<'_>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("{e:?}");
    root.fill(&WHITE).map_err(err)?;
    // with ground truth, a column on the right holds the error over distance
    let (root, side) = if m.truth.is_some() {
        let (l, r) = root.split_horizontally(root.dim_in_pixel().1);
        (l, Some(r))
    } else {
        (root, None)
    };
    let shown: Vec<&MapShape> = m.objects.iter().filter(|o| o.state != ObjectState::Moving).collect();
    let moving = m.objects.len() - shown.len();
    let (lo, hi) = frame_of(m)?;
    let view = square_view(lo, hi);
    let (x0, x1, z0, z1) = view;
    let mut chart = ChartBuilder::on(&root)
        .caption("Top-down map: x right, z forward of the first camera (metres)", ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(40)
        .build_cartesian_2d(x0..x1, z0..z1)
        .map_err(err)?;
    chart.configure_mesh().light_line_style(WHITE).x_desc("x (m)").y_desc("z (m)").draw().map_err(err)?;
    draw_map_points(&mut chart, m, view)?;
    // the estimate, each step coloured by its position error when there is ground truth
    let errors: Option<Vec<f64>> = m.truth.map(|t| {
        m.estimate.iter().zip(t).map(|(e, g)| ((e[0] - g[0]).powi(2) + (e[1] - g[1]).powi(2)).sqrt()).collect()
    });
    draw_trajectories(&mut chart, m, &errors)?;
    draw_objects(&mut chart, &shown)?;
    draw_legend(&mut chart, moving)?;
    if let (Some(e), Some(t), Some(side)) = (&errors, m.truth, side) {
        draw_error_inset(side, e, t)?;
    }
    root.present().map_err(err)?;
    Ok(())
}

/// The chart of a top-down map: x and z in metres.
type MapChart<'a, DB> =
    ChartContext<'a, DB, Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>>;

/// The map's view `(x0, x1, z0, z1)`: the frame `lo`..`hi` with a margin, both axes at one scale.
fn square_view(lo: [f64; 2], hi: [f64; 2]) -> (f64, f64, f64, f64) {
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
    (x0, x1, z0, z1)
}

/// The map points inside the view, grey, evenly thinned to at most MAX_POINTS.
fn draw_map_points<DB: DrawingBackend>(
    chart: &mut MapChart<'_, DB>,
    m: &TopDown<'_>,
    (x0, x1, z0, z1): (f64, f64, f64, f64),
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("{e:?}");
    let grey = RGBColor(170, 170, 170);
    let inside: Vec<&[f64; 2]> = m.points.iter().filter(|p| p[0] > x0 && p[0] < x1 && p[1] > z0 && p[1] < z1).collect();
    let step = inside.len().div_ceil(MAX_POINTS).max(1);
    chart
        .draw_series(inside.iter().step_by(step).map(|p| Circle::new((p[0], p[1]), 1, grey.filled())))
        .map_err(err)?
        .label("map points")
        .legend(move |(x, y)| Circle::new((x + 8, y), 2, grey.filled()));
    Ok(())
}

/// The ground truth (dashed) and the estimate, coloured by its position error `errors` when given.
fn draw_trajectories<DB: DrawingBackend>(
    chart: &mut MapChart<'_, DB>,
    m: &TopDown<'_>,
    errors: &Option<Vec<f64>>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("{e:?}");
    if let Some(t) = m.truth {
        let c = BLACK;
        chart
            .draw_series(DashedLineSeries::new(t.iter().map(|p| (p[0], p[1])), 6, 4, c.stroke_width(2)))
            .map_err(err)?
            .label("ground truth (dashed)")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
    }
    match errors {
        Some(e) if !e.is_empty() => {
            let max = e.iter().cloned().fold(0.0, f64::max).max(1e-3);
            let segs: Vec<PathElement<(f64, f64)>> = m
                .estimate
                .windows(2)
                .zip(e.iter().skip(1))
                .map(|(w, &d)| {
                    PathElement::new(
                        vec![(w[0][0], w[0][1]), (w[1][0], w[1][1])],
                        error_colour(d / max).stroke_width(3),
                    )
                })
                .collect();
            chart
                .draw_series(segs)
                .map_err(err)?
                .label(format!("estimate, coloured by error: blue 0 m, yellow {:.2} m, red {max:.2} m", max / 2.0))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], error_colour(1.0).stroke_width(3)));
        }
        _ => {
            let c = RGBColor(31, 119, 180);
            chart
                .draw_series(LineSeries::new(m.estimate.iter().map(|p| (p[0], p[1])), c.stroke_width(2)))
                .map_err(err)?
                .label("estimate")
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
        }
    }
    Ok(())
}

/// The legend box, with an entry for the `moving` objects left out of the map when there are any.
fn draw_legend<'a, DB: DrawingBackend + 'a>(chart: &mut MapChart<'a, DB>, moving: usize) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("{e:?}");
    if moving > 0 {
        let c = RGBColor(220, 30, 40);
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
            .map_err(err)?
            .label(format!("{moving} moving object(s): not mapped, not drawn"))
            .legend(move |(x, y)| Cross::new((x + 9, y), 5, c.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(err)?;
    Ok(())
}

/// The static and dynamic objects of a top-down map: filled outlines in their state's colour, each
/// labelled at its far end, one legend entry per state shown.
fn draw_objects<DB: DrawingBackend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    shown: &[&MapShape],
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("{e:?}");
    for state in [ObjectState::Static, ObjectState::Dynamic] {
        let [r, g, b] = state.rgb();
        let colour = RGBColor(r, g, b);
        let of_state: Vec<&&MapShape> = shown.iter().filter(|o| o.state == state).collect();
        let closed = |o: &MapShape| -> Vec<(f64, f64)> {
            let mut pts: Vec<(f64, f64)> = o.outline.iter().map(|p| (p[0], p[1])).collect();
            if let Some(&f) = pts.first() {
                pts.push(f);
            }
            pts
        };
        let series = chart
            .draw_series(of_state.iter().map(|o| Polygon::new(closed(o), colour.mix(0.35).filled())))
            .map_err(err)?;
        if !of_state.is_empty() {
            series
                .label(state.meaning())
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], colour.filled()));
        }
        chart.draw_series(of_state.iter().map(|o| PathElement::new(closed(o), colour.stroke_width(2)))).map_err(err)?;
        for o in of_state {
            if let Some(&(x, z)) = closed(o).iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
                chart
                    .draw_series(std::iter::once(Text::new(
                        o.label.clone(),
                        (x, z + 1.0),
                        ("sans-serif", 13).into_font().color(&colour),
                    )))
                    .map_err(err)?;
            }
        }
    }
    Ok(())
}

/// The inset of a top-down map with ground truth: the estimate's position error `e` over the distance
/// travelled along the truth `t`, coloured as the trajectory is.
fn draw_error_inset<DB: DrawingBackend>(
    side: DrawingArea<DB, plotters::coord::Shift>,
    e: &[f64],
    t: &[[f64; 2]],
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("{e:?}");
    if e.len() >= 2 {
        let mut dist = vec![0.0];
        for w in t.windows(2) {
            let last = dist.last().copied().unwrap_or(0.0);
            dist.push(last + ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt());
        }
        let (pw, ph) = side.dim_in_pixel();
        let inset = side.shrink((0, ph / 8), (pw, ph / 2));
        let dmax = dist.last().copied().unwrap_or(1.0).max(1e-3);
        let emax = e.iter().cloned().fold(0.0, f64::max).max(1e-3) * 1.1;
        let mut c = ChartBuilder::on(&inset)
            .caption("estimate: position error over distance", ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(32)
            .y_label_area_size(44)
            .build_cartesian_2d(0f64..dmax, 0f64..emax)
            .map_err(err)?;
        c.configure_mesh()
            .light_line_style(WHITE)
            .x_desc("distance (m)")
            .y_desc("error (m)")
            .label_style(("sans-serif", 13))
            .draw()
            .map_err(err)?;
        c.draw_series(dist.windows(2).zip(e.windows(2)).map(|(d, v)| {
            PathElement::new(vec![(d[0], v[0]), (d[1], v[1])], error_colour(v[1] / (emax / 1.1)).stroke_width(3))
        }))
        .map_err(err)?;
    }
    Ok(())
}

/// Largest extent of a top-down map, metres: a continent; beyond it the positions are not a drive's.
pub const MAX_SPAN_M: f64 = 1e7;

/// Write the top-down map as `<stem>.svg` and `<stem>.png`.
pub fn topdown_figure(m: &TopDown<'_>, out: &Path, stem: &str) -> Result<Vec<PathBuf>, VizError> {
    register_font();
    let size = if m.truth.is_some() { (1400, 900) } else { (900, 900) };
    // refused before a file is made: nothing half-drawn is left
    frame_of(m).map_err(|message| VizError::NotDrawable { message })?;
    let svg = out.join(format!("{stem}.svg"));
    let png = out.join(format!("{stem}.png"));
    draw_topdown(SVGBackend::new(&svg, size).into_drawing_area(), m)
        .map_err(|message| VizError::Draw { path: svg.clone(), message })?;
    draw_topdown(BitMapBackend::new(&png, size).into_drawing_area(), m)
        .map_err(|message| VizError::Draw { path: png.clone(), message })?;
    Ok(vec![svg, png])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Positions no drive has (a pose file in the wrong units, a corrupt number) are refused with a
    /// message instead of drawn: drawing axes over 1e300 m never finished.
    #[test]
    fn a_map_too_large_or_not_finite_is_refused_not_drawn() {
        let dir = std::env::temp_dir().join(format!("topdown-refuse-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let estimate = [[0.0, 0.0], [0.1, 1.2], [0.2, 2.4]];
        let draw = |truth: &[[f64; 2]]| {
            topdown_figure(&TopDown { estimate: &estimate, truth: Some(truth), points: &[], objects: &[] }, &dir, "m")
        };
        let far = draw(&[[0.0, 0.0], [0.0, 1.2], [1e300, 2.4]]).expect_err("1e300 m").to_string();
        assert!(far.starts_with("not drawn: the trajectories and objects span 1.000e300 m"), "{far}");
        let nan = draw(&[[0.0, 0.0], [f64::NAN, 1.2], [0.0, 2.4]]).expect_err("NaN").to_string();
        assert!(nan.contains("position 1 of the ground truth is not finite"), "{nan}");
        assert!(!dir.join("m.svg").exists() && !dir.join("m.png").exists(), "refused before a file is made");
        let files = draw(&[[0.0, 0.0], [0.0, 1.2], [0.0, 2.4]]).expect("a drive's map is drawn");
        assert!(files.iter().all(|f| f.is_file()));
        std::fs::remove_dir_all(&dir).ok();
    }
}
