//! Invariants that hold for all inputs, checked with proptest over fixed and dynamic sizes.

use kalibra::filters::{Ekf, Filter, Kf};
use kalibra::linalg::{
    Covariance, DMatrix, DVector, Matrix4, SMatrix, Vector4, joseph_update, propagate,
    semidefinite_factor, standard_update,
};
use kalibra::models::{
    Bearing, BearingReference, LinearGaussian, LinearObservation, Measurement, Moving,
    check_measurement_jacobian, wrap_angle,
};
use proptest::prelude::*;

/// A random symmetric positive definite matrix `A A^T + eps I` with entries of `A` in
/// [-scale, scale].
fn spd<const D: usize>(scale: f64) -> impl Strategy<Value = SMatrix<f64, D, D>> {
    prop::collection::vec(-1.0f64..1.0, D * D).prop_map(move |v| {
        let a = SMatrix::<f64, D, D>::from_column_slice(&v) * scale;
        a * a.transpose() + SMatrix::<f64, D, D>::identity() * (1e-3 * scale * scale)
    })
}

fn matrix<const R: usize, const C: usize>() -> impl Strategy<Value = SMatrix<f64, R, C>> {
    prop::collection::vec(-2.0f64..2.0, R * C)
        .prop_map(|v| SMatrix::<f64, R, C>::from_column_slice(&v))
}

fn dyn_spd(n: usize) -> impl Strategy<Value = DMatrix<f64>> {
    prop::collection::vec(-1.0f64..1.0, n * n).prop_map(move |v| {
        let a = DMatrix::from_column_slice(n, n, &v);
        &a * a.transpose() + DMatrix::identity(n, n) * 1e-3
    })
}

fn rel_close<const R: usize, const C: usize>(
    a: &SMatrix<f64, R, C>,
    b: &SMatrix<f64, R, C>,
    tol: f64,
) -> bool {
    (a - b).amax() <= tol * (1.0 + a.amax().max(b.amax()))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// At the optimal gain the Joseph form equals the standard update.
    #[test]
    fn joseph_equals_standard_at_optimal_gain(p in spd::<4>(3.0), h in matrix::<2, 4>(), r in spd::<2>(1.0)) {
        let s = propagate(&h, &p) + r;
        let k = p * h.transpose() * s.try_inverse().unwrap();
        prop_assert!(rel_close(&joseph_update(&p, &k, &h, &r), &standard_update(&p, &k, &h), 1e-9));
    }

    /// The same on run-time sizes: one generic implementation serves `Dyn`.
    #[test]
    fn joseph_equals_standard_on_dynamic_sizes((n, m, p, hv, r) in (1usize..7, 1usize..4).prop_flat_map(|(n, m)| {
        (Just(n), Just(m), dyn_spd(n), prop::collection::vec(-2.0f64..2.0, m * n), dyn_spd(m))
    })) {
        let h = DMatrix::from_column_slice(m, n, &hv);
        let s = propagate(&h, &p) + &r;
        let k = &p * h.transpose() * s.try_inverse().unwrap();
        let (a, b) = (joseph_update(&p, &k, &h, &r), standard_update(&p, &k, &h));
        prop_assert!((&a - &b).amax() <= 1e-9 * (1.0 + a.amax()));
    }

    /// The Joseph form keeps the covariance symmetric positive semi-definite for any gain.
    #[test]
    fn joseph_is_psd_for_any_gain(p in spd::<4>(2.0), h in matrix::<2, 4>(), r in spd::<2>(1.0), k in matrix::<4, 2>()) {
        let out = joseph_update(&p, &k, &h, &r);
        prop_assert_eq!(out, out.transpose());
        prop_assert!(semidefinite_factor(&out, "P").is_ok());
    }

    /// Quadratic form, solve and log-determinant through the factor agree with the inverse.
    #[test]
    fn covariance_kernels_match_explicit_inverse(c in spd::<4>(2.0), v in matrix::<4, 1>()) {
        let cov = Covariance::new(c).unwrap();
        let inv = c.try_inverse().unwrap();
        let direct = (v.transpose() * inv * v)[0];
        prop_assert!((cov.quad_form(&v).unwrap() - direct).abs() <= 1e-8 * (1.0 + direct.abs()));
        prop_assert!((cov.log_det() - c.determinant().ln()).abs() <= 1e-8 * (1.0 + c.determinant().ln().abs()));
        prop_assert!(rel_close(&cov.solve(&v).unwrap(), &(inv * v), 1e-8));
    }

    /// The semi-definite factor reconstructs rank-deficient covariances `G G^T` exactly.
    #[test]
    fn semidefinite_factor_reconstructs_rank_deficient(g in matrix::<5, 2>()) {
        let q = g * g.transpose();
        let (l, rank) = semidefinite_factor(&q, "Q").unwrap();
        prop_assert!(rank <= 2);
        prop_assert!(rel_close(&(l * l.transpose()), &q, 1e-9));
    }

    /// A Kalman update never increases the variance in any direction.
    #[test]
    fn update_never_increases_variance(p in spd::<4>(3.0), h in matrix::<2, 4>(), r in spd::<2>(1.0), v in matrix::<4, 1>(), z in matrix::<2, 1>()) {
        let f = LinearGaussian::new(Matrix4::identity(), Matrix4::zeros()).unwrap();
        let obs = LinearObservation::new(h, r).unwrap();
        let mut kf = Kf::new(&f, &obs, Vector4::zeros(), p).unwrap();
        let post = kf.update(&z).unwrap().posterior().cov;
        let (before, after) = ((v.transpose() * p * v)[0], (v.transpose() * post * v)[0]);
        prop_assert!(after <= before * (1.0 + 1e-9) + 1e-12, "{} > {}", after, before);
    }

    /// The EKF equals the KF on any linear model (to 1e-12), over several steps.
    #[test]
    fn ekf_equals_kf_on_random_linear_models(fm in matrix::<4, 4>(), q in spd::<4>(0.3), h in matrix::<2, 4>(), r in spd::<2>(1.0), p0 in spd::<4>(1.0), zs in prop::collection::vec(matrix::<2, 1>(), 1..6)) {
        // Keep F stable-ish so that values stay moderate over a few steps.
        let fm = fm * 0.5;
        let dynamics = LinearGaussian::new(fm, q).unwrap();
        let obs = LinearObservation::new(h, r).unwrap();
        let mut kf = Kf::new(&dynamics, &obs, Vector4::zeros(), p0).unwrap();
        let mut ekf = Ekf::new(&dynamics, &obs, Vector4::zeros(), p0).unwrap();
        for (i, z) in zs.iter().enumerate() {
            if i > 0 { kf.predict().unwrap(); ekf.predict().unwrap(); }
            let a = kf.update(z).unwrap().clone();
            let b = ekf.update(z).unwrap();
            prop_assert!(rel_close(&a.posterior().mean, &b.posterior().mean, 1e-12));
            prop_assert!(rel_close(&a.posterior().cov, &b.posterior().cov, 1e-12));
            // The prior split adds up to S.
            prop_assert!(rel_close(&(a.compute_a() + a.compute_b() + a.r()), a.s_matrix(), 1e-12));
        }
    }

    /// Wrapping lands in (-pi, pi] and changes the angle by a whole number of turns.
    #[test]
    fn wrap_angle_is_canonical(a in -100.0f64..100.0) {
        let w = wrap_angle(a);
        prop_assert!(w > -std::f64::consts::PI && w <= std::f64::consts::PI);
        let turns = (a - w) / (2.0 * std::f64::consts::PI);
        prop_assert!((turns - turns.round()).abs() < 1e-9);
    }

    /// The bearing Jacobian matches finite differences anywhere away from the platform.
    #[test]
    fn bearing_jacobian_matches_finite_differences(x in -50.0f64..50.0, y in -50.0f64..50.0, k in 0usize..50) {
        let platform = Moving(|k: usize| kalibra::linalg::Vector2::new((k as f64).cos(), (k as f64).sin()));
        let m = Bearing::new(kalibra::linalg::U4, [0, 1], BearingReference::North, 1e-3, platform).unwrap();
        let p = (x - (k as f64).cos(), y - (k as f64).sin());
        prop_assume!(p.0.hypot(p.1) > 1.0);
        let check = check_measurement_jacobian(&m, k, &Vector4::new(x, y, 0.0, 0.0));
        prop_assert!(check.scaled_error < 1e-6, "{:?}", check);
        prop_assert!(m.measure(k, &Vector4::new(x, y, 0.0, 0.0))[0].abs() <= std::f64::consts::PI);
    }
}

#[test]
fn dynamic_measurement_of_wrong_length_is_an_error_not_a_panic() {
    let f = LinearGaussian::new(DMatrix::<f64>::identity(2, 2), DMatrix::zeros(2, 2)).unwrap();
    let h =
        LinearObservation::new(DMatrix::<f64>::identity(1, 2), DMatrix::identity(1, 1)).unwrap();
    let mut kf = Kf::new(&f, &h, DVector::zeros(2), DMatrix::identity(2, 2)).unwrap();
    assert!(kf.update(&DVector::zeros(2)).is_err());
}
