//! The figures of paper 004 (Spall and Wei 2023): marginal densities of `e_1000`, empirical
//! against the surrogate (the paper's Fig. 4), per reading and component.

use super::{COMPONENTS, Report};

use crate::figure::{Figure, Series};

/// Every figure of the study as `(file name, SVG)`.
pub(super) fn figures(report: &Report) -> Vec<(String, Figure)> {
    let mut out = Vec::new();
    for r in &report.readings {
        for (i, d) in r.densities.iter().enumerate() {
            let fig = Figure::new(
                format!(
                    "{}: density of e_{} (reading `{}`)",
                    COMPONENTS[i], report.config.steps, r.reading.name
                ),
                "error x - x_hat",
                "density",
            )
            .series(Series::line(
                format!("empirical ({} replicates)", report.config.replicates),
                d.x.iter()
                    .copied()
                    .zip(d.empirical.iter().copied())
                    .collect(),
            ))
            .series(
                Series::line(
                    "surrogate N(0, P_bar)",
                    d.x.iter()
                        .copied()
                        .zip(d.surrogate.iter().copied())
                        .collect(),
                )
                .dashed(),
            );
            out.push((
                format!("fig4_{}_{}.svg", r.reading.name, COMPONENTS[i]),
                fig,
            ));
        }
    }
    out
}
