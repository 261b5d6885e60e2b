//! The human-readable report of `kalibra tune`: the recommendation in words, the sweep's
//! table and figures, as a [`Document`] (written like `kalibra eval`'s).

use std::path::Path;

use kalibra_plot::{Annotation, Figure, Series};
use kalibra_tune::{NoCrossover, TuneReport};

use crate::document::{Block, Document, fmt};

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |f| f.to_string_lossy().into_owned(),
    )
}

/// The recommendation in one sentence.
fn recommendation(report: &TuneReport) -> String {
    let first = report.points.first().map_or(f64::NAN, |p| p.p);
    let last = report.points.last().map_or(f64::NAN, |p| p.p);
    match (&report.crossover, report.findings.no_crossover) {
        (Some(c), _) => format!(
            "use Q = 10^{} Q_nom: J1 and J2 cross at p_c = {}, where J_c = {} and nq_c = {} \
             (log10 of the mean tr(B_k); {} as the mean of log10 tr(B_k))",
            fmt(Some(c.p)),
            fmt(Some(c.p)),
            fmt(Some(c.j)),
            fmt(c.nq_log10_mean),
            fmt(c.nq_mean_log10)
        ),
        (None, Some(NoCrossover::J1AboveJ2)) => format!(
            "no crossover on the grid p = {} .. {}: J1 lies above J2 at every point, so the \
             crossing is above p = {}; raise the grid's upper end (--p FROM:TO:STEP with a larger TO)",
            fmt(Some(first)),
            fmt(Some(last)),
            fmt(Some(last))
        ),
        (None, Some(NoCrossover::J2AboveJ1)) => format!(
            "no crossover on the grid p = {} .. {}: J2 lies above J1 at every point, so the \
             crossing is below p = {}; lower the grid's lower end (--p FROM:TO:STEP with a smaller FROM)",
            fmt(Some(first)),
            fmt(Some(last)),
            fmt(Some(first))
        ),
        (None, None) => {
            "no crossover: J1 and J2 touch without crossing on this grid; refine the grid \
             (a smaller STEP in --p FROM:TO:STEP)"
                .to_string()
        }
    }
}

fn matrix_text(rows: &[Vec<f64>]) -> String {
    let rows: Vec<String> = rows
        .iter()
        .map(|r| {
            let cells: Vec<String> = r.iter().map(|&v| fmt(Some(v))).collect();
            format!("[{}]", cells.join(", "))
        })
        .collect();
    format!("[{}]", rows.join(", "))
}

impl Document {
    /// The report of `kalibra tune` on `model` and `measurements`.
    pub fn tune(model: &Path, measurements: &Path, report: &TuneReport) -> Self {
        let title = format!(
            "kalibra tune: {} on {}",
            file_name(model),
            file_name(measurements)
        );
        let words = recommendation(report);
        let headline = format!("recommendation: {words}");
        let mut blocks = vec![
            Block::Heading(title.clone()),
            Block::Paragraph(Some(format!("Recommendation: {words}.")), String::new()),
        ];
        if let Some(q) = &report.recommended_q {
            blocks.push(Block::Paragraph(
                Some("Recommended Q:".into()),
                matrix_text(q),
            ));
        }
        if let Some(m) = &report.rmse_minimum {
            let beside = report.crossover.map_or(String::new(), |c| {
                format!(" (the crossover is at p_c = {})", fmt(Some(c.p)))
            });
            let mut text = format!(
                "the smallest state RMSE against the truth is {} at p = {}{beside}.",
                fmt(Some(m.state)),
                fmt(Some(m.p_state))
            );
            if let (Some(p), Some(r)) = (m.p_position, m.position) {
                text.push_str(&format!(
                    " The smallest position RMSE is {} at p = {}.",
                    fmt(Some(r)),
                    fmt(Some(p))
                ));
            }
            blocks.push(Block::Paragraph(Some("With the truth:".into()), text));
        }
        blocks.push(Block::Paragraph(
            None,
            format!(
                "Q = 10^p Q_nom swept over {} points; state dimension {}, measurement dimension \
                 {}; {} steps, {} with a measurement; {}; P0 {}. J1 = tr(S^-1 R) falls and \
                 J2 = tr((A + B)^-1 B) rises with p, both in [0, {}]; the papers take their \
                 crossing as the compromise Q.",
                report.points.len(),
                report.state_dim,
                report.meas_dim,
                report.steps,
                report.updates,
                if report.predict_first {
                    "x0 one step before the first measurement (predict first)"
                } else {
                    "x0 at the first measurement (update first)"
                },
                match report.initial_covariance {
                    kalibra_tune::InitialCovariance::AsGiven => "taken as given",
                    _ => "checked symmetric positive semi-definite",
                },
                report.meas_dim
            ),
        ));
        let f = &report.findings;
        if f.indefinite_updates > 0 || f.points_outside_bounds > 0 {
            blocks.push(Block::Paragraph(
                Some("Findings:".into()),
                format!(
                    "{} update(s) at {} point(s) had an A + B that is not positive definite \
                     (first at p = {}); {} point(s) have J1 or J2 outside [0, m].",
                    f.indefinite_updates,
                    f.points_with_indefinite_updates,
                    fmt(f.first_indefinite_p),
                    f.points_outside_bounds
                ),
            ));
        }
        blocks.push(Block::Heading("Figures".into()));
        let mut figures = Vec::new();
        let j1: Vec<(f64, f64)> = report.points.iter().map(|p| (p.p, p.j1)).collect();
        let j2: Vec<(f64, f64)> = report.points.iter().map(|p| (p.p, p.j2)).collect();
        let mut fig = Figure::new("J1 and J2 against p", "p (Q = 10^p Q_nom)", "J")
            .series(Series::line_markers("J1 (sensitivity)", j1))
            .series(Series::line_markers("J2 (robustness)", j2));
        if let Some(c) = &report.crossover {
            fig = fig
                .annotate(Annotation::VLine {
                    x: c.p,
                    label: format!("p_c = {}", fmt(Some(c.p))),
                })
                .annotate(Annotation::Point {
                    x: c.p,
                    y: c.j,
                    label: format!("J_c = {}", fmt(Some(c.j))),
                });
        }
        blocks.push(Block::Paragraph(
            None,
            "J1 and J2 at every p of the grid, the crossover marked.".into(),
        ));
        blocks.push(Block::Figure(figures.len()));
        figures.push(("j1j2.svg".to_string(), fig));
        let rmse: Vec<(f64, f64)> = report
            .points
            .iter()
            .filter_map(|p| p.rmse.as_ref().map(|r| (p.p, r.state)))
            .collect();
        if !rmse.is_empty() {
            let mut fig = Figure::new("RMSE against p", "p (Q = 10^p Q_nom)", "RMSE")
                .series(Series::line_markers("state RMSE", rmse));
            let position: Vec<(f64, f64)> = report
                .points
                .iter()
                .filter_map(|p| p.rmse.as_ref().and_then(|r| r.position.map(|v| (p.p, v))))
                .collect();
            if !position.is_empty() {
                fig = fig.series(Series::line_markers("position RMSE", position));
            }
            if let Some(c) = &report.crossover {
                fig = fig.annotate(Annotation::VLine {
                    x: c.p,
                    label: format!("p_c = {}", fmt(Some(c.p))),
                });
            }
            if let Some(m) = &report.rmse_minimum {
                fig = fig.annotate(Annotation::Point {
                    x: m.p_state,
                    y: m.state,
                    label: "smallest".into(),
                });
            }
            blocks.push(Block::Paragraph(
                None,
                "RMSE against the truth at every p, beside the crossover: how well J1 and J2 \
                 predicted it."
                    .into(),
            ));
            blocks.push(Block::Figure(figures.len()));
            figures.push(("rmse.svg".to_string(), fig));
        }
        blocks.push(Block::Heading("The sweep".into()));
        let with_rmse = report.rmse_minimum.is_some();
        let mut head: Vec<String> = ["p", "J1", "J2", "nq (log10 mean)", "nq (mean log10)"]
            .iter()
            .map(|s| (*s).to_string())
            .collect();
        if with_rmse {
            head.push("state RMSE".into());
        }
        let rows = report
            .points
            .iter()
            .map(|p| {
                let mut row = vec![
                    fmt(Some(p.p)),
                    fmt(Some(p.j1)),
                    fmt(Some(p.j2)),
                    fmt(p.nq_log10_mean),
                    fmt(p.nq_mean_log10),
                ];
                if with_rmse {
                    row.push(fmt(p.rmse.as_ref().map(|r| r.state)));
                }
                row
            })
            .collect();
        blocks.push(Block::Table(head, rows));
        blocks.push(Block::Paragraph(
            None,
            "Every number is in report.json (its schema_version says which fields it holds)."
                .into(),
        ));
        Self::from_parts(title, headline, blocks, figures)
    }
}
