//! The human-readable report: one list of blocks, written as Markdown (`report.md`) and as
//! self-contained HTML with the figures inline (`report.html`), so both say the same.

use std::fmt::Write as _;
use std::path::Path;

use kalibra_eval::{Band, ConsistencyTest, FindingCount, Report, TestMethod, VerdictKind};
use kalibra_plot::{Annotation, Figure, Series, ToSvg};

/// A block of the report.
pub(crate) enum Block {
    Heading(String),
    /// A paragraph, with an optional bold lead.
    Paragraph(Option<String>, String),
    /// A table: header and rows.
    Table(Vec<String>, Vec<Vec<String>>),
    /// A figure: its index in `Document::figures`.
    Figure(usize),
}

/// The report as blocks and figures.
pub struct Document {
    title: String,
    headline: String,
    blocks: Vec<Block>,
    /// File name and figure.
    pub figures: Vec<(String, Figure)>,
}

/// The verdict in words.
fn verdict_words(kind: VerdictKind) -> &'static str {
    match kind {
        VerdictKind::Consistent => {
            "consistent: the filter's covariance matches the errors it actually makes"
        }
        VerdictKind::Optimistic => {
            "optimistic: the filter's covariance is too small, it claims more accuracy than it has"
        }
        VerdictKind::Pessimistic => {
            "pessimistic: the filter's covariance is too large, it is more accurate than it claims"
        }
        VerdictKind::Undetermined => "undetermined: the log holds nothing the verdict can rest on",
    }
}

pub(crate) fn fmt(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() => {
            if v != 0.0 && (v.abs() < 1e-3 || v.abs() >= 1e5) {
                format!("{v:.3e}")
            } else {
                format!("{v:.4}")
            }
        }
        Some(v) => v.to_string(),
        None => "-".to_string(),
    }
}

fn percent(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |v| format!("{:.1}%", 100.0 * v))
}

fn test_words(t: &ConsistencyTest) -> String {
    match t.method {
        TestMethod::RunAverageT => format!(
            "t-test of the runs' averages against 1: t = {}, p = {}",
            fmt(t.t),
            fmt(t.p_value)
        ),
        TestMethod::TimeAverageChiSquare => format!(
            "time average against its chi-square band [{}, {}]",
            fmt(t.band.map(|b| b.lower)),
            fmt(t.band.map(|b| b.upper))
        ),
    }
}

fn finding_row(what: &str, f: &FindingCount) -> Vec<String> {
    let first = f.first.as_ref().map_or("-".to_string(), |x| {
        format!(
            "{} at run {}, step {} ({:?})",
            x.array, x.run, x.step, x.reason
        )
    });
    vec![
        what.to_string(),
        f.cells.to_string(),
        f.steps.to_string(),
        first,
    ]
}

/// `(x, y)` per step, with a gap (NaN) where `y` is missing; x is the time when logged.
fn points(report: &Report, ys: impl Iterator<Item = Option<f64>>) -> Vec<(f64, f64)> {
    ys.enumerate()
        .map(|(k, y)| {
            let x = report
                .times
                .as_ref()
                .and_then(|t| t.get(k).copied())
                .unwrap_or(k as f64);
            (x, y.unwrap_or(f64::NAN))
        })
        .collect()
}

fn x_label(report: &Report) -> &'static str {
    if report.times.is_some() {
        "time"
    } else {
        "step"
    }
}

/// A statistic per step with its band, and the reference line at 1.
fn band_figure(
    report: &Report,
    title: &str,
    label: &str,
    values: &[Option<f64>],
    band: &[Option<Band>],
) -> Figure {
    Figure::new(title, x_label(report), label)
        .series(Series::line(label, points(report, values.iter().copied())))
        .series(
            Series::line(
                "band (lower)",
                points(report, band.iter().map(|b| b.map(|b| b.lower))),
            )
            .dashed(),
        )
        .series(
            Series::line(
                "band (upper)",
                points(report, band.iter().map(|b| b.map(|b| b.upper))),
            )
            .dashed(),
        )
        .annotate(Annotation::HLine {
            y: 1.0,
            label: "consistent".into(),
        })
}

fn figures(report: &Report) -> Vec<(String, String, Figure)> {
    let mut out = Vec::new();
    let conf = format!("{:.0}%", 100.0 * report.confidence);
    if report.anees_per_step.iter().any(Option::is_some) {
        out.push((
            "anees.svg".into(),
            format!("ANEES per step with its {conf} chi-square band over runs."),
            band_figure(
                report,
                "ANEES per step",
                "ANEES",
                &report.anees_per_step,
                &report.anees_band,
            ),
        ));
    }
    if report.anis_per_step.iter().any(Option::is_some) {
        out.push((
            "anis.svg".into(),
            format!("ANIS per step with its {conf} chi-square band over runs."),
            band_figure(
                report,
                "ANIS per step",
                "ANIS",
                &report.anis_per_step,
                &report.anis_band,
            ),
        ));
    }
    if report.nci_per_step.iter().any(Option::is_some) {
        out.push((
            "nci.svg".into(),
            "Non-credibility index per step (dB; above 0: optimistic, below: pessimistic).".into(),
            Figure::new("NCI per step", x_label(report), "NCI [dB]")
                .series(Series::line(
                    "NCI",
                    points(report, report.nci_per_step.iter().copied()),
                ))
                .annotate(Annotation::HLine {
                    y: 0.0,
                    label: "credible".into(),
                }),
        ));
    }
    if !report.rmse_per_step.is_empty() {
        let mut fig = Figure::new("RMSE per step", x_label(report), "RMSE");
        for s in &report.rmse_per_step {
            fig = fig.series(Series::line(
                s.name.clone(),
                points(report, s.values.iter().copied()),
            ));
        }
        out.push((
            "rmse.svg".into(),
            "RMSE over runs per step, per component and group.".into(),
            fig,
        ));
    }
    if let Some(w) = &report.whiteness {
        let lag = |f: fn(&kalibra_eval::LagReport) -> f64| -> Vec<(f64, f64)> {
            w.lags.iter().map(|l| (l.lag as f64, f(l))).collect()
        };
        out.push((
            "whiteness.svg".into(),
            format!(
                "Autocorrelation of run {}'s normalised innovations per lag, with its {conf} band.",
                w.run
            ),
            Figure::new(
                format!("Innovation whiteness (run {})", w.run),
                "lag",
                "autocorrelation",
            )
            .series(Series::line_markers(
                "autocorrelation",
                lag(|l| l.autocorrelation),
            ))
            .series(Series::line("band (upper)", lag(|l| l.bound)).dashed())
            .series(Series::line("band (lower)", lag(|l| -l.bound)).dashed())
            .annotate(Annotation::HLine {
                y: 0.0,
                label: String::new(),
            }),
        ));
    }
    if let Some(j) = &report.j {
        out.push((
            "j1j2.svg".into(),
            "J1 and J2 per step (mean over runs).".into(),
            Figure::new("J1 and J2 per step", x_label(report), "J")
                .series(Series::line(
                    "J1",
                    points(report, j.j1_per_step.iter().copied()),
                ))
                .series(Series::line(
                    "J2",
                    points(report, j.j2_per_step.iter().copied()),
                )),
        ));
    }
    out
}

impl Document {
    /// The report of the log at `log` as blocks and figures.
    pub fn new(log: &Path, report: &Report) -> Self {
        let s = &report.summary;
        let file = log.file_name().map_or_else(
            || log.display().to_string(),
            |f| f.to_string_lossy().into_owned(),
        );
        let title = format!("kalibra report: {file}");
        let words = verdict_words(s.verdict.kind);
        let headline = format!("verdict: {words}");
        let mut blocks = vec![
            Block::Heading(title.clone()),
            Block::Paragraph(Some(format!("Verdict: {words}.")), String::new()),
            Block::Paragraph(Some("Evidence:".into()), s.verdict.evidence.clone()),
            Block::Paragraph(Some("Test:".into()), s.verdict.test.clone()),
            Block::Paragraph(
                None,
                format!(
                    "{} run(s) of {} steps; state dimension {}, measurement dimension {}; \
                     confidence {}.",
                    report.runs,
                    report.steps.len(),
                    report.state_dim.map_or("-".into(), |n| n.to_string()),
                    report.measurement_dim.map_or("-".into(), |m| m.to_string()),
                    report.confidence
                ),
            ),
            Block::Heading("Headline numbers".into()),
        ];
        let mut rows = vec![
            vec![
                "ANEES (mean NEES / n; 1 if consistent)".into(),
                fmt(s.anees),
                s.anees_test.as_ref().map_or("-".into(), test_words),
            ],
            vec![
                "ANIS (mean NIS / m; 1 if consistent)".into(),
                fmt(s.anis),
                s.anis_test.as_ref().map_or("-".into(), test_words),
            ],
            vec![
                "NCI (dB; 0 if credible, above: optimistic)".into(),
                fmt(s.nci),
                "mean over steps".into(),
            ],
            vec![
                "Steps with ANEES inside its band".into(),
                percent(s.anees_fraction_inside),
                format!("expected about {:.0}%", 100.0 * report.confidence),
            ],
            vec![
                "Steps with ANIS inside its band".into(),
                percent(s.anis_fraction_inside),
                format!("expected about {:.0}%", 100.0 * report.confidence),
            ],
            vec![
                "Whiteness lags inside their band".into(),
                percent(s.whiteness_fraction_inside),
                report.whiteness.as_ref().map_or("-".into(), |w| {
                    format!(
                        "run {}; Box-Pierce p = {} ({})",
                        w.run,
                        fmt(Some(w.p_value)),
                        if w.white { "white" } else { "not white" }
                    )
                }),
            ],
        ];
        for r in &report.rmse_per_step {
            rows.push(vec![
                format!("RMSE over time, {}", r.name),
                fmt(r.over_time),
                String::new(),
            ]);
        }
        if let Some(j) = &report.j {
            rows.push(vec![
                "J1 / J2".into(),
                format!("{} / {}", fmt(Some(j.j1)), fmt(Some(j.j2))),
                format!("{} updates", j.updates),
            ]);
        }
        blocks.push(Block::Table(
            vec!["quantity".into(), "value".into(), "test or note".into()],
            rows,
        ));
        blocks.push(Block::Heading("Findings".into()));
        let f = &report.findings;
        if f.state.cells + f.innovation.cells == 0 {
            blocks.push(Block::Paragraph(
                None,
                "Every logged covariance was symmetric and positive definite, and every \
                 vector finite."
                    .into(),
            ));
        } else {
            blocks.push(Block::Paragraph(
                None,
                "Cells with a NaN, asymmetric or indefinite covariance or a non-finite vector \
                 are findings about the filter: counted here and left out of the statistics \
                 they would poison."
                    .into(),
            ));
            blocks.push(Block::Table(
                vec![
                    "arrays".into(),
                    "cells".into(),
                    "steps".into(),
                    "first".into(),
                ],
                vec![
                    finding_row("estimate, covariance", &f.state),
                    finding_row("innovation, innovation_cov", &f.innovation),
                ],
            ));
        }
        blocks.push(Block::Heading("Figures".into()));
        let mut figs = Vec::new();
        for (name, caption, fig) in figures(report) {
            blocks.push(Block::Paragraph(None, caption));
            blocks.push(Block::Figure(figs.len()));
            figs.push((name, fig));
        }
        blocks.push(Block::Paragraph(
            None,
            "Every number is in report.json (its schema_version says which fields it holds)."
                .into(),
        ));
        Self {
            title,
            headline,
            blocks,
            figures: figs,
        }
    }

    /// A document from its parts (the title is the first heading's text).
    pub(crate) fn from_parts(
        title: String,
        headline: String,
        blocks: Vec<Block>,
        figures: Vec<(String, Figure)>,
    ) -> Self {
        Self {
            title,
            headline,
            blocks,
            figures,
        }
    }

    /// The verdict in one line.
    pub fn headline(&self) -> &str {
        &self.headline
    }

    /// `report.md`.
    pub fn markdown(&self) -> String {
        let mut out = String::new();
        let mut first = true;
        for block in &self.blocks {
            match block {
                Block::Heading(h) => {
                    let level = if first { "#" } else { "##" };
                    let _ = writeln!(out, "{level} {}\n", md_escape(h));
                    first = false;
                }
                Block::Paragraph(lead, text) => {
                    let lead = lead
                        .as_ref()
                        .map(|l| format!("**{}** ", md_escape(l)))
                        .unwrap_or_default();
                    let _ = writeln!(out, "{}\n", (lead + &md_escape(text)).trim_end());
                }
                Block::Table(head, rows) => {
                    let line = |cells: &[String]| {
                        let cells: Vec<String> = cells
                            .iter()
                            .map(|c| md_escape(c).replace('|', "\\|"))
                            .collect();
                        format!("| {} |", cells.join(" | "))
                    };
                    let _ = writeln!(out, "{}", line(head));
                    let _ = writeln!(out, "|{}", " --- |".repeat(head.len()));
                    for r in rows {
                        let _ = writeln!(out, "{}", line(r));
                    }
                    out.push('\n');
                }
                Block::Figure(i) => {
                    let (name, fig) = &self.figures[*i];
                    let _ = writeln!(out, "![{}]({name})\n", md_escape(&fig.title));
                }
            }
        }
        out
    }

    /// `report.html`: the same content, figures inline, no external resources.
    pub fn html(&self) -> String {
        let mut out = String::new();
        let _ = write!(
            out,
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
             <title>{}</title>\n<style>\nbody {{ font-family: sans-serif; max-width: 60em; \
             margin: 2em auto; padding: 0 1em; color: #222; }}\ntable {{ border-collapse: \
             collapse; margin: 1em 0; }}\nth, td {{ border: 1px solid #ccc; padding: 0.3em \
             0.6em; text-align: left; }}\nfigure {{ margin: 1em 0; }}\nsvg {{ max-width: 100%; \
             height: auto; }}\n</style>\n</head>\n<body>\n",
            html_escape(&self.title)
        );
        let mut first = true;
        for block in &self.blocks {
            match block {
                Block::Heading(h) => {
                    let tag = if first { "h1" } else { "h2" };
                    let _ = writeln!(out, "<{tag}>{}</{tag}>", html_escape(h));
                    first = false;
                }
                Block::Paragraph(lead, text) => {
                    let lead = lead
                        .as_ref()
                        .map(|l| format!("<strong>{}</strong> ", html_escape(l)))
                        .unwrap_or_default();
                    let _ = writeln!(out, "<p>{}</p>", (lead + &html_escape(text)).trim_end());
                }
                Block::Table(head, rows) => {
                    out.push_str("<table>\n<tr>");
                    for h in head {
                        let _ = write!(out, "<th>{}</th>", html_escape(h));
                    }
                    out.push_str("</tr>\n");
                    for r in rows {
                        out.push_str("<tr>");
                        for c in r {
                            let _ = write!(out, "<td>{}</td>", html_escape(c));
                        }
                        out.push_str("</tr>\n");
                    }
                    out.push_str("</table>\n");
                }
                Block::Figure(i) => {
                    let (_, fig) = &self.figures[*i];
                    // Each SVG names its clip path `kalibra-plot-area`; inline in one page the
                    // ids must differ, or every figure would clip to the first one's area.
                    let svg = fig
                        .to_svg()
                        .replace("kalibra-plot-area", &format!("kalibra-plot-area-{i}"));
                    let _ = writeln!(out, "<figure>\n{}\n</figure>", svg.trim_end());
                }
            }
        }
        out.push_str("</body>\n</html>\n");
        out
    }
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Keeps text that came from the log or the report literal in Markdown.
fn md_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if matches!(c, '\\' | '*' | '_' | '`' | '[' | ']' | '<' | '>') {
            out.push('\\');
        }
        out.push(c);
    }
    out
}
