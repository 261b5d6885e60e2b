//! The smoothers' invariants: the smoothed covariance never exceeds the filtered one, the last
//! step is the filter's, the KF, EKF and UKF smoothers agree on linear models, the fixed-lag
//! smoother is the full one on the log cut `lag` steps later, and a failed step is named.

use kalibra_filters::smooth::{FixedLagSmoother, Smoothable, Smoothed, SmoothedStep};
use kalibra_filters::{Ekf, Filter, FilterError, Kf, SigmaSet, Start, Ukf};
use kalibra_linalg::{Matrix2, Matrix3, SMatrix, U1, U2, U3, Vector1, Vector2, Vector3};
use kalibra_models::{LinearGaussian, LinearObservation};
use proptest::prelude::*;

type Model = (
    LinearGaussian<U3>,
    LinearObservation<U3, kalibra_linalg::U2>,
);
type Run = (Model, Vector3<f64>, Matrix3<f64>, Vec<Option<Vector2<f64>>>);

/// `A A^T + floor I` from nine entries.
fn spd(entries: &[f64], floor: f64) -> Matrix3<f64> {
    let a = Matrix3::from_row_slice(entries);
    a * a.transpose() + Matrix3::identity() * floor
}

/// A random linear-Gaussian model of 3 states and 2 measurements, an initial estimate, and a
/// measurement sequence with gaps.
fn runs() -> impl Strategy<Value = Run> {
    let entries = || prop::collection::vec(-1.0f64..1.0, 9);
    (
        (entries(), entries(), prop::collection::vec(-1.0f64..1.0, 6)),
        (entries(), prop::collection::vec(-1.0f64..1.0, 3), entries()),
        prop::collection::vec(
            (prop::bool::weighted(0.75), -5.0f64..5.0, -5.0f64..5.0),
            1..30,
        ),
        0.5f64..3.0,
    )
        .prop_map(|((f, q, h), (r, x0, p0), z, r_scale)| {
            let f = Matrix3::identity() + Matrix3::from_row_slice(&f) * 0.3;
            let q = spd(&q, 0.01) * 0.1;
            let h = SMatrix::<f64, 2, 3>::from_row_slice(&h);
            let r = spd(&r, 0.1).fixed_view::<2, 2>(0, 0).into_owned() * r_scale;
            let z = z
                .into_iter()
                .map(|(seen, a, b)| seen.then(|| Vector2::new(a, b)))
                .collect();
            (
                (
                    LinearGaussian::new(f, q).unwrap(),
                    LinearObservation::new(h, r).unwrap(),
                ),
                Vector3::from_row_slice(&x0),
                spd(&p0, 0.1),
                z,
            )
        })
}

fn starts() -> impl Strategy<Value = Start> {
    prop_oneof![Just(Start::PredictFirst), Just(Start::UpdateFirst)]
}

fn kf_smooth(((f, h), x0, p0, z): &Run, start: Start) -> (Smoothed<U3>, Vec<Matrix3<f64>>) {
    let mut kf = Kf::new(f, h, *x0, *p0).unwrap();
    let pass = kf.forward(z.iter().map(Option::as_ref), start).unwrap();
    let filtered = pass.filtered().iter().map(|s| s.estimate().cov).collect();
    (pass.smooth().unwrap(), filtered)
}

/// The largest difference of two smoothed runs, relative to the largest entry.
fn difference(a: &Smoothed<U3>, b: &Smoothed<U3>) -> f64 {
    assert_eq!(a.steps().len(), b.steps().len());
    let mut worst = 0.0f64;
    for (x, y) in a.steps().iter().zip(b.steps()) {
        assert_eq!(x.step(), y.step());
        let scale = x.mean().amax().max(x.covariance().amax()).max(1.0);
        worst = worst.max((x.mean() - y.mean()).amax() / scale);
        worst = worst.max((x.covariance() - y.covariance()).amax() / scale);
        if let (Some(p), Some(q)) = (x.lag_one(), y.lag_one()) {
            worst = worst.max((p - q).amax() / scale);
        }
        assert_eq!(x.lag_one().is_some(), y.lag_one().is_some());
    }
    worst
}

fn same_step(a: &SmoothedStep<U3>, b: &SmoothedStep<U3>) {
    assert_eq!(a.step(), b.step());
    assert_eq!(a.updated(), b.updated());
    assert_eq!(a.estimate(), b.estimate());
    assert_eq!(a.lag_one(), b.lag_one());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// `P_k - P_{k|n}` is positive semi-definite: no eigenvalue below `-1e-9` of the scale.
    #[test]
    fn smoothed_covariance_never_exceeds_the_filtered(run in runs(), start in starts()) {
        let (smoothed, filtered) = kf_smooth(&run, start);
        for (s, p) in smoothed.steps().iter().zip(&filtered) {
            let lowest = (p - s.covariance()).symmetric_eigenvalues().min();
            prop_assert!(lowest >= -1e-9 * p.amax().max(1.0), "step {}: {lowest:e}", s.step());
        }
    }

    /// The last smoothed step is the filter's estimate, to the bit, with or without a final
    /// measurement.
    #[test]
    fn last_step_is_the_filters(run in runs(), start in starts()) {
        let ((f, h), x0, p0, z) = &run;
        let mut kf = Kf::new(f, h, *x0, *p0).unwrap();
        let smoothed = kf.smooth(z.iter().map(Option::as_ref), start).unwrap();
        let last = smoothed.steps().last().unwrap();
        prop_assert_eq!(last.mean(), kf.mean());
        prop_assert_eq!(last.covariance(), kf.covariance());
        prop_assert_eq!(last.step(), kf.step_index());
        let expected = z.len() + usize::from(start == Start::PredictFirst);
        prop_assert_eq!(smoothed.steps().len(), expected);
    }

    /// On a linear model the EKF smoother is the KF's (to 1e-12) and the UKF's, for two sigma
    /// sets, agrees to 1e-8 of the scale (the unscented transform is exact there; rounding
    /// differs).
    #[test]
    fn kf_ekf_and_ukf_smoothers_agree_on_linear_models(run in runs(), start in starts()) {
        let ((f, h), x0, p0, z) = &run;
        let (kf, _) = kf_smooth(&run, start);
        let ekf = Ekf::new(f, h, *x0, *p0).unwrap()
            .smooth(z.iter().map(Option::as_ref), start).unwrap();
        prop_assert!(difference(&kf, &ekf) < 1e-12);
        for set in [SigmaSet::recommended(3), SigmaSet::Scaled { alpha: 0.9, beta: 2.0, kappa: 1.0 }] {
            let ukf = Ukf::new(f, h, *x0, *p0, set).unwrap()
                .smooth(z.iter().map(Option::as_ref), start).unwrap();
            let d = difference(&kf, &ukf);
            prop_assert!(d < 1e-8, "{set:?}: {d:e}");
        }
    }

    /// The fixed-lag smoother's step `k` is the full smoother's over the log cut after step
    /// `k + lag`, to the bit; its last `lag` steps are the full smoother's over the whole log.
    #[test]
    fn fixed_lag_is_the_full_smoother_of_the_cut_log(
        run in runs(), start in starts(), lag in 0usize..6,
    ) {
        let ((f, h), x0, p0, z) = &run;
        let mut lagged = FixedLagSmoother::new(Kf::new(f, h, *x0, *p0).unwrap(), lag, start);
        let mut steps = Vec::new();
        let offset = usize::from(start == Start::PredictFirst);
        for (j, zk) in z.iter().enumerate() {
            let ready = lagged.step(zk.as_ref()).unwrap();
            // The newest step is j + offset: what comes back is `lag` steps behind it.
            if let Some(last) = ready.last() {
                prop_assert_eq!(steps.len() + ready.len() - 1 + lag, j + offset);
                prop_assert_eq!(last.step() + lag, lagged.filter().step_index());
            }
            steps.extend(ready);
        }
        let (_, tail) = lagged.finish().unwrap();
        let emitted_before_finish = steps.len();
        steps.extend(tail);
        let full = |cut: usize| {
            Kf::new(f, h, *x0, *p0).unwrap()
                .smooth(z[..cut].iter().map(Option::as_ref), start).unwrap()
        };
        let whole = full(z.len());
        prop_assert_eq!(steps.len(), whole.steps().len());
        // Step i of the pass is measurement i (UpdateFirst) or i - 1 (PredictFirst, x0 first).
        for (i, step) in steps.iter().enumerate() {
            if i < emitted_before_finish {
                // Emitted once the measurement `lag` steps later was in.
                let cut = (i + lag + 1 - offset).min(z.len());
                same_step(step, &full(cut).steps()[i]);
            } else {
                same_step(step, &whole.steps()[i]);
            }
        }
        // The memory bound: nothing is emitted before `lag` later steps exist.
        prop_assert_eq!(emitted_before_finish, (z.len() + offset).saturating_sub(lag));
    }

    /// `smooth_fixed_lag` visits every step once, in order, as the streaming smoother returns
    /// them.
    #[test]
    fn smooth_fixed_lag_visits_every_step(run in runs(), start in starts(), lag in 0usize..4) {
        let ((f, h), x0, p0, z) = &run;
        let mut visited = Vec::new();
        Kf::new(f, h, *x0, *p0).unwrap()
            .smooth_fixed_lag(z.iter().map(Option::as_ref), start, lag, |s| visited.push(s.clone()))
            .unwrap();
        let mut lagged = FixedLagSmoother::new(Kf::new(f, h, *x0, *p0).unwrap(), lag, start);
        let mut streamed = Vec::new();
        for zk in z {
            streamed.extend(lagged.step(zk.as_ref()).unwrap());
        }
        streamed.extend(lagged.finish().unwrap().1);
        prop_assert_eq!(visited.len(), streamed.len());
        for (a, b) in visited.iter().zip(&streamed) {
            same_step(a, b);
        }
    }
}

/// The lag-one covariance is `Cov(x_k, x_{k-1} | all z)`: on a scalar random walk with both
/// steps measured it is the off-diagonal of the inverse of the joint information matrix.
#[test]
fn lag_one_is_the_joint_posterior_cross_covariance() {
    let (p0, q, r) = (2.0, 0.5, 1.0);
    let f =
        LinearGaussian::new(SMatrix::<f64, 1, 1>::new(1.0), SMatrix::<f64, 1, 1>::new(q)).unwrap();
    let h = LinearObservation::new(SMatrix::<f64, 1, 1>::new(1.0), SMatrix::<f64, 1, 1>::new(r))
        .unwrap();
    let z = [Vector1::new(0.3), Vector1::new(-0.4)];
    let smoothed = Kf::new(&f, &h, Vector1::new(0.0), SMatrix::<f64, 1, 1>::new(p0))
        .unwrap()
        .smooth(z.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    // Joint information of (x0, x1): prior 1/p0 on x0, the walk (x1 - x0)^2 / q, and 1/r each.
    let information = Matrix2::new(
        1.0 / p0 + 1.0 / q + 1.0 / r,
        -1.0 / q,
        -1.0 / q,
        1.0 / q + 1.0 / r,
    );
    let joint = information.try_inverse().unwrap();
    let steps = smoothed.steps();
    assert!((steps[0].covariance()[(0, 0)] - joint[(0, 0)]).abs() < 1e-14);
    assert!((steps[1].covariance()[(0, 0)] - joint[(1, 1)]).abs() < 1e-14);
    assert!((steps[1].lag_one().unwrap()[(0, 0)] - joint[(1, 0)]).abs() < 1e-14);
}

/// A model whose second state the dynamics zero and no noise refills, so every predicted
/// covariance is singular, and two measurements of the first state.
fn singular_prediction() -> (
    LinearGaussian<U2>,
    LinearObservation<U2, U1>,
    [Vector1<f64>; 2],
) {
    let f = LinearGaussian::new(Matrix2::new(1.0, 0.0, 0.0, 0.0), Matrix2::zeros()).unwrap();
    let h = LinearObservation::new(
        SMatrix::<f64, 1, 2>::new(1.0, 0.0),
        SMatrix::<f64, 1, 1>::new(1.0),
    )
    .unwrap();
    (f, h, [Vector1::new(0.5), Vector1::new(0.7)])
}

/// A predicted covariance without a Cholesky factor (a state that the dynamics zero and no
/// noise refills) fails the smoothing step that solves with it, named by its step.
#[test]
fn a_singular_prediction_names_its_step() {
    let (f, h, z) = singular_prediction();
    let mut kf = Kf::new(&f, &h, Vector2::zeros(), Matrix2::identity()).unwrap();
    let pass = kf.forward(z.iter().map(Some), Start::PredictFirst).unwrap();
    assert_eq!(pass.filtered().len(), 3);
    assert!(matches!(
        pass.smooth(),
        Err(FilterError::NotPositiveDefinite { step: 2, .. })
    ));
}

/// An empty sequence smooths to the initial estimate alone.
#[test]
fn an_empty_sequence_is_the_initial_estimate() {
    let f = LinearGaussian::new(Matrix2::identity(), Matrix2::identity()).unwrap();
    let h = LinearObservation::new(
        SMatrix::<f64, 1, 2>::new(1.0, 0.0),
        SMatrix::<f64, 1, 1>::new(1.0),
    )
    .unwrap();
    for start in [Start::PredictFirst, Start::UpdateFirst] {
        let mut kf = Kf::new(&f, &h, Vector2::new(1.0, 2.0), Matrix2::identity()).unwrap();
        let smoothed = kf.smooth(std::iter::empty(), start).unwrap();
        assert_eq!(smoothed.steps().len(), 1);
        assert_eq!(smoothed.steps()[0].mean(), &Vector2::new(1.0, 2.0));
        assert!(smoothed.steps()[0].lag_one().is_none());
    }
}

/// A filter's state as far as its accessors show it: the estimate, the step and the last
/// update's record.
fn filter_state(kf: &Kf<U3, U2, &LinearGaussian<U3>, &LinearObservation<U3, U2>>) -> String {
    let record = kf.last_record().map(|r| {
        (
            r.step(),
            r.prior().clone(),
            r.posterior().clone(),
            *r.innovation(),
            *r.s_matrix(),
            *r.gain(),
            *r.f(),
            *r.propagated(),
            *r.process_noise(),
        )
    });
    format!(
        "{:?}",
        (kf.step_index(), kf.mean(), kf.covariance(), record)
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The KF's `smooth` (its own forward pass, `smooth/linear.rs`) is its forward pass
    /// smoothed, to the bit, and leaves the filter as the forward pass does, record included,
    /// for the next prediction too (after a last step without a measurement it carries the
    /// prior's split).
    #[test]
    fn kf_smooth_is_its_forward_pass_smoothed(run in runs(), start in starts()) {
        let ((f, h), x0, p0, z) = &run;
        let mut fast = Kf::new(f, h, *x0, *p0).unwrap();
        let mut slow = Kf::new(f, h, *x0, *p0).unwrap();
        let a = fast.smooth(z.iter().map(Option::as_ref), start).unwrap();
        let b = slow.forward(z.iter().map(Option::as_ref), start).unwrap().smooth().unwrap();
        prop_assert_eq!(a.steps().len(), b.steps().len());
        for (x, y) in a.steps().iter().zip(b.steps()) {
            same_step(x, y);
        }
        prop_assert_eq!(filter_state(&fast), filter_state(&slow));
        fast.predict().unwrap();
        slow.predict().unwrap();
        prop_assert_eq!(filter_state(&fast), filter_state(&slow));
    }
}

/// A non-finite measurement fails the KF's `smooth` as it fails its forward pass: the same
/// typed error naming the step, and the filter left at the same place.
#[test]
fn a_non_finite_measurement_fails_smooth_as_forward() {
    let f = LinearGaussian::new(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity()).unwrap();
    let h = LinearObservation::new(
        SMatrix::<f64, 1, 2>::new(1.0, 0.0),
        SMatrix::<f64, 1, 1>::new(1.0),
    )
    .unwrap();
    let z = [Vector1::new(0.5), Vector1::new(f64::NAN), Vector1::new(0.7)];
    for start in [Start::PredictFirst, Start::UpdateFirst] {
        let mut fast = Kf::new(&f, &h, Vector2::zeros(), Matrix2::identity()).unwrap();
        let mut slow = fast.clone();
        let a = fast.smooth(z.iter().map(Some), start).unwrap_err();
        let b = slow.forward(z.iter().map(Some), start).unwrap_err();
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
        assert!(matches!(a, FilterError::NonFinite { .. }), "{a:?}");
        assert_eq!(fast.step_index(), slow.step_index());
        assert_eq!(fast.mean(), slow.mean());
    }
}

/// A predicted covariance without a Cholesky factor fails the KF's `smooth` as it fails its
/// forward pass smoothed, naming the same step.
#[test]
fn a_singular_prediction_fails_smooth_as_the_pass() {
    let (f, h, z) = singular_prediction();
    let mut fast = Kf::new(&f, &h, Vector2::zeros(), Matrix2::identity()).unwrap();
    let mut slow = fast.clone();
    let a = fast
        .smooth(z.iter().map(Some), Start::PredictFirst)
        .unwrap_err();
    let b = slow
        .forward(z.iter().map(Some), Start::PredictFirst)
        .unwrap()
        .smooth()
        .unwrap_err();
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
    assert!(
        matches!(a, FilterError::NotPositiveDefinite { step: 2, .. }),
        "{a:?}"
    );
    assert_eq!(fast.step_index(), slow.step_index());
}
