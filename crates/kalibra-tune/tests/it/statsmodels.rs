//! Maximum likelihood against statsmodels 0.15 (`MLEModel` with `initialization="known"`) on
//! the committed fixture written by `tests/fixtures/make_statsmodels.py`: a constant-velocity
//! target with noise through `G`, a scaled `Qw` and a full `R`, three steps missing.

use kalibra_tune::{
    CovarianceForm, DMatrix, DVector, MaximumLikelihood, NoiseProblem, Parametrisation, Start,
    log_likelihood,
};
use serde_json::Value;

fn fixture() -> Value {
    let text = include_str!("../fixtures/statsmodels.json");
    serde_json::from_str(text).unwrap()
}

fn matrix(v: &Value) -> DMatrix<f64> {
    let rows: Vec<Vec<f64>> = serde_json::from_value(v.clone()).unwrap();
    DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
}

fn vector(v: &Value) -> DVector<f64> {
    let values: Vec<f64> = serde_json::from_value(v.clone()).unwrap();
    DVector::from_vec(values)
}

fn problem(fx: &Value) -> NoiseProblem {
    let noise = Parametrisation::new(
        Some(matrix(&fx["G"])),
        CovarianceForm::scaled(DMatrix::identity(1, 1)),
        CovarianceForm::full(DMatrix::identity(2, 2)),
    )
    .unwrap();
    let run = fx["measurements"]
        .as_array()
        .unwrap()
        .iter()
        .map(|z| (!z.is_null()).then(|| vector(z)))
        .collect();
    NoiseProblem::new(
        matrix(&fx["F"]),
        matrix(&fx["H"]),
        vector(&fx["x0"]),
        matrix(&fx["P0"]),
        Start::UpdateFirst,
        noise,
        vec![run],
    )
    .unwrap()
}

/// `theta` of statsmodels' natural parameters `[q, R00, R10, R11]`.
fn theta_of(problem: &NoiseProblem, p: &[f64]) -> DVector<f64> {
    let qw = DMatrix::from_element(1, 1, p[0]);
    let r = DMatrix::from_row_slice(2, 2, &[p[1], p[2], p[2], p[3]]);
    problem.noise().theta_of(&qw, &r).unwrap()
}

#[test]
fn log_likelihood_equals_statsmodels_loglike() {
    let fx = fixture();
    let problem = problem(&fx);
    for point in fx["loglike_at"].as_array().unwrap() {
        let params: Vec<f64> = serde_json::from_value(point["params"].clone()).unwrap();
        let expected = point["loglike"].as_f64().unwrap();
        let ours = log_likelihood(&problem, theta_of(&problem, &params).as_slice()).unwrap();
        assert!(
            (ours - expected).abs() <= 1e-9 * expected.abs(),
            "at {params:?}: kalibra {ours}, statsmodels {expected}"
        );
    }
}

/// Both optimisers stop where their gradients are small, not at the exact maximum: with the
/// gradient of `-ln L / N` below `1e-8` (kalibra) and statsmodels' `pgtol 1e-10`, the
/// log-likelihoods differ by about `N^2 g^2 / (2 lambda_min)`, far below `1e-6`, and a parameter
/// by about `sqrt(2 dl / I_ii)`: with `se(q) = 0.05`, `dl = 1e-8` gives `7e-6` absolute,
/// `2e-5` of `q`. The tolerance, `1e-4` relative, is five times that.
#[test]
fn ml_estimate_equals_statsmodels_fit() {
    let fx = fixture();
    let problem = problem(&fx);
    let est = MaximumLikelihood::new().estimate(&problem).unwrap();
    let fit = &fx["fit"];
    assert!(fit["converged"].as_bool().unwrap());
    assert!(est.converged, "{:?}", est.warnings);
    let expected: Vec<f64> = serde_json::from_value(fit["params"].clone()).unwrap();
    let names: Vec<&str> = est
        .parameters
        .iter()
        .map(|p| p.parameter.name.as_str())
        .collect();
    assert_eq!(names, ["q", "R[0,0]", "R[1,0]", "R[1,1]"]);
    for (p, e) in est.parameters.iter().zip(&expected) {
        assert!(
            (p.value - e).abs() <= 1e-4 * e.abs(),
            "{}: kalibra {}, statsmodels {e}",
            p.parameter.name,
            p.value
        );
    }
    let llf = fit["loglike"].as_f64().unwrap();
    assert!(
        (est.log_likelihood - llf).abs() < 1e-6,
        "kalibra {}, statsmodels {llf}",
        est.log_likelihood
    );
    // The observed information's standard errors beside statsmodels' (its `bse_approx` come from a
    // numerical Hessian of its own, on the natural scale): the same to 1e-3.
    let bse: Vec<f64> = serde_json::from_value(fit["bse_approx"].clone()).unwrap();
    for (p, b) in est.parameters.iter().zip(&bse) {
        let se = p.stderr.unwrap();
        assert!(
            (se - b).abs() < 1e-3 * b,
            "{}: se {se} vs bse {b}",
            p.parameter.name
        );
        let [lo, hi] = p.ci95.unwrap();
        assert!(lo < p.value && p.value < hi);
    }
    let id = est.identifiability.unwrap();
    assert!(id.identifiable, "{}", id.message);
    assert_eq!(id.rank, 4);
}
