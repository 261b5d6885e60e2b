//! The SVG renderer of [`Figure`] data: axes with "nice" ticks (linear or log10), title and
//! axis labels, series as lines and/or markers (gaps where a point cannot be drawn), a legend
//! placed where it covers the least data, and reference lines and points with labels that avoid
//! each other.
//!
//! It is our own, about 900 lines of rendering and 400 of tests, rather than a plotting crate
//! (the reasons are in `docs/ARCHITECTURE.md`, Decisions). Two properties matter more than
//! looks, because the reports are compared across runs: the same figure gives byte-identical
//! output (coordinates rounded to two decimals, no hash-ordered state, no timestamps, text set
//! by the viewer rather than measured from system fonts; only a platform `log10` differing in
//! the last bit could move a log-axis coordinate by 0.01), and no input data can make it panic
//! or write an invalid document.

use std::fmt::Write as _;

use crate::figure::{Annotation, Figure, Series};

/// Smallest width actually drawn; below it the margins would leave no plot area.
const MIN_WIDTH: u32 = 160;
/// Smallest height actually drawn, for the same reason.
const MIN_HEIGHT: u32 = 120;

/// Series colours (Tableau 10 without its grey, which the annotations use, and its olive,
/// which is hard to tell from green on projectors). Cycled when there are more series.
const PALETTE: [&str; 8] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

/// Colour of annotation lines and labels: neutral so it never reads as another series.
const ANNOTATION_COLOUR: &str = "#666666";

/// Values on a linear axis are clamped to this magnitude so that the span, the margins and
/// the tick arithmetic stay finite even for data near `f64::MAX` (such values are drawn at the
/// limit, which no real figure reaches).
const LINEAR_LIMIT: f64 = 1e300;

/// Pixel coordinates are clamped to this magnitude before printing; they can only get there
/// through pathological ranges, and a huge number is still better than an invalid document.
const PIXEL_LIMIT: f64 = 1e6;

/// Identifier of the clip path for the plot area (data never spills over the axes).
const CLIP_ID: &str = "kalibra-plot-area";

/// Average glyph advance of the 11 px sans-serif text, for sizing boxes around labels.
const TEXT_ADVANCE: f64 = 6.2;

/// Renders a [`Figure`] as SVG.
pub trait ToSvg {
    /// The figure as a complete standalone SVG document.
    ///
    /// Deterministic: the same figure always gives the same bytes. A figure without any
    /// drawable point still gives a valid document, with a "no data" note in the plot area.
    fn to_svg(&self) -> String;
}

impl ToSvg for Figure {
    fn to_svg(&self) -> String {
        Plot(self).render()
    }
}

/// The renderer's view of a figure (the figure itself is plain data, [`crate::figure`]).
struct Plot<'a>(&'a Figure);

impl std::ops::Deref for Plot<'_> {
    type Target = Figure;
    fn deref(&self) -> &Figure {
        self.0
    }
}

impl Plot<'_> {
    fn render(&self) -> String {
        let width = self.width.max(MIN_WIDTH);
        let height = self.height.max(MIN_HEIGHT);
        let (w, h) = (f64::from(width), f64::from(height));

        // Every point in axis space (log10 for a log y axis); `None` marks a gap.
        let mapped: Vec<Vec<Option<(f64, f64)>>> = self
            .series
            .iter()
            .map(|s| s.points.iter().map(|&(x, y)| self.to_axes(x, y)).collect())
            .collect();
        let has_data = mapped.iter().flatten().any(Option::is_some);

        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for &(x, y) in mapped.iter().flatten().flatten() {
            xs.push(x);
            ys.push(y);
        }
        for a in &self.annotations {
            match *a {
                Annotation::VLine { x, .. } => xs.extend(to_axis(x, false)),
                Annotation::HLine { y, .. } => ys.extend(to_axis(y, self.log_y)),
                Annotation::Point { x, y, .. } => {
                    if let Some((x, y)) = self.to_axes(x, y) {
                        xs.push(x);
                        ys.push(y);
                    }
                }
            }
        }
        let (x_lo, x_hi) = padded_range(&xs, false);
        let (y_lo, y_hi) = padded_range(&ys, self.log_y);

        // Layout. The y ticks come first because their label width sets the left margin,
        // which sets the plot width, which sets how many x ticks fit.
        let top = if self.title.is_empty() { 16.0 } else { 36.0 };
        let bottom = h - if self.x_label.is_empty() { 28.0 } else { 44.0 };
        // At least 35 px between y ticks and 80 px between x ticks, so labels never overlap.
        let y_target = ((bottom - top) / 35.0) as usize;
        let y_ticks = if self.log_y {
            log_ticks(y_lo, y_hi, y_target.max(2))
        } else {
            linear_ticks(y_lo, y_hi, y_target.max(2))
        };
        let widest = y_ticks
            .iter()
            .map(|(_, l)| l.chars().count())
            .max()
            .unwrap_or(1);
        let y_label_room = if self.y_label.is_empty() { 0.0 } else { 20.0 };
        let left = (14.0 + y_label_room + 6.5 * widest as f64).min(w * 0.35);
        let right = w - 20.0;
        let x_ticks = linear_ticks(x_lo, x_hi, (((right - left) / 80.0) as usize).max(2));
        let frame = Frame {
            left,
            right,
            top,
            bottom,
            x_lo,
            x_hi,
            y_lo,
            y_hi,
        };

        let mut out = String::new();
        // Writing to a String cannot fail, so the `fmt::Result`s below are ignored.
        let _ = writeln!(
            out,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="11">"#
        );
        let _ = writeln!(
            out,
            r#"<rect width="{width}" height="{height}" fill="white"/>"#
        );
        let _ = writeln!(
            out,
            r#"<defs><clipPath id="{CLIP_ID}"><rect x="{}" y="{}" width="{}" height="{}"/></clipPath></defs>"#,
            num(left),
            num(top),
            num(right - left),
            num(bottom - top)
        );
        write_grid(&mut out, &frame, &x_ticks, &y_ticks);
        self.write_annotation_lines(&mut out, &frame);
        let _ = writeln!(out, r#"<g clip-path="url(#{CLIP_ID})">"#);
        for (i, points) in mapped.iter().enumerate() {
            if let Some(s) = self.series.get(i) {
                write_series(&mut out, &frame, s, i, points);
            }
        }
        let _ = writeln!(out, "</g>");
        self.write_annotation_marks(&mut out, &frame);
        write_axes(&mut out, &frame, &x_ticks, &y_ticks);
        if !has_data {
            let _ = writeln!(
                out,
                r##"<text x="{}" y="{}" text-anchor="middle" font-size="14" fill="#888888">no data</text>"##,
                num((left + right) / 2.0),
                num((top + bottom) / 2.0)
            );
        }
        self.write_legend(&mut out, &frame, &mapped);
        self.write_labels(&mut out, &frame, w, h);
        out.push_str("</svg>\n");
        out
    }

    /// `(x, y)` in axis space, or `None` when the point cannot be drawn.
    fn to_axes(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        Some((to_axis(x, false)?, to_axis(y, self.log_y)?))
    }

    /// Reference lines go under the data so they never hide it.
    fn write_annotation_lines(&self, out: &mut String, f: &Frame) {
        for a in &self.annotations {
            let (x1, y1, x2, y2) = match *a {
                Annotation::VLine { x, .. } => match to_axis(x, false) {
                    Some(x) => (f.px(x), f.top, f.px(x), f.bottom),
                    None => continue,
                },
                Annotation::HLine { y, .. } => match to_axis(y, self.log_y) {
                    Some(y) => (f.left, f.py(y), f.right, f.py(y)),
                    None => continue,
                },
                Annotation::Point { .. } => continue,
            };
            let _ = writeln!(
                out,
                r#"<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="{ANNOTATION_COLOUR}" stroke-dasharray="5 4"/>"#,
                num(x1),
                num(y1),
                num(x2),
                num(y2)
            );
        }
    }

    /// Annotation labels and circled points go over the data so they stay readable.
    fn write_annotation_marks(&self, out: &mut String, f: &Frame) {
        let circled = self.annotations.iter().filter_map(|a| match *a {
            Annotation::Point { x, y, .. } => self.to_axes(x, y),
            _ => None,
        });
        for (x, y) in circled {
            let _ = writeln!(
                out,
                r##"<circle cx="{}" cy="{}" r="4.5" fill="none" stroke="#333333" stroke-width="1.5"/>"##,
                num(f.px(x)),
                num(f.py(y))
            );
        }
        for l in self.annotation_labels(f) {
            write_text(out, l.x, l.y, l.anchor, l.fill, l.text);
        }
    }

    /// Where the annotation labels go; shared by the drawing and the legend placement, which
    /// must know where the labels are to avoid covering them.
    fn annotation_labels(&self, f: &Frame) -> Vec<Label<'_>> {
        // Labels right of three quarters of the width are right-aligned so they stay inside.
        let beside = |px: f64, gap: f64| {
            if px > f.left + 0.75 * (f.right - f.left) {
                (px - gap, "end")
            } else {
                (px + gap, "start")
            }
        };
        let mut labels = Vec::new();
        for a in &self.annotations {
            match a {
                Annotation::VLine { x, label } => {
                    if let Some(x) = to_axis(*x, false) {
                        let (x, anchor) = beside(f.px(x), 4.0);
                        let y = f.top + 12.0;
                        labels.push(Label {
                            x,
                            y,
                            anchor,
                            fill: ANNOTATION_COLOUR,
                            text: label,
                        });
                    }
                }
                Annotation::HLine { y, label } => {
                    if let Some(y) = to_axis(*y, self.log_y) {
                        let py = f.py(y);
                        // Below the line when it runs along the top edge, above it otherwise.
                        let y = if py < f.top + 14.0 {
                            py + 13.0
                        } else {
                            py - 4.0
                        };
                        let (x, anchor) = (f.left + 4.0, "start");
                        labels.push(Label {
                            x,
                            y,
                            anchor,
                            fill: ANNOTATION_COLOUR,
                            text: label,
                        });
                    }
                }
                Annotation::Point { x, y, label } => {
                    if let Some((x, y)) = self.to_axes(*x, *y) {
                        let (x, anchor) = beside(f.px(x), 7.0);
                        let y = f.py(y) - 7.0;
                        labels.push(Label {
                            x,
                            y,
                            anchor,
                            fill: "#333333",
                            text: label,
                        });
                    }
                }
            }
        }
        labels.retain(|l| !l.text.is_empty());
        labels
    }

    /// Legend box in the corner of the plot area that covers the least, one row per series.
    fn write_legend(&self, out: &mut String, f: &Frame, mapped: &[Vec<Option<(f64, f64)>>]) {
        if self.series.is_empty() {
            return;
        }
        const ROW: f64 = 16.0;
        const SAMPLE: f64 = 22.0;
        let widest = self
            .series
            .iter()
            .map(|s| s.label.chars().count())
            .max()
            .unwrap_or(0);
        let box_w = 10.0 + SAMPLE + 6.0 + TEXT_ADVANCE * widest as f64 + 8.0;
        let box_h = ROW * self.series.len() as f64 + 8.0;
        let (x0, y0) = self.legend_origin(f, mapped, box_w, box_h);
        let _ = writeln!(
            out,
            r##"<rect x="{}" y="{}" width="{}" height="{}" fill="white" fill-opacity="0.85" stroke="#999999"/>"##,
            num(x0),
            num(y0),
            num(box_w),
            num(box_h)
        );
        for (i, s) in self.series.iter().enumerate() {
            let colour = colour(i);
            let cy = y0 + 4.0 + ROW * (i as f64 + 0.5);
            let (sx1, sx2) = (x0 + 10.0, x0 + 10.0 + SAMPLE);
            if s.style.has_line() {
                let _ = writeln!(
                    out,
                    r#"<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="{colour}" stroke-width="1.5"{}/>"#,
                    num(sx1),
                    num(cy),
                    num(sx2),
                    num(cy),
                    dash_attr(s.dashed)
                );
            }
            if s.style.has_markers() {
                let mut d = String::new();
                marker_path(&mut d, i, (sx1 + sx2) / 2.0, cy);
                let _ = writeln!(out, r#"<path d="{d}" fill="{colour}"/>"#);
            }
            write_text(out, sx2 + 6.0, cy + 4.0, "start", "#222222", &s.label);
        }
    }

    /// Top-left corner of the legend box: the first of top-right, top-left, bottom-right and
    /// bottom-left that hides the fewest data points, line pieces and annotation labels (a
    /// label counts as much as many points, since a hidden label loses its whole message).
    fn legend_origin(
        &self,
        f: &Frame,
        mapped: &[Vec<Option<(f64, f64)>>],
        box_w: f64,
        box_h: f64,
    ) -> (f64, f64) {
        const LABEL_WEIGHT: usize = 50;
        let (x_right, x_left) = ((f.right - 8.0 - box_w).max(f.left + 4.0), f.left + 8.0);
        let (y_top, y_bottom) = (f.top + 8.0, (f.bottom - 8.0 - box_h).max(f.top + 8.0));
        let corners = [
            (x_right, y_top),
            (x_left, y_top),
            (x_right, y_bottom),
            (x_left, y_bottom),
        ];
        let labels: Vec<Rect> = self
            .annotation_labels(f)
            .iter()
            .map(Label::bounds)
            .collect();
        let mut best = (usize::MAX, corners[0]);
        for (x0, y0) in corners {
            let area = Rect {
                x0,
                y0,
                x1: x0 + box_w,
                y1: y0 + box_h,
            };
            let mut hidden = LABEL_WEIGHT * labels.iter().filter(|l| l.overlaps(&area)).count();
            for (i, points) in mapped.iter().enumerate() {
                let line = self.series.get(i).is_some_and(|s| s.style.has_line());
                let mut previous: Option<(f64, f64)> = None;
                for p in points {
                    let p = p.map(|(x, y)| (f.px(x), f.py(y)));
                    if let Some(p) = p {
                        hidden += usize::from(area.contains(p));
                        if let (true, Some(q)) = (line, previous) {
                            hidden += usize::from(area.crossed_by(q, p));
                        }
                    }
                    previous = p;
                }
            }
            if hidden < best.0 {
                best = (hidden, (x0, y0));
            }
        }
        best.1
    }

    fn write_labels(&self, out: &mut String, f: &Frame, w: f64, h: f64) {
        if !self.title.is_empty() {
            let _ = writeln!(
                out,
                r#"<text x="{}" y="22" text-anchor="middle" font-size="14">{}</text>"#,
                num(w / 2.0),
                escape(&self.title)
            );
        }
        if !self.x_label.is_empty() {
            let _ = writeln!(
                out,
                r#"<text x="{}" y="{}" text-anchor="middle" font-size="12">{}</text>"#,
                num((f.left + f.right) / 2.0),
                num(h - 10.0),
                escape(&self.x_label)
            );
        }
        if !self.y_label.is_empty() {
            let _ = writeln!(
                out,
                r#"<text transform="translate(16,{}) rotate(-90)" text-anchor="middle" font-size="12">{}</text>"#,
                num((f.top + f.bottom) / 2.0),
                escape(&self.y_label)
            );
        }
    }
}

/// Ticks at "nice" values covering `[lo, hi]` together with their step, which the label
/// formatting needs (see the tests' `nice_ticks` for the contract).
fn nice_step_ticks(lo: f64, hi: f64, target: usize) -> Option<(f64, Vec<f64>)> {
    if !lo.is_finite() || !hi.is_finite() {
        return None;
    }
    let (lo, hi) = if lo <= hi { (lo, hi) } else { (hi, lo) };
    if lo == hi {
        return Some((0.0, vec![lo]));
    }
    let target = target.clamp(1, 1000);
    let raw = (hi - lo) / target as f64;
    if !raw.is_finite() || raw <= 0.0 {
        return None;
    }
    // The step is 1, 2, 5 or 10 times 10^exp, the smallest of them not below `raw`.
    let mut exp = raw.log10().floor() as i32;
    // `log10` may be off by one ulp at exact powers of ten; nudge `exp` so 10^exp <= raw.
    if pow10(exp) > raw {
        exp -= 1;
    }
    let mag = pow10(exp);
    if !(mag > 0.0 && mag.is_finite()) {
        return None;
    }
    let mult = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .find(|m| m * mag >= raw)
        .unwrap_or(10.0);
    let step = mult * mag;
    // A tick is k * step; for negative exponents it is computed as (k * mult) / 10^-exp, so
    // 3 * 0.1 comes out as the double nearest 0.3 rather than 0.30000000000000004.
    let value = |k: f64| {
        if (-300..0).contains(&exp) {
            k * mult / pow10(-exp)
        } else {
            k * mult * mag
        }
    };
    let mut k0 = (lo / step).floor();
    let mut k1 = (hi / step).ceil();
    if value(k0) > lo {
        k0 -= 1.0;
    }
    if value(k1) < hi {
        k1 += 1.0;
    }
    // With exact arithmetic k1 - k0 <= target + 2; more means the values lost their precision
    // (a tiny span far from zero), and the loop must not run away.
    let intervals = k1 - k0;
    if intervals.is_nan() || intervals > target as f64 + 3.0 {
        return None;
    }
    let mut ticks = Vec::new();
    let mut k = k0;
    while k <= k1 {
        let v = value(k);
        // Distinct k may give the same double far from zero; keep one of each.
        if v.is_finite() && ticks.last() != Some(&v) {
            ticks.push(v);
        }
        k += 1.0;
    }
    Some((step, ticks))
}

/// The data extent of an axis with a small margin; a degenerate extent (one value, or values
/// equal to within rounding) is widened so that the mapping never divides by zero.
fn padded_range(values: &[f64], log: bool) -> (f64, f64) {
    let mut it = values.iter().copied();
    let (lo, hi) = match it.next() {
        Some(first) => it.fold((first, first), |(lo, hi), v| (lo.min(v), hi.max(v))),
        // No data: an arbitrary unit range (1 to 10 on a log axis) so the frame still draws.
        None => (0.0, 1.0),
    };
    let span = hi - lo;
    let scale = lo.abs().max(hi.abs());
    let (lo, hi) = if span > scale * 1e-12 && span > 1e-290 {
        (lo, hi)
    } else {
        let centre = lo * 0.5 + hi * 0.5;
        // One decade either side on a log axis; 10% of the value (or 1 around zero) on a
        // linear one, which keeps tick labels meaningful for large and tiny constants alike.
        let half = if log {
            1.0
        } else if centre.abs() > 1e-280 {
            centre.abs() * 0.1
        } else {
            1.0
        };
        (centre - half, centre + half)
    };
    let margin = (hi - lo) * 0.04;
    (lo - margin, hi + margin)
}

/// Linear-axis ticks inside `[lo, hi]` with their labels.
fn linear_ticks(lo: f64, hi: f64, target: usize) -> Vec<(f64, String)> {
    let Some((step, ticks)) = nice_step_ticks(lo, hi, target) else {
        return Vec::new();
    };
    let eps = (hi - lo) * 1e-9;
    ticks
        .into_iter()
        .filter(|t| *t >= lo - eps && *t <= hi + eps)
        .map(|t| (t, format_tick(t, step)))
        .collect()
}

/// Log-axis ticks inside `[lo, hi]` (bounds in decades) as `(log10 value, label)`.
///
/// Powers of ten when at least two fit (every 2nd, 5th, 10th... when too many do); otherwise
/// 1, 2 and 5 times powers of ten; for a range narrower than that, linear nice ticks.
fn log_ticks(lo: f64, hi: f64, target: usize) -> Vec<(f64, String)> {
    if !lo.is_finite() || !hi.is_finite() || lo >= hi {
        return Vec::new();
    }
    // Axis-space bounds come from log10 of finite doubles plus margins: within about ±400.
    let (e_lo, e_hi) = (lo.ceil().max(-400.0) as i32, hi.floor().min(400.0) as i32);
    let count = e_hi - e_lo + 1;
    if count >= 2 {
        let target = target.max(2) as i32;
        let stride = [1, 2, 5, 10, 20, 50, 100, 200, 500]
            .into_iter()
            .find(|s| (count + s - 1) / s <= target)
            .unwrap_or(1000);
        let ticks: Vec<(f64, String)> = (e_lo..=e_hi)
            .filter(|e| e.rem_euclid(stride) == 0)
            .map(|e| (f64::from(e), format_tick(pow10(e), pow10(e))))
            .collect();
        if ticks.len() >= 2 {
            return ticks;
        }
    }
    let eps = (hi - lo) * 1e-9;
    let mut ticks = Vec::new();
    for e in (lo.floor().max(-400.0) as i32)..=(hi.ceil().min(400.0) as i32) {
        for m in [1.0, 2.0, 5.0] {
            let v = m * pow10(e);
            let l = v.log10();
            if v > 0.0 && l >= lo - eps && l <= hi + eps {
                ticks.push((l, format_tick(v, pow10(e))));
            }
        }
    }
    if ticks.len() >= 2 {
        return ticks;
    }
    let (vlo, vhi) = (10f64.powf(lo), 10f64.powf(hi));
    linear_ticks(vlo, vhi, 4)
        .into_iter()
        .filter(|(v, _)| *v > 0.0)
        .map(|(v, label)| (v.log10(), label))
        .collect()
}

/// Compact tick label: plain decimals for magnitudes in `[0.01, 1e4)` (`0.5`, `10`, `2500`),
/// scientific otherwise (`1e-3`, `2.5e4`), with as many digits as the tick `step` needs to
/// tell neighbouring ticks apart and no trailing zeros.
fn format_tick(v: f64, step: f64) -> String {
    if !v.is_finite() {
        return String::new();
    }
    // Rounding residue next to a zero tick (e.g. 3 * 0.1 - 0.3) is zero.
    if v == 0.0 || (step > 0.0 && v.abs() < step * 1e-9) {
        return "0".to_string();
    }
    let a = v.abs();
    let v_exp = a.log10().floor() as i32;
    let step_exp = if step > 0.0 && step.is_finite() {
        step.log10().floor() as i32
    } else {
        v_exp
    };
    if (0.01..1e4).contains(&a) {
        // At least one significant digit of the value itself, whatever the step.
        let decimals = (-step_exp).max(-v_exp).clamp(0, 15) as usize;
        let s = trim_zeros(format!("{v:.decimals$}"));
        if s == "-0" { "0".to_string() } else { s }
    } else {
        // Rust's `{:e}` renormalises the mantissa itself when rounding carries (9.99 -> 1.0e1).
        let digits = (v_exp - step_exp).clamp(0, 6) as usize;
        let s = format!("{v:.digits$e}");
        match s.split_once('e') {
            Some((mantissa, exp)) => format!("{}e{exp}", trim_zeros(mantissa.to_string())),
            None => s,
        }
    }
}

/// 10^e as the correctly rounded double (`powi` is not, and its error shows in labels).
fn pow10(e: i32) -> f64 {
    format!("1e{e}").parse().unwrap_or(0.0)
}

/// The position of `v` on an axis (log10 on a log axis), or `None` when it cannot be drawn.
fn to_axis(v: f64, log: bool) -> Option<f64> {
    if !v.is_finite() {
        None
    } else if log {
        (v > 0.0).then(|| v.log10())
    } else {
        Some(v.clamp(-LINEAR_LIMIT, LINEAR_LIMIT))
    }
}

/// The plot area and the axis ranges (in axis space) that map onto it.
struct Frame {
    left: f64,
    right: f64,
    top: f64,
    bottom: f64,
    x_lo: f64,
    x_hi: f64,
    y_lo: f64,
    y_hi: f64,
}

impl Frame {
    fn px(&self, x: f64) -> f64 {
        self.left + (x - self.x_lo) / (self.x_hi - self.x_lo) * (self.right - self.left)
    }

    fn py(&self, y: f64) -> f64 {
        self.bottom - (y - self.y_lo) / (self.y_hi - self.y_lo) * (self.bottom - self.top)
    }
}

/// A text label at `(x, y)` (baseline) with an SVG `text-anchor`.
struct Label<'a> {
    x: f64,
    y: f64,
    anchor: &'static str,
    fill: &'static str,
    text: &'a str,
}

impl Label<'_> {
    /// Approximate extent of the rendered text, from the average glyph advance.
    fn bounds(&self) -> Rect {
        let w = TEXT_ADVANCE * self.text.chars().count() as f64;
        let x0 = match self.anchor {
            "end" => self.x - w,
            "middle" => self.x - w / 2.0,
            _ => self.x,
        };
        Rect {
            x0,
            y0: self.y - 10.0,
            x1: x0 + w,
            y1: self.y + 2.0,
        }
    }
}

/// An axis-aligned pixel rectangle with `x0 <= x1` and `y0 <= y1`.
struct Rect {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Rect {
    fn contains(&self, (x, y): (f64, f64)) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }

    fn overlaps(&self, other: &Rect) -> bool {
        self.x0 <= other.x1 && other.x0 <= self.x1 && self.y0 <= other.y1 && other.y0 <= self.y1
    }

    /// Whether the segment from `a` to `b` passes through the rectangle (Liang-Barsky
    /// clipping: shrink the parameter interval [0, 1] against each edge).
    fn crossed_by(&self, a: (f64, f64), b: (f64, f64)) -> bool {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
        let edges = [
            (-dx, a.0 - self.x0),
            (dx, self.x1 - a.0),
            (-dy, a.1 - self.y0),
            (dy, self.y1 - a.1),
        ];
        for (p, q) in edges {
            if p == 0.0 {
                // Parallel to this edge: inside its half-plane or never.
                if q < 0.0 {
                    return false;
                }
            } else if p < 0.0 {
                t0 = t0.max(q / p);
            } else {
                t1 = t1.min(q / p);
            }
        }
        t0 <= t1
    }
}

/// Light grid lines at the ticks, under everything else.
fn write_grid(out: &mut String, f: &Frame, x_ticks: &[(f64, String)], y_ticks: &[(f64, String)]) {
    let mut d = String::new();
    for (x, _) in x_ticks {
        let _ = write!(d, "M{},{}V{}", num(f.px(*x)), num(f.top), num(f.bottom));
    }
    for (y, _) in y_ticks {
        let _ = write!(d, "M{},{}H{}", num(f.left), num(f.py(*y)), num(f.right));
    }
    if !d.is_empty() {
        let _ = writeln!(out, r##"<path d="{d}" stroke="#e5e5e5" fill="none"/>"##);
    }
}

/// Frame, tick marks and tick labels.
fn write_axes(out: &mut String, f: &Frame, x_ticks: &[(f64, String)], y_ticks: &[(f64, String)]) {
    let _ = writeln!(
        out,
        r#"<rect x="{}" y="{}" width="{}" height="{}" fill="none" stroke="black"/>"#,
        num(f.left),
        num(f.top),
        num(f.right - f.left),
        num(f.bottom - f.top)
    );
    let mut d = String::new();
    for (x, _) in x_ticks {
        let _ = write!(d, "M{},{}v5", num(f.px(*x)), num(f.bottom));
    }
    for (y, _) in y_ticks {
        let _ = write!(d, "M{},{}h-5", num(f.left), num(f.py(*y)));
    }
    if !d.is_empty() {
        let _ = writeln!(out, r#"<path d="{d}" stroke="black" fill="none"/>"#);
    }
    for (x, label) in x_ticks {
        write_text(out, f.px(*x), f.bottom + 17.0, "middle", "#222222", label);
    }
    for (y, label) in y_ticks {
        write_text(out, f.left - 8.0, f.py(*y) + 4.0, "end", "#222222", label);
    }
}

/// One series: polylines for the runs of drawable points, then its markers.
fn write_series(
    out: &mut String,
    f: &Frame,
    s: &Series,
    index: usize,
    points: &[Option<(f64, f64)>],
) {
    let colour = colour(index);
    if s.style.has_line() {
        for run in points.split(Option::is_none) {
            // Consecutive points on the same printed pixel add bytes but nothing visible.
            let mut coords: Vec<(String, String)> = Vec::new();
            for &(x, y) in run.iter().flatten() {
                let c = (num(f.px(x)), num(f.py(y)));
                if coords.last() != Some(&c) {
                    coords.push(c);
                }
            }
            match coords.as_slice() {
                [] => {}
                // A run of one point would be an invisible polyline; show it as a dot.
                [(x, y)] => {
                    let _ = writeln!(
                        out,
                        r#"<circle cx="{x}" cy="{y}" r="1.5" fill="{colour}"/>"#
                    );
                }
                _ => {
                    let list: Vec<String> =
                        coords.iter().map(|(x, y)| format!("{x},{y}")).collect();
                    let _ = writeln!(
                        out,
                        r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="1.5" stroke-linejoin="round"{}/>"#,
                        list.join(" "),
                        dash_attr(s.dashed)
                    );
                }
            }
        }
    }
    if s.style.has_markers() {
        // All markers of a series in one path: far smaller than one element per point.
        let mut d = String::new();
        for &(x, y) in points.iter().flatten() {
            marker_path(&mut d, index, f.px(x), f.py(y));
        }
        if !d.is_empty() {
            let _ = writeln!(out, r#"<path d="{d}" fill="{colour}"/>"#);
        }
    }
}

/// Appends a marker centred on `(x, y)`. The shape cycles with the series index (circle,
/// square, triangle, diamond) so that markers stay distinguishable in grey-scale print.
fn marker_path(d: &mut String, index: usize, x: f64, y: f64) {
    const R: f64 = 3.0;
    let _ = match index % 4 {
        0 => write!(d, "M{},{}a3,3 0 1 0 6,0a3,3 0 1 0 -6,0", num(x - R), num(y)),
        1 => write!(d, "M{},{}h6v6h-6z", num(x - R), num(y - R)),
        2 => write!(d, "M{},{}l3.5,6h-7z", num(x), num(y - 3.5)),
        _ => write!(
            d,
            "M{},{}l3.5,3.5l-3.5,3.5l-3.5,-3.5z",
            num(x),
            num(y - 3.5)
        ),
    };
}

fn write_text(out: &mut String, x: f64, y: f64, anchor: &str, fill: &str, text: &str) {
    if text.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        r#"<text x="{}" y="{}" text-anchor="{anchor}" fill="{fill}">{}</text>"#,
        num(x),
        num(y),
        escape(text)
    );
}

fn colour(index: usize) -> &'static str {
    PALETTE[index % PALETTE.len()]
}

fn dash_attr(dashed: bool) -> &'static str {
    if dashed {
        r#" stroke-dasharray="6 4""#
    } else {
        ""
    }
}

/// A coordinate with at most two decimals and no trailing zeros: small files, stable diffs.
fn num(v: f64) -> String {
    let v = if v.is_finite() {
        v.clamp(-PIXEL_LIMIT, PIXEL_LIMIT)
    } else {
        0.0
    };
    let s = trim_zeros(format!("{v:.2}"));
    if s == "-0" { "0".to_string() } else { s }
}

fn trim_zeros(s: String) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Text safe for both element content and double-quoted attributes. Control characters are
/// dropped because XML 1.0 does not allow them, and a report label must not void the file.
fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\t' | '\n' | '\r' => out.push(' '),
            c if c.is_control() || c == '\u{FFFE}' || c == '\u{FFFF}' => {}
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ticks at "nice" values (1, 2 or 5 times a power of ten apart) covering `[lo, hi]`: the
    /// first tick is at or below `lo`, the last at or above `hi`, and there are about `target`
    /// intervals (never more than `target + 3` ticks).
    ///
    /// The bounds may come in either order. Returns `[lo]` when they are equal, and an empty
    /// vector when either is not finite or their difference overflows. `target` is clamped to
    /// `1..=1000` so a careless caller cannot ask for millions of ticks.
    fn nice_ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
        nice_step_ticks(lo, hi, target)
            .map(|(_, ticks)| ticks)
            .unwrap_or_default()
    }

    /// Checks that every element is closed in order (a tiny XML well-formedness check that
    /// works because all text and attribute values are escaped).
    fn assert_well_formed(svg: &str) {
        let mut stack: Vec<String> = Vec::new();
        let mut rest = svg;
        while let Some(start) = rest.find('<') {
            let after = &rest[start + 1..];
            let end = after.find('>').expect("unterminated tag");
            let tag = &after[..end];
            let name = |t: &str| t.split_whitespace().next().unwrap_or("").to_string();
            if let Some(closing) = tag.strip_prefix('/') {
                assert_eq!(stack.pop(), Some(name(closing)), "mismatched </{closing}>");
            } else if !tag.ends_with('/') {
                stack.push(name(tag));
            }
            rest = &after[end + 1..];
        }
        assert!(stack.is_empty(), "unclosed elements {stack:?}");
        assert!(!rest.contains('>'), "stray '>' after the last tag");
    }

    fn assert_valid(svg: &str) {
        assert!(
            svg.starts_with(r#"<svg xmlns="http://www.w3.org/2000/svg" "#),
            "{svg}"
        );
        assert!(svg.contains("viewBox="));
        assert!(!svg.contains("NaN"), "{svg}");
        assert!(!svg.contains("inf"), "{svg}");
        for tag in ["svg", "text", "g", "defs", "clipPath"] {
            assert_eq!(
                svg.matches(&format!("<{tag}")).count(),
                svg.matches(&format!("</{tag}>")).count(),
                "<{tag}> unbalanced"
            );
        }
        assert_eq!(svg.matches("<svg").count(), 1);
        assert_well_formed(svg);
    }

    fn is_one_two_five(step: f64) -> bool {
        let norm = step / pow10(step.log10().floor() as i32);
        [1.0, 2.0, 5.0, 10.0]
            .iter()
            .any(|m| (norm - m).abs() < 1e-9)
    }

    #[test]
    fn nice_ticks_cover_with_one_two_five_steps() {
        let ranges = [
            (0.0, 1.0),
            (0.0, 10.0),
            (-3.7, 12.2),
            (-1e-7, -2e-8),
            (1e-9, 3e-9),
            (2.5e4, 9.1e6),
            (-1e12, 1e12),
            (0.1, 0.3),
            (-5.0, -4.99),
            (1e-300, 7e-300),
            (-3e290, 8e290),
            (12.0, 3.0),
        ];
        for (lo, hi) in ranges {
            for target in [2, 5, 10] {
                let t = nice_ticks(lo, hi, target);
                let (lo, hi) = (lo.min(hi), lo.max(hi));
                assert!(
                    t.len() >= 2 && t.len() <= target + 3,
                    "{lo} {hi} {target}: {t:?}"
                );
                assert!(t[0] <= lo && *t.last().unwrap() >= hi, "{lo} {hi}: {t:?}");
                let step = t[1] - t[0];
                assert!(
                    step > 0.0 && is_one_two_five(step),
                    "{lo} {hi}: step {step}"
                );
                for pair in t.windows(2) {
                    let d = pair[1] - pair[0];
                    assert!((d - step).abs() <= 1e-9 * step.max(pair[1].abs()), "{t:?}");
                }
            }
        }
    }

    #[test]
    fn nice_ticks_are_clean_decimals_and_handle_edge_inputs() {
        assert_eq!(nice_ticks(0.0, 1.0, 5), vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
        assert_eq!(nice_ticks(0.1, 0.3, 2), vec![0.1, 0.2, 0.3]);
        assert_eq!(nice_ticks(3.0, 3.0, 5), vec![3.0]);
        assert!(nice_ticks(f64::NAN, 1.0, 5).is_empty());
        assert!(nice_ticks(0.0, f64::INFINITY, 5).is_empty());
        assert!(nice_ticks(-f64::MAX, f64::MAX, 5).is_empty());
        assert!(nice_ticks(0.0, 1.0, 0).len() >= 2);
        assert!(nice_ticks(0.0, 1.0, usize::MAX).len() <= 1003);
    }

    #[test]
    fn tick_labels_are_compact() {
        assert_eq!(format_tick(0.5, 0.1), "0.5");
        assert_eq!(format_tick(10.0, 5.0), "10");
        assert_eq!(format_tick(1e-3, 1e-3), "1e-3");
        assert_eq!(format_tick(25000.0, 5000.0), "2.5e4");
        assert_eq!(format_tick(0.01, 0.01), "0.01");
        assert_eq!(format_tick(1e4, 1e4), "1e4");
        assert_eq!(format_tick(1000.0, 1000.0), "1000");
        assert_eq!(format_tick(-1.5, 0.5), "-1.5");
        assert_eq!(format_tick(0.30000000000000004, 0.1), "0.3");
        assert_eq!(format_tick(5.551115123125783e-17, 0.1), "0");
        assert_eq!(format_tick(-2e-8, 2e-8), "-2e-8");
        assert_eq!(format_tick(1.25e-5, 5e-7), "1.25e-5");
    }

    #[test]
    fn gap_in_a_series_breaks_the_line() {
        for gap in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let points = vec![(0.0, 0.0), (1.0, 1.0), (2.0, gap), (3.0, 3.0), (4.0, 4.0)];
            let svg = Figure::new("gap", "x", "y")
                .series(Series::line("s", points))
                .to_svg();
            assert_valid(&svg);
            assert_eq!(svg.matches("<polyline").count(), 2, "{svg}");
        }
        // A gap in x breaks the line as well; an isolated point still shows (as a dot).
        let points = vec![(0.0, 0.0), (f64::NAN, 1.0), (2.0, 2.0), (f64::NAN, 3.0)];
        let svg = Figure::new("", "", "")
            .series(Series::line("s", points))
            .to_svg();
        assert_valid(&svg);
        assert_eq!(svg.matches("<polyline").count(), 0);
        assert_eq!(svg.matches(r#"r="1.5""#).count(), 2);
    }

    #[test]
    fn log_axis_skips_non_positive_values_and_ticks_at_powers_of_ten() {
        let points = vec![
            (0.0, 1.0),
            (1.0, 10.0),
            (2.0, 0.0),
            (3.0, 100.0),
            (4.0, 1000.0),
        ];
        let svg = Figure::new("log", "x", "y")
            .log_y()
            .series(Series::line_markers("s", points))
            .annotate(Annotation::HLine {
                y: -1.0,
                label: "hidden".into(),
            })
            .to_svg();
        assert_valid(&svg);
        assert_eq!(svg.matches("<polyline").count(), 2);
        assert!(!svg.contains("hidden"));
        for label in [">1<", ">10<", ">100<", ">1000<"] {
            assert!(svg.contains(label), "{label} missing");
        }

        let points: Vec<(f64, f64)> = (-3..=4).map(|e| (f64::from(e), pow10(e))).collect();
        let svg = Figure::new("", "", "")
            .log_y()
            .series(Series::line("s", points))
            .to_svg();
        assert_valid(&svg);
        for label in [">1e-3<", ">0.01<", ">0.1<", ">1<", ">100<", ">1e4<"] {
            assert!(svg.contains(label), "{label} missing");
        }
        assert_eq!(svg.matches("<polyline").count(), 1);

        // Within one decade there are no two powers of ten: 1-2-5 ticks instead.
        let svg = Figure::new("", "", "")
            .log_y()
            .series(Series::line("s", vec![(0.0, 3.0), (1.0, 40.0)]))
            .to_svg();
        assert_valid(&svg);
        assert!(
            svg.contains(">5<") && svg.contains(">10<") && svg.contains(">20<"),
            "{svg}"
        );
    }

    #[test]
    fn text_is_escaped_everywhere() {
        let nasty = r#"a < b & "c" > d"#;
        let svg = Figure::new(nasty, nasty, nasty)
            .series(Series::line(nasty, vec![(0.0, 1.0), (1.0, 2.0)]))
            .annotate(Annotation::VLine {
                x: 0.5,
                label: nasty.into(),
            })
            .annotate(Annotation::HLine {
                y: 1.5,
                label: nasty.into(),
            })
            .annotate(Annotation::Point {
                x: 0.2,
                y: 1.2,
                label: format!("{nasty}\u{0}"),
            })
            .to_svg();
        assert_valid(&svg);
        let escaped = "a &lt; b &amp; &quot;c&quot; &gt; d";
        assert_eq!(svg.matches(escaped).count(), 7);
        assert!(!svg.contains(nasty));
        assert!(!svg.contains('\u{0}'));
        assert_eq!(escape("<&>\"x"), "&lt;&amp;&gt;&quot;x");
    }

    fn full_figure() -> Figure {
        let wave: Vec<(f64, f64)> = (0..200)
            .map(|i| (f64::from(i) * 0.05, (f64::from(i) * 0.05).sin()))
            .collect();
        let cloud: Vec<(f64, f64)> = (0..30)
            .map(|i| (f64::from(i) * 0.3, 0.5 * (f64::from(i) * 0.7).cos()))
            .collect();
        Figure::new("Figure", "time [s]", "value")
            .series(Series::line("sin", wave.clone()))
            .series(Series::markers("cos", cloud.clone()))
            .series(
                Series::line_markers(
                    "shifted",
                    cloud.iter().map(|&(x, y)| (x, y + 0.3)).collect(),
                )
                .dashed(),
            )
            .series(
                Series::line("neg", wave.iter().map(|&(x, y)| (x, -y * 1.2)).collect()).dashed(),
            )
            .annotate(Annotation::VLine {
                x: 3.0,
                label: "event".into(),
            })
            .annotate(Annotation::HLine {
                y: 0.0,
                label: "zero".into(),
            })
            .annotate(Annotation::Point {
                x: 1.57,
                y: 1.0,
                label: "peak".into(),
            })
    }

    #[test]
    fn output_is_deterministic_and_complete() {
        let a = full_figure().to_svg();
        let b = full_figure().to_svg();
        assert_eq!(a, b);
        assert_eq!(a, full_figure().to_svg());
        assert_valid(&a);
        assert!(a.contains(r#"width="640" height="400" viewBox="0 0 640 400""#));
        assert!(a.trim_end().ends_with("</svg>"));
        for label in [
            "sin", "cos", "shifted", "neg", "event", "zero", "peak", "Figure",
        ] {
            assert!(a.contains(&format!(">{label}</text>")), "{label} missing");
        }
        assert!(a.contains(r#"stroke-dasharray="6 4""#));
        assert!(!a.contains("no data"));
        // Coordinates carry at most two decimals.
        for number in a.split(|c: char| !(c.is_ascii_digit() || c == '.')) {
            if let Some((_, frac)) = number.split_once('.') {
                assert!(frac.len() <= 2, "{number}");
            }
        }
        // Palette colours cycle past eight series.
        let mut many = Figure::new("", "", "");
        for i in 0..10 {
            many = many.series(Series::line(
                format!("s{i}"),
                vec![(0.0, f64::from(i)), (1.0, 1.0)],
            ));
        }
        let svg = many.to_svg();
        assert_valid(&svg);
        assert!(svg.matches(PALETTE[0]).count() >= 4);
    }

    /// The x attribute of the legend box (the only half-transparent rectangle).
    fn legend_x(svg: &str) -> f64 {
        let line = svg
            .lines()
            .find(|l| l.contains("fill-opacity"))
            .expect("legend");
        let x = line
            .split("x=\"")
            .nth(1)
            .and_then(|r| r.split('"').next())
            .expect("x");
        x.parse().expect("number")
    }

    #[test]
    fn legend_moves_away_from_data_and_labels() {
        let rising = vec![(0.0, 0.0), (10.0, 10.0)];
        let svg = Figure::new("", "", "")
            .series(Series::line("up", rising.clone()))
            .to_svg();
        assert!(legend_x(&svg) < 200.0, "{svg}");
        let falling = vec![(0.0, 10.0), (10.0, 0.0)];
        let svg = Figure::new("", "", "")
            .series(Series::line("down", falling))
            .to_svg();
        assert!(legend_x(&svg) > 400.0, "{svg}");
        // A label in the top-left corner outweighs a line: back to the right, at the bottom.
        let svg = Figure::new("", "", "")
            .series(Series::line("up", rising))
            .annotate(Annotation::VLine {
                x: 0.5,
                label: "start of the manoeuvre".into(),
            })
            .to_svg();
        assert!(legend_x(&svg) > 400.0, "{svg}");

        let r = Rect {
            x0: 0.0,
            y0: 0.0,
            x1: 10.0,
            y1: 10.0,
        };
        assert!(r.crossed_by((-5.0, 5.0), (15.0, 5.0)));
        assert!(r.crossed_by((5.0, -5.0), (5.0, 15.0)));
        assert!(r.crossed_by((2.0, 2.0), (3.0, 3.0)));
        assert!(!r.crossed_by((-5.0, 5.0), (-1.0, 5.0)));
        assert!(!r.crossed_by((-5.0, 0.0), (0.0, -5.0)));
        assert!(!r.crossed_by((11.0, 0.0), (20.0, 9.0)));
        assert!(r.contains((10.0, 0.0)) && !r.contains((10.1, 0.0)));
    }

    #[test]
    fn degenerate_and_extreme_data_still_make_valid_svg() {
        let empty = Figure::new("empty", "x", "y").to_svg();
        assert_valid(&empty);
        assert!(empty.contains("no data"));
        assert!(Figure::new("", "", "").log_y().to_svg().contains("no data"));

        let all_invalid = Figure::new("", "", "")
            .log_y()
            .series(Series::line(
                "s",
                vec![(0.0, 0.0), (f64::NAN, 1.0), (1.0, -3.0)],
            ))
            .to_svg();
        assert_valid(&all_invalid);
        assert!(all_invalid.contains("no data"));

        let specials = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            1e-310,
            5e-324,
            f64::MIN_POSITIVE,
            1e300,
            f64::MAX,
            -f64::MAX,
            1e16,
            1e16 + 2.0,
            f64::NAN,
            f64::INFINITY,
        ];
        for &a in &specials {
            for &b in &specials {
                for log in [false, true] {
                    let mut fig = Figure::new("t", "x", "y")
                        .series(Series::line_markers("one", vec![(a, b)]))
                        .series(Series::line("two", vec![(a, a), (b, b), (a, b)]))
                        .series(Series::markers("same", vec![(b, a); 3]))
                        .annotate(Annotation::Point {
                            x: a,
                            y: b,
                            label: "p".into(),
                        });
                    if log {
                        fig = fig.log_y();
                    }
                    assert_valid(&fig.to_svg());
                }
            }
        }

        let only_annotations = Figure::new("", "", "")
            .annotate(Annotation::VLine {
                x: 5.0,
                label: "v".into(),
            })
            .annotate(Annotation::HLine {
                y: f64::NAN,
                label: "h".into(),
            })
            .to_svg();
        assert_valid(&only_annotations);
        assert!(only_annotations.contains(">v</text>") && !only_annotations.contains(">h</text>"));

        let tiny = Figure::new("tiny", "x", "y")
            .size(0, 0)
            .series(Series::line("s", vec![(0.0, 1.0), (1.0, 2.0)]))
            .to_svg();
        assert_valid(&tiny);
        assert!(tiny.contains(r#"viewBox="0 0 160 120""#));
    }
}
