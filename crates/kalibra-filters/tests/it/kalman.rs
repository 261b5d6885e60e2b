//! KF and EKF behaviour: agreement with each other and with a textbook implementation, the
//! prior split used by J1/J2, and typed errors that leave the filter untouched.

use approx::assert_relative_eq;
use kalibra_filters::{
    Ekf, Filter, FilterError, FilterOptions, InitialCheck, Kf, Start, UpdateForm,
};
use kalibra_linalg::{
    DMatrix, DVector, Dyn, Matrix2, Matrix4, SMatrix, Vector2, Vector4, propagate, quad_form_once,
};
use kalibra_models::{Kinematic, LinearGaussian, LinearObservation, ProcessNoise, simulate};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;

use crate::common::{p0, truth, w1};

/// W1's models with run-time (`Dyn`) sizes.
fn w1_dynamic() -> (LinearGaussian<Dyn>, LinearObservation<Dyn, Dyn>) {
    let (f, h) = w1();
    (
        LinearGaussian::new(
            DMatrix::from_column_slice(4, 4, f.f().as_slice()),
            DMatrix::from_column_slice(4, 4, f.q().matrix().as_slice()),
        )
        .unwrap(),
        LinearObservation::new(
            DMatrix::from_column_slice(2, 4, h.h().as_slice()),
            DMatrix::from_column_slice(2, 2, h.r().matrix().as_slice()),
        )
        .unwrap(),
    )
}

#[test]
fn ekf_equals_kf_on_a_linear_model() {
    let (f, h) = w1();
    let t = truth(1, 200);
    let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let kf = Kf::new(&f, &h, x0, p0())
        .unwrap()
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    let ekf = Ekf::new(&f, &h, x0, p0())
        .unwrap()
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    assert_eq!(kf.len(), 200);
    for (a, b) in kf.iter().zip(&ekf) {
        assert_relative_eq!(
            a.posterior().mean,
            b.posterior().mean,
            epsilon = 1e-12,
            max_relative = 1e-12
        );
        assert_relative_eq!(
            a.posterior().cov,
            b.posterior().cov,
            epsilon = 1e-12,
            max_relative = 1e-12
        );
        assert_relative_eq!(a.gain(), b.gain(), epsilon = 1e-12);
    }
}

/// The textbook recursion with an explicit inverse and the standard update, written out here
/// independently of the library.
#[test]
fn kf_matches_a_textbook_recursion() {
    let (f, h) = w1();
    let (fm, qm, hm, rm) = (*f.f(), *f.q().matrix(), *h.h(), *h.r().matrix());
    let t = truth(2, 100);
    let (mut x, mut p) = (Vector4::new(0.0, 0.0, 10.0, -5.0), p0());
    let mut kf = Kf::new(&f, &h, x, p).unwrap();
    for (i, z) in t.measurements.iter().enumerate() {
        if i > 0 {
            x = fm * x;
            p = fm * p * fm.transpose() + qm;
            kf.predict().unwrap();
        }
        let s = hm * p * hm.transpose() + rm;
        let k = p * hm.transpose() * s.try_inverse().unwrap();
        x += k * (z - hm * x);
        p = (Matrix4::identity() - k * hm) * p;
        let rec = kf.update(z).unwrap();
        assert_relative_eq!(rec.posterior().mean, x, max_relative = 1e-9);
        assert_relative_eq!(rec.posterior().cov, p, max_relative = 1e-9, epsilon = 1e-9);
        assert_relative_eq!(rec.s_matrix(), &s, max_relative = 1e-12);
    }
}

#[test]
fn fixed_and_dynamic_sizes_agree() {
    let (f, h) = w1();
    let (fd, hd) = w1_dynamic();
    let t = truth(3, 50);
    let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let fixed = Kf::new(&f, &h, x0, p0())
        .unwrap()
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    let zs: Vec<DVector<f64>> = t
        .measurements
        .iter()
        .map(|z| DVector::from_column_slice(z.as_slice()))
        .collect();
    let mut kd = Kf::new(
        &fd,
        &hd,
        DVector::from_column_slice(x0.as_slice()),
        DMatrix::from_column_slice(4, 4, p0().as_slice()),
    )
    .unwrap();
    let dynamic = kd
        .run_collect(zs.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    for (a, b) in fixed.iter().zip(&dynamic) {
        assert_relative_eq!(
            a.posterior().mean.as_slice(),
            b.posterior().mean.as_slice(),
            max_relative = 1e-12
        );
        assert_relative_eq!(a.nis(), b.nis(), max_relative = 1e-12);
    }
    // A measurement of the wrong length is a typed error at the dynamic boundary.
    let err = kd
        .update(&DVector::from_vec(vec![1.0, 2.0, 3.0]))
        .unwrap_err();
    assert!(
        matches!(
            err,
            FilterError::DimensionMismatch {
                expected: 2,
                found: 3,
                ..
            }
        ),
        "{err}"
    );
    let wrong_x0 = Kf::<Dyn, Dyn, _, _>::new(&fd, &hd, DVector::zeros(3), DMatrix::identity(4, 4));
    assert!(matches!(wrong_x0, Err(FilterError::Initial(_))));
}

#[test]
fn prior_splits_into_propagated_and_process_noise() {
    let (f, h) = w1();
    let t = truth(4, 30);
    let mut kf = Kf::new(&f, &h, Vector4::new(0.0, 0.0, 10.0, -5.0), p0()).unwrap();
    let first = kf.update(&t.measurements[0]).unwrap().clone();
    // An update with no prediction before it: the prior is all "propagated", B = 0.
    assert_eq!(first.compute_b(), Matrix2::zeros());
    assert_relative_eq!(
        first.compute_a() + first.r(),
        first.s_matrix(),
        max_relative = 1e-12
    );
    let mut prev_post = first.posterior().cov;
    for z in &t.measurements[1..10] {
        kf.predict().unwrap();
        let rec = kf.update(z).unwrap();
        assert_relative_eq!(
            rec.propagated(),
            &(f.f() * prev_post * f.f().transpose()),
            max_relative = 1e-12
        );
        assert_relative_eq!(rec.process_noise(), f.q().matrix(), max_relative = 1e-12);
        assert_relative_eq!(
            rec.compute_a() + rec.compute_b() + rec.r(),
            rec.s_matrix(),
            max_relative = 1e-12
        );
        prev_post = rec.posterior().cov;
    }
    // Two predictions between updates carry both parts.
    kf.predict().unwrap();
    kf.predict().unwrap();
    let rec = kf.update(&t.measurements[12]).unwrap();
    let ff = f.f() * f.f();
    assert_relative_eq!(
        rec.propagated(),
        &(ff * prev_post * ff.transpose()),
        max_relative = 1e-12
    );
    assert_relative_eq!(
        rec.process_noise(),
        &(propagate(f.f(), f.q().matrix()) + f.q().matrix()),
        max_relative = 1e-12
    );
    assert_relative_eq!(
        rec.compute_a() + rec.compute_b() + rec.r(),
        rec.s_matrix(),
        max_relative = 1e-12
    );
}

#[test]
fn gaps_in_the_sequence_only_predict() {
    let (f, h) = w1();
    let t = truth(5, 20);
    let zs: Vec<Option<&Vector2<f64>>> = t
        .measurements
        .iter()
        .enumerate()
        .map(|(i, z)| (i % 3 != 1).then_some(z))
        .collect();
    let mut kf = Kf::new(&f, &h, Vector4::new(0.0, 0.0, 10.0, -5.0), p0()).unwrap();
    let recs = kf.run_collect(zs, Start::UpdateFirst).unwrap();
    let steps: Vec<usize> = recs.iter().map(|r| r.step()).collect();
    assert_eq!(steps, (0..20).filter(|i| i % 3 != 1).collect::<Vec<_>>());
    assert_eq!(kf.step_index(), 19);
    let mut late = Kf::new(&f, &h, Vector4::new(0.0, 0.0, 10.0, -5.0), p0()).unwrap();
    let recs = late
        .run_collect(t.measurements.iter().map(Some), Start::PredictFirst)
        .unwrap();
    assert_eq!(recs[0].step(), 1);
}

#[test]
fn bad_data_gives_typed_errors_and_leaves_the_filter_untouched() {
    let (f, h) = w1();
    let mut kf = Kf::new(&f, &h, Vector4::new(0.0, 0.0, 10.0, -5.0), p0()).unwrap();
    let (x, p) = (*kf.mean(), *kf.covariance());
    for bad in [
        Vector2::new(f64::NAN, 0.0),
        Vector2::new(0.0, f64::INFINITY),
        Vector2::new(f64::NEG_INFINITY, 1.0),
    ] {
        let err = kf.update(&bad).unwrap_err();
        assert!(
            matches!(
                err,
                FilterError::NonFinite {
                    what: "measurement",
                    step: 0
                }
            ),
            "{err}"
        );
        assert_eq!((*kf.mean(), *kf.covariance()), (x, p));
    }
    // Singular S: no measurement noise and no uncertainty in the measured components.
    let exact = LinearObservation::new(*h.h(), Matrix2::zeros()).unwrap();
    let certain = Matrix4::from_diagonal(&Vector4::new(0.0, 0.0, 1.0, 1.0));
    let mut kf = Kf::new(&f, &exact, Vector4::zeros(), certain).unwrap();
    let err = kf.update(&Vector2::new(1.0, 1.0)).unwrap_err();
    assert!(
        matches!(
            err,
            FilterError::NotPositiveDefinite {
                what: "innovation covariance S",
                step: 0
            }
        ),
        "{err}"
    );
    assert_eq!(kf.covariance(), &certain);
    // Indefinite or non-finite initial covariance.
    let indefinite = Matrix4::from_diagonal(&Vector4::new(1.0, -1.0, 1.0, 1.0));
    assert!(matches!(
        Kf::new(&f, &h, Vector4::zeros(), indefinite),
        Err(FilterError::Initial(_))
    ));
    let mut nan = p0();
    nan[(2, 2)] = f64::NAN;
    assert!(matches!(
        Kf::new(&f, &h, Vector4::zeros(), nan),
        Err(FilterError::Initial(_))
    ));
    // The symmetric-only check accepts the indefinite P0 (for paper 000's printed matrix).
    let opts = FilterOptions {
        initial_check: InitialCheck::SymmetricOnly,
        ..Default::default()
    };
    assert!(Kf::with_options(&f, &h, Vector4::zeros(), indefinite, opts).is_ok());
}

/// The record's NEES is the checked quadratic form of `kalibra_linalg::quad_form_once` (what
/// `kalibra_metrics::nees` computes), bit for bit, and reports bad errors and a singular
/// posterior as typed errors.
#[test]
fn record_nees_equals_the_checked_quadratic_form() {
    let (f, h) = w1();
    let t = truth(5, 50);
    let mut kf = Kf::new(&f, &h, Vector4::new(0.0, 0.0, 10.0, -5.0), p0()).unwrap();
    for (k, (x, z)) in t.states.iter().zip(&t.measurements).enumerate() {
        if k > 0 {
            kf.predict().unwrap();
        }
        let rec = kf.update(z).unwrap();
        let e = x - rec.posterior().mean;
        let checked = quad_form_once(&rec.posterior().cov, &e, "P").unwrap();
        assert_eq!(rec.nees(&e).unwrap().to_bits(), checked.to_bits());
        assert!(matches!(
            rec.nees(&Vector4::new(0.0, f64::NAN, 0.0, 0.0)),
            Err(FilterError::NonFinite { step, .. }) if step == k
        ));
    }
    // A semi-definite P0 with no process noise in between keeps the posterior singular.
    let certain = Matrix4::from_diagonal(&Vector4::new(1.0, 1.0, 0.0, 0.0));
    let mut kf = Kf::new(&f, &h, Vector4::zeros(), certain).unwrap();
    let rec = kf.update(&Vector2::new(1.0, 1.0)).unwrap();
    assert!(matches!(
        rec.nees(&Vector4::new(1.0, 0.0, 0.0, 0.0)),
        Err(FilterError::NotPositiveDefinite {
            what: "posterior covariance P+",
            step: 0
        })
    ));
    // Dynamic sizes check the length.
    let (fd, hd) = w1_dynamic();
    let mut kf = Kf::new(
        &fd,
        &hd,
        DVector::zeros(4),
        DMatrix::from_column_slice(4, 4, p0().as_slice()),
    )
    .unwrap();
    let rec = kf.update(&DVector::from_vec(vec![1.0, 1.0])).unwrap();
    assert!(matches!(
        rec.nees(&DVector::zeros(3)),
        Err(FilterError::DimensionMismatch {
            expected: 4,
            found: 3,
            ..
        })
    ));
}

#[test]
fn standard_form_is_available_and_agrees_at_the_optimal_gain() {
    let (f, h) = w1();
    let t = truth(6, 50);
    let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let opts = FilterOptions {
        update: UpdateForm::Standard,
        ..Default::default()
    };
    let a = Kf::new(&f, &h, x0, p0())
        .unwrap()
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    let b = Kf::with_options(&f, &h, x0, p0(), opts)
        .unwrap()
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    for (a, b) in a.iter().zip(&b) {
        assert_relative_eq!(
            a.posterior().cov,
            b.posterior().cov,
            max_relative = 1e-10,
            epsilon = 1e-10
        );
    }
}

#[test]
fn continuous_noise_model_and_ca_run_without_error() {
    let ca = Kinematic::constant_acceleration(1, 0.1)
        .unwrap()
        .noise(ProcessNoise::Continuous { q: 0.3 });
    let f = ca.dynamics(kalibra_linalg::U3).unwrap();
    let h = ca
        .position_measurement(
            kalibra_linalg::U3,
            kalibra_linalg::U1,
            SMatrix::<f64, 1, 1>::new(0.5),
        )
        .unwrap();
    let t = simulate(
        &f,
        &h,
        kalibra_linalg::Vector3::new(0.0, 1.0, 0.1),
        100,
        &mut ChaCha8Rng::seed_from_u64(9),
    )
    .unwrap();
    let mut kf = Kf::new(
        &f,
        &h,
        kalibra_linalg::Vector3::zeros(),
        kalibra_linalg::Matrix3::identity(),
    )
    .unwrap();
    let recs = kf
        .run_collect(t.measurements.iter().map(Some), Start::UpdateFirst)
        .unwrap();
    let mean_nis: f64 = recs.iter().map(|r| r.nis()).sum::<f64>() / recs.len() as f64;
    // 100 NIS values of 1 degree of freedom: the mean is within 0.5 of 1 with probability > 0.999.
    assert!((mean_nis - 1.0).abs() < 0.5, "{mean_nis}");
}

#[test]
fn steady_state_is_where_the_kf_converges() {
    use kalibra_filters::steady_state;
    let (f, h) = w1();
    let ss = steady_state(f.f(), h.h(), f.q().matrix(), h.r().matrix()).unwrap();
    // The covariance recursion does not depend on the data: run the KF long enough.
    let t = truth(5, 400);
    let mut kf = Kf::new(&f, &h, Vector4::zeros(), p0()).unwrap();
    let records = kf
        .run_collect(t.measurements.iter().map(Some), Start::PredictFirst)
        .unwrap();
    let last = records.last().unwrap();
    assert_relative_eq!(*last.gain(), ss.gain, max_relative = 1e-9);
    assert_relative_eq!(last.prior().cov, ss.prior, max_relative = 1e-9);
    assert_relative_eq!(last.posterior().cov, ss.posterior, max_relative = 1e-9);
    // Fixed point: one more Riccati step reproduces the prior.
    let next = propagate(f.f(), &ss.posterior) + f.q().matrix();
    assert_relative_eq!(next, ss.prior, max_relative = 1e-11);
}

#[test]
fn steady_state_of_an_undetectable_model_is_an_error() {
    use kalibra_filters::steady_state;
    // An unstable mode the measurement never sees: the prior grows without bound.
    let f = Matrix2::new(2.0, 0.0, 0.0, 0.5);
    let h = kalibra_linalg::nalgebra::Matrix1x2::new(0.0, 1.0);
    let r = kalibra_linalg::Matrix1::new(1.0);
    assert!(steady_state(&f, &h, &Matrix2::identity(), &r).is_err());
    assert!(steady_state(&(f * f64::NAN), &h, &Matrix2::identity(), &r).is_err());
}

#[test]
fn constant_gain_kf_with_the_steady_state_gain_equals_the_kf_after_convergence() {
    use kalibra_filters::ConstantGainKf;
    let (f, h) = w1();
    let t = truth(9, 600);
    let gain = ConstantGainKf::steady_state_gain(&f, &h, 0, &Vector4::zeros()).unwrap();
    let mut kf = Kf::new(&f, &h, Vector4::zeros(), p0()).unwrap();
    let mut cgkf = ConstantGainKf::new(&f, &h, Vector4::zeros(), p0(), gain).unwrap();
    let a = kf
        .run_collect(t.measurements.iter().map(Some), Start::PredictFirst)
        .unwrap();
    let b = cgkf
        .run_collect(t.measurements.iter().map(Some), Start::PredictFirst)
        .unwrap();
    assert!(b.iter().all(|r| *r.gain() == gain));
    // Early on the two differ (the KF's gain is still large) ...
    let gap = |i: usize| (a[i].posterior().mean - b[i].posterior().mean).amax();
    assert!(gap(0) > 1.0);
    // ... then the KF's gain converges to the constant one and the difference of the
    // estimates decays with the closed loop: equal to rounding after convergence.
    let last = a.len() - 1;
    assert!(gap(last) <= 1e-9 * (1.0 + a[last].posterior().mean.amax()));
    assert_relative_eq!(
        a[last].posterior().cov,
        b[last].posterior().cov,
        max_relative = 1e-9
    );
}

#[test]
fn constant_gain_kf_rejects_a_bad_gain_and_keeps_its_gain() {
    use kalibra_filters::ConstantGainKf;
    let (f, h) = w1();
    let mut bad = SMatrix::<f64, 4, 2>::zeros();
    bad[(0, 0)] = f64::NAN;
    assert!(matches!(
        ConstantGainKf::new(&f, &h, Vector4::zeros(), p0(), bad),
        Err(FilterError::Initial(_))
    ));
    // Dyn sizes: a gain of the wrong shape is a typed error.
    let (fd, hd) = w1_dynamic();
    assert!(
        ConstantGainKf::new(
            &fd,
            &hd,
            DVector::zeros(4),
            DMatrix::identity(4, 4),
            DMatrix::zeros(4, 3)
        )
        .is_err()
    );
    // A detuned gain stays as given, and the Joseph covariance stays symmetric PSD.
    let gain = SMatrix::<f64, 4, 2>::new(0.5, 0.0, 0.0, 0.5, 0.1, 0.0, 0.0, 0.1);
    let mut cgkf = ConstantGainKf::new(&f, &h, Vector4::zeros(), p0(), gain).unwrap();
    let t = truth(3, 50);
    cgkf.run(t.measurements.iter().map(Some), Start::PredictFirst, |r| {
        assert_eq!(*r.gain(), gain);
        let p = &r.posterior().cov;
        assert_eq!(*p, p.transpose());
        assert!(p.symmetric_eigenvalues().min() > 0.0);
    })
    .unwrap();
    assert_eq!(*cgkf.gain(), gain);
}

/// `steady_state` refuses noise covariances that are not covariances (asymmetric, indefinite,
/// negative) at step 0 by the shared check, naming the matrix, rather than returning `Ok`.
#[test]
fn steady_state_refuses_noise_that_is_not_a_covariance() {
    use kalibra_filters::steady_state;
    let f = Matrix2::new(1.0, 1.0, 0.0, 1.0);
    let h = kalibra_linalg::nalgebra::Matrix1x2::new(1.0, 0.0);
    let r = kalibra_linalg::Matrix1::new(1.0);
    let q = Matrix2::new(0.25, 0.5, 0.5, 1.0);
    assert!(steady_state(&f, &h, &q, &r).is_ok());
    for bad_q in [
        Matrix2::new(0.25, 0.5, 0.0, 1.0),
        Matrix2::new(1.0, 2.0, 2.0, 1.0),
        -q,
    ] {
        assert!(
            matches!(
                steady_state(&f, &h, &bad_q, &r),
                Err(FilterError::NotPositiveDefinite {
                    what: "process noise Q",
                    step: 0
                })
            ),
            "{bad_q}"
        );
    }
    assert!(matches!(
        steady_state(&f, &h, &q, &kalibra_linalg::Matrix1::new(-1.0)),
        Err(FilterError::NotPositiveDefinite {
            what: "measurement noise R",
            step: 0
        })
    ));
}

/// `Dyn` sizes that disagree are a `DimensionMismatch` naming both sizes,
/// not a panic inside nalgebra.
#[test]
fn steady_state_checks_dyn_sizes() {
    use kalibra_filters::steady_state;
    let f = DMatrix::<f64>::identity(2, 2) * 0.5;
    let h = DMatrix::<f64>::identity(1, 2);
    let (q, r) = (
        DMatrix::<f64>::identity(2, 2),
        DMatrix::<f64>::identity(1, 1),
    );
    assert!(steady_state(&f, &h, &q, &r).is_ok());
    let mismatch = |e| matches!(e, Err(FilterError::DimensionMismatch { .. }));
    assert!(mismatch(steady_state(&f, &h, &DMatrix::identity(2, 3), &r)));
    assert!(mismatch(steady_state(&f, &h, &DMatrix::identity(3, 3), &r)));
    assert!(mismatch(steady_state(&f, &h, &q, &DMatrix::identity(1, 2))));
    assert!(mismatch(steady_state(&f, &h, &q, &DMatrix::identity(2, 2))));
    assert!(mismatch(steady_state(&f, &DMatrix::identity(1, 3), &q, &r)));
    assert!(mismatch(steady_state(&DMatrix::identity(2, 3), &h, &q, &r)));
    assert_eq!(
        steady_state(&f, &h, &DMatrix::identity(2, 3), &r).err(),
        Some(FilterError::DimensionMismatch {
            what: "process noise Q columns",
            expected: 2,
            found: 3
        })
    );
}
