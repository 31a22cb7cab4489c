//! Charts for the demo and the experiments: plotters with a pure-Rust font (DejaVu Sans, shipped under
//! `assets/fonts/` with its licence), written as both SVG and PNG.

use std::path::{Path, PathBuf};
use std::sync::Once;

use anyhow::{Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

const FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

/// Registers the shipped font once; plotters draws no text without a registered font.
fn ensure_font() {
    static REGISTER: Once = Once::new();
    REGISTER.call_once(|| {
        // A font that does not parse is a build-time mistake; charts would then fail with FontUnavailable.
        let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// Colours cycled by series.
pub const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

/// A named series of points.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points (x, y).
    pub points: Vec<(f64, f64)>,
    /// Draw as markers instead of a line.
    pub markers: bool,
    /// Dashed (drawn thinner) line, for references and bounds.
    pub dashed: bool,
}

impl Series {
    /// A line series.
    pub fn line(label: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Series { label: label.into(), points, markers: false, dashed: false }
    }
    /// A marker series.
    pub fn markers(label: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Series { label: label.into(), points, markers: true, dashed: false }
    }
    /// A reference line (drawn thin).
    pub fn reference(label: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Series { label: label.into(), points, markers: false, dashed: true }
    }
}

/// Where a chart's legend goes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Legend {
    /// Upper right corner (the default).
    #[default]
    UpperRight,
    /// Upper left corner.
    UpperLeft,
    /// Lower right corner.
    LowerRight,
    /// Lower left corner.
    LowerLeft,
}

impl Legend {
    fn position(self) -> SeriesLabelPosition {
        match self {
            Legend::UpperRight => SeriesLabelPosition::UpperRight,
            Legend::UpperLeft => SeriesLabelPosition::UpperLeft,
            Legend::LowerRight => SeriesLabelPosition::LowerRight,
            Legend::LowerLeft => SeriesLabelPosition::LowerLeft,
        }
    }
}

/// What a line or scatter chart shows.
#[derive(Clone, Debug)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// Equal scales on both axes (trajectories).
    pub equal_axes: bool,
    /// The series.
    pub series: Vec<Series>,
    /// Where the legend goes.
    pub legend: Legend,
}

impl Chart {
    /// A chart with linear axes.
    pub fn new(title: impl Into<String>, x_label: impl Into<String>, y_label: impl Into<String>) -> Self {
        Chart {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            log_x: false,
            log_y: false,
            equal_axes: false,
            series: Vec::new(),
            legend: Legend::UpperRight,
        }
    }
    /// Adds a series.
    pub fn with(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }
    /// Puts the legend in another corner.
    pub fn legend(mut self, legend: Legend) -> Self {
        self.legend = legend;
        self
    }
}

/// The name of category `v` when `v` is (nearly) an index into `names`, else nothing.
fn category_label(names: &[String], v: f64) -> String {
    let i = v.round();
    if (v - i).abs() < 1e-6 && i >= 0.0 {
        names.get(i as usize).cloned().unwrap_or_default()
    } else {
        String::new()
    }
}

/// An axis tick label: at most 3 significant digits, exponent notation outside 0.001..100000.
pub fn tick_label(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v.abs() < 1e-12 {
        return "0".into();
    }
    let magnitude = v.abs().log10().floor() as i32;
    let scale = 10f64.powi(2 - magnitude);
    let rounded = (v * scale).round() / scale;
    if !(-3..5).contains(&magnitude) {
        let mantissa = (rounded / 10f64.powi(magnitude) * 100.0).round() / 100.0;
        format!("{mantissa}e{magnitude}")
    } else {
        format!("{rounded}")
    }
}

/// A log-axis tick label: only at 1, 2 and 5 times a power of ten (the axis may place a tick at every
/// digit; the others stay unlabelled so the labels never crowd).
pub fn log_tick_label(v: f64) -> String {
    if !(v > 0.0 && v.is_finite()) {
        return String::new();
    }
    let mantissa = v / 10f64.powf(v.log10().floor());
    let nearest = mantissa.round();
    if (mantissa - nearest).abs() < 1e-6 && [1.0, 2.0, 5.0, 10.0].contains(&nearest) {
        tick_label(v)
    } else {
        String::new()
    }
}

/// Writes `stem.svg` and `stem.png`; returns both paths.
pub fn save(chart: &Chart, stem: &Path) -> Result<Vec<PathBuf>> {
    ensure_font();
    if let Some(dir) = stem.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let svg = stem.with_extension("svg");
    let png = stem.with_extension("png");
    draw(chart, SVGBackend::new(&svg, (900, 560)).into_drawing_area())
        .with_context(|| format!("drawing {}", svg.display()))?;
    draw(chart, BitMapBackend::new(&png, (900, 560)).into_drawing_area())
        .with_context(|| format!("drawing {}", png.display()))?;
    Ok(vec![svg, png])
}

fn bounds(chart: &Chart) -> ((f64, f64), (f64, f64)) {
    let mut xs = (f64::INFINITY, f64::NEG_INFINITY);
    let mut ys = (f64::INFINITY, f64::NEG_INFINITY);
    for s in &chart.series {
        for &(x, y) in &s.points {
            if x.is_finite() && (!chart.log_x || x > 0.0) {
                xs = (xs.0.min(x), xs.1.max(x));
            }
            if y.is_finite() && (!chart.log_y || y > 0.0) {
                ys = (ys.0.min(y), ys.1.max(y));
            }
        }
    }
    let pad = |(lo, hi): (f64, f64), log: bool| {
        if !lo.is_finite() {
            return if log { (0.1, 10.0) } else { (0.0, 1.0) };
        }
        if log {
            // Start at a power of ten: log axes label only powers of ten and their 2 and 5 multiples counted
            // from the first power of ten in range, so a partial decade at the bottom would stay unlabelled.
            (10f64.powf((lo / 1.5).log10().floor()) * 0.999, hi * 1.5)
        } else {
            let span = (hi - lo).max(1e-12 * hi.abs().max(1.0));
            (lo - 0.05 * span, hi + 0.05 * span)
        }
    };
    let (mut x, mut y) = (pad(xs, chart.log_x), pad(ys, chart.log_y));
    if chart.equal_axes {
        let (wx, wy) = (x.1 - x.0, y.1 - y.0);
        let w = wx.max(wy * 900.0 / 560.0);
        let h = w * 560.0 / 900.0;
        let (cx, cy) = ((x.0 + x.1) / 2.0, (y.0 + y.1) / 2.0);
        x = (cx - w / 2.0, cx + w / 2.0);
        y = (cy - h / 2.0, cy + h / 2.0);
    }
    (x, y)
}

fn draw<DB: DrawingBackend>(chart: &Chart, area: DrawingArea<DB, Shift>) -> Result<()>
where
    DB::ErrorType: 'static,
{
    area.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
    let ((x0, x1), (y0, y1)) = bounds(chart);
    let mut builder = ChartBuilder::on(&area);
    builder.caption(&chart.title, ("sans-serif", 22)).margin(14).x_label_area_size(44).y_label_area_size(74);
    macro_rules! body {
        ($ctx:expr) => {{
            let mut ctx = $ctx;
            ctx.configure_mesh()
                .x_desc(chart.x_label.as_str())
                .y_desc(chart.y_label.as_str())
                .x_labels(if chart.log_x { 20 } else { 10 })
                .y_labels(if chart.log_y { 20 } else { 10 })
                .light_line_style(if chart.log_x || chart.log_y { WHITE.mix(0.0) } else { BLACK.mix(0.04) })
                .x_label_formatter(&|v| if chart.log_x { log_tick_label(*v) } else { tick_label(*v) })
                .y_label_formatter(&|v| if chart.log_y { log_tick_label(*v) } else { tick_label(*v) })
                .label_style(("sans-serif", 14))
                .axis_desc_style(("sans-serif", 16))
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            for (i, s) in chart.series.iter().enumerate() {
                let color = PALETTE[i % PALETTE.len()];
                let pts: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|(x, y)| {
                        x.is_finite() && y.is_finite() && (!chart.log_x || *x > 0.0) && (!chart.log_y || *y > 0.0)
                    })
                    .collect();
                let anno = if s.markers {
                    ctx.draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))
                        .map_err(|e| anyhow::anyhow!("{e}"))?
                } else {
                    let style = if s.dashed { color.stroke_width(1) } else { color.stroke_width(2) };
                    ctx.draw_series(LineSeries::new(pts, style)).map_err(|e| anyhow::anyhow!("{e}"))?
                };
                anno.label(s.label.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(3)));
            }
            ctx.configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 14))
                .position(chart.legend.position())
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        }};
    }
    match (chart.log_x, chart.log_y) {
        (false, false) => body!(builder.build_cartesian_2d(x0..x1, y0..y1).map_err(|e| anyhow::anyhow!("{e}"))?),
        (true, false) => {
            body!(builder.build_cartesian_2d((x0..x1).log_scale(), y0..y1).map_err(|e| anyhow::anyhow!("{e}"))?)
        }
        (false, true) => {
            body!(builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale()).map_err(|e| anyhow::anyhow!("{e}"))?)
        }
        (true, true) => {
            body!(builder
                .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
                .map_err(|e| anyhow::anyhow!("{e}"))?)
        }
    }
    area.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(())
}

/// A stability map: cells on a grid of (x, y) values, each stable (green) or not (red), with optional
/// overlay curves (e.g. a passivity bound).
#[derive(Clone, Debug)]
pub struct StabilityMap {
    /// Title.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// Logarithmic axes.
    pub log: bool,
    /// Cells: (x, y, stable).
    pub cells: Vec<(f64, f64, bool)>,
    /// Curves (or markers) drawn over the map.
    pub overlays: Vec<Series>,
    /// Where the legend goes.
    pub legend: Legend,
    /// Names of the rows when y is a category (row `i` at y = i); empty for a numeric y axis.
    pub y_categories: Vec<String>,
}

/// Writes a stability map as `stem.svg` and `stem.png`.
pub fn save_map(map: &StabilityMap, stem: &Path) -> Result<Vec<PathBuf>> {
    ensure_font();
    if let Some(dir) = stem.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let svg = stem.with_extension("svg");
    let png = stem.with_extension("png");
    draw_map(map, SVGBackend::new(&svg, (760, 620)).into_drawing_area())?;
    draw_map(map, BitMapBackend::new(&png, (760, 620)).into_drawing_area())?;
    Ok(vec![svg, png])
}

fn sorted_unique(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(|a, b| a.total_cmp(b));
    v.dedup();
    v
}

/// The edges of a map's cells around the sorted grid values `v`: halfway between neighbours (geometric
/// halfway on log axes), the outer cells as wide as their inner neighbours' half-widths.
fn cell_edges(v: &[f64], log: bool) -> Vec<f64> {
    let mid = |a: f64, b: f64| if log { (a * b).sqrt() } else { (a + b) / 2.0 };
    let mut e = Vec::with_capacity(v.len() + 1);
    let first = if v.len() > 1 {
        if log {
            v[0] * v[0] / mid(v[0], v[1])
        } else {
            2.0 * v[0] - mid(v[0], v[1])
        }
    } else if log {
        v[0] / 2.0
    } else {
        v[0] - 0.5
    };
    e.push(first);
    for w in v.windows(2) {
        e.push(mid(w[0], w[1]));
    }
    let n = v.len();
    let last = if n > 1 {
        if log {
            v[n - 1] * v[n - 1] / mid(v[n - 2], v[n - 1])
        } else {
            2.0 * v[n - 1] - mid(v[n - 2], v[n - 1])
        }
    } else if log {
        v[0] * 2.0
    } else {
        v[0] + 0.5
    };
    e.push(last);
    e
}

fn draw_map<DB: DrawingBackend>(map: &StabilityMap, area: DrawingArea<DB, Shift>) -> Result<()>
where
    DB::ErrorType: 'static,
{
    area.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
    let xs = sorted_unique(map.cells.iter().map(|c| c.0).collect());
    let ys = sorted_unique(map.cells.iter().map(|c| c.1).collect());
    anyhow::ensure!(!xs.is_empty() && !ys.is_empty(), "empty stability map");
    let (ex, ey) = (cell_edges(&xs, map.log), cell_edges(&ys, map.log));
    let (x0, x1, y0, y1) = (ex[0], *ex.last().unwrap_or(&1.0), ey[0], *ey.last().unwrap_or(&1.0));
    let mut builder = ChartBuilder::on(&area);
    // Category rows name themselves: room for the longest name (about 7 px a character at this size).
    let longest = map.y_categories.iter().map(|c| c.chars().count()).max().unwrap_or(0) as u32;
    let y_labels = 70.max(24 + 7 * longest);
    builder.caption(&map.title, ("sans-serif", 20)).margin(14).x_label_area_size(44).y_label_area_size(y_labels);
    let stable = RGBColor(120, 200, 120);
    let unstable = RGBColor(230, 110, 100);
    macro_rules! body {
        ($ctx:expr) => {{
            let mut ctx = $ctx;
            ctx.configure_mesh()
                .x_desc(map.x_label.as_str())
                .y_desc(map.y_label.as_str())
                .x_labels(if map.log { 20 } else { 10 })
                .y_labels(if map.log { 20 } else { 10 })
                .x_label_formatter(&|v| if map.log { log_tick_label(*v) } else { tick_label(*v) })
                .y_label_formatter(&|v| {
                    if !map.y_categories.is_empty() {
                        category_label(&map.y_categories, *v)
                    } else if map.log {
                        log_tick_label(*v)
                    } else {
                        tick_label(*v)
                    }
                })
                .label_style(("sans-serif", 13))
                .axis_desc_style(("sans-serif", 15))
                .disable_mesh()
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            ctx.draw_series(map.cells.iter().map(|&(x, y, ok)| {
                let i = xs.iter().position(|v| *v == x).unwrap_or(0);
                let j = ys.iter().position(|v| *v == y).unwrap_or(0);
                Rectangle::new(
                    [(ex[i], ey[j]), (ex[i + 1], ey[j + 1])],
                    if ok { stable.filled() } else { unstable.filled() },
                )
            }))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
            for (k, s) in map.overlays.iter().enumerate() {
                let color =
                    [BLACK, RGBColor(30, 30, 160), RGBColor(120, 0, 120), RGBColor(190, 110, 0), RGBColor(0, 110, 110)]
                        [k % 5];
                let pts: Vec<(f64, f64)> =
                    s.points.iter().copied().filter(|(x, y)| *x >= x0 && *x <= x1 && *y >= y0 && *y <= y1).collect();
                if s.markers {
                    ctx.draw_series(pts.iter().map(|&p| Circle::new(p, 6, color.stroke_width(3))))
                        .map_err(|e| anyhow::anyhow!("{e}"))?
                        .label(s.label.as_str())
                        .legend(move |(x, y)| Circle::new((x + 9, y), 5, color.stroke_width(2)));
                } else {
                    let style = if s.dashed { color.stroke_width(2) } else { color.stroke_width(3) };
                    ctx.draw_series(LineSeries::new(pts, style))
                        .map_err(|e| anyhow::anyhow!("{e}"))?
                        .label(s.label.as_str())
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(3)));
                }
            }
            ctx.draw_series(std::iter::once(Rectangle::new([(x0, y0), (x0, y0)], stable.filled())))
                .map_err(|e| anyhow::anyhow!("{e}"))?
                .label("stable")
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], stable.filled()));
            ctx.draw_series(std::iter::once(Rectangle::new([(x0, y0), (x0, y0)], unstable.filled())))
                .map_err(|e| anyhow::anyhow!("{e}"))?
                .label("unstable")
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], unstable.filled()));
            ctx.configure_series_labels()
                .background_style(WHITE.mix(0.9))
                .border_style(BLACK)
                .label_font(("sans-serif", 13))
                .position(map.legend.position())
                .draw()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        }};
    }
    if map.log {
        body!(builder
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| anyhow::anyhow!("{e}"))?);
    } else {
        body!(builder.build_cartesian_2d(x0..x1, y0..y1).map_err(|e| anyhow::anyhow!("{e}"))?);
    }
    area.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick_label(0.0009000000001), "9e-4");
        assert_eq!(tick_label(0.0020000000001), "0.002");
        assert_eq!(tick_label(1000.0), "1000");
        assert_eq!(tick_label(2.5e-6), "2.5e-6");
        assert_eq!(tick_label(1e6), "1e6");
        assert_eq!(tick_label(-0.5), "-0.5");
        assert_eq!(log_tick_label(2000.0), "2000");
        assert_eq!(log_tick_label(3000.0), "");
    }

    /// Charts render text with the shipped font into non-trivial PNG and SVG files.
    #[test]
    fn charts_render_png_and_svg_with_text() {
        let dir = tempfile::tempdir().unwrap();
        let chart = Chart::new("test chart", "time (s)", "value")
            .with(Series::line("sine", (0..100).map(|i| (i as f64 * 0.1, (i as f64 * 0.1).sin())).collect()))
            .with(Series::markers("points", vec![(1.0, 0.5), (2.0, -0.5)]));
        let files = save(&chart, &dir.path().join("c")).unwrap();
        let svg = std::fs::read_to_string(&files[0]).unwrap();
        assert!(svg.contains("test chart") && svg.contains("time (s)"), "SVG carries the labels");
        let png = std::fs::read(&files[1]).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        assert!(png.len() > 10_000, "a real picture, {} bytes", png.len());

        let map = StabilityMap {
            title: "map".into(),
            x_label: "k".into(),
            y_label: "b".into(),
            log: true,
            cells: vec![(1.0, 1.0, true), (10.0, 1.0, false), (1.0, 10.0, true), (10.0, 10.0, true)],
            overlays: vec![Series::line("bound", vec![(1.0, 0.5), (10.0, 5.0)])],
            legend: Legend::UpperLeft,
            y_categories: Vec::new(),
        };
        let files = save_map(&map, &dir.path().join("m")).unwrap();
        assert!(std::fs::read(&files[1]).unwrap().len() > 5_000);
    }
}

/// A table of values as coloured cells: rows and columns are categories, each cell carries a value printed
/// in it and whether it meets its bound (green) or not (red); a missing cell is grey.
#[derive(Clone, Debug)]
pub struct HeatMap {
    /// Title.
    pub title: String,
    /// Row names, top to bottom.
    pub rows: Vec<String>,
    /// Column names, left to right.
    pub columns: Vec<String>,
    /// `cells[row][column]`: (value, meets its bound).
    pub cells: Vec<Vec<Option<(f64, bool)>>>,
}

impl HeatMap {
    /// An empty map.
    pub fn new(title: impl Into<String>, rows: Vec<String>, columns: Vec<String>) -> Self {
        let cells = vec![vec![None; columns.len()]; rows.len()];
        HeatMap { title: title.into(), rows, columns, cells }
    }

    /// Sets a cell (out-of-range indices are ignored).
    pub fn set(&mut self, row: usize, column: usize, value: f64, ok: bool) {
        if let Some(cell) = self.cells.get_mut(row).and_then(|r| r.get_mut(column)) {
            *cell = Some((value, ok));
        }
    }
}

/// Writes a heat map as `stem.svg` and `stem.png`.
pub fn save_heat_map(map: &HeatMap, stem: &Path) -> Result<Vec<PathBuf>> {
    ensure_font();
    if let Some(dir) = stem.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let label_width = 12 + 7 * map.rows.iter().map(|r| r.chars().count()).max().unwrap_or(10) as u32;
    let size = (label_width + 110 * map.columns.len().max(1) as u32 + 20, 80 + 22 * map.rows.len().max(1) as u32);
    let svg = stem.with_extension("svg");
    let png = stem.with_extension("png");
    draw_heat_map(map, label_width, SVGBackend::new(&svg, size).into_drawing_area())?;
    draw_heat_map(map, label_width, BitMapBackend::new(&png, size).into_drawing_area())?;
    Ok(vec![svg, png])
}

fn draw_heat_map<DB: DrawingBackend>(map: &HeatMap, label_width: u32, area: DrawingArea<DB, Shift>) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("{e}");
    area.fill(&WHITE).map_err(err)?;
    let (cell_w, cell_h, top) = (110i32, 22i32, 56i32);
    let left = label_width as i32;
    area.draw(&Text::new(map.title.clone(), (10, 8), ("sans-serif", 17))).map_err(err)?;
    for (c, name) in map.columns.iter().enumerate() {
        let x = left + c as i32 * cell_w + 4;
        area.draw(&Text::new(name.clone(), (x, top - 18), ("sans-serif", 12))).map_err(err)?;
    }
    let (good, bad, none) = (RGBColor(150, 215, 150), RGBColor(235, 130, 120), RGBColor(225, 225, 225));
    for (r, name) in map.rows.iter().enumerate() {
        let y = top + r as i32 * cell_h;
        area.draw(&Text::new(name.clone(), (6, y + 5), ("sans-serif", 12))).map_err(err)?;
        for c in 0..map.columns.len() {
            let x = left + c as i32 * cell_w;
            let cell = map.cells[r][c];
            let colour = match cell {
                Some((_, true)) => good,
                Some((_, false)) => bad,
                None => none,
            };
            area.draw(&Rectangle::new([(x, y), (x + cell_w - 2, y + cell_h - 2)], colour.filled())).map_err(err)?;
            if let Some((value, _)) = cell {
                let text = if value.is_finite() {
                    format!("{:.3}", crate::rounding::significant(value, 3))
                } else {
                    "n/a".into()
                };
                area.draw(&Text::new(text, (x + 6, y + 4), ("sans-serif", 12))).map_err(err)?;
            }
        }
    }
    area.present().map_err(err)?;
    Ok(())
}
