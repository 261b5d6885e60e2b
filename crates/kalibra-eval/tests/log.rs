//! Validation errors of the log and the options, findings (NaN, asymmetric and indefinite
//! covariances) and the property that the report equals kalibra-metrics on the same arrays.

use kalibra_eval::{EvalError, Evaluation, FilterLog, Matrices, Reason, Vectors, VerdictKind};
use kalibra_linalg::{Covariance, DMatrix, DVector};
use kalibra_metrics::{nees, nis};
use proptest::prelude::*;

#[test]
fn shapes_are_checked_and_named() {
    let log = FilterLog::new(2, 3).unwrap();
    assert_eq!(FilterLog::new(0, 3), Err(EvalError::Empty { what: "runs" }));
    assert_eq!(
        log.clone().with_truth(Vectors::dense(2, vec![0.0; 11])),
        Err(EvalError::Shape {
            array: "truth",
            unit: "values",
            expected: 12,
            found: 11
        })
    );
    let mut cells = vec![Some(vec![0.0, 0.0]); 6];
    cells[4] = Some(vec![0.0]);
    assert_eq!(
        log.clone().with_estimate(Vectors::cells(2, cells)),
        Err(EvalError::CellLength {
            array: "estimate",
            run: 1,
            step: 1,
            expected: 2,
            found: 1
        })
    );
    let with_truth = log
        .clone()
        .with_truth(Vectors::dense(2, vec![0.0; 12]))
        .unwrap();
    assert_eq!(
        with_truth
            .clone()
            .with_covariance(Matrices::constant(3, 3, vec![0.0; 9])),
        Err(EvalError::Mismatch {
            array: "covariance",
            what: "state dimension",
            expected: 2,
            found: 3
        })
    );
    assert!(matches!(
        with_truth
            .clone()
            .with_covariance(Matrices::per_step(2, 3, vec![0.0; 18])),
        Err(EvalError::Mismatch {
            array: "covariance",
            ..
        })
    ));
    let mut truth = vec![0.0; 12];
    truth[9] = f64::NAN;
    assert_eq!(
        log.clone().with_truth(Vectors::dense(2, truth)),
        Err(EvalError::NonFinite {
            array: "truth",
            run: 1,
            step: 1
        })
    );
    assert_eq!(
        log.clone().with_times(vec![0.0, 1.0, 1.0]),
        Err(EvalError::TimesNotIncreasing { step: 2 })
    );
    assert!(matches!(
        log.clone()
            .with_innovation_cov(Matrices::cells(1, 1, vec![None; 5])),
        Err(EvalError::Shape {
            array: "innovation_cov",
            unit: "cells",
            ..
        })
    ));
    let f = || Matrices::constant(2, 2, vec![1.0, 0.0, 0.0, 1.0]);
    assert!(matches!(
        with_truth.with_model(
            f(),
            Matrices::constant(1, 3, vec![1.0, 0.0, 0.0]),
            f(),
            Matrices::constant(1, 1, vec![1.0])
        ),
        Err(EvalError::Mismatch { array: "H", .. })
    ));
    assert_eq!(
        Evaluation::new().evaluate(&log),
        Err(EvalError::NothingToEvaluate)
    );
}

#[test]
fn options_are_checked() {
    assert!(matches!(
        Evaluation::new().confidence(1.0),
        Err(EvalError::InvalidOption {
            name: "confidence",
            ..
        })
    ));
    assert!(Evaluation::new().window(1).is_err());
    assert!(Evaluation::new().lags(0).is_err());
    assert!(Evaluation::new().group("empty", vec![]).is_err());
    let log = FilterLog::new(1, 2)
        .unwrap()
        .with_truth(Vectors::dense(1, vec![0.0, 0.0]))
        .unwrap()
        .with_estimate(Vectors::dense(1, vec![0.0, 0.0]))
        .unwrap()
        .with_covariance(Matrices::constant(1, 1, vec![1.0]))
        .unwrap();
    assert_eq!(
        Evaluation::new()
            .group("pos", vec![0, 1])
            .unwrap()
            .evaluate(&log),
        Err(EvalError::GroupIndex {
            group: "pos".into(),
            index: 1,
            dim: 1
        })
    );
    assert!(Evaluation::new().diagnostic_run(1).evaluate(&log).is_err());
}

#[test]
fn bad_covariances_are_counted_named_and_left_out() {
    // Three runs, two steps, n = 2; errors (1, 1) everywhere and P = I, so NEES = 2.
    let good = vec![1.0, 0.0, 0.0, 1.0];
    let mut cells = vec![Some(good.clone()); 6];
    cells[3] = Some(vec![1.0, 0.5, 0.0, 1.0]); // run 1, step 1: asymmetric
    cells[4] = Some(vec![f64::NAN, 0.0, 0.0, 1.0]); // run 2, step 0: NaN
    cells[5] = Some(vec![1.0, 2.0, 2.0, 1.0]); // run 2, step 1: indefinite
    let log = FilterLog::new(3, 2)
        .unwrap()
        .with_truth(Vectors::dense(2, vec![0.0; 12]))
        .unwrap()
        .with_estimate(Vectors::dense(2, vec![1.0; 12]))
        .unwrap()
        .with_covariance(Matrices::cells(2, 2, cells))
        .unwrap();
    let r = Evaluation::new().evaluate(&log).unwrap();
    let f = &r.findings.state;
    assert_eq!((f.cells, f.steps), (3, 2));
    assert_eq!(
        (f.non_finite, f.not_symmetric, f.not_positive_definite),
        (1, 1, 1)
    );
    let first = f.first.as_ref().unwrap();
    assert_eq!(
        (first.array.as_str(), first.run, first.step, first.reason),
        ("covariance", 1, 1, Reason::NotSymmetric)
    );
    // Left out of ANEES (every valid cell has NEES / n = 1), not of the RMSE.
    assert_eq!(r.nees_runs_per_step, vec![2, 1]);
    assert_eq!(r.anees_per_step, vec![Some(1.0), Some(1.0)]);
    assert_eq!(r.rmse_per_step[0].values, vec![Some(1.0), Some(1.0)]);
    assert!(r.summary.verdict.evidence.contains("3 cells left out"));
    // Exactly 1 in every run: no spread, so the chi-square fallback decides.
    assert_eq!(r.summary.verdict.kind, VerdictKind::Consistent);
}

/// A random positive definite matrix `L L^T + 0.1 I`.
fn spd(dim: usize) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-2.0..2.0f64, dim * dim).prop_map(move |l| {
        let l = DMatrix::from_row_slice(dim, dim, &l);
        let p = &l * l.transpose() + DMatrix::identity(dim, dim) * 0.1;
        (0..dim)
            .flat_map(|i| (0..dim).map(move |j| (i, j)))
            .map(|(i, j)| p[(i, j)])
            .collect()
    })
}

fn cells(count: usize, cell: impl Strategy<Value = Vec<f64>>) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(cell, count).prop_map(|c| c.concat())
}

#[derive(Debug, Clone)]
struct Arrays {
    runs: usize,
    steps: usize,
    n: usize,
    m: usize,
    truth: Vec<f64>,
    estimate: Vec<f64>,
    cov: Vec<f64>,
    innovation: Vec<f64>,
    s: Vec<f64>,
}

fn arrays() -> impl Strategy<Value = Arrays> {
    (1usize..4, 1usize..6, 1usize..4, 1usize..3).prop_flat_map(|(runs, steps, n, m)| {
        let c = runs * steps;
        (
            cells(c, prop::collection::vec(-5.0..5.0f64, n)),
            cells(c, prop::collection::vec(-5.0..5.0f64, n)),
            cells(c, spd(n)),
            cells(c, prop::collection::vec(-5.0..5.0f64, m)),
            cells(c, spd(m)),
        )
            .prop_map(move |(truth, estimate, cov, innovation, s)| Arrays {
                runs,
                steps,
                n,
                m,
                truth,
                estimate,
                cov,
                innovation,
                s,
            })
    })
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * b.abs().max(1.0)
}

proptest! {
    #[test]
    fn report_equals_the_metrics_on_the_same_arrays(a in arrays()) {
        let log = FilterLog::new(a.runs, a.steps).unwrap()
            .with_truth(Vectors::dense(a.n, a.truth.clone())).unwrap()
            .with_estimate(Vectors::dense(a.n, a.estimate.clone())).unwrap()
            .with_covariance(Matrices::dense(a.n, a.n, a.cov.clone())).unwrap()
            .with_innovation(Vectors::dense(a.m, a.innovation.clone())).unwrap()
            .with_innovation_cov(Matrices::dense(a.m, a.m, a.s.clone())).unwrap();
        let r = Evaluation::new().evaluate(&log).unwrap();
        prop_assert_eq!(r.findings.state.cells + r.findings.innovation.cells, 0);
        let (n, m) = (a.n, a.m);
        let (mut all_nees, mut all_nis) = (0.0, 0.0);
        for k in 0..a.steps {
            let (mut sum_nees, mut sum_nis) = (0.0, 0.0);
            let mut sq = vec![0.0; n];
            for run in 0..a.runs {
                let c = run * a.steps + k;
                let x = DVector::from_column_slice(&a.truth[c * n..(c + 1) * n]);
                let xhat = DVector::from_column_slice(&a.estimate[c * n..(c + 1) * n]);
                let p = DMatrix::from_row_slice(n, n, &a.cov[c * n * n..(c + 1) * n * n]);
                let e = &x - &xhat;
                sum_nees += nees(&e, &p).unwrap();
                for (s, e) in sq.iter_mut().zip(e.iter()) {
                    *s += e * e;
                }
                let nu = DVector::from_column_slice(&a.innovation[c * m..(c + 1) * m]);
                let s = Covariance::new(DMatrix::from_row_slice(m, m, &a.s[c * m * m..(c + 1) * m * m])).unwrap();
                sum_nis += nis(&nu, &s).unwrap();
            }
            all_nees += sum_nees;
            all_nis += sum_nis;
            let runs = a.runs as f64;
            prop_assert!(close(r.anees_per_step[k].unwrap(), sum_nees / runs / n as f64));
            prop_assert!(close(r.anis_per_step[k].unwrap(), sum_nis / runs / m as f64));
            for (series, sq) in r.rmse_per_step.iter().zip(&sq) {
                prop_assert!(close(series.values[k].unwrap(), (sq / runs).sqrt()));
            }
        }
        let cells = (a.runs * a.steps) as f64;
        prop_assert!(close(r.summary.anees.unwrap(), all_nees / cells / n as f64));
        prop_assert!(close(r.summary.anis.unwrap(), all_nis / cells / m as f64));
    }
}
