//! SVG figures (plotters, SVG backend only): the CMIF with picked modes (Fig. 3 of the
//! wafer-stage paper), Bode magnitude grids of data and model, one entry with data, model
//! and residual against the noise.
//!
//! The building blocks are reusable:
//!
//! - [`LinePlot`]: one panel with a linear or logarithmic [`Axis`] each way, any number of
//!   [`Series`] (lines, dashed lines, points) and labelled [`Marker`]s;
//! - [`PlotGrid`]: panels in rows and columns under one title;
//! - ready-made figures: [`cmif_plot`] / [`cmif_svg`], [`magnitude_grid`] and
//!   [`entry_overlay`].
//!
//! Values that a log axis cannot show (zero, negative, non-finite) break the line
//! instead of failing; axis ranges are taken from the data unless given.

use crate::FrfitError;
use frf_data::cmif::{Cmif, CmifPeak};
use frf_data::FrfDataset;
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

/// Colours of successive series (the "tab10" palette).
pub const PALETTE: [(u8, u8, u8); 10] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
];

/// Linear or base-10 logarithmic axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Linear.
    Linear,
    /// Logarithmic (only positive values are drawn).
    Log,
}

/// One axis: label, scale and an optional fixed range.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// Axis label, e.g. `"Frequency [Hz]"`.
    pub label: String,
    /// Linear or log.
    pub scale: Scale,
    /// Fixed `(min, max)`; `None` takes the range of the data (with a small margin).
    pub range: Option<(f64, f64)>,
}

impl Axis {
    /// A logarithmic axis with a label and an automatic range.
    pub fn log(label: impl Into<String>) -> Self {
        Self {
            label: label.into(),
            scale: Scale::Log,
            range: None,
        }
    }
    /// A linear axis with a label and an automatic range.
    pub fn linear(label: impl Into<String>) -> Self {
        Self {
            label: label.into(),
            scale: Scale::Linear,
            range: None,
        }
    }
    /// The same axis with a fixed range.
    pub fn with_range(mut self, lo: f64, hi: f64) -> Self {
        self.range = Some((lo, hi));
        self
    }
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeriesKind {
    /// A solid line.
    Line,
    /// A dashed line.
    Dashed,
    /// Dots, one per point.
    Points,
}

/// One series of points `(x[i], y[i])`.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry (an empty name is left out of the legend).
    pub name: String,
    /// Abscissae.
    pub x: Vec<f64>,
    /// Ordinates (same length as `x`; extra values of either are ignored).
    pub y: Vec<f64>,
    /// Line or point style.
    pub kind: SeriesKind,
    /// RGB colour; `None` takes the next colour of [`PALETTE`].
    pub color: Option<(u8, u8, u8)>,
    /// Line width or dot radius, pixels.
    pub width: u32,
}

impl Series {
    /// A solid line.
    pub fn line(name: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self {
            name: name.into(),
            x,
            y,
            kind: SeriesKind::Line,
            color: None,
            width: 1,
        }
    }
    /// A dashed line.
    pub fn dashed(name: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self {
            kind: SeriesKind::Dashed,
            ..Self::line(name, x, y)
        }
    }
    /// Dots.
    pub fn points(name: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self {
            kind: SeriesKind::Points,
            width: 2,
            ..Self::line(name, x, y)
        }
    }
    /// The same series in colour `rgb`.
    pub fn with_color(mut self, rgb: (u8, u8, u8)) -> Self {
        self.color = Some(rgb);
        self
    }
    /// The same series with line width (or dot radius) `w` pixels.
    pub fn with_width(mut self, w: u32) -> Self {
        self.width = w.max(1);
        self
    }
}

/// A labelled dot, e.g. a picked mode.
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    /// Abscissa.
    pub x: f64,
    /// Ordinate.
    pub y: f64,
    /// Text written next to the dot.
    pub label: Option<String>,
    /// RGB colour (default black).
    pub color: Option<(u8, u8, u8)>,
}

/// One panel: title, axes, series and markers.
#[derive(Debug, Clone, PartialEq)]
pub struct LinePlot {
    /// Panel title (empty for none).
    pub title: String,
    /// Horizontal axis.
    pub x: Axis,
    /// Vertical axis.
    pub y: Axis,
    /// The series, drawn in order.
    pub series: Vec<Series>,
    /// Dots with labels, drawn on top.
    pub markers: Vec<Marker>,
    /// Draw a legend of the named series.
    pub legend: bool,
}

impl LinePlot {
    /// A Bode-magnitude style panel: log frequency in Hz against a log magnitude.
    pub fn new(title: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            x: Axis::log("Frequency [Hz]"),
            y: Axis::log("Magnitude"),
            series: Vec::new(),
            markers: Vec::new(),
            legend: true,
        }
    }
    /// Replaces the horizontal axis.
    pub fn with_x(mut self, axis: Axis) -> Self {
        self.x = axis;
        self
    }
    /// Replaces the vertical axis.
    pub fn with_y(mut self, axis: Axis) -> Self {
        self.y = axis;
        self
    }
    /// Adds a series.
    pub fn with_series(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }
    /// Adds a marker.
    pub fn with_marker(mut self, m: Marker) -> Self {
        self.markers.push(m);
        self
    }

    /// Writes this panel alone to an SVG file of `size` pixels.
    pub fn write_svg(&self, path: impl AsRef<Path>, size: (u32, u32)) -> Result<(), FrfitError> {
        let path = path.as_ref();
        let root = SVGBackend::new(path, size).into_drawing_area();
        let res = root
            .fill(&WHITE)
            .map_err(|e| e.to_string())
            .and_then(|_| self.draw(&root))
            .and_then(|_| root.present().map_err(|e| e.to_string()));
        res.map_err(|message| plot_error(path, message))
    }

    /// Draws the panel on a drawing area (of an SVG, or a cell of a [`PlotGrid`]).
    pub fn draw(&self, area: &DrawingArea<SVGBackend<'_>, Shift>) -> Result<(), String> {
        self.draw_with(area, &PanelStyle::default())
    }

    /// Draws the panel on a drawing area in the given [`PanelStyle`] (tick labels, title
    /// placement, fonts), with the ranges of its own axes.
    pub fn draw_with(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        style: &PanelStyle,
    ) -> Result<(), String> {
        let xr = axis_range(
            &self.x,
            self.series.iter().map(|s| &s.x),
            &self.markers,
            true,
        );
        let yr = axis_range(
            &self.y,
            self.series.iter().map(|s| &s.y),
            &self.markers,
            false,
        );
        self.draw_ranged(area, style, xr, yr)
    }

    /// Draws with the given ranges (already valid for the scales of the axes).
    fn draw_ranged(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        style: &PanelStyle,
        (x0, x1): (f64, f64),
        (y0, y1): (f64, f64),
    ) -> Result<(), String> {
        // Approximate plotting-area size, for the density of log-axis labels.
        let (w, h) = area.dim_in_pixel();
        let (x_area, y_area, margin, font) = self.layout(area, style);
        let caption = if self.title.is_empty() || style.inset_title {
            0
        } else {
            font + 3 + margin
        };
        let px_w = (w as i32 - y_area as i32 - 2 * margin).max(1) as f64;
        let px_h = (h as i32 - x_area as i32 - 2 * margin - caption).max(1) as f64;
        let log_x = |r: std::ops::Range<f64>| {
            let (mut bold, light) = log_key_points(x0, x1, px_w, 48.0);
            let clear = style.right_edge_clear as f64;
            if clear > 0.0 && x1 > x0 && x0 > 0.0 {
                let span = (x1 / x0).ln();
                bold.retain(|v| (x1 / v).ln() / span * px_w >= clear);
            }
            r.log_scale().with_key_points(bold).with_light_points(light)
        };
        let log_y = |r: std::ops::Range<f64>| {
            let (bold, light) = log_key_points(y0, y1, px_h, 26.0);
            r.log_scale().with_key_points(bold).with_light_points(light)
        };
        match (self.x.scale, self.y.scale) {
            (Scale::Log, Scale::Log) => self.draw_in(area, style, log_x(x0..x1), log_y(y0..y1)),
            (Scale::Log, Scale::Linear) => self.draw_in(area, style, log_x(x0..x1), y0..y1),
            (Scale::Linear, Scale::Log) => self.draw_in(area, style, x0..x1, log_y(y0..y1)),
            (Scale::Linear, Scale::Linear) => self.draw_in(area, style, x0..x1, y0..y1),
        }
    }

    /// Label-area heights and widths, margin and font of this panel in `style`.
    fn layout(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        style: &PanelStyle,
    ) -> (u32, u32, i32, i32) {
        let (w, h) = area.dim_in_pixel();
        let small = w < 500 || h < 300;
        let font: i32 = style
            .font
            .map_or(if small { 11 } else { 14 }, |f| f.min(200) as i32);
        let (x_area, y_area) = style
            .label_area
            .unwrap_or(if small { (30, 52) } else { (45, 70) });
        let margin = style.margin.unwrap_or(if small { 4 } else { 10 }).min(1000) as i32;
        (x_area, y_area, margin, font)
    }

    fn draw_in<XR, YR>(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        style: &PanelStyle,
        xr: XR,
        yr: YR,
    ) -> Result<(), String>
    where
        XR: AsRangedCoord<Value = f64>,
        YR: AsRangedCoord<Value = f64>,
        XR::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
        YR::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
    {
        let err = |e: DrawingAreaErrorKind<_>| e.to_string();
        let (x_area, y_area, margin, font) = self.layout(area, style);
        let mut builder = ChartBuilder::on(area);
        builder
            .margin(margin)
            .x_label_area_size(x_area)
            .y_label_area_size(y_area);
        if !self.title.is_empty() && !style.inset_title {
            builder.caption(&self.title, ("sans-serif", font + 3));
        }
        let mut chart = builder.build_cartesian_2d(xr, yr).map_err(err)?;
        let x_log = self.x.scale == Scale::Log;
        let y_log = self.y.scale == Scale::Log;
        let xf = move |v: &f64| fmt_tick(*v, x_log);
        let yf = move |v: &f64| fmt_tick(*v, y_log);
        {
            let mut mesh = chart.configure_mesh();
            mesh.x_label_formatter(&xf)
                .y_label_formatter(&yf)
                .label_style(("sans-serif", font))
                .axis_desc_style(("sans-serif", font))
                .light_line_style(RGBColor(235, 235, 235))
                .bold_line_style(RGBColor(200, 200, 200));
            if style.axis_desc {
                mesh.x_desc(self.x.label.as_str())
                    .y_desc(self.y.label.as_str());
            }
            if let Some((nx, ny)) = style.max_ticks {
                mesh.x_labels(nx).y_labels(ny);
            }

            mesh.draw().map_err(err)?;
        }
        let (pw, ph) = chart.plotting_area().dim_in_pixel();
        if style.frame {
            chart
                .plotting_area()
                .strip_coord_spec()
                .draw(&Rectangle::new(
                    [(0, 0), (pw as i32 - 1, ph as i32 - 1)],
                    ShapeStyle::from(RGBColor(150, 150, 150)).stroke_width(1),
                ))
                .map_err(err)?;
        }
        // Thousands of lines in a few hundred pixels: keep the first, last, lowest and
        // highest point of every pixel column (resonance peaks and notches survive).
        let max_points = 2 * pw.max(1) as usize;
        let mut any_named = false;
        for (idx, s) in self.series.iter().enumerate() {
            let (r, g, b) = s.color.unwrap_or(PALETTE[idx % PALETTE.len()]);
            let color = RGBColor(r, g, b);
            let style = ShapeStyle::from(color).stroke_width(s.width);
            let segments = segments(s, x_log, y_log);
            let mut first = true;
            for seg in segments {
                let seg = decimate(seg, max_points, |p| chart.backend_coord(p));
                let anno = match s.kind {
                    SeriesKind::Line => chart
                        .draw_series(LineSeries::new(seg, style))
                        .map_err(err)?,
                    SeriesKind::Dashed => chart
                        .draw_series(DashedLineSeries::new(seg, 6, 4, style))
                        .map_err(err)?,
                    SeriesKind::Points => chart
                        .draw_series(
                            seg.into_iter()
                                .map(|p| Circle::new(p, s.width, style.filled())),
                        )
                        .map_err(err)?,
                };
                if first && !s.name.is_empty() {
                    let kind = s.kind;
                    anno.label(s.name.as_str()).legend(move |(x, y)| {
                        if kind == SeriesKind::Points {
                            EmptyElement::at((x, y))
                                + Circle::new((10, 0), 3, style.filled()).into_dyn()
                        } else if kind == SeriesKind::Dashed {
                            EmptyElement::at((x, y))
                                + DashedPathElement::new(vec![(0, 0), (20, 0)], 6, 4, style)
                                    .into_dyn()
                        } else {
                            EmptyElement::at((x, y))
                                + PathElement::new(vec![(0, 0), (20, 0)], style).into_dyn()
                        }
                    });
                    any_named = true;
                }
                first = false;
            }
        }
        // Markers: dots, then labels placed in pixel space so that close labels do not
        // overlap (a label moves up until it clears the ones already placed).
        let mut placed: Vec<(i32, i32, i32, i32)> = Vec::new();
        let mut marks: Vec<&Marker> = self
            .markers
            .iter()
            .filter(|m| visible(m.x, x_log) && visible(m.y, y_log))
            .collect();
        marks.sort_by(|a, b| a.x.total_cmp(&b.x));
        for m in &marks {
            let (r, g, b) = m.color.unwrap_or((0, 0, 0));
            let c = RGBColor(r, g, b);
            chart
                .draw_series(std::iter::once(Circle::new((m.x, m.y), 3, c.filled())))
                .map_err(err)?;
        }
        let (ax0, ay0) = chart.plotting_area().get_base_pixel();
        for m in &marks {
            let Some(text) = &m.label else { continue };
            let (px, py) = chart.backend_coord(&(m.x, m.y));
            let (px, py) = (px - ax0, py - ay0);
            let tw = (text.chars().count() as f64 * font as f64 * 0.55).ceil() as i32;
            let th = font + 2;
            let mut x = px - tw / 2;
            let mut y = py - 8 - th;
            let mut tries = 0;
            while tries < 12
                && placed
                    .iter()
                    .any(|&(a, b, c, d)| x < c && x + tw > a && y < d && y + th > b)
            {
                y -= th;
                tries += 1;
            }
            x = x.max(0);
            y = y.max(0);
            placed.push((x, y, x + tw, y + th));
            let (r, g, b) = m.color.unwrap_or((0, 0, 0));
            let text_color = RGBColor(r, g, b);
            let style = TextStyle::from(("sans-serif", font - 1).into_font()).color(&text_color);
            chart
                .plotting_area()
                .strip_coord_spec()
                .draw(&Text::new(text.clone(), (x, y), style))
                .map_err(err)?;
            if y + th < py - 8 {
                // A leader from a raised label to its dot.
                chart
                    .plotting_area()
                    .strip_coord_spec()
                    .draw(&PathElement::new(
                        vec![(px, y + th), (px, py - 4)],
                        ShapeStyle::from(RGBColor(150, 150, 150)).stroke_width(1),
                    ))
                    .map_err(err)?;
            }
        }
        if style.inset_title && !self.title.is_empty() {
            let tw = (self.title.chars().count() as f64 * font as f64 * 0.6).ceil() as i32;
            let area = chart.plotting_area().strip_coord_spec();
            area.draw(&Rectangle::new(
                [(1, 1), (tw + 6, font + 4)],
                WHITE.mix(0.8).filled(),
            ))
            .map_err(err)?;
            area.draw(&Text::new(
                self.title.clone(),
                (4, 2),
                ("sans-serif", font).into_font().color(&BLACK),
            ))
            .map_err(err)?;
        }
        if self.legend && style.legend && any_named {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font(("sans-serif", font))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(err)?;
        }
        Ok(())
    }
}

/// Panels in a grid under one title.
#[derive(Debug, Clone, PartialEq)]
pub struct PlotGrid {
    /// Title over the grid (empty for none).
    pub title: String,
    /// Number of rows.
    pub rows: usize,
    /// Number of columns.
    pub cols: usize,
    /// The panels, row after row (missing panels stay blank, extra ones are dropped).
    pub panels: Vec<LinePlot>,
    /// Size of one panel, pixels.
    pub panel_size: (u32, u32),
}

impl PlotGrid {
    /// Writes the grid to an SVG file.
    pub fn write_svg(&self, path: impl AsRef<Path>) -> Result<(), FrfitError> {
        let path = path.as_ref();
        let (rows, cols) = (self.rows.max(1), self.cols.max(1));
        let title_h = if self.title.is_empty() { 0 } else { 40 };
        let w = (self.panel_size.0 as usize * cols).min(20_000) as u32;
        let h = (self.panel_size.1 as usize * rows).min(20_000) as u32 + title_h;
        let root = SVGBackend::new(path, (w, h)).into_drawing_area();
        let run = || -> Result<(), String> {
            root.fill(&WHITE).map_err(|e| e.to_string())?;
            let body = if self.title.is_empty() {
                root.clone()
            } else {
                root.titled(&self.title, ("sans-serif", 22))
                    .map_err(|e| e.to_string())?
            };
            let cells = body.split_evenly((rows, cols));
            for (cell, panel) in cells.iter().zip(&self.panels) {
                panel.draw(cell)?;
            }
            root.present().map_err(|e| e.to_string())
        };
        run().map_err(|message| plot_error(path, message))
    }
}

/// How a panel draws its frame, ticks and title (see [`LinePlot::draw_with`]); the
/// default is the stand-alone look of [`LinePlot::draw`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PanelStyle {
    /// Font size, pixels; `None` picks 14 (11 on panels smaller than 500 x 300).
    pub font: Option<u32>,
    /// Heights of the tick-label area below and widths of the one left of the plotting
    /// area, pixels (`0` hides the tick labels); `None` picks by panel size.
    pub label_area: Option<(u32, u32)>,
    /// Margin around the panel, pixels; `None` picks by panel size.
    pub margin: Option<u32>,
    /// Write the axis labels ([`Axis::label`]) next to the tick labels.
    pub axis_desc: bool,
    /// Write the title inside the plotting area's top-left corner instead of above it.
    pub inset_title: bool,
    /// Draw a thin frame around the plotting area (useful without tick-label areas).
    pub frame: bool,
    /// Draw the panel's own legend (when [`LinePlot::legend`] is also set).
    pub legend: bool,
    /// At most this many tick labels along x and y (`None`: the plotters default; log
    /// axes place their own).
    pub max_ticks: Option<(usize, usize)>,
    /// No x tick label on a log axis within this many pixels of the right end (so that
    /// it does not run into the first label of the panel to the right); 0 for none.
    pub right_edge_clear: u32,
}

impl Default for PanelStyle {
    fn default() -> Self {
        Self {
            font: None,
            label_area: None,
            margin: None,
            axis_desc: true,
            inset_title: false,
            frame: false,
            legend: true,
            max_ticks: None,
            right_edge_clear: 0,
        }
    }
}

/// Panels with shared axes: every panel has the same x and y range, tick labels only on
/// the left column and the bottom row, the axis labels once for the whole figure, the
/// panel titles inside the panels and one legend under the title. This keeps many small
/// panels (an element-wise Bode grid of a 4 x 13 plant) readable.
#[derive(Debug, Clone, PartialEq)]
pub struct SharedGrid {
    /// Title over the grid (empty for none).
    pub title: String,
    /// Number of rows.
    pub rows: usize,
    /// Number of columns.
    pub cols: usize,
    /// The panels, row after row; `None` leaves a cell blank. Their own axes are ignored
    /// in favour of [`SharedGrid::x`] and [`SharedGrid::y`].
    pub panels: Vec<Option<LinePlot>>,
    /// The shared horizontal axis (range from all panels when not fixed).
    pub x: Axis,
    /// The shared vertical axis (range from all panels when not fixed).
    pub y: Axis,
    /// Size of the plotting area of one panel, pixels.
    pub panel_size: (u32, u32),
    /// Draw one legend (the named series of the first panel) under the title.
    pub legend: bool,
}

impl SharedGrid {
    /// Writes the grid to an SVG file.
    pub fn write_svg(&self, path: impl AsRef<Path>) -> Result<(), FrfitError> {
        let path = path.as_ref();
        let (rows, cols) = (self.rows.max(1), self.cols.max(1));
        let (pw, ph) = (
            self.panel_size.0.clamp(40, 2000),
            self.panel_size.1.clamp(30, 2000),
        );
        let gap = 3u32;
        let (cw, ch) = (pw + 2 * gap, ph + 2 * gap);
        let font = 11u32;
        let (y_ticks, x_ticks) = (44u32, 18u32);
        let (y_desc, x_desc) = (20u32, 22u32);
        let title_h = if self.title.is_empty() { 6 } else { 34 };
        let legend_h = if self.legend { 22 } else { 0 };
        let top = title_h + legend_h;
        let body_w = y_ticks + cw * cols as u32;
        let body_h = ch * rows as u32 + x_ticks;
        let w = (y_desc + body_w + 12).min(30_000);
        let h = (top + body_h + x_desc).min(30_000);
        let all_x = self.panels.iter().flatten().flat_map(|p| p.series.iter());
        let xr = axis_range(
            &self.x,
            all_x.map(|s| &s.x),
            &self
                .panels
                .iter()
                .flatten()
                .flat_map(|p| p.markers.iter().cloned())
                .collect::<Vec<_>>(),
            true,
        );
        let all_y = self.panels.iter().flatten().flat_map(|p| p.series.iter());
        let yr = axis_range(&self.y, all_y.map(|s| &s.y), &[], false);
        let root = SVGBackend::new(path, (w, h)).into_drawing_area();
        let run = || -> Result<(), String> {
            let err = |e: DrawingAreaErrorKind<_>| e.to_string();
            root.fill(&WHITE).map_err(err)?;
            if !self.title.is_empty() {
                let style = TextStyle::from(("sans-serif", 19).into_font())
                    .pos(Pos::new(HPos::Center, VPos::Top));
                root.draw(&Text::new(self.title.clone(), (w as i32 / 2, 8), style))
                    .map_err(err)?;
            }
            if self.legend {
                if let Some(first) = self.panels.iter().flatten().next() {
                    let mut x = (y_desc + y_ticks) as i32;
                    let y = title_h as i32 + 10;
                    for (idx, s) in first.series.iter().enumerate() {
                        if s.name.is_empty() {
                            continue;
                        }
                        let (r, g, b) = s.color.unwrap_or(PALETTE[idx % PALETTE.len()]);
                        let st = ShapeStyle::from(RGBColor(r, g, b)).stroke_width(s.width.max(2));
                        match s.kind {
                            SeriesKind::Points => root
                                .draw(&Circle::new((x + 10, y), 3, st.filled()))
                                .map_err(err)?,
                            SeriesKind::Dashed => root
                                .draw(&PathElement::new(vec![(x, y), (x + 8, y)], st))
                                .and_then(|_| {
                                    root.draw(&PathElement::new(vec![(x + 13, y), (x + 21, y)], st))
                                })
                                .map_err(err)?,
                            SeriesKind::Line => root
                                .draw(&PathElement::new(vec![(x, y), (x + 21, y)], st))
                                .map_err(err)?,
                        }
                        let style = TextStyle::from(("sans-serif", 13).into_font())
                            .pos(Pos::new(HPos::Left, VPos::Center));
                        root.draw(&Text::new(s.name.clone(), (x + 27, y), style))
                            .map_err(err)?;
                        x += 27 + (s.name.chars().count() as f64 * 7.5) as i32 + 22;
                    }
                }
            }
            // Axis labels, once.
            let style = TextStyle::from(("sans-serif", 13).into_font())
                .pos(Pos::new(HPos::Center, VPos::Bottom));
            root.draw(&Text::new(
                self.x.label.clone(),
                (
                    (y_desc + y_ticks + cw * cols as u32 / 2) as i32,
                    h as i32 - 4,
                ),
                style,
            ))
            .map_err(err)?;
            let style = TextStyle::from(
                ("sans-serif", 13)
                    .into_font()
                    .transform(FontTransform::Rotate270),
            )
            .pos(Pos::new(HPos::Center, VPos::Top));
            root.draw(&Text::new(
                self.y.label.clone(),
                (3, (top + ch * rows as u32 / 2) as i32),
                style,
            ))
            .map_err(err)?;
            let body = root.clone().shrink((y_desc, top), (body_w, body_h));
            let xs: Vec<u32> = (1..cols).map(|c| y_ticks + cw * c as u32).collect();
            let ys: Vec<u32> = (1..rows).map(|r| ch * r as u32).collect();
            let cells = body.split_by_breakpoints(xs, ys);
            for (idx, cell) in cells.iter().enumerate() {
                let (r, c) = (idx / cols, idx % cols);
                let Some(Some(panel)) = self.panels.get(idx) else {
                    continue;
                };
                let panel_style = PanelStyle {
                    font: Some(font),
                    label_area: Some((
                        if r + 1 == rows { x_ticks } else { 0 },
                        if c == 0 { y_ticks } else { 0 },
                    )),
                    margin: Some(gap),
                    axis_desc: false,
                    inset_title: true,
                    frame: true,
                    legend: false,
                    max_ticks: Some((6, 5)),
                    right_edge_clear: if c + 1 < cols { 16 } else { 0 },
                };
                let mut p = panel.clone();
                p.x.scale = self.x.scale;
                p.y.scale = self.y.scale;
                p.draw_ranged(cell, &panel_style, xr, yr)?;
            }
            root.present().map_err(err)
        };
        run().map_err(|message| plot_error(path, message))
    }
}

/// Keeps, of every run of consecutive points that fall in the same pixel column, the
/// first, the lowest, the highest and the last (in their order): the drawn line is the
/// same, peaks and notches included, with at most four points per column. Series with at
/// most `max_points` points are returned unchanged.
fn decimate(
    seg: Vec<(f64, f64)>,
    max_points: usize,
    px: impl Fn(&(f64, f64)) -> (i32, i32),
) -> Vec<(f64, f64)> {
    if seg.len() <= max_points {
        return seg;
    }
    let pix: Vec<(i32, i32)> = seg.iter().map(&px).collect();
    let mut out = Vec::with_capacity(max_points * 2);
    let mut start = 0;
    while start < seg.len() {
        let col = pix[start].0;
        let (mut lo, mut hi) = (start, start);
        let mut end = start + 1;
        while end < seg.len() && pix[end].0 == col {
            // Pixel y grows downwards.
            if pix[end].1 > pix[lo].1 {
                lo = end;
            }
            if pix[end].1 < pix[hi].1 {
                hi = end;
            }
            end += 1;
        }
        let mut keep = [start, lo, hi, end - 1];
        keep.sort_unstable();
        let mut last = usize::MAX;
        for k in keep {
            if k != last {
                out.push(seg[k]);
                last = k;
            }
        }
        start = end;
    }
    out
}

fn plot_error(path: &Path, message: String) -> FrfitError {
    FrfitError::Plot {
        path: path.display().to_string(),
        message,
    }
}

fn visible(v: f64, log: bool) -> bool {
    v.is_finite() && (!log || v > 0.0)
}

/// Splits a series into runs of drawable points.
fn segments(s: &Series, x_log: bool, y_log: bool) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for (&x, &y) in s.x.iter().zip(&s.y) {
        if visible(x, x_log) && visible(y, y_log) {
            cur.push((x, y));
        } else if !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// The range of an axis: the fixed one when valid, else that of the data with a margin
/// (5 % linear, 3 % of the decades on log axes; the frequency axis gets none).
fn axis_range<'a>(
    axis: &Axis,
    values: impl Iterator<Item = &'a Vec<f64>>,
    markers: &[Marker],
    is_x: bool,
) -> (f64, f64) {
    let log = axis.scale == Scale::Log;
    if let Some((a, b)) = axis.range {
        if visible(a, log) && visible(b, log) && b > a {
            return (a, b);
        }
    }
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    let mut take = |v: f64| {
        if visible(v, log) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    };
    for vs in values {
        vs.iter().copied().for_each(&mut take);
    }
    for m in markers {
        take(if is_x { m.x } else { m.y });
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return if log { (1.0, 10.0) } else { (0.0, 1.0) };
    }
    if log {
        let (l, h) = (lo.log10(), hi.log10());
        let span = (h - l).max(1e-3);
        let pad = if is_x { 0.0 } else { 0.05 * span };
        let (l, h) = if h - l < 1e-3 {
            (l - 0.5, h + 0.5)
        } else {
            (l - pad, h + pad)
        };
        (10f64.powf(l), 10f64.powf(h))
    } else {
        let span = hi - lo;
        if span <= 0.0 {
            (lo - 1.0, hi + 1.0)
        } else {
            let pad = if is_x { 0.0 } else { 0.05 * span };
            (lo - pad, hi + pad)
        }
    }
}

/// Tick positions of a log axis over `(lo, hi)` drawn on `pixels` with labels at least
/// `gap` pixels apart: labelled (bold) points at 1, 2 and 5 times the decades when there
/// is room, else 1 and 3, else every decade or every 2nd, 3rd, 5th, 10th... decade; a
/// narrow range with fewer than three such points gets other integer multiples of its
/// decade (the roundest first) and, failing those, its rounded ends. Light grid lines at
/// the integer multiples of the decades (or at the decades when those are tight).
fn log_key_points(lo: f64, hi: f64, pixels: f64, gap: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo > 0.0 && hi > lo && lo.is_finite() && hi.is_finite()) {
        return (Vec::new(), Vec::new());
    }
    let decades = (hi / lo).log10();
    let ppd = pixels.max(1.0) / decades.max(1e-9);
    let (d0, d1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let inside = |v: f64| v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9);
    let multiples = |ms: &[f64], step: i32| -> Vec<f64> {
        let mut out = Vec::new();
        let mut d = d0;
        while d <= d1 {
            if d.rem_euclid(step) == 0 {
                for &m in ms {
                    let v = m * 10f64.powi(d);
                    if inside(v) {
                        out.push(v);
                    }
                }
            }
            d += 1;
        }
        out
    };
    let step = [1, 2, 3, 5, 10, 20, 50, 100]
        .into_iter()
        .find(|s| *s as f64 * ppd >= gap)
        .unwrap_or(100);
    let mut bold = multiples(&[1.0], step);
    if ppd * 2f64.log10() >= gap {
        bold.extend(multiples(&[2.0, 5.0], 1));
    } else if ppd * 3f64.log10() >= gap {
        bold.extend(multiples(&[3.0], 1));
    }
    if bold.len() < 3 {
        // A narrow range: any integer multiple of a decade that keeps the labels apart,
        // the roundest first.
        for m in [5.0, 2.0, 3.0, 4.0, 6.0, 7.0, 8.0, 9.0] {
            for v in multiples(&[m], 1) {
                if bold.iter().all(|b| (v / b).log10().abs() * ppd >= gap) {
                    bold.push(v);
                }
            }
        }
    }
    if bold.len() < 2 {
        let round = |v: f64| {
            let e = 10f64.powi(v.log10().floor() as i32 - 2);
            (v / e).round() * e
        };
        for v in [round(lo * 1.0001), round(hi * 0.9999)] {
            if inside(v) && bold.iter().all(|b| (v / b).log10().abs() * ppd >= gap) {
                bold.push(v);
            }
        }
    }
    bold.sort_by(f64::total_cmp);
    let light = if ppd >= 40.0 {
        multiples(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0], 1)
    } else {
        multiples(&[1.0], 1)
    };
    let max_points = (pixels / 2.0).max(2.0) as usize;
    bold.truncate(max_points);
    (bold, light)
}

/// Tick label: plain numbers for ordinary magnitudes, `1e-6` style otherwise.
fn fmt_tick(v: f64, log: bool) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if (1e-2..1e5).contains(&a) {
        let s = if a >= 100.0 || (log && (a - a.round()).abs() < 1e-9) {
            format!("{v:.0}")
        } else {
            let s = format!("{v:.3}");
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        };
        s
    } else {
        let s = format!("{v:.0e}");
        s
    }
}

/// The CMIF figure of section 4.4 / Fig. 3 of the wafer-stage paper as a [`LinePlot`]:
/// `sigma_i^2` against frequency on log axes, one line per singular value, the picked
/// peaks as dots labelled with their frequency in Hz.
pub fn cmif_plot(cmif: &Cmif, peaks: &[CmifPeak], title: &str) -> LinePlot {
    let mut plot = LinePlot::new(title).with_y(Axis::log("sigma_i^2 (CMIF)"));
    let f = cmif.freq_hz.clone();
    for i in 0..cmif.n_sv() {
        let y: Vec<f64> = cmif.sv2.iter().map(|row| row[i]).collect();
        plot.series
            .push(Series::line(format!("sigma_{}^2", i + 1), f.clone(), y));
    }
    // Keep the noise floor of rank-deficient data from squashing the curves: show at
    // most 12 decades below the largest value.
    let top = cmif
        .sv2
        .iter()
        .filter_map(|r| r.first().copied())
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold(0.0, f64::max);
    let bottom = cmif
        .sv2
        .iter()
        .flat_map(|r| r.iter().copied())
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold(f64::INFINITY, f64::min);
    if top > 0.0 && bottom.is_finite() {
        let lo = bottom.max(top * 1e-12);
        let (l, h) = (lo.log10(), top.log10());
        let pad = 0.04 * (h - l).max(1.0);
        // Room on top for the peak labels and the legend.
        plot.y.range = Some((10f64.powf(l - pad), 10f64.powf(h + 7.0 * pad)));
    }
    for p in peaks {
        plot.markers.push(Marker {
            x: p.f_hz,
            y: p.sv2,
            label: Some(fmt_hz(p.f_hz)),
            color: None,
        });
    }
    plot
}

fn fmt_hz(f: f64) -> String {
    if f >= 100.0 {
        format!("{f:.0}")
    } else if f >= 10.0 {
        format!("{f:.1}")
    } else {
        format!("{f:.2}")
    }
}

/// Writes the CMIF figure ([`cmif_plot`]) to an SVG file (1000 x 600 pixels).
pub fn cmif_svg(
    path: impl AsRef<Path>,
    cmif: &Cmif,
    peaks: &[CmifPeak],
    title: &str,
) -> Result<(), FrfitError> {
    cmif_plot(cmif, peaks, title).write_svg(path, (1000, 600))
}

/// A grid of Bode magnitude panels, one per entry `G_ij` (row = output, column = input),
/// each with one line per dataset (e.g. `[("data", &frf), ("model", &model_response)]`).
/// The datasets should have the same dimensions; entries a dataset lacks are skipped.
pub fn magnitude_grid(title: &str, sets: &[(&str, &dyn FrfDataset)]) -> PlotGrid {
    let ny = sets.iter().map(|(_, d)| d.ny()).max().unwrap_or(0);
    let nu = sets.iter().map(|(_, d)| d.nu()).max().unwrap_or(0);
    let mut panels = Vec::with_capacity(ny * nu);
    for i in 0..ny {
        for j in 0..nu {
            let mut p = LinePlot::new(format!("G{}_{}", i + 1, j + 1));
            p.legend = i == 0 && j == 0;
            for (name, d) in sets {
                if i < d.ny() && j < d.nu() {
                    let f = d.freqs_hz();
                    let y = (0..d.n_lines()).map(|k| d.value(k, i, j).norm()).collect();
                    p.series.push(Series::line(*name, f, y));
                }
            }
            panels.push(p);
        }
    }
    PlotGrid {
        title: title.to_string(),
        rows: ny.max(1),
        cols: nu.max(1),
        panels,
        panel_size: (320, 240),
    }
}

/// One entry `(i, j)` (0-based) with the data, the model, the magnitude of the residual
/// `G - M` on lines where the two share a frequency, and the noise standard deviation
/// `sqrt(var)` when the data carry a variance: the residual is significant where it
/// stands above the noise.
pub fn entry_overlay(
    title: &str,
    data: &dyn FrfDataset,
    model: &dyn FrfDataset,
    i: usize,
    j: usize,
) -> LinePlot {
    let mut p = LinePlot::new(title);
    if i >= data.ny() || j >= data.nu() {
        return p;
    }
    let f = data.freqs_hz();
    let g: Vec<f64> = (0..data.n_lines())
        .map(|k| data.value(k, i, j).norm())
        .collect();
    p.series.push(Series::line("data", f.clone(), g));
    if i < model.ny() && j < model.nu() {
        let fm = model.freqs_hz();
        let m = (0..model.n_lines())
            .map(|k| model.value(k, i, j).norm())
            .collect();
        p.series.push(Series::dashed("model", fm.clone(), m));
        // Residual on common lines (both sorted ascending).
        let (mut a, mut b) = (0, 0);
        let (mut rf, mut rv) = (Vec::new(), Vec::new());
        while a < f.len() && b < fm.len() {
            let (x, y) = (f[a], fm[b]);
            if (x - y).abs() <= 1e-9 * x.abs().max(1.0) {
                rf.push(x);
                rv.push((data.value(a, i, j) - model.value(b, i, j)).norm());
                a += 1;
                b += 1;
            } else if x < y {
                a += 1;
            } else {
                b += 1;
            }
        }
        p.series.push(Series::line("|residual|", rf, rv));
    }
    if data.has_variance() {
        let s = (0..data.n_lines())
            .map(|k| data.variance(k, i, j).unwrap_or(f64::NAN).sqrt())
            .collect();
        p.series
            .push(Series::line("noise std", f, s).with_color((127, 127, 127)));
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_keeps_peaks_and_ends() {
        // 10 000 points on 100 "pixel columns" with one narrow peak.
        let seg: Vec<(f64, f64)> = (0..10_000)
            .map(|k| {
                let x = k as f64;
                (x, if k == 4321 { 100.0 } else { (x * 0.01).sin() })
            })
            .collect();
        let px = |p: &(f64, f64)| ((p.0 / 100.0) as i32, (-p.1 * 10.0) as i32);
        let out = decimate(seg.clone(), 400, px);
        assert!(out.len() <= 400, "{}", out.len());
        assert_eq!(out.first(), seg.first());
        assert_eq!(out.last(), seg.last());
        assert!(out.iter().any(|p| p.1 == 100.0));
        assert!(out.windows(2).all(|w| w[0].0 < w[1].0));
        // Short series are left alone.
        assert_eq!(decimate(seg[..300].to_vec(), 400, px).len(), 300);
    }

    #[test]
    fn log_ticks_adapt_to_the_room() {
        // 4 decades on 900 pixels: 1, 2, 5 per decade.
        let (bold, light) = log_key_points(0.25, 2000.0, 900.0, 48.0);
        for v in [0.5, 1.0, 2.0, 5.0, 10.0, 1000.0, 2000.0] {
            assert!(
                bold.iter().any(|b| (b / v - 1.0).abs() < 1e-9),
                "{v}: {bold:?}"
            );
        }
        assert!(light.len() > bold.len());
        // 16 decades on 120 pixels: labels at least 26 pixels apart.
        let (bold, _) = log_key_points(1e-14, 1e2, 120.0, 26.0);
        assert!(bold.len() >= 3 && bold.len() <= 5, "{bold:?}");
        // Inside one decade: more than one label.
        let (bold, _) = log_key_points(0.55, 1.9, 300.0, 26.0);
        assert!(bold.len() >= 3, "{bold:?}");
        assert!(bold.iter().all(|v| (0.55..=1.9).contains(v)));
        // Degenerate ranges give nothing rather than failing.
        assert!(log_key_points(0.0, 1.0, 100.0, 20.0).0.is_empty());
        assert!(log_key_points(f64::NAN, 1.0, 100.0, 20.0).0.is_empty());
    }
}
