//! The figures of paper 002 (Minh, Luong, Bang, Toan) from its report: states and estimates
//! (Fig. 1), errors (Fig. 2), sliding-window RMSE, bias and std of the angle (Fig. 3), and the
//! manoeuvre-amplitude sweep (ours; not in the paper).

use super::{PHASE, Q_SETS, Report, STATE_NAMES, WINDOW};

use crate::figure::{Annotation, Figure, Series};

/// Units of the three states.
const UNITS: [&str; 3] = ["deg", "deg/s", "deg/s^2"];

fn phase_marks(fig: Figure) -> Figure {
    fig.annotate(Annotation::VLine {
        x: PHASE.0,
        label: "phase start".into(),
    })
    .annotate(Annotation::VLine {
        x: PHASE.1,
        label: "phase end".into(),
    })
}

/// `fig` with one line per `Q` set: `pick(set)[k][state]` against `t_k`, `k = 1 .. K`.
fn per_set(
    report: &Report,
    mut fig: Figure,
    state: usize,
    pick: impl Fn(&super::QSetResult) -> &[[f64; 3]],
) -> Figure {
    for set in &Q_SETS {
        let values = pick(&report.q_sets[set.name]);
        fig = fig.series(Series::line(
            set.name,
            report
                .times
                .iter()
                .zip(values)
                .skip(1)
                .map(|(t, x)| (*t, x[state]))
                .collect(),
        ));
    }
    fig
}

fn states(report: &Report, state: usize) -> Figure {
    let fig = Figure::new(
        format!("{} and its estimates (default truth)", STATE_NAMES[state]),
        "t (s)",
        UNITS[state],
    )
    .series(Series::line(
        "truth",
        report
            .times
            .iter()
            .zip(&report.truth)
            .map(|(t, x)| (*t, x[state]))
            .collect(),
    ));
    per_set(report, fig, state, |r| &r.estimates)
}

fn errors(report: &Report, state: usize) -> Figure {
    let fig = Figure::new(
        format!(
            "{} error e = estimate - truth (default truth)",
            STATE_NAMES[state]
        ),
        "t (s)",
        UNITS[state],
    );
    phase_marks(per_set(report, fig, state, |r| &r.errors))
}

fn windows(report: &Report, what: &str, pick: impl Fn(&super::Windows) -> &[f64]) -> Figure {
    let mut fig = Figure::new(
        format!("angle: sliding-window {what}, W = {WINDOW} (at the window's first sample)"),
        "t (s)",
        "deg",
    );
    for set in &Q_SETS {
        let w = &report.q_sets[set.name].windows_theta;
        fig = fig.series(Series::line(
            set.name,
            w.start_time
                .iter()
                .zip(pick(w))
                .map(|(t, v)| (*t, *v))
                .collect(),
        ));
    }
    phase_marks(fig)
}

fn sweep(report: &Report) -> Figure {
    let mut fig = Figure::new(
        "mean angle RMSE in the 6-14 s phase against manoeuvre amplitude (default: 10)",
        "oscillation amplitude (deg/s^2)",
        "deg",
    );
    for (i, set) in Q_SETS.iter().enumerate() {
        fig = fig.series(Series::line_markers(
            set.name,
            report
                .sweep
                .iter()
                .map(|r| (r.amplitude, r.mean_rmse_theta_phase[i]))
                .collect(),
        ));
    }
    if let Some(a) = report.first_reversal_amplitude {
        fig = fig.annotate(Annotation::VLine {
            x: a,
            label: "ordering changes".into(),
        });
    }
    fig
}

/// Every figure of the study as `(file name, SVG)`.
pub(super) fn figures(report: &Report) -> Vec<(String, Figure)> {
    let mut out = Vec::new();
    for (state, name) in STATE_NAMES.iter().enumerate() {
        out.push((format!("fig1_{name}.svg"), states(report, state)));
        out.push((format!("fig2_errors_{name}.svg"), errors(report, state)));
    }
    out.push((
        "fig3_window_rmse.svg".into(),
        windows(report, "RMSE", |w| &w.rmse),
    ));
    out.push((
        "fig3_window_bias.svg".into(),
        windows(report, "bias", |w| &w.bias),
    ));
    out.push((
        "fig3_window_std.svg".into(),
        windows(report, "standard deviation", |w| &w.std),
    ));
    out.push(("fig4_sweep.svg".into(), sweep(report)));
    out
}
