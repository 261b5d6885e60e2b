//! Figures as data: what a study or a report wants drawn (series, annotations, axes), not how.
//!
//! A study or a report returns [`Figure`] values; [`crate::ToSvg`] renders them to SVG (`cargo
//! xtask reproduce` beside a study's report, `kalibra eval` beside a log's). Keeping the figure
//! as data lets tests check what a figure shows (the series and their points) without parsing
//! a drawing, and lets another front end (a notebook, a web page) draw the same figure its own
//! way.

use serde::Serialize;

/// Default figure width in pixels.
pub const DEFAULT_WIDTH: u32 = 640;
/// Default figure height in pixels.
pub const DEFAULT_HEIGHT: u32 = 400;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Style {
    /// A polyline through the points, broken at invalid points.
    #[default]
    Line,
    /// One marker per point, no line.
    Markers,
    /// A polyline and a marker at every point.
    LineMarkers,
}

impl Style {
    /// Whether a polyline is drawn.
    pub fn has_line(self) -> bool {
        matches!(self, Style::Line | Style::LineMarkers)
    }

    /// Whether a marker is drawn at every point.
    pub fn has_markers(self) -> bool {
        matches!(self, Style::Markers | Style::LineMarkers)
    }
}

/// One data series: `(x, y)` points drawn in order (they are not sorted).
///
/// Points with a non-finite coordinate, or with `y <= 0` on a log axis, are skipped and break
/// the line, so a gap in the data shows as a gap in the plot.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Series {
    /// Text shown in the legend.
    pub label: String,
    /// The data, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// Line, markers, or both.
    pub style: Style,
    /// Draw the line dashed (no effect on markers).
    pub dashed: bool,
}

impl Series {
    /// A solid line through `points`.
    pub fn line(label: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self::styled(label, points, Style::Line)
    }

    /// A marker at each of `points`, no line.
    pub fn markers(label: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self::styled(label, points, Style::Markers)
    }

    /// A solid line through `points` with a marker at each.
    pub fn line_markers(label: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self::styled(label, points, Style::LineMarkers)
    }

    /// The same series with a dashed line.
    pub fn dashed(mut self) -> Self {
        self.dashed = true;
        self
    }

    fn styled(label: impl Into<String>, points: Vec<(f64, f64)>, style: Style) -> Self {
        Self {
            label: label.into(),
            points,
            style,
            dashed: false,
        }
    }
}

/// A reference mark drawn over the data. Its coordinates are included in the axis ranges so
/// it is always visible; annotations with invalid coordinates are not drawn.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Annotation {
    /// A dashed vertical line at `x` across the plot area, labelled near the top.
    VLine {
        /// Position on the x axis.
        x: f64,
        /// Text next to the line (may be empty).
        label: String,
    },
    /// A dashed horizontal line at `y` across the plot area, labelled at the left.
    HLine {
        /// Position on the y axis.
        y: f64,
        /// Text next to the line (may be empty).
        label: String,
    },
    /// A circled point with a label beside it.
    Point {
        /// Position on the x axis.
        x: f64,
        /// Position on the y axis.
        y: f64,
        /// Text next to the circle (may be empty).
        label: String,
    },
}

/// A line plot: axes with ticks, title, axis labels, legend, series and annotations.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figure {
    /// Title above the plot area (omitted when empty).
    pub title: String,
    /// Label under the x axis (omitted when empty).
    pub x_label: String,
    /// Label left of the y axis, rotated (omitted when empty).
    pub y_label: String,
    /// Logarithmic y axis: data mapped by `log10`, ticks at powers of ten.
    pub log_y: bool,
    /// The data, drawn in order; colours follow the palette by index.
    pub series: Vec<Series>,
    /// Reference marks drawn over the data.
    pub annotations: Vec<Annotation>,
    /// Width in pixels (drawn at least 160).
    pub width: u32,
    /// Height in pixels (drawn at least 120).
    pub height: u32,
}

impl Figure {
    /// An empty 640x400 figure with a linear y axis.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            log_y: false,
            series: Vec::new(),
            annotations: Vec::new(),
            width: DEFAULT_WIDTH,
            height: DEFAULT_HEIGHT,
        }
    }

    /// The same figure with a logarithmic y axis.
    pub fn log_y(mut self) -> Self {
        self.log_y = true;
        self
    }

    /// The same figure with another size in pixels.
    pub fn size(mut self, width: u32, height: u32) -> Self {
        self.width = width;
        self.height = height;
        self
    }

    /// The same figure with `s` added after the existing series.
    pub fn series(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }

    /// The same figure with `a` added after the existing annotations.
    pub fn annotate(mut self, a: Annotation) -> Self {
        self.annotations.push(a);
        self
    }
}
