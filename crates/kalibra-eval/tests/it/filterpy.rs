//! A log written by an independent implementation: FilterPy's `KalmanFilter` over 40 runs of
//! 30 steps, with the consistency metrics computed by numpy in the same script
//! (`fixtures/filterpy/make_log.py`, run once; its output `log.json` is committed). The
//! filter's R is half the truth's, so every metric sits away from its consistent value and a
//! wrong normalisation (n vs m, runs vs runs - 1, natural vs decimal logarithm) would show.

use kalibra_eval::{Evaluation, FilterLog, Matrices, Vectors};
use serde_json::Value;

/// Flattens a nested JSON array of numbers in row-major (numpy C) order.
fn flat(value: &Value) -> Vec<f64> {
    match value {
        Value::Array(items) => items.iter().flat_map(flat).collect(),
        Value::Number(n) => vec![n.as_f64().expect("a finite number")],
        other => panic!("not a number or an array: {other}"),
    }
}

#[test]
fn report_equals_filterpy_and_numpy_to_1e_10() {
    let text = include_str!("../fixtures/filterpy/log.json");
    let log: Value = serde_json::from_str(text).unwrap();
    let runs = log["truth"].as_array().unwrap().len();
    let steps = log["truth"][0].as_array().unwrap().len();
    assert_eq!((runs, steps), (40, 30));
    let filter_log = FilterLog::new(runs, steps)
        .unwrap()
        .with_truth(Vectors::dense(4, flat(&log["truth"])))
        .unwrap()
        .with_estimate(Vectors::dense(4, flat(&log["estimate"])))
        .unwrap()
        .with_covariance(Matrices::dense(4, 4, flat(&log["covariance"])))
        .unwrap()
        .with_innovation(Vectors::dense(2, flat(&log["innovation"])))
        .unwrap()
        .with_innovation_cov(Matrices::dense(2, 2, flat(&log["innovation_cov"])))
        .unwrap();
    let report = Evaluation::new().evaluate(&filter_log).unwrap();

    let expected = &log["expected"];
    for (name, ours) in [
        ("anees_per_step", &report.anees_per_step),
        ("anis_per_step", &report.anis_per_step),
        ("nci_per_step", &report.nci_per_step),
    ] {
        let theirs = flat(&expected[name]);
        assert_eq!(ours.len(), theirs.len(), "{name}");
        for (k, (a, b)) in ours.iter().zip(&theirs).enumerate() {
            let a = a.unwrap_or_else(|| panic!("{name} missing at step {k}"));
            assert!(
                (a - b).abs() <= 1e-10 * b.abs().max(1.0),
                "{name} step {k}: kalibra {a}, FilterPy/numpy {b}"
            );
        }
    }
    // The filter is optimistic (R halved), and the report says so.
    assert_eq!(
        report.summary.verdict.kind,
        kalibra_eval::VerdictKind::Optimistic
    );
}
