//! EM against pykalman 0.11.2's `KalmanFilter.em` with unconstrained `Q` and `R`, from the
//! fixture `fixtures/make_pykalman_em.py` wrote (run once; its JSON output is committed, so the
//! test needs no Python): `Q`, `R` after each of ten iterations and the log-likelihood of the
//! starting point and every iterate, to 1e-9 relative.

use kalibra_tune::{CovarianceForm, DMatrix, DVector, Em, NoiseProblem, Parametrisation, Start};
use serde_json::Value;

const TOLERANCE: f64 = 1e-9;

fn fixture() -> Value {
    let path = format!(
        "{}/tests/fixtures/pykalman_em.json",
        env!("CARGO_MANIFEST_DIR")
    );
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn vector(v: &Value) -> DVector<f64> {
    let a = v.as_array().unwrap();
    DVector::from_iterator(a.len(), a.iter().map(|x| x.as_f64().unwrap()))
}

fn matrix(v: &Value) -> DMatrix<f64> {
    let rows: Vec<DVector<f64>> = v.as_array().unwrap().iter().map(vector).collect();
    DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
}

/// `|a - b|` over the largest magnitude of `b`'s entries.
fn relative(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax()
}

#[test]
fn em_matches_pykalman_iteration_by_iteration() {
    let fx = fixture();
    let noise = Parametrisation::new(
        None,
        CovarianceForm::full(matrix(&fx["q_start"])),
        CovarianceForm::full(matrix(&fx["r_start"])),
    )
    .unwrap();
    let run: Vec<Option<DVector<f64>>> = fx["z"]
        .as_array()
        .unwrap()
        .iter()
        .map(|z| (!z.is_null()).then(|| vector(z)))
        .collect();
    assert!(run.iter().any(Option::is_none), "the fixture has gaps");
    // pykalman's initial state is the prior at the first observation: update first.
    let problem = NoiseProblem::new(
        matrix(&fx["f"]),
        matrix(&fx["h"]),
        vector(&fx["x0"]),
        matrix(&fx["p0"]),
        Start::UpdateFirst,
        noise,
        vec![run],
    )
    .unwrap();
    let expected_ll: Vec<f64> = fx["log_likelihood"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let qs = fx["q"].as_array().unwrap();
    let rs = fx["r"].as_array().unwrap();
    for (i, (q, r)) in qs.iter().zip(rs).enumerate() {
        let fit = Em::new()
            .exact_iterations(i + 1)
            .estimate(&problem)
            .unwrap();
        assert_eq!(fit.iterations, i + 1);
        let (dq, dr) = (
            relative(&fit.matrices.q, &matrix(q)),
            relative(&fit.matrices.r, &matrix(r)),
        );
        assert!(
            dq < TOLERANCE && dr < TOLERANCE,
            "iteration {}: Q {dq:e}, R {dr:e}",
            i + 1
        );
        assert_eq!(fit.log_likelihood.len(), i + 2);
        for (k, (ours, theirs)) in fit.log_likelihood.iter().zip(&expected_ll).enumerate() {
            let d = (ours - theirs).abs() / theirs.abs();
            assert!(
                d < TOLERANCE,
                "log-likelihood after {k} iterations: {ours} vs {theirs}"
            );
        }
    }
}
