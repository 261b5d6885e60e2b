//! The report of a log equals kalibra-metrics' own
//! functions on the same arrays. Random small logs (1 to 5 runs, 1 to 20 steps, n of 1 to 3,
//! m of 1 or 2, random positive definite covariances, each cell of each array missing at
//! random) are evaluated, and every per-step series, band, window and headline number is
//! recomputed here from `nees`, `nis`, `Credibility`, `SquaredErrors`, `rmse`,
//! `sliding_window` and `ChiSquareBand::for_normalized_mean`, deciding which cells enter
//! which statistic from the definitions in the crate documentation.
//!
//! Tolerance: counts, presence (`Some`/`None`) and the chi-square bands (the same function of
//! the same arguments) are compared exactly; every other number to 1e-12 relative to the
//! larger magnitude (absolute below 1). The report may sum in another order than this test
//! (per run, then over runs; `NEES / n` before or after the sum), which moves the last bits
//! of a mean of at most 100 terms by a few ulps, far below 1e-12; a wrong cell in or out of a
//! statistic moves it by far more.

use kalibra_eval::{Band, Evaluation, FilterLog, Matrices, Report, Vectors};
use kalibra_linalg::{Covariance, DMatrix, DVector};
use kalibra_metrics::{ChiSquareBand, Credibility, SquaredErrors, nees, nis, rmse, sliding_window};
use proptest::prelude::*;

/// A random positive definite matrix `L L^T + 0.1 I`, row by row.
fn spd(dim: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-2.0..2.0f64, dim * dim).prop_map(move |l| {
        let l = DMatrix::from_row_slice(dim, dim, &l);
        let p = &l * l.transpose() + DMatrix::identity(dim, dim) * 0.1;
        p.transpose().as_slice().to_vec()
    })
}

/// `count` cells, each present with probability 0.8.
fn cells(
    count: usize,
    cell: impl Strategy<Value = Vec<f64>>,
) -> impl Strategy<Value = Vec<Option<Vec<f64>>>> {
    prop::collection::vec(prop::option::weighted(0.8, cell), count)
}

/// A log's arrays, one entry per cell in run-major order, and the evaluation's options.
#[derive(Debug, Clone)]
struct Case {
    runs: usize,
    steps: usize,
    n: usize,
    m: usize,
    truth: Vec<Option<Vec<f64>>>,
    estimate: Vec<Option<Vec<f64>>>,
    cov: Vec<Option<Vec<f64>>>,
    innovation: Vec<Option<Vec<f64>>>,
    s: Vec<Option<Vec<f64>>>,
    confidence: f64,
    window: Option<usize>,
}

fn cases() -> impl Strategy<Value = Case> {
    (1usize..=5, 1usize..=20, 1usize..=3, 1usize..=2).prop_flat_map(|(runs, steps, n, m)| {
        let c = runs * steps;
        let vectors = |dim| cells(c, prop::collection::vec(-5.0..5.0f64, dim));
        (
            (vectors(n), vectors(n), cells(c, spd(n))),
            (vectors(m), cells(c, spd(m))),
            0.5..0.999f64,
            prop::option::of(2usize..8),
        )
            .prop_map(
                move |((truth, estimate, cov), (innovation, s), confidence, window)| Case {
                    runs,
                    steps,
                    n,
                    m,
                    truth,
                    estimate,
                    cov,
                    innovation,
                    s,
                    confidence,
                    window,
                },
            )
    })
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0)
}

/// Both absent, or both present and close.
fn close_opt(a: Option<f64>, b: Option<f64>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => close(a, b),
        _ => false,
    }
}

fn close_all(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(a, b)| close(*a, *b))
}

fn evaluate(c: &Case) -> Report {
    let log = FilterLog::new(c.runs, c.steps)
        .unwrap()
        .with_truth(Vectors::cells(c.n, c.truth.clone()))
        .unwrap()
        .with_estimate(Vectors::cells(c.n, c.estimate.clone()))
        .unwrap()
        .with_covariance(Matrices::cells(c.n, c.n, c.cov.clone()))
        .unwrap()
        .with_innovation(Vectors::cells(c.m, c.innovation.clone()))
        .unwrap()
        .with_innovation_cov(Matrices::cells(c.m, c.m, c.s.clone()))
        .unwrap();
    let mut evaluation = Evaluation::new()
        .confidence(c.confidence)
        .unwrap()
        .group("all", (0..c.n).collect())
        .unwrap();
    if let Some(w) = c.window {
        evaluation = evaluation.window(w).unwrap();
    }
    evaluation.evaluate(&log).unwrap()
}

/// Per step, the mean of the values pushed there divided by `dof`, their count and the band
/// of that many samples; and over all steps, the mean of every value divided by `dof`.
struct Normalised {
    per_step: Vec<Option<f64>>,
    counts: Vec<usize>,
    bands: Vec<Option<Band>>,
    overall: Option<f64>,
}

fn normalised(values: &[Vec<f64>], dof: usize, confidence: f64) -> Normalised {
    let d = dof as f64;
    let band = |samples| {
        let b = ChiSquareBand::for_normalized_mean(d, samples, confidence).unwrap();
        Band {
            lower: b.lower,
            upper: b.upper,
        }
    };
    let all: Vec<f64> = values.iter().flatten().copied().collect();
    Normalised {
        per_step: values
            .iter()
            .map(|v| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64 / d))
            .collect(),
        counts: values.iter().map(Vec::len).collect(),
        bands: values
            .iter()
            .map(|v| (!v.is_empty()).then(|| band(v.len())))
            .collect(),
        overall: (!all.is_empty()).then(|| all.iter().sum::<f64>() / all.len() as f64 / d),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn report_equals_the_metrics_on_the_same_arrays(c in cases()) {
        let r = evaluate(&c);
        let (n, m, steps) = (c.n, c.m, c.steps);
        prop_assert_eq!(r.findings.state.cells + r.findings.innovation.cells, 0);

        // The state side: a cell with truth and estimate enters the RMSE (and, in run 0, the
        // windows); with its covariance too, NEES and NCI.
        let mut nees_values = vec![Vec::new(); steps];
        let mut squared = SquaredErrors::new(steps, n);
        let mut credibility = Credibility::new(steps, n);
        let mut run0_errors: Vec<(usize, DVector<f64>)> = Vec::new();
        // The innovation side: innovation and its covariance give NIS.
        let mut nis_values = vec![Vec::new(); steps];
        for run in 0..c.runs {
            for k in 0..steps {
                let cell = run * steps + k;
                if let (Some(x), Some(xhat)) = (&c.truth[cell], &c.estimate[cell]) {
                    let e = DVector::from_column_slice(xhat) - DVector::from_column_slice(x);
                    squared.push_slice(k, e.as_slice()).unwrap();
                    if run == 0 {
                        run0_errors.push((k, e.clone()));
                    }
                    if let Some(p) = &c.cov[cell] {
                        let p = DMatrix::from_row_slice(n, n, p);
                        nees_values[k].push(nees(&e, &p).unwrap());
                        credibility.push(k, &e, &p).unwrap();
                    }
                }
                if let (Some(nu), Some(s)) = (&c.innovation[cell], &c.s[cell]) {
                    let s = Covariance::new(DMatrix::from_row_slice(m, m, s)).unwrap();
                    nis_values[k].push(nis(&DVector::from_column_slice(nu), &s).unwrap());
                }
            }
        }

        let anees = normalised(&nees_values, n, c.confidence);
        prop_assert_eq!(&r.nees_runs_per_step, &anees.counts);
        prop_assert_eq!(&r.anees_band, &anees.bands);
        for k in 0..steps {
            prop_assert!(close_opt(r.anees_per_step[k], anees.per_step[k]), "anees, step {}", k);
        }
        prop_assert!(close_opt(r.summary.anees, anees.overall));
        let anis = normalised(&nis_values, m, c.confidence);
        prop_assert_eq!(&r.nis_runs_per_step, &anis.counts);
        prop_assert_eq!(&r.anis_band, &anis.bands);
        for k in 0..steps {
            prop_assert!(close_opt(r.anis_per_step[k], anis.per_step[k]), "anis, step {}", k);
        }
        prop_assert!(close_opt(r.summary.anis, anis.overall));

        // NCI at the steps with at least two runs, for a log of at least two runs.
        if c.runs >= 2 {
            let nci: Vec<Option<f64>> = (0..steps)
                .map(|k| {
                    (credibility.runs(k) >= 2)
                        .then(|| credibility.step_summary(k).unwrap().nci)
                        .filter(|v| v.is_finite())
                })
                .collect();
            prop_assert_eq!(r.nci_per_step.len(), steps);
            for (k, (&a, &b)) in r.nci_per_step.iter().zip(&nci).enumerate() {
                prop_assert!(close_opt(a, b), "nci, step {}", k);
            }
            let present: Vec<f64> = nci.iter().flatten().copied().collect();
            let mean = (!present.is_empty())
                .then(|| present.iter().sum::<f64>() / present.len() as f64);
            prop_assert!(close_opt(r.summary.nci, mean));
        } else {
            prop_assert!(r.nci_per_step.is_empty() && r.summary.nci.is_none());
        }

        // RMSE per component, then the group of all components.
        let groups: Vec<Vec<usize>> =
            (0..n).map(|i| vec![i]).chain(std::iter::once((0..n).collect())).collect();
        prop_assert_eq!(r.rmse_per_step.len(), groups.len());
        for (series, group) in r.rmse_per_step.iter().zip(&groups) {
            prop_assert_eq!(&series.components, group);
            let values: Vec<Option<f64>> = (0..steps)
                .map(|k| squared.rmse_group(k, group).ok().filter(|v| v.is_finite()))
                .collect();
            prop_assert_eq!(series.values.len(), steps);
            for (k, (&a, &b)) in series.values.iter().zip(&values).enumerate() {
                prop_assert!(close_opt(a, b), "rmse, step {}", k);
            }
            let present: Vec<f64> = values.iter().flatten().copied().collect();
            let over_time = (!present.is_empty()).then(|| rmse(&present).unwrap());
            prop_assert!(close_opt(series.over_time, over_time));
        }

        // Sliding windows over run 0's errors, counted in samples.
        let window = c.window.unwrap_or((steps / 10).max(2));
        match &r.window {
            None => prop_assert!(run0_errors.len() < window),
            Some(w) => {
                prop_assert!(run0_errors.len() >= window);
                prop_assert_eq!((w.run, w.window), (0, window));
                let starts: Vec<usize> =
                    run0_errors[..=run0_errors.len() - window].iter().map(|(k, _)| *k).collect();
                prop_assert_eq!(&w.start_steps, &starts);
                prop_assert_eq!(w.components.len(), n);
                for (i, component) in w.components.iter().enumerate() {
                    let series: Vec<f64> = run0_errors.iter().map(|(_, e)| e[i]).collect();
                    let expected = sliding_window(&series, window).unwrap();
                    prop_assert_eq!(component.component, i);
                    prop_assert!(close_all(&component.rmse, &expected.rmse));
                    prop_assert!(close_all(&component.bias, &expected.bias));
                    prop_assert!(close_all(&component.std, &expected.std));
                }
            }
        }
    }
}
