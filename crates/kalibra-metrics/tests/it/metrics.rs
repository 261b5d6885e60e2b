//! Accumulators and consistency statistics against direct computations.

use kalibra_linalg::{Matrix2, Vector2};
use kalibra_metrics::{
    ChiSquareBand, Merge, MetricsError, SquaredErrors, StepMean, nees, time_average,
};
use proptest::prelude::*;

proptest! {
    /// Splitting the runs into two partial accumulators and merging gives the sums of one
    /// accumulator fed everything (to rounding: the order of additions differs).
    #[test]
    fn merged_partials_equal_one_accumulator(values in prop::collection::vec(prop::collection::vec(-1e3f64..1e3, 3), 1..40), split in 0usize..40) {
        let split = split.min(values.len());
        let steps = 2;
        let mut whole = SquaredErrors::new(steps, 3);
        let mut a = SquaredErrors::new(steps, 3);
        let mut b = SquaredErrors::new(steps, 3);
        let mut mw = StepMean::new(steps);
        let (mut ma, mut mb) = (StepMean::new(steps), StepMean::new(steps));
        for (i, v) in values.iter().enumerate() {
            let k = i % steps;
            whole.push_slice(k, v).unwrap();
            mw.push(k, v[0]).unwrap();
            if i < split { a.push_slice(k, v).unwrap(); ma.push(k, v[0]).unwrap(); } else { b.push_slice(k, v).unwrap(); mb.push(k, v[0]).unwrap(); }
        }
        a.merge(&b);
        ma.merge(&mb);
        for k in 0..steps {
            prop_assert_eq!(ma.count(k), mw.count(k));
            if mw.count(k) > 0 {
                match (ma.mean(k), mw.mean(k)) {
                    (Some(a), Some(w)) => prop_assert!((a - w).abs() <= 1e-12 * (1.0 + w.abs())),
                    (a, w) => prop_assert_eq!(a, w),
                }
                for i in 0..3 {
                    let (x, y) = (a.mse(k, i).unwrap(), whole.mse(k, i).unwrap());
                    prop_assert!((x - y).abs() <= 1e-12 * (1.0 + y));
                }
            }
        }
    }

    /// The group RMSE is the root of the sum of the component MSEs, and never below any
    /// component's RMSE.
    #[test]
    fn group_rmse_dominates_components(values in prop::collection::vec(prop::collection::vec(-10f64..10.0, 4), 1..20)) {
        let mut acc = SquaredErrors::new(1, 4);
        for v in &values { acc.push_slice(0, v).unwrap(); }
        let group = acc.rmse_group(0, &[0, 2]).unwrap();
        let direct = (values.iter().map(|v| v[0] * v[0] + v[2] * v[2]).sum::<f64>() / values.len() as f64).sqrt();
        prop_assert!((group - direct).abs() <= 1e-12 * (1.0 + direct));
        prop_assert!(group + 1e-12 >= acc.rmse(0, 0).unwrap());
    }
}

#[test]
fn rmse_over_time_is_root_mean_of_mse() {
    let mut acc = SquaredErrors::new(3, 1);
    for (k, e) in [1.0, 2.0, 3.0].iter().enumerate() {
        acc.push_slice(k, &[*e]).unwrap();
    }
    assert!((acc.rmse_over_time(&[0], 0..3).unwrap() - (14.0f64 / 3.0).sqrt()).abs() < 1e-15);
    assert!((acc.rmse_over_time(&[0], 1..3).unwrap() - 6.5f64.sqrt()).abs() < 1e-15);
    assert!(matches!(
        acc.rmse_over_time(&[0], 2..2),
        Err(MetricsError::InvalidParameter { .. })
    ));
    assert!((time_average(&[1.0, 2.0, 6.0]).unwrap() - 3.0).abs() < 1e-15);
}

#[test]
fn typed_errors_for_bad_input() {
    let mut acc = SquaredErrors::new(2, 2);
    assert!(matches!(
        acc.push_slice(2, &[0.0, 0.0]),
        Err(MetricsError::StepOutOfRange { step: 2, steps: 2 })
    ));
    assert!(matches!(
        acc.push_slice(0, &[0.0]),
        Err(MetricsError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        acc.mse(0, 5),
        Err(MetricsError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        StepMean::new(1).push(1, 0.0),
        Err(MetricsError::StepOutOfRange { .. })
    ));
    let e = Vector2::new(1.0, 1.0);
    assert!(matches!(
        nees(&e, &Matrix2::new(1.0, 2.0, 2.0, 1.0)),
        Err(MetricsError::Linalg(_))
    ));
    assert!(matches!(
        nees(&e, &Matrix2::new(f64::NAN, 0.0, 0.0, 1.0)),
        Err(MetricsError::Linalg(_))
    ));
    assert!(matches!(
        ChiSquareBand::for_mean(0.0, 10, 0.95),
        Err(MetricsError::InvalidParameter { .. })
    ));
    assert!(matches!(
        ChiSquareBand::for_mean(2.0, 0, 0.95),
        Err(MetricsError::InvalidParameter { .. })
    ));
    assert!(matches!(
        ChiSquareBand::for_mean(2.0, 10, 1.0),
        Err(MetricsError::InvalidParameter { .. })
    ));
    assert_eq!(StepMean::new(2).mean(0), None);
    // A sum beyond f64's range would have made the mean inf; it is refused and the
    // accumulator stays as it was.
    let mut m = StepMean::new(1);
    m.push(0, f64::MAX).unwrap();
    assert!(matches!(
        m.push(0, f64::MAX),
        Err(MetricsError::NonFiniteSample { index: 0, .. })
    ));
    assert_eq!(m.mean(0), Some(f64::MAX));
    assert_eq!(m.count(0), 1);
    assert!(matches!(time_average(&[]), Err(MetricsError::Empty { .. })));
    assert_eq!(time_average(&[f64::MAX; 3]), Ok(f64::MAX));
    assert!(matches!(
        time_average(&[0.0, f64::INFINITY]),
        Err(MetricsError::NonFiniteSample { index: 1, .. })
    ));
}

#[test]
fn chi_square_band_matches_tabulated_quantiles() {
    // chi2 quantiles for 100 dof: 2.5% = 74.2219, 97.5% = 129.5612 (standard tables).
    let b = ChiSquareBand::for_mean(4.0, 25, 0.95).unwrap();
    assert!((b.lower * 25.0 - 74.2219).abs() < 1e-3, "{b:?}");
    assert!((b.upper * 25.0 - 129.5612).abs() < 1e-3, "{b:?}");
    let n = ChiSquareBand::for_normalized_mean(4.0, 25, 0.95).unwrap();
    assert!((n.lower - b.lower / 4.0).abs() < 1e-15 && n.contains(1.0) && !n.contains(1.5));
}

/// The NIS and NEES of a NaN or infinite vector came back as a NaN or an infinity
/// inside `Ok`; a form beyond f64's range of a finite vector did too.
#[test]
fn nis_and_nees_of_non_finite_vectors_are_errors() {
    use kalibra_linalg::{Covariance, LinalgError};
    use kalibra_metrics::nis;
    let p = Matrix2::new(2.0, 0.5, 0.5, 1.0);
    let s = Covariance::new(p).unwrap();
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let v = Vector2::new(1.0, bad);
        assert!(matches!(
            nis(&v, &s),
            Err(MetricsError::Linalg(LinalgError::NonFinite {
                what: "vector"
            }))
        ));
        assert!(matches!(
            s.quad_form(&v),
            Err(LinalgError::NonFinite { .. })
        ));
        assert!(nees(&v, &p).is_err());
    }
    let huge = Vector2::new(1e300, -1e300);
    assert!(matches!(
        nis(
            &huge,
            &Covariance::new(Matrix2::identity() * 1e-300).unwrap()
        ),
        Err(MetricsError::Linalg(LinalgError::NonFinite {
            what: "quadratic form"
        }))
    ));
    // Extremes whose form is finite are computed.
    let q = nis(
        &Vector2::new(1e150, 0.0),
        &Covariance::new(Matrix2::identity()).unwrap(),
    );
    assert!((q.unwrap() / 1e300 - 1.0).abs() < 1e-12);
    let tiny = Covariance::new(Matrix2::identity() * 1e-300).unwrap();
    assert!((nis(&Vector2::new(1e-150, 0.0), &tiny).unwrap() - 1.0).abs() < 1e-12);
    // Solves refuse what would come back non-finite.
    assert!(matches!(
        s.solve(&Vector2::new(f64::NAN, 0.0)),
        Err(LinalgError::NonFinite {
            what: "right-hand side"
        })
    ));
    assert!(tiny.solve(&Vector2::new(1e300, 0.0)).is_err());
    assert!(
        s.trace_solve(&(Matrix2::identity() * f64::INFINITY))
            .is_err()
    );
}

/// Found by the adversarial suite: subnormal degrees of freedom panicked inside
/// statrs, a confidence whose upper tail rounds to 1 gave an infinite bound, and degrees of
/// freedom near f64::MAX an infinite or NaN bound, all inside `Ok`. Every `Ok` band is finite.
#[test]
fn chi_square_bands_at_extreme_parameters_are_finite_or_errors() {
    for dof in [5e-324, 1e-308, 1e-10, 1e-3, 0.5, 3.0, 1e7, 1e300, f64::MAX] {
        for samples in [1usize, 2, 5, 1 << 40, usize::MAX] {
            for confidence in [0.95, 1.0 - 1e-16, 1e-300, 0.5] {
                let band =
                    std::panic::catch_unwind(|| ChiSquareBand::for_mean(dof, samples, confidence))
                        .unwrap_or_else(|_| panic!("panic at {dof:e} {samples} {confidence}"));
                if let Ok(b) = band {
                    assert!(
                        b.lower.is_finite() && b.upper.is_finite() && b.lower <= b.upper,
                        "{dof:e} {samples} {confidence}: {b:?}"
                    );
                }
            }
        }
    }
    assert!(ChiSquareBand::for_mean(5e-324, 2, 0.95).is_err());
    assert!(ChiSquareBand::for_mean(2.0, 10, 1.0 - 1e-16).is_err());
    assert!(ChiSquareBand::for_mean(1e-3, 1, 0.95).is_ok());
}

/// Found by the adversarial suite: a squared error beyond f64's range made the RMSE
/// inf inside `Ok`; it is refused, and MSEs near f64::MAX still give a finite group RMSE.
#[test]
fn squared_errors_stay_finite() {
    let mut acc = SquaredErrors::new(1, 2);
    assert!(matches!(
        acc.push_slice(0, &[0.0, 2e300]),
        Err(MetricsError::NonFiniteSample { index: 0, .. })
    ));
    assert!(acc.mse(0, 0).is_err(), "nothing stored");
    // Each square within range (1.44e308), their sum beyond it.
    acc.push_slice(0, &[1.2e154, 1.2e154]).unwrap();
    let group = acc.rmse_group(0, &[0, 1]).unwrap();
    assert!((group / (1.2e154 * 2f64.sqrt()) - 1.0).abs() < 1e-15);
    let mut big = SquaredErrors::new(2, 2);
    for k in 0..2 {
        big.push_slice(k, &[1.2e154, 1.2e154]).unwrap();
    }
    let over_time = big.rmse_over_time(&[0, 1], 0..2).unwrap();
    assert!(over_time.is_finite());
    assert!((over_time / (1.2e154 * 2f64.sqrt()) - 1.0).abs() < 1e-15);
}

/// The accumulators a Monte Carlo shard writes read back to the bit (serde_json with
/// float_roundtrip), and a record whose parts disagree does not read.
#[test]
fn accumulators_round_trip_through_json_and_refuse_inconsistent_records() {
    use kalibra_metrics::{Credibility, SquaredErrors, StepMean};
    let mut mean = StepMean::new(2);
    let mut squared = SquaredErrors::new(2, 2);
    let mut cred = Credibility::new(2, 2);
    for (i, v) in [0.1, 1.0 / 3.0, 2e-300, 7e150].iter().enumerate() {
        mean.push(i % 2, *v).unwrap();
        squared.push_slice(i % 2, &[*v, -v / 7.0]).unwrap();
        cred.push_nees(i % 2, &[*v, -v / 7.0], *v).unwrap();
    }
    let back: StepMean = serde_json::from_str(&serde_json::to_string(&mean).unwrap()).unwrap();
    assert_eq!(back, mean);
    let back: SquaredErrors =
        serde_json::from_str(&serde_json::to_string(&squared).unwrap()).unwrap();
    assert_eq!(back, squared);
    let back: Credibility = serde_json::from_str(&serde_json::to_string(&cred).unwrap()).unwrap();
    assert_eq!(back, cred);

    let bad = [
        (r#"{"sum":[1.0],"count":[]}"#, "1 sums and 0 counts"),
        (r#"{"sum":[1.0],"count":[1],"extra":0}"#, "unknown field"),
    ];
    for (text, why) in bad {
        let err = serde_json::from_str::<StepMean>(text)
            .unwrap_err()
            .to_string();
        assert!(err.contains(why), "{err}");
    }
    let err = serde_json::from_str::<SquaredErrors>(r#"{"dim":2,"sum":[1.0],"count":[1]}"#)
        .unwrap_err()
        .to_string();
    assert!(err.contains("dimension 2 with 1 sums for 1 steps"), "{err}");
    let err = serde_json::from_str::<Credibility>(r#"{"dim":2,"errors":[[1.0]],"nees":[[1.0]]}"#)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("1 error values for 1 runs of dimension 2"),
        "{err}"
    );
}
