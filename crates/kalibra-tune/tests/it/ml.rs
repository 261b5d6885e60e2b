//! Maximum likelihood on simulated logs: coverage of the 95% intervals, what the data cannot
//! identify named in words, a parameter at its bound, and the typed errors.

use kalibra_tune::{
    Bound, CovarianceForm, DMatrix, DVector, MaximumLikelihood, MlError, MlWarning, NoiseProblem,
    Parametrisation, Run, Start,
};
use rand::RngExt;
use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};
use rand_distr::StandardNormal;

fn one(v: f64) -> DMatrix<f64> {
    DMatrix::from_element(1, 1, v)
}

/// A scalar random walk `x_k = x_{k-1} + w`, `z_k = x_k + v`, `x_0 = 0` known.
fn random_walk(q: f64, r: f64, steps: usize, seed: u64) -> Run {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut x = 0.0;
    (0..steps)
        .map(|_| {
            let w: f64 = rng.sample(StandardNormal);
            let v: f64 = rng.sample(StandardNormal);
            x += q.sqrt() * w;
            Some(DVector::from_element(1, x + r.sqrt() * v))
        })
        .collect()
}

fn scaled_walk(run: Run) -> NoiseProblem {
    let noise = Parametrisation::new(
        None,
        CovarianceForm::scaled(one(1.0)),
        CovarianceForm::scaled(one(1.0)),
    )
    .unwrap();
    NoiseProblem::new(
        one(1.0),
        one(1.0),
        DVector::zeros(1),
        one(0.0),
        Start::PredictFirst,
        noise,
        vec![run],
    )
    .unwrap()
}

/// Over 100 seeded logs of 150 steps (true q = 0.5, r = 1), the 95% intervals of q and r each
/// cover the truth in 90 to 99 of them. For exact 95% intervals the count is Binomial(100,
/// 0.95), outside 90..=99 with probability 1.2% (P(X <= 89) = 0.6%, P(X = 100) = 0.6%); the
/// seeds are fixed, so the test's outcome is fixed too.
#[test]
#[allow(clippy::print_stderr)]
fn intervals_cover_the_truth() {
    let (q, r) = (0.5, 1.0);
    let mut covered = [0usize; 2];
    for seed in 0..100 {
        let est = MaximumLikelihood::new()
            .estimate(&scaled_walk(random_walk(q, r, 150, seed)))
            .unwrap();
        assert!(est.converged, "seed {seed}: {:?}", est.warnings);
        for (i, truth) in [q, r].into_iter().enumerate() {
            let [lo, hi] = est.parameters[i].ci95.unwrap();
            covered[i] += usize::from(lo <= truth && truth <= hi);
        }
    }
    // The figures a closing note quotes (`-- --nocapture`); the verdict is the assertion.
    eprintln!("scaled random walk: covering logs of 100: [q, r] = {covered:?}");
    for (name, c) in ["q", "r"].iter().zip(covered) {
        assert!(
            (90..=99).contains(&c),
            "{name}: {c} of 100 intervals cover the truth"
        );
    }
}

/// The sum of two random walks seen as one number: only the sum of their variances reaches
/// the data, and the estimate says so in words.
#[test]
fn unidentifiable_parameters_are_named() {
    let run = random_walk(0.8, 1.0, 200, 7);
    let noise = Parametrisation::new(
        None,
        CovarianceForm::diagonal(DMatrix::from_diagonal_element(2, 2, 0.3)),
        CovarianceForm::fixed(one(1.0)),
    )
    .unwrap();
    let problem = NoiseProblem::new(
        DMatrix::identity(2, 2),
        DMatrix::from_row_slice(1, 2, &[1.0, 1.0]),
        DVector::zeros(2),
        DMatrix::zeros(2, 2),
        Start::PredictFirst,
        noise,
        vec![run],
    )
    .unwrap();
    let est = MaximumLikelihood::new().estimate(&problem).unwrap();
    let id = est.identifiability.clone().unwrap();
    assert_eq!(id.rank, 1, "{}", id.message);
    assert!(!id.identifiable);
    assert_eq!(id.identified[0].text, "Qw[0,0] + Qw[1,1]", "{}", id.message);
    assert!(
        id.message.contains("identify only 1 of 2"),
        "{}",
        id.message
    );
    assert!(
        est.warnings
            .iter()
            .any(|w| matches!(w, MlWarning::Unidentifiable { .. }))
    );
    assert!(est.parameters.iter().all(|p| p.stderr.is_none()));
    // The sum is estimated all the same.
    let sum = est.matrices.q[(0, 0)] + est.matrices.q[(1, 1)];
    assert!((sum - 0.8).abs() < 0.4, "q0 + q1 = {sum}");
}

/// A walk without process noise: q runs to its bound 0, which the estimate says, and the
/// interval's lower end is 0.
#[test]
fn a_parameter_at_its_bound_is_reported() {
    let est = MaximumLikelihood::new()
        .estimate(&scaled_walk(random_walk(0.0, 1.0, 200, 3)))
        .unwrap();
    let q = &est.parameters[0];
    assert_eq!(q.at_bound, Some(Bound::Zero), "{q:?}");
    assert!(est.warnings.contains(&MlWarning::AtBound {
        parameter: "q".to_string(),
        bound: Bound::Zero
    }));
    if let Some([lo, _]) = q.ci95 {
        assert_eq!(lo, 0.0);
    }
    assert!((est.parameters[1].value - 1.0).abs() < 0.3);
}

#[test]
fn bad_starts_and_empty_parametrisations_are_typed_errors() {
    // R = 0 and P0 = 0 updating first: S = 0 at the first measurement.
    let noise = Parametrisation::new(
        None,
        CovarianceForm::scaled(one(1.0)),
        CovarianceForm::fixed(one(0.0)),
    )
    .unwrap();
    let problem = NoiseProblem::new(
        one(1.0),
        one(1.0),
        DVector::zeros(1),
        one(0.0),
        Start::UpdateFirst,
        noise,
        vec![random_walk(1.0, 1.0, 10, 1)],
    )
    .unwrap();
    let err = MaximumLikelihood::new().estimate(&problem).unwrap_err();
    assert!(matches!(err, MlError::Start(_)), "{err}");
    assert!(err.to_string().contains("not positive definite"), "{err}");
    let fixed = Parametrisation::new(
        None,
        CovarianceForm::fixed(one(1.0)),
        CovarianceForm::fixed(one(1.0)),
    )
    .unwrap();
    let problem = NoiseProblem::new(
        one(1.0),
        one(1.0),
        DVector::zeros(1),
        one(1.0),
        Start::PredictFirst,
        fixed,
        vec![random_walk(1.0, 1.0, 10, 1)],
    )
    .unwrap();
    assert_eq!(
        MaximumLikelihood::new().estimate(&problem).unwrap_err(),
        MlError::NothingToEstimate
    );
    assert!(
        MaximumLikelihood::new()
            .gradient_tolerance(f64::NAN)
            .is_err()
    );
}

/// An iteration limit too small to converge is a warning of the estimate, not a silent answer.
#[test]
fn non_convergence_is_reported() {
    let est = MaximumLikelihood::new()
        .max_iterations(1)
        .estimate(&scaled_walk(random_walk(0.5, 1.0, 100, 11)))
        .unwrap();
    assert!(!est.converged);
    assert!(
        est.warnings
            .iter()
            .any(|w| matches!(w, MlWarning::NotConverged { .. }))
    );
}

/// The starts and the gradient's evaluations run side by side on rayon's pool; the estimate,
/// every start's outcome and the evaluation count are the same on one thread and on three.
#[test]
fn the_estimate_does_not_depend_on_the_thread_count() {
    let problem = scaled_walk(random_walk(0.5, 1.0, 150, 7));
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| MaximumLikelihood::new().estimate(&problem).unwrap())
    };
    let one = on(1);
    assert_eq!(one.starts.len(), 3);
    assert_eq!(one, on(3));
}
