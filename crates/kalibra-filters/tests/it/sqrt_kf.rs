//! The square-root KF: equal to the Joseph-form `Kf` where both work (a property test over
//! random stable models, `Const` and `Dyn` sizes), its record's invariants, and typed errors.

use kalibra_filters::smooth::Smoothable;
use kalibra_filters::{
    Filter, FilterError, FilterOptions, InitialCheck, Kf, SqrtKf, Start, UpdateForm,
};
use kalibra_linalg::{
    Alloc, Const, DMatrix, DVector, DefaultAllocator, Dim, Dyn, Matrix1, Matrix2, Matrix3, OMatrix,
    OVector, SMatrix, SVector, U2, U3, Vector2,
};
use kalibra_models::{LinearGaussian, LinearObservation};
use proptest::prelude::*;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::{Rng, SeedableRng};

use crate::sqrt_common::{rel, worst_difference};

/// A uniform draw in `[-1, 1)`.
fn unit(rng: &mut ChaCha8Rng) -> f64 {
    (rng.next_u64() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// A random `r x c` matrix with entries in `[-1, 1)`.
fn random<R: Dim, C: Dim>(rng: &mut ChaCha8Rng, r: R, c: C) -> OMatrix<f64, R, C>
where
    DefaultAllocator: kalibra_linalg::nalgebra::allocator::Allocator<R, C>,
{
    OMatrix::<f64, R, C>::from_fn_generic(r, c, |_, _| unit(rng))
}

/// A random covariance `G G^T + floor I` scaled by `scale`.
fn random_cov<D: Dim>(rng: &mut ChaCha8Rng, d: D, scale: f64, floor: f64) -> OMatrix<f64, D, D>
where
    DefaultAllocator: Alloc<D>,
{
    let g = random(rng, d, d);
    (&g * g.transpose() + OMatrix::<f64, D, D>::identity_generic(d, d) * floor) * scale
}

/// A random stable linear-Gaussian model of sizes `n, m`, an initial estimate and `steps`
/// measurements (a random walk around zero: equality needs no truth).
#[allow(clippy::type_complexity)]
fn random_problem<N: Dim, M: Dim>(
    seed: u64,
    n: N,
    m: M,
    steps: usize,
) -> (
    LinearGaussian<N>,
    LinearObservation<N, M>,
    OVector<f64, N>,
    OMatrix<f64, N, N>,
    Vec<OVector<f64, M>>,
)
where
    DefaultAllocator: Alloc<N, M>,
{
    let rng = &mut ChaCha8Rng::seed_from_u64(seed);
    let mut f = random(rng, n, n);
    // Frobenius norm bounds the spectral radius: scaled below 0.98, the model is stable.
    let norm = f.norm();
    if norm > 0.98 {
        f *= 0.98 / norm;
    }
    let q = random_cov(rng, n, 0.1, 1e-3);
    let h = random(rng, m, n);
    let r = random_cov(rng, m, 1.0, 1e-2);
    let p0 = random_cov(rng, n, 10.0, 1e-2);
    let x0 = random(rng, n, kalibra_linalg::U1) * 5.0;
    let zs = (0..steps)
        .map(|_| random(rng, m, kalibra_linalg::U1) * 3.0)
        .collect();
    (
        LinearGaussian::new(f, q).unwrap(),
        LinearObservation::new(h, r).unwrap(),
        x0,
        p0,
        zs,
    )
}

/// Runs the KF and the square-root KF on one random problem (every third measurement missing,
/// so double predictions are covered) and returns the worst difference.
fn kf_vs_sqrt<N: Dim, M: Dim>(seed: u64, n: N, m: M) -> f64
where
    DefaultAllocator: Alloc<N, M>,
{
    let (f, h, x0, p0, zs) = random_problem(seed, n, m, 30);
    let zs: Vec<Option<&OVector<f64, M>>> = zs
        .iter()
        .enumerate()
        .map(|(i, z)| (i % 3 != 2).then_some(z))
        .collect();
    let kf = Kf::new(&f, &h, x0.clone(), p0.clone())
        .unwrap()
        .run_collect(zs.iter().copied(), Start::PredictFirst)
        .unwrap();
    let mut sqrt = SqrtKf::new(&f, &h, x0, p0).unwrap();
    let records = sqrt
        .run_collect(zs.iter().copied(), Start::PredictFirst)
        .unwrap();
    // The factor stands for the covariance the filter reports.
    let s = sqrt.factor();
    assert!(rel(sqrt.covariance(), &(s * s.transpose())) < 1e-12);
    worst_difference(&kf, &records)
}

/// The square-root smoother and the covariance-form one (the `Kf`'s) on one random problem
/// (every third measurement missing), from `start`: the worst relative difference of the
/// smoothed means, covariances and lag-one covariances.
fn smoothers<N: Dim, M: Dim>(seed: u64, n: N, m: M, start: Start) -> f64
where
    DefaultAllocator: Alloc<N, M>,
{
    let (f, h, x0, p0, zs) = random_problem(seed, n, m, 30);
    let zs: Vec<Option<&OVector<f64, M>>> = zs
        .iter()
        .enumerate()
        .map(|(i, z)| (i % 3 != 2).then_some(z))
        .collect();
    let standard = Kf::new(&f, &h, x0.clone(), p0.clone())
        .unwrap()
        .smooth(zs.iter().copied(), start)
        .unwrap();
    let mut sqrt = SqrtKf::new(&f, &h, x0, p0).unwrap();
    let factors = sqrt.smooth(zs.iter().copied(), start).unwrap();
    assert_eq!(standard.steps().len(), factors.steps().len());
    let mut worst = 0.0f64;
    for (a, b) in standard.steps().iter().zip(factors.steps()) {
        assert_eq!((a.step(), a.updated()), (b.step(), b.updated()));
        worst = worst.max(rel(a.mean(), b.mean()));
        worst = worst.max(rel(a.covariance(), b.covariance()));
        match (a.lag_one(), b.lag_one()) {
            (Some(x), Some(y)) => worst = worst.max(rel(x, y)),
            (None, None) => {}
            _ => panic!("lag-one covariances at different steps"),
        }
    }
    // The last step is the filter's.
    let last = factors.steps().last().unwrap();
    assert_eq!(last.mean(), sqrt.mean());
    worst
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Equal to the Joseph-form KF to 1e-10 (relative) on random stable models, fixed sizes.
    #[test]
    fn equals_the_kf_on_random_stable_models_fixed_sizes(seed in 0u64..1_000_000) {
        let worst = kf_vs_sqrt(seed, Const::<4>, Const::<2>);
        prop_assert!(worst < 1e-10, "4x2: {worst:e}");
        let worst = kf_vs_sqrt(seed, Const::<3>, Const::<1>);
        prop_assert!(worst < 1e-10, "3x1: {worst:e}");
    }

    /// The same with run-time sizes, including more measurements than states.
    #[test]
    fn equals_the_kf_on_random_stable_models_dyn_sizes(
        seed in 0u64..1_000_000, n in 1usize..7, m in 1usize..5,
    ) {
        let worst = kf_vs_sqrt(seed, Dyn(n), Dyn(m));
        prop_assert!(worst < 1e-10, "{n}x{m}: {worst:e}");
    }

    /// The square-root smoother equals the covariance-form smoother to 1e-10 (relative),
    /// lag-one covariances included, from either start, fixed and run-time sizes.
    #[test]
    fn the_square_root_smoother_equals_the_kf_smoother(
        seed in 0u64..1_000_000, n in 1usize..6, m in 1usize..4,
    ) {
        for start in [Start::PredictFirst, Start::UpdateFirst] {
            let worst = smoothers(seed, Const::<4>, Const::<2>, start);
            prop_assert!(worst < 1e-10, "4x2 {start:?}: {worst:e}");
            let worst = smoothers(seed, Dyn(n), Dyn(m), start);
            prop_assert!(worst < 1e-10, "{n}x{m} {start:?}: {worst:e}");
        }
    }
}

#[test]
fn the_record_splits_the_prior_and_sums_to_s() {
    let (f, h, x0, p0, zs) = random_problem(7, U3, U2, 5);
    let mut sqrt = SqrtKf::new(&f, &h, x0, p0).unwrap();
    sqrt.predict().unwrap();
    sqrt.predict().unwrap();
    let rec = sqrt.update(&zs[0]).unwrap();
    let s = rec.compute_a() + rec.compute_b() + rec.r();
    assert!(rel(rec.s_matrix(), &s) < 1e-12);
    assert!(rec.s().is_some());
    let lower = sqrt.factor();
    assert!((0..3).all(|i| lower[(i, i)] >= 0.0 && (i + 1..3).all(|j| lower[(i, j)] == 0.0)));
}

#[test]
fn a_rank_deficient_process_noise_and_initial_covariance_are_accepted() {
    // Q = G G^T of rank one and a singular P0: the pivoted roots carry them.
    let g = Vector2::new(0.5, 1.0);
    let f = LinearGaussian::new(Matrix2::new(1.0, 1.0, 0.0, 1.0), g * g.transpose()).unwrap();
    let h = LinearObservation::new(SMatrix::<f64, 1, 2>::new(1.0, 0.0), Matrix1::new(1.0)).unwrap();
    let p0 = Matrix2::new(1.0, 0.0, 0.0, 0.0);
    let zs: Vec<SVector<f64, 1>> = (0..10).map(|i| SVector::<f64, 1>::new(i as f64)).collect();
    let kf = Kf::new(&f, &h, Vector2::zeros(), p0)
        .unwrap()
        .run_collect(zs.iter().map(Some), Start::PredictFirst)
        .unwrap();
    let sqrt = SqrtKf::new(&f, &h, Vector2::zeros(), p0)
        .unwrap()
        .run_collect(zs.iter().map(Some), Start::PredictFirst)
        .unwrap();
    let worst = worst_difference(&kf, &sqrt);
    assert!(worst < 1e-10, "{worst:e}");
}

#[test]
fn failed_steps_are_typed_and_leave_the_filter_unchanged() {
    let (f, h, x0, p0, zs) = random_problem(11, U3, U2, 3);
    let mut sqrt = SqrtKf::new(&f, &h, x0, p0).unwrap();
    sqrt.update(&zs[0]).unwrap();
    let (mean, factor, step) = (*sqrt.mean(), *sqrt.factor(), sqrt.step_index());
    let err = sqrt.update(&Vector2::new(f64::NAN, 0.0)).unwrap_err();
    assert!(matches!(err, FilterError::NonFinite { .. }), "{err:?}");
    assert_eq!(
        (*sqrt.mean(), *sqrt.factor(), sqrt.step_index()),
        (mean, factor, step)
    );
    assert!(sqrt.last_record().is_some());

    // Options the square-root filter has no meaning for are refused, not ignored.
    for options in [
        FilterOptions {
            update: UpdateForm::Standard,
            ..FilterOptions::default()
        },
        FilterOptions {
            initial_check: InitialCheck::AsGiven,
            ..FilterOptions::default()
        },
    ] {
        let err = SqrtKf::with_options(&f, &h, x0, p0, options).unwrap_err();
        assert!(matches!(err, FilterError::Unsupported { .. }), "{err:?}");
    }
    // An indefinite P0 that only the symmetric check lets through has no factor.
    let indefinite = Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0);
    let options = FilterOptions {
        initial_check: InitialCheck::SymmetricOnly,
        ..FilterOptions::default()
    };
    let err = SqrtKf::with_options(&f, &h, x0, indefinite, options).unwrap_err();
    assert!(matches!(err, FilterError::Initial(_)), "{err:?}");
}

#[test]
fn dyn_sizes_are_checked() {
    let f = LinearGaussian::new(DMatrix::identity(3, 3), DMatrix::identity(3, 3)).unwrap();
    let h = LinearObservation::new(DMatrix::identity(2, 4), DMatrix::identity(2, 2)).unwrap();
    let err = SqrtKf::new(&f, &h, DVector::zeros(3), DMatrix::identity(3, 3)).unwrap_err();
    assert!(
        matches!(err, FilterError::DimensionMismatch { .. }),
        "{err:?}"
    );
    let h = LinearObservation::new(DMatrix::identity(2, 3), DMatrix::identity(2, 2)).unwrap();
    let mut sqrt = SqrtKf::new(&f, &h, DVector::zeros(3), DMatrix::identity(3, 3)).unwrap();
    let err = sqrt.update(&DVector::zeros(3)).unwrap_err();
    assert!(
        matches!(err, FilterError::DimensionMismatch { .. }),
        "{err:?}"
    );
}
