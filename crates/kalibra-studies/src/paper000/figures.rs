//! The figures of the reproduction reports, built from the studies' reports with
//! [`crate::plot`]. Each function returns `(file name, SVG document)` pairs; the caller writes
//! them beside the study's `report.md`, whose links use these names.

use super::{CROSSOVER_NQ_RANGE, READINGS, Report, TABLE_I};
use crate::reentry::{CrossoverRow, SweepRow};

use crate::figure::{Annotation, Figure, Series};

/// Curves closer than this everywhere are drawn on top of each other (about 2 px on these
/// figures); the title says so, since the one drawn first is hidden.
const SAME_CURVE: f64 = 0.01;

/// The x axis of paper 000's figures.
const NQ_LABEL: &str = "nq = mean log10 tr(B_k)";

/// Paper 000's figures (Fig. 1 of the paper, and how the readings move it):
/// * `j1j2_kf.svg`, `j1j2_ekf.svg`: J1 and J2 against `nq` on the fine sweep of the `paper`
///   reading (lines), Table I's printed values (markers), the crossover (circled) and the
///   paper's claimed crossover range (two dashed vertical lines);
/// * `j1j2_readings.svg`: the EKF's J1 (solid) and J2 (dashed) against `nq` for every reading.
pub(super) fn figures(report: &Report) -> Vec<(String, Figure)> {
    let paper = report
        .reading(READINGS[0].name)
        .or_else(|| report.readings.first());
    let mut out = Vec::new();
    if let Some(r) = paper {
        let filters = [
            (
                "KF",
                "j1j2_kf.svg",
                &r.sweep.kf,
                r.crossover.kf,
                (printed(|t| t.2), printed(|t| t.3)),
            ),
            (
                "EKF",
                "j1j2_ekf.svg",
                &r.sweep.ekf,
                r.crossover.ekf,
                (printed(|t| t.4), printed(|t| t.5)),
            ),
        ];
        for (filter, file, sweep, crossover, (j1_paper, j2_paper)) in filters {
            let title = format!(
                "Paper 000, {filter}: J1 and J2 against nq (reading '{}')",
                r.reading.name
            );
            let figure = range_lines(
                Figure::new(title, NQ_LABEL, "J")
                    .size(800, 450)
                    .series(Series::line("J1", curve(sweep, j1)))
                    .series(Series::line("J2", curve(sweep, j2)))
                    .series(Series::markers("J1 paper", j1_paper))
                    .series(Series::markers("J2 paper", j2_paper)),
            );
            let figure = match crossover {
                Some(c) => figure.annotate(crossover_point(&c)),
                None => figure,
            };
            out.push((file.to_string(), figure));
        }
    }

    // Readings whose EKF curves (J1 and J2) coincide with an earlier reading's are drawn over
    // it; the title says so, since the earlier one is hidden.
    let same = |a: &[SweepRow], b: &[SweepRow]| {
        a.len() == b.len()
            && a.iter().zip(b).all(|(a, b)| {
                a.nq == b.nq && (a.j1 - b.j1).abs() < SAME_CURVE && (a.j2 - b.j2).abs() < SAME_CURVE
            })
    };
    let covers: Vec<String> = report
        .readings
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            report.readings[..i]
                .iter()
                .find(|o| same(&o.sweep.ekf, &r.sweep.ekf))
                .map(|o| format!("{} covers {}", r.reading.name, o.reading.name))
        })
        .collect();
    let mut title =
        "Paper 000, EKF: J1 (solid) and J2 (dashed) against nq, every reading".to_string();
    if !covers.is_empty() {
        title = format!("{title} ({})", covers.join("; "));
    }
    let mut readings = Figure::new(title, NQ_LABEL, "J").size(800, 450);
    for r in &report.readings {
        let name = r.reading.name;
        readings = readings
            .series(Series::line(format!("{name} J1"), curve(&r.sweep.ekf, j1)))
            .series(Series::line(format!("{name} J2"), curve(&r.sweep.ekf, j2)).dashed());
    }
    out.push(("j1j2_readings.svg".to_string(), range_lines(readings)));
    out
}

/// A row of [`TABLE_I`]: `(p printed, nq, J1 KF, J2 KF, J1 EKF, J2 EKF)`.
type TableIRow = (f64, f64, f64, f64, f64, f64);

/// `(nq, value)` of Table I as printed.
fn printed(value: fn(&TableIRow) -> f64) -> Vec<(f64, f64)> {
    TABLE_I.iter().map(|r| (r.1, value(r))).collect()
}

/// J1 of a sweep row.
fn j1(s: &SweepRow) -> f64 {
    s.j1
}

/// J2 of a sweep row.
fn j2(s: &SweepRow) -> f64 {
    s.j2
}

/// `(nq, value)` along a sweep.
fn curve(sweep: &[SweepRow], value: fn(&SweepRow) -> f64) -> Vec<(f64, f64)> {
    sweep.iter().map(|s| (s.nq, value(s))).collect()
}

/// The paper's claimed crossover range as two dashed vertical lines.
fn range_lines(figure: Figure) -> Figure {
    let (lo, hi) = CROSSOVER_NQ_RANGE;
    figure
        .annotate(Annotation::VLine {
            x: lo,
            label: format!("{lo}"),
        })
        .annotate(Annotation::VLine {
            x: hi,
            label: format!("{hi}: paper's crossover range"),
        })
}

/// The crossover, circled and labelled.
fn crossover_point(c: &CrossoverRow) -> Annotation {
    Annotation::Point {
        x: c.nq,
        y: c.j,
        label: format!("crossover nq={:.2}, J={:.2}", c.nq, c.j),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::paper000::{Config, run};

    /// Every figure has data; the crossover is marked; the readings figure names each reading.
    #[test]
    fn figures_have_data() {
        let report = run(&Config::quick()).unwrap();
        let figures = figures(&report);
        let names: Vec<&str> = figures.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["j1j2_kf.svg", "j1j2_ekf.svg", "j1j2_readings.svg"]);
        crate::figure::assert_drawable(&figures);
        assert!(figures[0].1.annotations.iter().any(
            |a| matches!(a, Annotation::Point { label, .. } if label.contains("crossover nq="))
        ));
        for r in &report.readings {
            let fig = &figures[2].1;
            assert!(
                fig.title.contains(r.reading.name)
                    || fig.series.iter().any(|s| s.label.contains(r.reading.name)),
                "{}",
                r.reading.name
            );
        }
    }
}
