//! EM's properties: the log-likelihood never decreases (for every form EM supports, with
//! `G`, gaps and several runs), the forms are kept, the stopping rules hold, and the forms EM
//! cannot honour are refused.

use kalibra_tune::{
    CovarianceForm, DMatrix, DVector, Em, EmError, NoiseProblem, Parametrisation, Run, Start,
};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// A draw of `N(0, cov)` by its Cholesky factor.
fn draw(rng: &mut ChaCha8Rng, cov: &DMatrix<f64>) -> DVector<f64> {
    let l = cov.clone().cholesky().unwrap().l();
    let e = DVector::from_fn(cov.nrows(), |_, _| StandardNormal.sample(rng));
    l * e
}

/// Runs of `x_k = F x_{k-1} + G u_k`, `z_k = H x_k + v_k` from `x0`, each step missing with
/// probability `gap`.
#[allow(clippy::too_many_arguments)]
fn simulate(
    seed: u64,
    f: &DMatrix<f64>,
    h: &DMatrix<f64>,
    g: &DMatrix<f64>,
    qw: &DMatrix<f64>,
    r: &DMatrix<f64>,
    runs: usize,
    steps: usize,
    gap: f64,
) -> Vec<Run> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..runs)
        .map(|_| {
            let mut x = DVector::zeros(f.nrows());
            (0..steps)
                .map(|_| {
                    x = f * &x + g * draw(&mut rng, qw);
                    let z = h * &x + draw(&mut rng, r);
                    let u: f64 = rand::RngExt::random(&mut rng);
                    (u >= gap).then_some(z)
                })
                .collect()
        })
        .collect()
}

fn system() -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let f = DMatrix::from_row_slice(2, 2, &[1.0, 0.5, 0.0, 0.95]);
    let h = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.3, 1.0]);
    let g = DMatrix::from_column_slice(2, 1, &[0.125, 0.5]);
    (f, h, g)
}

fn form(kind: u8, start: DMatrix<f64>, fix_first: bool) -> CovarianceForm {
    match kind {
        0 => CovarianceForm::fixed(start),
        1 => CovarianceForm::scaled(start),
        2 if fix_first => CovarianceForm::diagonal(start).fix(0, 0),
        2 => CovarianceForm::diagonal(start),
        _ => CovarianceForm::full(start),
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn log_likelihood_never_decreases(
        seed in 0u64..1_000,
        with_g in any::<bool>(),
        qw_kind in 0u8..4,
        r_kind in 0u8..4,
        fix_first in any::<bool>(),
        start_scale in 0.05f64..20.0,
        update_first in any::<bool>(),
    ) {
        let (f, h, g) = system();
        let qw_true = DMatrix::from_element(1, 1, 0.4);
        let r_true = DMatrix::from_row_slice(2, 2, &[0.3, 0.05, 0.05, 0.2]);
        let runs = simulate(seed, &f, &h, &g, &qw_true, &r_true, 2, 40, 0.15);
        let (g_used, qw_start) = if with_g {
            (Some(g.clone()), DMatrix::from_element(1, 1, 0.4 * start_scale))
        } else {
            (None, &g * &qw_true * g.transpose() + DMatrix::identity(2, 2) * 0.01 * start_scale)
        };
        let r_start = DMatrix::from_diagonal_element(2, 2, 0.25 * start_scale);
        let noise = Parametrisation::new(
            g_used,
            form(qw_kind, qw_start, fix_first),
            form(r_kind, r_start, fix_first),
        );
        // Parametrisations asking for more than the innovations identify are refused up front.
        prop_assume!(noise.is_ok());
        let start = if update_first { Start::UpdateFirst } else { Start::PredictFirst };
        let problem = NoiseProblem::new(
            f, h, DVector::zeros(2), DMatrix::identity(2, 2), start, noise.unwrap(), runs,
        ).unwrap();
        let fit = Em::new().exact_iterations(8).estimate(&problem).unwrap();
        prop_assert_eq!(fit.log_likelihood.len(), 9);
        for w in fit.log_likelihood.windows(2) {
            prop_assert!(w[1] >= w[0] - 1e-9 * w[0].abs(), "{:?}", fit.log_likelihood);
        }
        // The forms are kept: a diagonal R stays diagonal, Q stays in G's range.
        if r_kind == 2 {
            prop_assert_eq!(fit.matrices.r[(0, 1)], 0.0);
        }
        if with_g {
            let qw = fit.matrices.qw[(0, 0)];
            prop_assert!((&fit.matrices.q - &g * g.transpose() * qw).amax() < 1e-15);
        }
    }
}

#[test]
fn a_fixed_diagonal_entry_stays_and_the_others_move() {
    let (f, h, g) = system();
    let qw = DMatrix::from_element(1, 1, 0.4);
    let r = DMatrix::from_diagonal_element(2, 2, 0.3);
    let runs = simulate(7, &f, &h, &g, &qw, &r, 1, 200, 0.0);
    let noise = Parametrisation::new(
        Some(g),
        CovarianceForm::scaled(DMatrix::from_element(1, 1, 1.0)),
        CovarianceForm::diagonal(DMatrix::from_diagonal_element(2, 2, 1.0)).fix(1, 1),
    )
    .unwrap();
    let problem = NoiseProblem::new(
        f,
        h,
        DVector::zeros(2),
        DMatrix::identity(2, 2),
        Start::PredictFirst,
        noise,
        runs,
    )
    .unwrap();
    let fit = Em::new().estimate(&problem).unwrap();
    assert!(fit.converged && fit.iterations < 500, "{}", fit.iterations);
    assert_eq!(fit.matrices.r[(1, 1)], 1.0);
    assert!(fit.matrices.r[(0, 0)] != 1.0);
    let names: Vec<_> = fit.parameters.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["q", "R[0,0]"]);
    assert_eq!(fit.values[0], fit.matrices.qw[(0, 0)]);
    assert_eq!(fit.values[1], fit.matrices.r[(0, 0)]);
    // Converged: one more iteration changes the likelihood by at most the tolerance.
    let ll = &fit.log_likelihood;
    let (a, b) = (ll[ll.len() - 2], ll[ll.len() - 1]);
    assert!((b - a).abs() <= 1e-8 * b.abs());
}

#[test]
fn a_full_form_with_fixed_entries_is_refused() {
    let (f, h, g) = system();
    let runs = simulate(
        3,
        &f,
        &h,
        &g,
        &DMatrix::from_element(1, 1, 0.4),
        &DMatrix::identity(2, 2),
        1,
        20,
        0.0,
    );
    let noise = Parametrisation::new(
        Some(g),
        CovarianceForm::fixed(DMatrix::from_element(1, 1, 0.4)),
        CovarianceForm::full(DMatrix::identity(2, 2)).fix(1, 0),
    )
    .unwrap();
    let problem = NoiseProblem::new(
        f,
        h,
        DVector::zeros(2),
        DMatrix::identity(2, 2),
        Start::PredictFirst,
        noise,
        runs,
    )
    .unwrap();
    let err = Em::new().estimate(&problem).unwrap_err();
    assert!(
        matches!(err, EmError::Unsupported { what: "R", .. }),
        "{err}"
    );
}
