//! The figures of paper 003 (Saha, Ghosh, Goswami 2014) from its report: J1/J2 against nq
//! (Fig. 1), RMSE per state against the CRLB (Fig. 2), observability singular values
//! (Fig. 3), altitude and density (Fig. 4) and ITSE (Fig. 5).

use super::{Report, STATE_NAMES};
use crate::reentry::SweepRow;

use crate::figure::{Annotation, Figure, Series};

/// `f` of the sweep at `nq`, interpolated linearly between the neighbouring rows (the rows
/// are ordered by `p`, and `nq` increases with `p`); `None` outside the sweep.
fn at_nq(rows: &[SweepRow], nq: f64, f: impl Fn(&SweepRow) -> f64) -> Option<f64> {
    rows.windows(2).find_map(|w| {
        let (a, b) = (&w[0], &w[1]);
        let (lo, hi) = (a.nq.min(b.nq), a.nq.max(b.nq));
        if !(lo..=hi).contains(&nq) {
            return None;
        }
        if b.nq == a.nq {
            return Some(f(a));
        }
        let t = (nq - a.nq) / (b.nq - a.nq);
        Some(f(a) + t * (f(b) - f(a)))
    })
}

/// J1 and J2 against nq for the `paper` reading's fine sweep, with the crossover, the two
/// plateau edges, the five Monte Carlo settings and the published crossover.
fn j1j2(report: &Report) -> Figure {
    let Some(reading) = report.readings.first() else {
        return Figure::new("J1 and J2 against nq: no reading", "nq", "J");
    };
    let rows = &reading.sweep.ekf;
    let mut fig = Figure::new(
        format!(
            "EKF: J1 (sensitivity) and J2 (robustness) against nq, reading `{}`",
            reading.reading.name
        ),
        "nq = log10 mean tr(B_k)",
        "J",
    )
    .series(Series::line(
        "J1",
        rows.iter().map(|r| (r.nq, r.j1)).collect(),
    ))
    .series(Series::line(
        "J2",
        rows.iter().map(|r| (r.nq, r.j2)).collect(),
    ))
    .series(Series::markers(
        format!(
            "paper: crossover nq = {}, J = {}",
            super::CROSSOVER_NQ,
            super::CROSSOVER_J
        ),
        vec![(super::CROSSOVER_NQ, super::CROSSOVER_J)],
    ))
    .annotate(Annotation::VLine {
        x: reading.j1_edge.0.ours,
        label: format!("S3: J1 edge (paper {})", super::PLATEAU_EDGES.0),
    })
    .annotate(Annotation::VLine {
        x: reading.j2_edge.0.ours,
        label: format!("R3: J2 edge (paper {})", super::PLATEAU_EDGES.1),
    });
    for m in &report.monte_carlo {
        // C sits on the crossover; the sensitive settings on J1, the robust ones on J2.
        let point = match (m.name, reading.crossover.ekf) {
            ("C", Some(c)) => Some((
                c.nq,
                c.j,
                format!("C: crossover nq = {:.2}, J = {:.3}", c.nq, c.j),
            )),
            (name, _) if name.starts_with('R') => {
                at_nq(rows, m.nq, |r| r.j2).map(|j| (m.nq, j, name.to_string()))
            }
            (name, _) => at_nq(rows, m.nq, |r| r.j1).map(|j| (m.nq, j, name.to_string())),
        };
        if let Some((x, y, mut label)) = point {
            // S3 and R3 are the plateau edges, already named by their vertical lines.
            if matches!(m.name, "S3" | "R3") {
                label.clear();
            }
            fig = fig.annotate(Annotation::Point { x, y, label });
        }
    }
    fig
}

/// RMSE of state `i` per time for the five settings, with the CRLB dashed, on a log axis.
fn rmse(report: &Report, i: usize) -> Figure {
    let unit = if i.is_multiple_of(2) { "m" } else { "m/s" };
    let mut fig = Figure::new(
        format!(
            "RMSE of {} ({} runs) and the posterior CRLB",
            STATE_NAMES[i], report.config.runs
        ),
        "time [s]",
        format!("RMSE [{unit}]"),
    )
    .log_y();
    for m in &report.monte_carlo {
        fig = fig.series(Series::line(
            m.name,
            report
                .times
                .iter()
                .zip(&m.rmse)
                .map(|(t, r)| (*t, r[i]))
                .collect(),
        ));
    }
    fig.series(
        Series::line(
            "CRLB",
            report
                .times
                .iter()
                .zip(&report.crlb)
                .map(|(t, b)| (*t, b[i]))
                .collect(),
        )
        .dashed(),
    )
}

/// ITSE per state against the setting index, one series per state, on a log axis.
fn itse(report: &Report) -> Figure {
    let names: Vec<&str> = report.monte_carlo.iter().map(|m| m.name).collect();
    let mut fig = Figure::new(
        format!(
            "ITSE per state; x = 0 .. {}: {}",
            names.len().saturating_sub(1),
            names.join(", ")
        ),
        format!("setting ({})", names.join(", ")),
        "ITSE",
    )
    .log_y();
    for (i, name) in STATE_NAMES.iter().enumerate() {
        fig = fig.series(Series::line_markers(
            *name,
            report
                .monte_carlo
                .iter()
                .enumerate()
                .map(|(j, m)| (j as f64, m.itse[i]))
                .collect(),
        ));
    }
    fig
}

/// The four singular values of the observability matrix against the step, on a log axis.
fn observability(report: &Report) -> Figure {
    let mut fig = Figure::new(
        "Singular values of the observability matrix along the noise-free truth",
        "step k",
        "singular value",
    )
    .log_y();
    for i in 0..4 {
        fig = fig.series(Series::line(
            format!("SV{}", i + 1),
            report
                .observability
                .iter()
                .enumerate()
                .map(|(j, sv)| ((j + 1) as f64, sv[i]))
                .collect(),
        ));
    }
    fig
}

/// True altitude (km) and air density (x 10) against time.
fn altitude_density(report: &Report) -> Figure {
    let along = |f: fn(&(f64, f64)) -> f64| -> Vec<(f64, f64)> {
        report
            .times
            .iter()
            .zip(&report.altitude_density)
            .map(|(t, ad)| (*t, f(ad)))
            .collect()
    };
    Figure::new(
        "True altitude and air density along the noise-free truth",
        "time [s]",
        "altitude [km]; density x 10 [kg/m^3]",
    )
    .series(Series::line(
        "altitude / 1000 [km]",
        along(|ad| ad.0 / 1000.0),
    ))
    .series(Series::line(
        "density x 10 [kg/m^3]",
        along(|ad| ad.1 * 10.0),
    ))
}

/// The figures of paper 003 as `(file name, SVG document)`: `j1j2.svg`, `rmse_<state>.svg`
/// for every state, `itse.svg`, `observability.svg` and `altitude_density.svg`.
// reproduce.rs calls this next; until then only the tests below do.
#[allow(dead_code)]
pub(super) fn figures(report: &Report) -> Vec<(String, Figure)> {
    let mut out = vec![("j1j2.svg".to_string(), j1j2(report))];
    for (i, name) in STATE_NAMES.iter().enumerate() {
        out.push((format!("rmse_{name}.svg"), rmse(report, i)));
    }
    out.push(("itse.svg".to_string(), itse(report)));
    out.push(("observability.svg".to_string(), observability(report)));
    out.push(("altitude_density.svg".to_string(), altitude_density(report)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::paper003::{Config, run};

    /// Every figure of the quick study has data and no NaN in its text.
    #[test]
    fn figures_are_drawable() {
        let report = run(&Config::quick()).unwrap();
        let figures = figures(&report);
        let names: Vec<&str> = figures.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(
            names,
            [
                "j1j2.svg",
                "rmse_x1.svg",
                "rmse_x1dot.svg",
                "rmse_x2.svg",
                "rmse_x2dot.svg",
                "itse.svg",
                "observability.svg",
                "altitude_density.svg"
            ]
        );
        crate::figure::assert_drawable(&figures);
    }

    /// Interpolation between sweep rows, and `None` outside them.
    #[test]
    fn figures_interpolate_in_nq() {
        let row = |nq: f64, j1: f64| SweepRow {
            p: nq,
            nq,
            j1,
            j2: 0.0,
            indefinite_updates: 0,
            max_j2k: 0.0,
        };
        let rows = [row(0.0, 1.0), row(1.0, 3.0)];
        assert_eq!(at_nq(&rows, 0.5, |r| r.j1), Some(2.0));
        assert_eq!(at_nq(&rows, 2.0, |r| r.j1), None);
    }
}
