//! Validation errors of the log and the options, and findings (NaN, asymmetric and
//! indefinite covariances). The property that the report equals kalibra-metrics on the same
//! arrays is in `report_equals_metrics.rs`.

use kalibra_eval::{EvalError, Evaluation, FilterLog, Matrices, Reason, Vectors, VerdictKind};

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

/// Arrays read in place with the NaN rule (`nan_unlogged`, borrowed) give the report of the
/// same cells given one by one with `None` where every value is NaN; a truth partly NaN is
/// the same error, at the first such cell run after run.
#[test]
fn borrowed_arrays_with_nan_cells_equal_the_cells_given_one_by_one() {
    let (runs, steps, n, m) = (3, 40, 2, 1);
    let cells = runs * steps;
    let value = |i: usize, j: usize| ((i * 7 + j * 3) % 11) as f64 / 5.0 - 1.0;
    let truth: Vec<f64> = (0..cells * n).map(|i| value(i, 1)).collect();
    let mut estimate: Vec<f64> = (0..cells * n).map(|i| value(i, 2)).collect();
    let mut covariance = Vec::new();
    for i in 0..cells {
        covariance.extend([1.0 + value(i, 3).abs(), 0.1, 0.1, 2.0]);
    }
    let mut innovation: Vec<f64> = (0..cells * m).map(|i| value(i, 4)).collect();
    let mut s = vec![1.5; cells * m * m];
    // Unlogged cells (all NaN), and cells only partly NaN (kept: a finding).
    estimate[2 * 5..2 * 5 + 2].fill(f64::NAN);
    covariance[4 * 9..4 * 9 + 4].fill(f64::NAN);
    covariance[4 * 17] = f64::NAN;
    innovation[33] = f64::NAN;
    s[50] = f64::NAN;
    estimate[2 * 61] = f64::NAN;
    let split = |v: &[f64], w: usize| -> Vec<Option<Vec<f64>>> {
        v.chunks(w)
            .map(|c| (!c.iter().all(|x| x.is_nan())).then(|| c.to_vec()))
            .collect()
    };
    let borrowed = FilterLog::new(runs, steps)
        .and_then(|l| l.with_truth(Vectors::nan_unlogged(n, &truth[..])))
        .and_then(|l| l.with_estimate(Vectors::nan_unlogged(n, &estimate[..])))
        .and_then(|l| l.with_covariance(Matrices::nan_unlogged(n, n, &covariance[..])))
        .and_then(|l| l.with_innovation(Vectors::nan_unlogged(m, &innovation[..])))
        .and_then(|l| l.with_innovation_cov(Matrices::nan_unlogged(m, m, &s[..])))
        .unwrap();
    let given = FilterLog::new(runs, steps)
        .and_then(|l| l.with_truth(Vectors::cells(n, split(&truth, n))))
        .and_then(|l| l.with_estimate(Vectors::cells(n, split(&estimate, n))))
        .and_then(|l| l.with_covariance(Matrices::cells(n, n, split(&covariance, n * n))))
        .and_then(|l| l.with_innovation(Vectors::cells(m, split(&innovation, m))))
        .and_then(|l| l.with_innovation_cov(Matrices::cells(m, m, split(&s, m * m))))
        .unwrap();
    for run in 0..runs {
        for step in 0..steps {
            // As text: a NaN is not equal to itself.
            let (a, b) = (borrowed.cell(run, step), given.cell(run, step));
            assert_eq!(format!("{a:?}"), format!("{b:?}"));
        }
    }
    assert!(borrowed.cell(0, 5).estimate.is_none());
    assert!(borrowed.cell(0, 17).covariance.is_some());
    let evaluation = Evaluation::new().lags(3).unwrap();
    let (a, b) = (
        evaluation.evaluate(&borrowed).unwrap(),
        evaluation.evaluate(&given).unwrap(),
    );
    assert_eq!(a, b);
    // Cell 17's covariance and cell 61's estimate, partly NaN; cells 5 and 9 were not logged.
    assert_eq!(a.findings.state.cells, 2);
    assert_eq!((a.nees_runs_per_step[5], a.nees_runs_per_step[9]), (2, 2));
    // A truth partly NaN is an error, a truth all NaN at a cell is not logged.
    let mut bad = truth.clone();
    bad[2 * 70..2 * 70 + 2].fill(f64::NAN);
    bad[2 * 90] = f64::NAN;
    bad[2 * 100 + 1] = f64::INFINITY;
    assert_eq!(
        FilterLog::new(runs, steps).and_then(|l| l.with_truth(Vectors::nan_unlogged(n, &bad[..]))),
        Err(EvalError::NonFinite {
            array: "truth",
            run: 2,
            step: 10
        })
    );
}
