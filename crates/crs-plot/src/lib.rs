//! The one plot layer of the stack: a [`Figure`] of panels — [`Chart`]s (lines with a legend,
//! markers, filled or outlined rectangles, horizontal limits, vertical marks, text labels, a
//! linear or logarithmic y axis, named rows) and grouped [`Bars`] — drawn as SVG with plotters'
//! SVG backend. A figure's legend is either each chart's own (on the data) or one strip above
//! all panels ([`Figure::legend`]). Every writer of an SVG in the model and calibration crates
//! describes its figure with these types and calls [`Figure::svg`]; none writes SVG text itself.
//!
//! Input is data, not layout: non-finite values are left out, a panel without data draws
//! "no data", a degenerate range is widened, so a figure never panics on what it is handed.

use plotters::coord::Shift;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// A colour (sRGB, 8 bit per channel).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rgb(pub u8, pub u8, pub u8);

impl Rgb {
    pub const BLACK: Rgb = Rgb(0, 0, 0);
    pub const RED: Rgb = Rgb(214, 39, 40);
    pub const BLUE: Rgb = Rgb(31, 119, 180);
    pub const ORANGE: Rgb = Rgb(255, 127, 14);
    pub const GREEN: Rgb = Rgb(44, 160, 44);
    pub const GREY: Rgb = Rgb(153, 153, 153);

    /// The `i`-th colour of plotters' 99-colour palette (cables, one colour each).
    pub fn palette(i: usize) -> Rgb {
        let c = Palette99::pick(i).to_rgba();
        Rgb(c.0, c.1, c.2)
    }

    fn rgba(self, opacity: f64) -> RGBAColor {
        RGBColor(self.0, self.1, self.2).mix(opacity.clamp(0.0, 1.0))
    }
}

/// A polyline through `points` in data coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Line {
    /// Legend entry; `None` draws no entry.
    pub label: Option<String>,
    pub color: Rgb,
    pub width: u32,
    pub dashed: bool,
    pub opacity: f64,
    pub points: Vec<(f64, f64)>,
}

impl Line {
    /// A solid line of width 1 with a legend entry.
    pub fn new(label: impl Into<String>, color: Rgb, points: Vec<(f64, f64)>) -> Self {
        Line {
            label: Some(label.into()),
            color,
            width: 1,
            dashed: false,
            opacity: 1.0,
            points,
        }
    }
}

/// Circles at `points`, each optionally annotated with the text of the same index.
#[derive(Clone, Debug, PartialEq)]
pub struct Markers {
    pub label: Option<String>,
    pub color: Rgb,
    /// Radius, px.
    pub radius: u32,
    /// Filled discs or outlined circles.
    pub filled: bool,
    pub points: Vec<(f64, f64)>,
    /// Text drawn next to each point (empty or shorter than `points`: none for the rest).
    pub texts: Vec<String>,
}

impl Markers {
    /// Filled discs of radius 3 with a legend entry and no annotations.
    pub fn new(label: impl Into<String>, color: Rgb, points: Vec<(f64, f64)>) -> Self {
        Markers {
            label: Some(label.into()),
            color,
            radius: 3,
            filled: true,
            points,
            texts: Vec::new(),
        }
    }
}

/// An axis-aligned rectangle in data coordinates: a cell of a map, a region, a bound.
#[derive(Clone, Debug, PartialEq)]
pub struct Rect {
    pub min: (f64, f64),
    pub max: (f64, f64),
    /// Fill colour and opacity (0–1); `None`: not filled.
    pub fill: Option<(Rgb, f64)>,
    /// Outline colour, width (px) and whether dashed; `None`: no outline.
    pub stroke: Option<(Rgb, u32, bool)>,
    /// Text drawn at the centre.
    pub text: Option<String>,
}

impl Rect {
    /// A filled rectangle without outline or text.
    pub fn filled(min: (f64, f64), max: (f64, f64), color: Rgb, opacity: f64) -> Self {
        Rect {
            min,
            max,
            fill: Some((color, opacity)),
            stroke: None,
            text: None,
        }
    }

    /// An outlined rectangle without fill.
    pub fn outlined(min: (f64, f64), max: (f64, f64), color: Rgb, dashed: bool) -> Self {
        Rect {
            min,
            max,
            fill: None,
            stroke: Some((color, 1, dashed)),
            text: None,
        }
    }
}

/// A horizontal line across the chart at `y` (a limit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HLine {
    pub y: f64,
    pub color: Rgb,
    pub dashed: bool,
}

/// A vertical line across the chart at `x` (an event on a time axis).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VLine {
    pub x: f64,
    pub color: Rgb,
    pub dashed: bool,
}

/// Text whose top-left corner sits at `at` in data coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Label {
    pub at: (f64, f64),
    pub text: String,
    pub color: Rgb,
}

/// An axis range (lo, hi) in data units.
type Span = (f64, f64);

/// One x–y panel. The axis ranges are the data's (padded by 5 %) unless given.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    /// One metre is as long on both axes (maps, views of a path): the shorter range is
    /// widened about its centre to the panel's aspect.
    pub equal_scale: bool,
    /// A logarithmic y axis; values ≤ 0 are left out, as non-finite ones are.
    pub y_log: bool,
    /// Names of the rows y = 0, 1, … written as the y axis's tick labels instead of numbers.
    pub y_categories: Vec<String>,
    /// Drawn first, then the limits and marks, the lines, the markers and the labels on top.
    pub rects: Vec<Rect>,
    pub hlines: Vec<HLine>,
    pub vlines: Vec<VLine>,
    pub lines: Vec<Line>,
    pub markers: Vec<Markers>,
    pub labels: Vec<Label>,
}

impl Chart {
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Chart {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            ..Chart::default()
        }
    }

    /// (x range, y range) of the finite data, `None` without any.
    fn data_ranges(&self) -> (Option<Span>, Option<Span>) {
        let mut x = Extent::default();
        // On a logarithmic axis only positive values have a place.
        let mut y = Extent {
            positive_only: self.y_log,
            ..Extent::default()
        };
        for r in &self.rects {
            for p in [r.min, r.max] {
                x.add(p.0);
                y.add(p.1);
            }
        }
        for l in &self.lines {
            for p in &l.points {
                x.add(p.0);
                y.add(p.1);
            }
        }
        for m in &self.markers {
            for p in &m.points {
                x.add(p.0);
                y.add(p.1);
            }
        }
        for l in &self.labels {
            x.add(l.at.0);
            y.add(l.at.1);
        }
        // A limit widens y only when there is data to place it against.
        if x.get().is_some() {
            for h in &self.hlines {
                y.add(h.y);
            }
        }
        (x.get(), y.get())
    }
}

/// One series of a bar chart: a value per group.
#[derive(Clone, Debug, PartialEq)]
pub struct BarSeries {
    pub label: String,
    pub color: Rgb,
    pub values: Vec<f64>,
}

/// Grouped bars from zero: one group per name, one bar per series within it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bars {
    pub title: String,
    pub y_label: String,
    pub groups: Vec<String>,
    pub series: Vec<BarSeries>,
}

/// A panel of a figure.
#[derive(Clone, Debug, PartialEq)]
pub enum Panel {
    Chart(Chart),
    Bars(Bars),
}

/// A titled grid of panels with lines of notes under it.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    pub title: String,
    /// Width and height of the whole figure, px.
    pub size: (u32, u32),
    pub columns: usize,
    pub panels: Vec<Panel>,
    /// One line of text each, under the panels (what the colours mean, the source).
    pub notes: Vec<String>,
    /// A legend strip under the title, above every panel (a line sample in the colour and
    /// the text, one entry after the other): never on the data. Empty: no strip.
    pub legend: Vec<(String, Rgb)>,
}

/// Why a figure could not be drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("drawing the figure \"{title}\": {source}")]
    Draw {
        title: String,
        #[source]
        source: DrawingAreaErrorKind<std::io::Error>,
    },
    #[error("drawing {} (\"{title}\"): {source}", path.display())]
    DrawFile {
        path: std::path::PathBuf,
        title: String,
        #[source]
        source: DrawingAreaErrorKind<std::io::Error>,
    },
    #[error("writing {}: {source}", path.display())]
    Write {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
}

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;
type DrawResult<T> = Result<T, DrawingAreaErrorKind<std::io::Error>>;

const TITLE_PX: u32 = 30;
const NOTE_PX: u32 = 18;
const MARGIN: u32 = 8;
const X_LABEL_AREA: u32 = 36;
const Y_LABEL_AREA: u32 = 62;
const FONT: &str = "sans-serif";
/// Height of a figure's legend strip above its panels (px).
pub const LEGEND_STRIP_PX: u32 = 30;

impl Figure {
    /// A figure of one panel.
    pub fn single(title: impl Into<String>, size: (u32, u32), panel: Panel) -> Self {
        Figure {
            title: title.into(),
            size,
            columns: 1,
            panels: vec![panel],
            notes: Vec::new(),
            legend: Vec::new(),
        }
    }

    /// [`Figure::svg`] written to `path`; an error names the file.
    pub fn write(&self, path: &std::path::Path) -> Result<(), PlotError> {
        let svg = self.svg().map_err(|e| match e {
            PlotError::Draw { title, source } => PlotError::DrawFile {
                path: path.to_path_buf(),
                title,
                source,
            },
            other => other,
        })?;
        std::fs::write(path, svg).map_err(|source| PlotError::Write {
            path: path.to_path_buf(),
            source,
        })
    }

    /// The figure as an SVG document.
    pub fn svg(&self) -> Result<String, PlotError> {
        let mut out = String::new();
        {
            let root =
                SVGBackend::with_string(&mut out, (self.size.0.max(64), self.size.1.max(64)))
                    .into_drawing_area();
            self.draw(&root).map_err(|source| PlotError::Draw {
                title: self.title.clone(),
                source,
            })?;
        }
        Ok(out)
    }

    /// The figure as an SVG document, or — should plotters fail — an SVG that says what
    /// failed instead of a partial figure (for writers that hand on text, not a `Result`).
    pub fn render(&self) -> String {
        self.svg().unwrap_or_else(|e| {
            let failed = Figure {
                title: self.title.clone(),
                size: self.size,
                columns: 1,
                panels: Vec::new(),
                notes: vec![format!("this figure could not be drawn: {e}")],
                legend: Vec::new(),
            };
            failed.svg().unwrap_or_else(|_| {
                "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"400\" height=\"40\"><text x=\"10\" y=\"20\">this figure could not be drawn</text></svg>\n".to_string()
            })
        })
    }

    fn draw(&self, root: &Area<'_>) -> DrawResult<()> {
        root.fill(&WHITE)?;
        let (_, h) = root.dim_in_pixel();
        let mut body = root.clone();
        if !self.title.is_empty() {
            let (top, rest) = body.split_vertically(TITLE_PX);
            top.draw(&Text::new(
                self.title.clone(),
                (10, 8),
                (FONT, 17).into_font(),
            ))?;
            body = rest;
        }
        if !self.legend.is_empty() {
            let (strip, rest) = body.split_vertically(LEGEND_STRIP_PX);
            legend_strip(&strip, &self.legend)?;
            body = rest;
        }
        let notes_px = (NOTE_PX * self.notes.len() as u32
            + if self.notes.is_empty() { 0 } else { 6 })
        .min(h / 2);
        if notes_px > 0 {
            let (_, bh) = body.dim_in_pixel();
            let (rest, bottom) = body.split_vertically(bh.saturating_sub(notes_px));
            for (k, n) in self.notes.iter().enumerate() {
                bottom.draw(&Text::new(
                    n.clone(),
                    (10, 4 + NOTE_PX as i32 * k as i32),
                    (FONT, 14).into_font(),
                ))?;
            }
            body = rest;
        }
        if self.panels.is_empty() {
            no_data(&body, "")?;
        } else {
            let columns = self.columns.clamp(1, self.panels.len());
            let rows = self.panels.len().div_ceil(columns);
            let cells = body.split_evenly((rows, columns));
            for (panel, area) in self.panels.iter().zip(&cells) {
                match panel {
                    Panel::Chart(c) => draw_chart(area, c)?,
                    Panel::Bars(b) => draw_bars(area, b)?,
                }
            }
        }
        root.present()?;
        Ok(())
    }
}

/// Min and max of finite (and, if asked, positive) values.
#[derive(Default)]
struct Extent {
    range: Option<(f64, f64)>,
    positive_only: bool,
}

impl Extent {
    fn add(&mut self, v: f64) {
        if v.is_finite() && (!self.positive_only || v > 0.0) {
            self.range = Some(match self.range {
                None => (v, v),
                Some((a, b)) => (a.min(v), b.max(v)),
            });
        }
    }
    fn get(&self) -> Option<(f64, f64)> {
        self.range
    }
}

/// `r` padded by `pad` of its span; a span of rounding noise (below 1e-9 of the values or of
/// 1) widened to a visible one, so its ticks do not all read the same number.
fn padded((lo, hi): (f64, f64), pad: f64) -> (f64, f64) {
    let span = hi - lo;
    if span > 1e-9 * lo.abs().max(hi.abs()).max(1.0) {
        (lo - pad * span, hi + pad * span)
    } else {
        let w = (lo.abs() * 0.05).max(0.5);
        (lo - w, hi + w)
    }
}

/// A usable range: finite, lo < hi.
fn valid(r: (f64, f64)) -> Option<(f64, f64)> {
    (r.0.is_finite() && r.1.is_finite() && r.0 < r.1).then_some(r)
}

/// One entry after the other: a line sample in the colour, then the text.
fn legend_strip(strip: &Area<'_>, items: &[(String, Rgb)]) -> DrawResult<()> {
    let y = (LEGEND_STRIP_PX / 2) as i32;
    let mut x = 70i32;
    for (label, colour) in items {
        strip.draw(&PathElement::new(
            vec![(x, y), (x + 22, y)],
            colour.rgba(1.0).stroke_width(3),
        ))?;
        strip.draw(&Text::new(
            label.clone(),
            (x + 28, y - 7),
            (FONT, 15).into_font(),
        ))?;
        // Room for the text at ~8 px per character of a 15 px sans-serif font.
        x += 28 + 8 * label.chars().count() as i32 + 24;
    }
    Ok(())
}

fn no_data(area: &Area<'_>, title: &str) -> DrawResult<()> {
    let text = if title.is_empty() {
        "no data".to_string()
    } else {
        format!("{title}: no data")
    };
    area.draw(&Text::new(text, (20, 30), (FONT, 15).into_font()))?;
    Ok(())
}

fn draw_chart(area: &Area<'_>, c: &Chart) -> DrawResult<()> {
    let (dx, dy) = c.data_ranges();
    let x = c.x_range.and_then(valid).or(dx.map(|r| padded(r, 0.05)));
    let y = if c.y_log {
        // Padded by 5 % of the decades spanned; a range that is not positive is none.
        let positive = |r: Span| (r.0 > 0.0).then_some(r);
        c.y_range.and_then(valid).and_then(positive).or(dy.map(|r| {
            let (lo, hi) = padded((r.0.log10(), r.1.log10()), 0.05);
            (10f64.powf(lo), 10f64.powf(hi))
        }))
    } else {
        c.y_range.and_then(valid).or(dy.map(|r| padded(r, 0.05)))
    };
    let (Some(mut x), Some(mut y)) = (x, y) else {
        return no_data(area, &c.title);
    };
    let inner = if c.title.is_empty() {
        area.clone()
    } else {
        area.titled(&c.title, (FONT, 15))?
    };
    // Row names need room for their text left of the axis.
    let longest = c.y_categories.iter().map(|s| s.chars().count()).max();
    let y_label_area = longest.map_or(Y_LABEL_AREA, |n| Y_LABEL_AREA.max(n as u32 * 7 + 20));
    if c.equal_scale && !c.y_log {
        let (w, h) = inner.dim_in_pixel();
        let pw = w.saturating_sub(2 * MARGIN + y_label_area).max(1) as f64;
        let ph = h.saturating_sub(2 * MARGIN + X_LABEL_AREA).max(1) as f64;
        let s = (pw / (x.1 - x.0)).min(ph / (y.1 - y.0));
        let widen = |r: (f64, f64), px: f64| {
            let (mid, half) = (0.5 * (r.0 + r.1), 0.5 * px / s);
            (mid - half, mid + half)
        };
        x = widen(x, pw);
        y = widen(y, ph);
    }
    let mut builder = ChartBuilder::on(&inner);
    builder
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(y_label_area);
    if c.y_log {
        let mut chart = builder.build_cartesian_2d(x.0..x.1, (y.0..y.1).log_scale())?;
        fill_chart(&inner, &mut chart, c, x, y)
    } else {
        let mut chart = builder.build_cartesian_2d(x.0..x.1, y.0..y.1)?;
        fill_chart(&inner, &mut chart, c, x, y)
    }
}

/// The axes, their labels and the grid; named rows as the y axis's tick labels.
fn draw_mesh<'b, Y>(
    chart: &mut ChartContext<'b, SVGBackend<'b>, Cartesian2d<RangedCoordf64, Y>>,
    c: &Chart,
) -> DrawResult<()>
where
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let rows = &c.y_categories;
    let row_name = |v: &f64| {
        let k = v.round();
        if (v - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < rows.len() {
            rows[k as usize].clone()
        } else {
            String::new()
        }
    };
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(c.x_label.as_str())
        .y_desc(c.y_label.as_str())
        .light_line_style(TRANSPARENT)
        .bold_line_style(RGBColor(225, 225, 225))
        .label_style((FONT, 12))
        .axis_desc_style((FONT, 13));
    if !rows.is_empty() {
        mesh.y_labels(rows.len()).y_label_formatter(&row_name);
    }
    mesh.draw()?;
    Ok(())
}

/// The rectangles: fill, outline, text at the centre; those with a corner `finite` rejects are
/// left out.
fn draw_rects<'b, Y>(
    inner: &Area<'b>,
    chart: &mut ChartContext<'b, SVGBackend<'b>, Cartesian2d<RangedCoordf64, Y>>,
    rects: &[Rect],
    finite: impl Fn(&(f64, f64)) -> bool,
) -> DrawResult<()>
where
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    for r in rects {
        if !(finite(&r.min) && finite(&r.max)) {
            continue;
        }
        if let Some((col, op)) = r.fill {
            chart.draw_series(std::iter::once(Rectangle::new(
                [r.min, r.max],
                col.rgba(op).filled(),
            )))?;
        }
        if let Some((col, width, dashed)) = r.stroke {
            let ring = vec![r.min, (r.max.0, r.min.1), r.max, (r.min.0, r.max.1), r.min];
            let style = col.rgba(1.0).stroke_width(width);
            if dashed {
                chart.draw_series(std::iter::once(DashedPathElement::new(ring, 6, 4, style)))?;
            } else {
                chart.draw_series(std::iter::once(PathElement::new(ring, style)))?;
            }
        }
        if let Some(t) = &r.text {
            let centre = (0.5 * (r.min.0 + r.max.0), 0.5 * (r.min.1 + r.max.1));
            chart.draw_series(std::iter::once(Text::new(
                t.clone(),
                centre,
                (FONT, 11)
                    .into_font()
                    .into_text_style(inner)
                    .pos(Pos::new(HPos::Center, VPos::Center)),
            )))?;
        }
    }
    Ok(())
}

/// The mesh and everything of `c` on a chart whose y axis is linear or logarithmic.
fn fill_chart<'b, Y>(
    inner: &Area<'b>,
    chart: &mut ChartContext<'b, SVGBackend<'b>, Cartesian2d<RangedCoordf64, Y>>,
    c: &Chart,
    x: Span,
    y: Span,
) -> DrawResult<()>
where
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    draw_mesh(chart, c)?;
    let finite = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite() && (!c.y_log || p.1 > 0.0);
    draw_rects(inner, chart, &c.rects, finite)?;
    for h in &c.hlines {
        if !h.y.is_finite() {
            continue;
        }
        let pts = vec![(x.0, h.y), (x.1, h.y)];
        let style = h.color.rgba(1.0).stroke_width(1);
        if h.dashed {
            chart.draw_series(std::iter::once(DashedPathElement::new(pts, 5, 3, style)))?;
        } else {
            chart.draw_series(std::iter::once(PathElement::new(pts, style)))?;
        }
    }
    for v in &c.vlines {
        if !v.x.is_finite() {
            continue;
        }
        let pts = vec![(v.x, y.0), (v.x, y.1)];
        let style = v.color.rgba(1.0).stroke_width(1);
        if v.dashed {
            chart.draw_series(std::iter::once(DashedPathElement::new(pts, 5, 3, style)))?;
        } else {
            chart.draw_series(std::iter::once(PathElement::new(pts, style)))?;
        }
    }
    let mut legend = false;
    for l in &c.lines {
        let pts: Vec<(f64, f64)> = l.points.iter().copied().filter(finite).collect();
        let style = l.color.rgba(l.opacity).stroke_width(l.width.max(1));
        let drawn = if l.dashed {
            chart.draw_series(DashedLineSeries::new(pts, 6, 4, style))?
        } else {
            chart.draw_series(LineSeries::new(pts, style))?
        };
        if let Some(label) = &l.label {
            legend = true;
            let (color, dashed) = (l.color, l.dashed);
            drawn.label(label.as_str()).legend(move |(px, py)| {
                let s = color.rgba(1.0).stroke_width(2);
                if dashed {
                    DashedPathElement::new(vec![(px, py), (px + 18, py)], 4, 2, s).into_dyn()
                } else {
                    PathElement::new(vec![(px, py), (px + 18, py)], s).into_dyn()
                }
            });
        }
    }
    for m in &c.markers {
        let color = m.color.rgba(1.0);
        let style = if m.filled {
            color.filled()
        } else {
            color.stroke_width(2)
        };
        let r = m.radius.max(1);
        let pts: Vec<(f64, f64)> = m.points.iter().copied().filter(finite).collect();
        let drawn = chart.draw_series(pts.iter().map(|p| Circle::new(*p, r, style)))?;
        if let Some(label) = &m.label {
            legend = true;
            drawn
                .label(label.as_str())
                .legend(move |(px, py)| Circle::new((px + 9, py), r.max(3), style));
        }
        let texts = m
            .points
            .iter()
            .zip(&m.texts)
            .filter(|(p, t)| finite(p) && !t.is_empty());
        chart.draw_series(texts.map(|(p, t)| {
            EmptyElement::at(*p)
                + Text::new(
                    t.clone(),
                    (r as i32 + 2, -(r as i32) - 12),
                    (FONT, 12).into_font().color(&color),
                )
        }))?;
    }
    let labels = c
        .labels
        .iter()
        .filter(|l| finite(&l.at) && !l.text.is_empty());
    chart.draw_series(labels.map(|l| {
        Text::new(
            l.text.clone(),
            l.at,
            (FONT, 12).into_font().color(&l.color.rgba(1.0)),
        )
    }))?;
    if legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(170, 170, 170))
            .label_font((FONT, 12))
            .draw()?;
    }
    Ok(())
}

fn draw_bars(area: &Area<'_>, b: &Bars) -> DrawResult<()> {
    let n = b.groups.len();
    let top = b
        .series
        .iter()
        .flat_map(|s| s.values.iter())
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    if n == 0 || b.series.is_empty() || !top.is_finite() {
        return no_data(area, &b.title);
    }
    let bottom = b
        .series
        .iter()
        .flat_map(|s| s.values.iter())
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0, f64::min);
    // Head room above the highest bar for the legend (about 7 % of the height per entry).
    let (lo, hi) = padded((bottom, top.max(0.0)), 0.08);
    let hi = hi + (hi - lo) * 0.07 * b.series.len() as f64;
    let lo = if bottom >= 0.0 { 0.0 } else { lo };
    let inner = if b.title.is_empty() {
        area.clone()
    } else {
        area.titled(&b.title, (FONT, 15))?
    };
    // Group names under their groups; turned upright when they would run into each other.
    let (w, _) = inner.dim_in_pixel();
    let per_group = w.saturating_sub(2 * MARGIN + Y_LABEL_AREA) as f64 / n as f64;
    let longest = b
        .groups
        .iter()
        .map(|g| g.chars().count())
        .max()
        .unwrap_or(0);
    let upright = longest as f64 * 7.0 > per_group;
    let label_area = if upright {
        (longest as u32 * 7 + 12).min(180)
    } else {
        X_LABEL_AREA
    };
    let mut chart = ChartBuilder::on(&inner)
        .margin(MARGIN)
        .x_label_area_size(label_area)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(0f64..n as f64, lo..hi)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(0)
        .y_desc(b.y_label.as_str())
        .light_line_style(TRANSPARENT)
        .bold_line_style(RGBColor(225, 225, 225))
        .label_style((FONT, 12))
        .axis_desc_style((FONT, 13))
        .draw()?;
    // The group names, each under the centre of its group (the axis's own labels would sit
    // at round numbers, not at the groups).
    let base = inner.get_base_pixel();
    let name_style = if upright {
        (FONT, 12)
            .into_font()
            .transform(FontTransform::Rotate90)
            .into_text_style(&inner)
            .pos(Pos::new(HPos::Left, VPos::Center))
    } else {
        (FONT, 12)
            .into_font()
            .into_text_style(&inner)
            .pos(Pos::new(HPos::Center, VPos::Top))
    };
    for (g, name) in b.groups.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(g as f64 + 0.5, lo));
        inner.draw_text(name, &name_style, (px - base.0, py - base.1 + 6))?;
    }
    let k = b.series.len() as f64;
    let bw = 0.8 / k;
    for (j, s) in b.series.iter().enumerate() {
        let style = s.color.rgba(1.0).filled();
        let bars = s
            .values
            .iter()
            .take(n)
            .enumerate()
            .filter(|(_, v)| v.is_finite())
            .map(|(g, v)| {
                let x0 = g as f64 + 0.1 + bw * j as f64;
                Rectangle::new([(x0, 0.0), (x0 + bw, *v)], style)
            });
        let color = s.color;
        chart
            .draw_series(bars)?
            .label(s.label.as_str())
            .legend(move |(px, py)| {
                Rectangle::new([(px, py - 5), (px + 10, py + 5)], color.rgba(1.0).filled())
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(170, 170, 170))
        .label_font((FONT, 12))
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests;
