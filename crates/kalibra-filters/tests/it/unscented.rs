//! The unscented filters: UKF = KF on linear-Gaussian models for any valid sigma set, the
//! record's split and statistical linearisation, sigma bearings across +-pi, adaptive kappa
//! selection rules, and typed errors.

use approx::assert_relative_eq;
use kalibra_filters::{
    Filter, FilterError, KappaCriterion, KappaGrid, Kf, SigmaSet, Start, Ukf, UkfPrediction,
};
use kalibra_linalg::{Matrix2, Matrix4, U4, Vector1, Vector2, Vector4};
use kalibra_models::{
    Bearing, BearingReference, Kinematic, LinearObservation, Stationary, simulate, wrap_angle,
};
use proptest::prelude::*;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;

use crate::common::{p0, truth, w1};

/// Runs the UKF with `set` and the KF on the same W1 data; returns the largest relative
/// difference of posterior means and covariances.
fn ukf_vs_kf(set: SigmaSet, prediction: UkfPrediction, seed: u64) -> f64 {
    let (f, h) = w1();
    let t = truth(seed, 60);
    let x0 = Vector4::new(5.0, -5.0, 8.0, -4.0);
    let kf = Kf::new(&f, &h, x0, p0())
        .unwrap()
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    let ukf = Ukf::new(&f, &h, x0, p0(), set)
        .unwrap()
        .with_prediction(prediction)
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    let mut worst = 0.0f64;
    for (a, b) in kf.iter().zip(&ukf) {
        let (pa, pb) = (a.posterior(), b.posterior());
        worst = worst.max((pa.mean - pb.mean).amax() / pa.mean.amax().max(1.0));
        worst = worst.max((pa.cov - pb.cov).amax() / pa.cov.amax());
        worst = worst.max((a.s_matrix() - b.s_matrix()).amax() / a.s_matrix().amax());
        worst = worst.max((a.gain() - b.gain()).amax() / a.gain().amax());
        // The statistical linearisation of a linear measurement is its matrix.
        worst = worst.max((a.h() - b.h()).amax());
        worst =
            worst.max((a.propagated() - b.propagated()).amax() / a.propagated().amax().max(1.0));
    }
    worst
}

#[test]
fn ukf_equals_kf_on_a_linear_gaussian_model_for_the_usual_sets() {
    for set in [
        SigmaSet::recommended(4),
        SigmaSet::Symmetric {
            kappa: 3.0 - 4.0 + 0.5,
        },
        SigmaSet::Symmetric { kappa: 76.0 },
        SigmaSet::Scaled {
            alpha: 1e-3,
            beta: 2.0,
            kappa: 0.0,
        },
        SigmaSet::Scaled {
            alpha: 0.5,
            beta: 2.0,
            kappa: 1.0,
        },
    ] {
        for prediction in [UkfPrediction::Unscented, UkfPrediction::Linearised] {
            let worst = ukf_vs_kf(set, prediction, 3);
            // alpha = 1e-3 puts the points 1e-3 sigma from the mean with weights near -1e6:
            // rounding grows by about 1/alpha^2 there.
            let tol = match set {
                SigmaSet::Scaled { alpha, .. } if alpha < 0.1 => 1e-5,
                _ => 1e-10,
            };
            assert!(worst < tol, "{set:?} {prediction:?}: {worst:e}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// UKF = KF for any kappa with n + kappa > 0 (the unscented transform of a linear map is
    /// exact), including negative kappa where the central weight is negative.
    #[test]
    fn ukf_equals_kf_for_any_kappa(kappa in -3.9f64..200.0, seed in 0u64..1000) {
        let worst = ukf_vs_kf(SigmaSet::Symmetric { kappa }, UkfPrediction::Unscented, seed);
        // Rounding grows with the spread sqrt(n + kappa) and with 1/(n + kappa) near the edge.
        prop_assert!(worst < 1e-8, "kappa {kappa}: {worst:e}");
    }
}

#[test]
fn sigma_weights_sum_to_one_and_reject_an_empty_spread() {
    for set in [
        SigmaSet::Symmetric { kappa: -1.5 },
        SigmaSet::Symmetric { kappa: 38.0 },
        SigmaSet::Scaled {
            alpha: 0.3,
            beta: 2.0,
            kappa: 0.0,
        },
    ] {
        let n = 4;
        let w = set.weights(n).unwrap();
        assert_relative_eq!(
            w.mean_center + 2.0 * n as f64 * w.other,
            1.0,
            epsilon = 1e-12
        );
        // The covariance weights reproduce P: 2 W spread^2 = 1.
        assert_relative_eq!(2.0 * w.other * w.spread * w.spread, 1.0, epsilon = 1e-12);
    }
    assert!(matches!(
        SigmaSet::Symmetric { kappa: -4.0 }.weights(4),
        Err(FilterError::InvalidParameter { .. })
    ));
    assert!(matches!(
        SigmaSet::Scaled {
            alpha: 0.0,
            beta: 2.0,
            kappa: 0.0
        }
        .weights(4),
        Err(FilterError::InvalidParameter { .. })
    ));
    assert!(matches!(
        SigmaSet::Symmetric { kappa: f64::NAN }.weights(2),
        Err(FilterError::InvalidParameter { .. })
    ));
    assert_eq!(SigmaSet::recommended(2), SigmaSet::Symmetric { kappa: 1.0 });
    assert_eq!(SigmaSet::recommended(4), SigmaSet::Symmetric { kappa: 0.0 });
}

#[test]
fn kappa_grid_is_equidistant_and_validated() {
    let g = KappaGrid::equidistant(0.0, 76.0, 10).unwrap();
    assert_eq!(g.values().len(), 10);
    assert_eq!(g.values()[0], 0.0);
    assert_eq!(g.values()[9], 76.0);
    assert_relative_eq!(g.values()[1], 76.0 / 9.0, epsilon = 1e-15);
    assert!(KappaGrid::new(vec![]).is_err());
    assert!(KappaGrid::new(vec![1.0, 1.0]).is_err());
    assert!(KappaGrid::new(vec![0.0, f64::INFINITY]).is_err());
    assert!(KappaGrid::equidistant(0.0, 1.0, 0).is_err());
    // A grid value that makes n + kappa <= 0 is rejected when the filter adopts it.
    let (f, h) = w1();
    let ukf = Ukf::new(&f, &h, Vector4::zeros(), p0(), SigmaSet::recommended(4)).unwrap();
    assert!(matches!(
        ukf.with_adaptive_kappa(
            KappaCriterion::MaximumLikelihood,
            KappaGrid::new(vec![-5.0, 0.0]).unwrap()
        ),
        Err(FilterError::InvalidParameter { .. })
    ));
}

#[test]
fn adaptive_kappa_ties_go_to_the_smallest_value() {
    // A measurement that does not depend on the state gives bit-identical statistics, hence
    // bit-identical criteria, at every kappa: the first (smallest) grid value must win.
    let (f, _) = w1();
    let blind = LinearObservation::new(
        kalibra_linalg::SMatrix::<f64, 2, 4>::zeros(),
        Matrix2::identity() * 4.0,
    )
    .unwrap();
    let t = truth(5, 10);
    for criterion in [
        KappaCriterion::MaximumLikelihood,
        KappaCriterion::MaximumPosterior,
        KappaCriterion::PureMap,
    ] {
        let mut ukf = Ukf::new(&f, &blind, Vector4::zeros(), p0(), SigmaSet::recommended(4))
            .unwrap()
            .with_adaptive_kappa(criterion, KappaGrid::new(vec![2.0, 5.0, 9.0]).unwrap())
            .unwrap();
        ukf.run(t.measurements.iter().map(Some), Start::UpdateFirst, |_| {})
            .unwrap();
        assert_eq!(ukf.last_kappa(), Some(2.0), "{criterion:?}");
    }
}

/// A target due west of the platform: its bearing is +-pi, and the sigma points straddle the
/// cut. Unwrapping around the central point keeps the predicted bearing at the cut and the
/// innovation small.
#[test]
fn sigma_bearings_across_pi_do_not_jump() {
    let bearing = Bearing::new(
        U4,
        [0, 1],
        BearingReference::XAxis,
        1e-4,
        Stationary(Vector2::zeros()),
    )
    .unwrap();
    let cv = Kinematic::constant_velocity(2, 1.0)
        .unwrap()
        .dynamics(U4)
        .unwrap();
    for y in [1e-3, 0.0, -1e-3] {
        let x0 = Vector4::new(-100.0, y, 1.0, 0.0);
        let p = Matrix4::from_diagonal(&Vector4::new(25.0, 25.0, 1.0, 1.0));
        let mut ukf = Ukf::new(&cv, &bearing, x0, p, SigmaSet::recommended(4)).unwrap();
        let z = Vector1::new(wrap_angle(std::f64::consts::PI - 2e-3));
        let rec = ukf.update(&z).unwrap();
        let zhat = rec.predicted_measurement()[0];
        assert!(
            (wrap_angle(zhat - std::f64::consts::PI)).abs() < 1e-4,
            "zhat {zhat}"
        );
        assert!(
            rec.innovation()[0].abs() < 1e-2,
            "nu {}",
            rec.innovation()[0]
        );
        // Pz is the bearing variance from 5 m at 100 m plus R, not a 2 pi spread.
        let pz = rec.s_matrix()[(0, 0)];
        assert!(pz < 1e-2 && pz > 1e-4, "Pz {pz}");
        assert!(rec.posterior().mean[1].abs() < 1.0);
    }
}

#[test]
fn covariances_stay_symmetric_positive_definite_on_a_bearings_run() {
    let bearing = Bearing::new(
        U4,
        [0, 1],
        BearingReference::XAxis,
        1e-3,
        kalibra_models::Moving(|k: usize| Vector2::new(0.0, 3.0 * k as f64)),
    )
    .unwrap();
    let cv = Kinematic::constant_velocity(2, 1.0)
        .unwrap()
        .dynamics(U4)
        .unwrap();
    let x0 = Vector4::new(50.0, 20.0, -1.0, 0.5);
    let t = simulate(&cv, &bearing, x0, 80, &mut ChaCha8Rng::seed_from_u64(9)).unwrap();
    for criterion in [
        None,
        Some(KappaCriterion::MaximumLikelihood),
        Some(KappaCriterion::MaximumPosterior),
        Some(KappaCriterion::PureMap),
    ] {
        let mut ukf = Ukf::new(
            &cv,
            &bearing,
            x0,
            Matrix4::identity() * 4.0,
            SigmaSet::recommended(4),
        )
        .unwrap();
        if let Some(c) = criterion {
            ukf = ukf
                .with_adaptive_kappa(c, KappaGrid::equidistant(0.0, 76.0, 10).unwrap())
                .unwrap();
        }
        ukf.run(t.measurements.iter().map(Some), Start::UpdateFirst, |rec| {
            let p = &rec.posterior().cov;
            assert_eq!(p, &p.transpose());
            assert!(
                (*p).cholesky().is_some(),
                "{criterion:?} at {}: {p}",
                rec.step()
            );
        })
        .unwrap();
    }
}

#[test]
fn bad_measurements_give_typed_errors_and_leave_the_filter_untouched() {
    let (f, h) = w1();
    let mut ukf = Ukf::new(&f, &h, Vector4::zeros(), p0(), SigmaSet::recommended(4))
        .unwrap()
        .with_adaptive_kappa(
            KappaCriterion::MaximumLikelihood,
            KappaGrid::equidistant(0.0, 76.0, 10).unwrap(),
        )
        .unwrap();
    ukf.predict().unwrap();
    let before = (*ukf.mean(), *ukf.covariance());
    assert!(matches!(
        ukf.update(&Vector2::new(f64::NAN, 0.0)),
        Err(FilterError::NonFinite { .. })
    ));
    assert_eq!((*ukf.mean(), *ukf.covariance()), before);
    assert!(ukf.update(&Vector2::new(1.0, 0.0)).is_ok());
    assert!(matches!(
        Ukf::new(
            &f,
            &h,
            Vector4::zeros(),
            p0(),
            SigmaSet::Symmetric { kappa: -4.0 }
        ),
        Err(FilterError::InvalidParameter { .. })
    ));
}

mod angles_in_the_state {
    use super::*;
    use kalibra_filters::{AngleComponents, FilterError};
    use kalibra_linalg::{Matrix1, U1, U2};
    use kalibra_models::wrap_angle;
    use std::f64::consts::PI;

    /// A heading `theta` (wrapped into (-pi, pi] by the dynamics) turning at rate `omega`.
    #[derive(Clone, Debug)]
    struct Turning;

    impl kalibra_models::Dynamics<U2> for Turning {
        fn state_dim(&self) -> U2 {
            U2
        }
        fn transition(&self, _k: usize, x: &Vector2<f64>) -> Vector2<f64> {
            Vector2::new(wrap_angle(x[0] + x[1]), x[1])
        }
        fn jacobian(&self, _k: usize, _x: &Vector2<f64>) -> Matrix2<f64> {
            Matrix2::new(1.0, 1.0, 0.0, 1.0)
        }
        fn noise_cov(&self, _k: usize) -> Matrix2<f64> {
            Matrix2::new(1e-4, 0.0, 0.0, 1e-6)
        }
    }

    /// The heading measured directly; `wraps` chooses whether the residual wraps.
    #[derive(Clone, Debug)]
    struct Compass {
        wraps: bool,
    }

    impl kalibra_models::Measurement<U2, U1> for Compass {
        fn meas_dim(&self) -> U1 {
            U1
        }
        fn measure(&self, _k: usize, x: &Vector2<f64>) -> Vector1<f64> {
            Vector1::new(wrap_angle(x[0]))
        }
        fn jacobian(
            &self,
            _k: usize,
            _x: &Vector2<f64>,
        ) -> kalibra_linalg::nalgebra::Matrix1x2<f64> {
            kalibra_linalg::nalgebra::Matrix1x2::new(1.0, 0.0)
        }
        fn noise_cov(&self, _k: usize, _x: &Vector2<f64>) -> Matrix1<f64> {
            Matrix1::new(0.01)
        }
        fn residual(&self, z: &Vector1<f64>, zhat: &Vector1<f64>) -> Vector1<f64> {
            let d = z - zhat;
            if self.wraps {
                Vector1::new(wrap_angle(d[0]))
            } else {
                d
            }
        }
    }

    fn distance_to_pi(a: f64) -> f64 {
        wrap_angle(a - PI).abs()
    }

    /// Sigma points of a heading just below pi straddle +-pi after the wrapping dynamics: the
    /// plain mean lands near 0, the angle-aware state space near pi; the updated heading stays
    /// in (-pi, pi] and near pi.
    #[test]
    fn an_angle_state_near_pi_averages_to_pi_with_the_state_space() {
        let x0 = Vector2::new(PI - 0.05, 0.02);
        let p0 = Matrix2::new(0.2f64.powi(2), 0.0, 0.0, 1e-4);
        let set = SigmaSet::recommended(2);
        let compass = Compass { wraps: true };
        let mut plain = Ukf::new(Turning, compass.clone(), x0, p0, set).unwrap();
        let mut aware = Ukf::new(Turning, compass, x0, p0, set)
            .unwrap()
            .with_state_space(AngleComponents::new([0]))
            .unwrap();
        plain.predict().unwrap();
        aware.predict().unwrap();
        // The truth: pi - 0.03.
        assert!(
            distance_to_pi(aware.mean()[0]) < 0.05,
            "{}",
            aware.mean()[0]
        );
        assert!(distance_to_pi(plain.mean()[0]) > 1.0, "{}", plain.mean()[0]);
        // The angle-aware covariance is the spread of the points, not of a jump by 2 pi.
        assert!(aware.covariance()[(0, 0)] < 0.1);
        assert!(plain.covariance()[(0, 0)] > 1.0);

        // An update across the cut: measured -pi + 0.02 (that is pi + 0.02).
        let rec = aware.update(&Vector1::new(-PI + 0.02)).unwrap();
        let theta = rec.posterior().mean[0];
        assert!(theta > -PI && theta <= PI);
        assert!(distance_to_pi(theta) < 0.05, "{theta}");
        assert!(rec.nis() < 1.0);
    }

    /// A measurement model whose residual does not wrap: the default predicted measurement
    /// (central value plus mean residual) is thrown off by the cut, the circular mean is not.
    #[test]
    fn the_circular_measurement_mean_is_an_option() {
        let x0 = Vector2::new(PI - 0.05, 0.0);
        let p0 = Matrix2::new(0.2f64.powi(2), 0.0, 0.0, 1e-6);
        let set = SigmaSet::recommended(2);
        let compass = Compass { wraps: false };
        let mut plain = Ukf::new(Turning, compass.clone(), x0, p0, set).unwrap();
        let mut circular = Ukf::new(Turning, compass, x0, p0, set)
            .unwrap()
            .with_measurement_mean(AngleComponents::new([0]))
            .unwrap();
        let z = Vector1::new(PI - 0.04);
        let zhat_plain = plain.update(&z).unwrap().predicted_measurement()[0];
        let zhat_circular = circular.update(&z).unwrap().predicted_measurement()[0];
        assert!(distance_to_pi(zhat_circular) < 0.06, "{zhat_circular}");
        assert!(distance_to_pi(zhat_plain) > 1.0, "{zhat_plain}");
    }

    /// On a linear model without angles the spaces change nothing; an angle index beyond the
    /// dimension is a typed error.
    #[test]
    fn spaces_without_angles_equal_the_plain_ukf_and_bad_indices_are_errors() {
        let (f, h) = w1();
        let t = truth(2, 30);
        let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
        let set = SigmaSet::recommended(4);
        let plain = Ukf::new(&f, &h, x0, p0(), set)
            .unwrap()
            .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
            .unwrap();
        let spaced = Ukf::new(&f, &h, x0, p0(), set)
            .unwrap()
            .with_state_space(AngleComponents::new([]))
            .unwrap()
            .with_measurement_mean(AngleComponents::new([]))
            .unwrap()
            .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
            .unwrap();
        for (a, b) in plain.iter().zip(&spaced) {
            assert_relative_eq!(a.posterior().mean, b.posterior().mean, max_relative = 1e-12);
            assert_relative_eq!(a.posterior().cov, b.posterior().cov, max_relative = 1e-12);
        }
        assert!(matches!(
            Ukf::new(&f, &h, x0, p0(), set)
                .unwrap()
                .with_state_space(AngleComponents::new([4])),
            Err(FilterError::InvalidParameter { .. })
        ));
        assert!(matches!(
            Ukf::new(&f, &h, x0, p0(), set)
                .unwrap()
                .with_measurement_mean(AngleComponents::new([2])),
            Err(FilterError::InvalidParameter { .. })
        ));
    }
}
