//! The human-readable report of a noise estimate (`kalibra tune --method ...`): the
//! recommendation in words, the parameters with their intervals, what the data identify, the
//! consistency of the tuned filter beside the starting guess, and the profile likelihood of
//! each parameter (or its J1/J2 curve), as a [`Document`].

use std::path::Path;

use kalibra_plot::{Annotation, Figure, Series};
use kalibra_tune::MethodKind;

use crate::document::{Block, Document, fmt};
use crate::noise_report::{FilterConsistency, NoiseReportFile, method_words};

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |f| f.to_string_lossy().into_owned(),
    )
}

/// `v` to 4 significant digits without trailing zeros (`0.008978`, `4.089`, `0.1`), in
/// scientific notation outside
/// `[1e-3, 1e5)`: estimates span orders of magnitude, so fixed decimals would hide small ones.
fn sig(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() && v != 0.0 && v.abs() >= 1e-3 && v.abs() < 1e5 => {
            let decimals = (3 - v.abs().log10().floor() as i32).max(0) as usize;
            let text = format!("{v:.decimals$}");
            if text.contains('.') {
                text.trim_end_matches('0').trim_end_matches('.').to_string()
            } else {
                text
            }
        }
        other => fmt(other),
    }
}

fn matrix_text(rows: &[Vec<f64>]) -> String {
    let rows: Vec<String> = rows
        .iter()
        .map(|r| {
            let cells: Vec<String> = r.iter().map(|&v| sig(Some(v))).collect();
            format!("[{}]", cells.join(", "))
        })
        .collect();
    format!("[{}]", rows.join(", "))
}

fn band_text(b: Option<[f64; 2]>) -> String {
    b.map_or("-".into(), |[l, h]| {
        format!("[{}, {}]", sig(Some(l)), sig(Some(h)))
    })
}

fn interval_text(ci: Option<[Option<f64>; 2]>) -> String {
    ci.map_or("-".into(), |[l, h]| {
        format!(
            "[{}, {}]",
            l.map_or("beyond the grid".into(), |v| sig(Some(v))),
            h.map_or("inf".into(), |v| sig(Some(v)))
        )
    })
}

/// "the tuned filter's ANIS 1.02 is inside its 95% band [0.96, 1.04]", with the start beside
/// it.
fn anis_words(tuned: &FilterConsistency, start: Option<&FilterConsistency>) -> Option<String> {
    let anis = tuned.anis?;
    let place = |c: &FilterConsistency| match (c.anis_band, c.anis_consistent) {
        (Some(_), Some(true)) => "inside its 95% band",
        (Some(_), Some(false)) => "outside its 95% band",
        (None, Some(true)) => "consistent with 1 (t-test over the runs)",
        (None, Some(false)) => "not consistent with 1 (t-test over the runs)",
        _ => "beside its band",
    };
    let mut s = format!(
        "the tuned filter's ANIS {} is {}{}",
        sig(Some(anis)),
        place(tuned),
        tuned
            .anis_band
            .map_or(String::new(), |b| format!(" {}", band_text(Some(b))))
    );
    if let Some(a0) = start.and_then(|c| c.anis) {
        s.push_str(&format!(" (the starting guess's is {})", sig(Some(a0))));
    }
    Some(s)
}

/// The recommendation in one sentence.
fn recommendation(r: &NoiseReportFile) -> String {
    let mut parts = vec![format!(
        "use Q = {}, R = {}",
        matrix_text(&r.q),
        matrix_text(&r.r)
    )];
    let p = r.parameters.len();
    let id = &r.identifiable;
    // The J1/J2 point is no likelihood maximum: the information there says nothing of what
    // the data identify.
    let measured = if r.method == MethodKind::J1j2 {
        None
    } else {
        id.identifiable
    };
    match (measured, id.rank) {
        (Some(true), _) => parts.push(format!(
            "the data identify all {p} free parameter{}",
            if p == 1 { "" } else { "s" }
        )),
        (Some(false), Some(rank)) => parts.push(format!(
            "the data identify only {rank} combination(s) of the {p} free parameters ({})",
            if id.unidentifiable.is_empty() {
                id.message.clone()
            } else {
                format!("not: {}", id.unidentifiable.join("; "))
            }
        )),
        _ => {}
    }
    if let Some(t) = &r.consistency.tuned
        && let Some(w) = anis_words(t, r.consistency.start.as_ref())
    {
        parts.push(w);
    }
    if r.consistency
        .tuned
        .as_ref()
        .is_some_and(|t| t.anis_consistent == Some(false))
    {
        parts.push(
            "caution: the filter with this estimate fails its own consistency test on these \
             data"
                .to_string(),
        );
    }
    if !r.converged {
        parts.push(format!(
            "caution: {} did not converge in {} iterations",
            method_words(r.method),
            r.iterations
        ));
    }
    parts.join("; ")
}

/// A parameter's profile log-likelihood with the estimate, its 95% interval and the
/// likelihood-ratio threshold marked; on a log10 axis when it spans more than two decades of
/// a positive parameter.
fn profile_figure(r: &NoiseReportFile, index: usize) -> Option<(String, Figure)> {
    let param = r.parameters.get(index)?;
    let profile = param.profile.as_ref()?;
    let values: Vec<f64> = profile.points.iter().map(|p| p.0).collect();
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let log = lo > 0.0 && hi / lo > 100.0;
    let x = |v: f64| if log { v.log10() } else { v };
    let points: Vec<(f64, f64)> = profile
        .points
        .iter()
        .filter_map(|&(v, ll)| ll.map(|ll| (x(v), ll)))
        .collect();
    if points.len() < 2 {
        return None;
    }
    let x_label = if log {
        format!("log10 {}", param.name)
    } else {
        param.name.clone()
    };
    let mut fig = Figure::new(
        format!("Profile log-likelihood of {}", param.name),
        x_label,
        "log-likelihood",
    )
    .series(Series::line_markers("profile log-likelihood", points))
    .annotate(Annotation::HLine {
        y: profile.threshold,
        label: "95% level (max - 1.92)".into(),
    })
    .annotate(Annotation::Point {
        x: x(param.value),
        y: r.log_likelihood.unwrap_or(profile.threshold),
        label: format!("estimate {}", sig(Some(param.value))),
    });
    if let Some([l, h]) = param.ci95 {
        for (end, name) in [(l, "low"), (h, "high")] {
            if let Some(v) = end
                && (!log || v > 0.0)
                && v >= lo
                && v <= hi
            {
                fig = fig.annotate(Annotation::VLine {
                    x: x(v),
                    label: format!("95% {name} {}", sig(Some(v))),
                });
            }
        }
    }
    let file = format!("profile_{}.svg", slug(&param.name));
    Some((file, fig))
}

fn capitalise(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
        .unwrap_or_default()
}

/// A file-name-safe form of a parameter name: `Qw[1,0]` becomes `Qw_1_0`.
fn slug(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    s.trim_end_matches('_').to_string()
}

fn consistency_rows(
    tuned: Option<&FilterConsistency>,
    start: Option<&FilterConsistency>,
) -> Vec<Vec<String>> {
    let yes = |b: Option<bool>, y: &str, n: &str| match b {
        Some(true) => y.to_string(),
        Some(false) => n.to_string(),
        None => "-".to_string(),
    };
    let both = |f: &dyn Fn(&FilterConsistency) -> String| {
        vec![
            tuned.map_or("filter failed".into(), f),
            start.map_or("filter failed".into(), f),
        ]
    };
    let mut out = vec![
        [
            vec!["ANIS (mean NIS / m; 1 if consistent)".to_string()],
            both(&|c| fmt(c.anis)),
        ]
        .concat(),
        [
            vec!["ANIS test (95% band)".to_string()],
            both(&|c| {
                format!(
                    "{} ({})",
                    band_text(c.anis_band),
                    yes(c.anis_consistent, "consistent", "not consistent")
                )
            }),
        ]
        .concat(),
        [
            vec!["Innovation whiteness (Box-Pierce p)".to_string()],
            both(&|c| {
                format!(
                    "{} ({})",
                    fmt(c.whiteness_p_value),
                    yes(c.white, "white", "not white")
                )
            }),
        ]
        .concat(),
    ];
    if tuned.is_some_and(|t| t.anees.is_some() || t.rmse.is_some()) {
        out.push(
            [
                vec!["ANEES (with the truth)".to_string()],
                both(&|c| {
                    format!(
                        "{} in {} ({})",
                        fmt(c.anees),
                        band_text(c.anees_band),
                        yes(c.anees_consistent, "consistent", "not consistent")
                    )
                }),
            ]
            .concat(),
        );
        out.push([vec!["State RMSE".to_string()], both(&|c| fmt(c.rmse))].concat());
    }
    out
}

impl Document {
    /// The report of a noise estimate; `files` (MODEL.toml and the measurements) name the
    /// title when the estimate came from files.
    pub fn noise(files: Option<(&Path, &Path)>, r: &NoiseReportFile) -> Self {
        let title = match files {
            Some((model, measurements)) => format!(
                "kalibra tune --method {}: {} on {}",
                r.method.name(),
                file_name(model),
                file_name(measurements)
            ),
            None => format!("kalibra noise estimate ({})", r.method.name()),
        };
        let words = recommendation(r);
        let headline = format!("recommendation: {words}");
        let mut blocks = vec![
            Block::Heading(title.clone()),
            Block::Paragraph(Some(format!("Recommendation: {words}.")), String::new()),
        ];
        let mut estimate = format!("Q = {}", matrix_text(&r.q));
        if r.problem.channels != r.problem.state_dim || r.qw != r.q {
            estimate.push_str(&format!(" (G Qw G^T with Qw = {})", matrix_text(&r.qw)));
        }
        estimate.push_str(&format!(", R = {}.", matrix_text(&r.r)));
        blocks.push(Block::Paragraph(
            Some(format!("Estimate ({}):", method_words(r.method))),
            estimate,
        ));
        blocks.push(Block::Paragraph(
            Some("Starting guess:".into()),
            format!(
                "Q = {}, R = {}.",
                matrix_text(&r.start.q),
                matrix_text(&r.start.r)
            ),
        ));

        blocks.push(Block::Heading("Parameters".into()));
        let start_values = start_values(r);
        let rows = r
            .parameters
            .iter()
            .enumerate()
            .map(|(i, p)| {
                vec![
                    p.name.clone(),
                    sig(Some(p.value)),
                    sig(p.stderr),
                    interval_text(p.ci95),
                    p.profile
                        .as_ref()
                        .map_or("-".into(), |pr| interval_text(Some(pr.interval))),
                    sig(start_values.get(i).copied().flatten()),
                ]
            })
            .collect();
        blocks.push(Block::Table(
            vec![
                "parameter".into(),
                "estimate".into(),
                "std. error".into(),
                "95% interval".into(),
                "profile 95% interval".into(),
                "start".into(),
            ],
            rows,
        ));
        let id = &r.identifiable;
        let mut id_text = id.message.clone();
        if id_text.is_empty()
            && let Some(rank) = id.rank
        {
            id_text = format!(
                "rank {rank} of {} free parameters, condition number {}",
                id.parameters,
                id.condition.map_or("infinite".into(), |c| fmt(Some(c)))
            );
        }
        if r.method == MethodKind::J1j2 {
            id_text = "the J1/J2 crossover is no likelihood maximum, so it does not say what \
                       the data identify (use --method ml)"
                .to_string();
        }
        blocks.push(Block::Paragraph(
            Some("What the data identify:".into()),
            format!(
                "{id_text}; at most n m + m (m + 1) / 2 = {} parameters can be identified from \
                 innovations.",
                r.problem.identifiable_limit
            ),
        ));
        for w in &r.warnings {
            blocks.push(Block::Paragraph(Some("Warning:".into()), format!("{w}.")));
        }

        let c = &r.consistency;
        if c.tuned.is_some() || c.start.is_some() {
            blocks.push(Block::Heading("The filter on the data".into()));
            blocks.push(Block::Paragraph(
                None,
                format!(
                    "The {} run over the measurements with the estimate and with the \
                     starting guess: ANIS with its 95% chi-square band, and the whiteness of \
                     the normalised innovations (Box-Pierce test); with the truth, ANEES and \
                     the RMSE.",
                    filter_words(r.problem.filter.as_deref())
                ),
            ));
            blocks.push(Block::Table(
                vec![
                    "quantity".into(),
                    "tuned filter".into(),
                    "starting guess".into(),
                ],
                consistency_rows(c.tuned.as_ref(), c.start.as_ref()),
            ));
        }

        let mut figures = Vec::new();
        let profiles: Vec<_> = (0..r.parameters.len())
            .filter_map(|i| profile_figure(r, i))
            .collect();
        if !profiles.is_empty() || !r.curves.is_empty() {
            blocks.push(Block::Heading("Figures".into()));
        }
        if !profiles.is_empty() {
            blocks.push(Block::Paragraph(
                None,
                "The profile log-likelihood of each parameter (the others re-maximised at each \
                 point), the estimate and its 95% interval marked, and the level 1.92 below \
                 the maximum where a likelihood-ratio interval ends."
                    .into(),
            ));
            for (name, fig) in profiles {
                blocks.push(Block::Figure(figures.len()));
                figures.push((name, fig));
            }
        }
        for c in &r.curves {
            if c.points.is_empty() {
                continue;
            }
            let j1 = c.points.iter().map(|p| (p.p, p.j1)).collect();
            let j2 = c.points.iter().map(|p| (p.p, p.j2)).collect();
            let name = &c.parameter.name;
            let mut fig = Figure::new(
                format!("J1 and J2 of {name}"),
                format!("p ({name} times 10^p)"),
                "J",
            )
            .series(Series::line_markers("J1 (sensitivity)", j1))
            .series(Series::line_markers("J2 (robustness)", j2));
            if let Some(x) = &c.crossover {
                fig = fig.annotate(Annotation::VLine {
                    x: x.p,
                    label: format!("p_c = {}", fmt(Some(x.p))),
                });
            }
            blocks.push(Block::Figure(figures.len()));
            figures.push((format!("j1j2_{}.svg", slug(name)), fig));
        }

        blocks.push(Block::Heading("The estimate".into()));
        let pr = &r.problem;
        blocks.push(Block::Paragraph(
            None,
            format!(
                "{}: log-likelihood {} at the estimate, {} at the starting guess; {}, {} \
                 iteration(s). {} state(s), {} measurement(s), {} noise channel(s); {} run(s), \
                 {} steps, {} with a measurement; x0 {}.",
                capitalise(method_words(r.method)),
                fmt(r.log_likelihood),
                fmt(r.start.log_likelihood),
                if r.converged {
                    "converged"
                } else {
                    "not converged"
                },
                r.iterations,
                pr.state_dim,
                pr.meas_dim,
                pr.channels,
                pr.runs,
                pr.steps,
                pr.measurements,
                if pr.start == "update_first" {
                    "at the first measurement (update first)"
                } else {
                    "one step before the first measurement (predict first)"
                }
            ),
        ));
        blocks.push(Block::Paragraph(
            None,
            "Every number is in report.json at full precision (its schema_version says which \
             fields it holds)."
                .into(),
        ));
        Self::from_parts(title, headline, blocks, figures)
    }
}

/// Each parameter's value at the starting guess (a multiplier starts at 1).
fn start_values(r: &NoiseReportFile) -> Vec<Option<f64>> {
    r.parameters
        .iter()
        .map(|p| {
            if p.name == "q" || p.name == "r" {
                return Some(1.0);
            }
            let (m, rest) = if let Some(rest) = p.name.strip_prefix("Qw[") {
                (&r.start.qw, rest)
            } else if let Some(rest) = p.name.strip_prefix("R[") {
                (&r.start.r, rest)
            } else {
                return None;
            };
            let (i, j) = rest.trim_end_matches(']').split_once(',')?;
            let (i, j): (usize, usize) = (i.parse().ok()?, j.parse().ok()?);
            m.get(i).and_then(|row| row.get(j)).copied()
        })
        .collect()
}

/// The filter the report ran, in words: the Kalman filter for a linear model, the EKF or the
/// UKF (the one the likelihood was maximised through) for a nonlinear one.
fn filter_words(filter: Option<&str>) -> &'static str {
    match filter {
        Some("ekf") => "extended Kalman filter",
        Some("ukf") => "unscented Kalman filter",
        _ => "Kalman filter",
    }
}
