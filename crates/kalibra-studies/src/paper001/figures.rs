//! The figures of paper 001 (bearings-only tracking) from its report: per problem, position
//! and velocity RMSE (Figs. 2, 5, 9), NCI and ANEES with its 95% band (Figs. 3, 6, 10), and the
//! mean kappa of the adaptive filters (Fig. 7 for problem II; ours for I and III).

use super::{FILTERS, ProblemResult, Report};

use crate::figure::{Annotation, Figure, Series};

/// One line per filter: `pick(filter)` against the problem's labels; filters with an empty
/// series are skipped.
fn per_filter(
    p: &ProblemResult,
    mut fig: Figure,
    pick: impl Fn(&crate::paper001::FilterResult) -> Vec<Option<f64>>,
) -> Figure {
    for name in FILTERS {
        let values = pick(&p.filters[name]);
        if values.is_empty() {
            continue;
        }
        let points = p
            .labels
            .iter()
            .zip(values)
            .filter_map(|(&k, v)| v.filter(|v| v.is_finite()).map(|v| (k as f64, v)))
            .collect();
        let mut s = Series::line(name, points);
        if name == "UKF-MAP" {
            s = s.dashed();
        }
        fig = fig.series(s);
    }
    fig
}

/// A series with every value present.
fn some(values: &[f64]) -> Vec<Option<f64>> {
    values.iter().copied().map(Some).collect()
}

/// The SVG figures, as (file name, contents).
pub(super) fn figures(report: &Report) -> Vec<(String, Figure)> {
    let mut out = Vec::new();
    for (problem, p) in &report.problems {
        let unit = match *problem {
            "I" => ("m", "m/s"),
            "II" => ("km", "km/min"),
            _ => ("", ""),
        };
        let tag = problem.to_lowercase();
        let fig = Figure::new(
            format!("problem {problem}: position RMSE over {} runs", p.runs),
            "k",
            unit.0,
        )
        .log_y();
        out.push((
            format!("rmse_pos_{tag}.svg"),
            per_filter(p, fig, |f| some(&f.rmse_pos_steps)),
        ));
        if p.filters["EKF"].rmse_vel.is_some() {
            let fig = Figure::new(format!("problem {problem}: velocity RMSE"), "k", unit.1).log_y();
            out.push((
                format!("rmse_vel_{tag}.svg"),
                per_filter(p, fig, |f| some(&f.rmse_vel_steps)),
            ));
        }
        let fig = Figure::new(
            format!("problem {problem}: NCI (above 0: optimistic)"),
            "k",
            "dB",
        )
        .annotate(Annotation::HLine {
            y: 0.0,
            label: "credible".into(),
        });
        out.push((
            format!("nci_{tag}.svg"),
            per_filter(p, fig, |f| some(&f.nci_steps)),
        ));
        let fig = Figure::new(
            format!("problem {problem}: ANEES with its 95% band"),
            "k",
            "ANEES",
        )
        .log_y()
        .annotate(Annotation::HLine {
            y: p.anees_band.0,
            label: "95% band".into(),
        })
        .annotate(Annotation::HLine {
            y: p.anees_band.1,
            label: String::new(),
        });
        out.push((
            format!("anees_{tag}.svg"),
            per_filter(p, fig, |f| some(&f.anees_steps)),
        ));
        let fig = Figure::new(
            format!("problem {problem}: mean kappa of the unscented filters"),
            "k",
            "kappa",
        );
        out.push((
            format!("kappa_{tag}.svg"),
            per_filter(p, fig, |f| f.mean_kappa_steps.clone()),
        ));
    }
    out
}
