//! Every `Dyn` size is checked where it enters. Filters built from models
//! whose sizes disagree (an `H` for another state, a bearing sensor whose coordinates lie
//! outside the state) are a `DimensionMismatch` naming both sizes at construction; before,
//! the constructors accepted them and nalgebra panicked at the first step.

use kalibra_filters::{ConstantGainKf, Ekf, FilterError, Kf, SigmaSet, Srf, Ukf};
use kalibra_linalg::{DMatrix, DVector, Dyn, Vector2};
use kalibra_models::{
    Bearing, BearingReference, Coordinate, LinearGaussian, LinearObservation, Stationary,
};

fn dynamics(n: usize) -> LinearGaussian<Dyn> {
    LinearGaussian::new(DMatrix::identity(n, n) * 0.5, DMatrix::identity(n, n) * 0.1).unwrap()
}

fn observation(n: usize) -> LinearObservation<Dyn, Dyn> {
    LinearObservation::new(DMatrix::identity(2, n), DMatrix::identity(2, 2)).unwrap()
}

fn bearing(n: usize, index: usize) -> Bearing<Dyn, Stationary<2>> {
    Bearing::from_coordinates(
        Dyn(n),
        [Coordinate::State(0), Coordinate::State(index)],
        BearingReference::XAxis,
        1e-4,
        Stationary(Vector2::new(0.0, -10.0)),
    )
    .unwrap()
}

fn mismatch(expected: usize, found: usize) -> impl Fn(FilterError) -> bool {
    move |e| {
        matches!(e, FilterError::DimensionMismatch { expected: x, found: f, .. }
            if x == expected && f == found)
    }
}

#[test]
fn filters_refuse_models_built_for_another_state() {
    let (x0, p0) = (DVector::from_element(4, 1.0), DMatrix::identity(4, 4));
    let ok = mismatch(4, 6);
    // The matching pair builds.
    assert!(Kf::new(dynamics(4), observation(4), x0.clone(), p0.clone()).is_ok());
    assert!(ok(Kf::new(
        dynamics(4),
        observation(6),
        x0.clone(),
        p0.clone()
    )
    .unwrap_err()));
    assert!(ok(Ekf::new(
        dynamics(4),
        observation(6),
        x0.clone(),
        p0.clone()
    )
    .unwrap_err()));
    assert!(ok(Ukf::new(
        dynamics(4),
        observation(6),
        x0.clone(),
        p0.clone(),
        SigmaSet::Symmetric { kappa: 0.0 }
    )
    .unwrap_err()));
    let gain = DMatrix::zeros(4, 2);
    assert!(ok(ConstantGainKf::new(
        dynamics(4),
        observation(6),
        x0.clone(),
        p0.clone(),
        gain
    )
    .unwrap_err()));
    // Borrowed models are checked the same way.
    let (f, h) = (dynamics(4), observation(6));
    assert!(ok(Kf::new(&f, &h, x0.clone(), p0.clone()).unwrap_err()));
    assert!(ok(
        ConstantGainKf::steady_state_gain(&f, &h, 0, &x0).unwrap_err()
    ));
}

#[test]
fn a_bearing_sensor_whose_coordinates_lie_outside_the_state_is_refused() {
    let (x0, p0) = (DVector::from_element(4, 1.0), DMatrix::identity(4, 4));
    assert!(Srf::new(dynamics(4), bearing(4, 3), x0.clone(), p0.clone()).is_ok());
    // Built for a state of 6 with its y coordinate at index 5: outside a state of 4.
    let e = Srf::new(dynamics(4), bearing(6, 5), x0.clone(), p0.clone()).unwrap_err();
    assert!(mismatch(4, 6)(e));
    let e = Ekf::new(dynamics(4), bearing(6, 5), x0.clone(), p0.clone()).unwrap_err();
    assert!(mismatch(4, 6)(e));
    let e = Ukf::new(
        dynamics(4),
        bearing(6, 5),
        x0,
        p0,
        SigmaSet::Symmetric { kappa: 0.0 },
    )
    .unwrap_err();
    assert!(mismatch(4, 6)(e));
}

#[test]
fn a_linearisation_point_of_another_size_is_refused() {
    let (f, h) = (dynamics(4), observation(4));
    assert!(ConstantGainKf::steady_state_gain(&f, &h, 0, &DVector::zeros(4)).is_ok());
    let e = ConstantGainKf::steady_state_gain(&f, &h, 0, &DVector::zeros(3)).unwrap_err();
    assert!(mismatch(4, 3)(e));
    assert!(matches!(
        ConstantGainKf::steady_state_gain(&f, &h, 0, &DVector::from_element(4, f64::NAN)),
        Err(FilterError::NonFinite { .. })
    ));
}

/// A bearing sensor of a `Dyn` state whose Jacobian or position selection has one column too
/// many: the SRF's update is a `DimensionMismatch` naming both sizes, and
/// the filter is left as it was, where nalgebra panicked in the products.
#[test]
fn srf_refuses_a_bearing_sensor_answering_with_the_wrong_size() {
    use kalibra_filters::{BearingSensor, Filter};
    use kalibra_linalg::{DVector, Matrix1, OMatrix, U1, U2, Vector1};
    use kalibra_models::Measurement;

    #[derive(Clone, Copy, PartialEq)]
    enum Wrong {
        Jacobian,
        Selection,
    }
    struct Lying(Bearing<Dyn, Stationary<2>>, Wrong);
    impl Measurement<Dyn, U1> for Lying {
        fn meas_dim(&self) -> U1 {
            U1
        }
        fn expected_state_dim(&self) -> Option<usize> {
            self.0.expected_state_dim()
        }
        fn measure(&self, k: usize, x: &DVector<f64>) -> Vector1<f64> {
            self.0.measure(k, x)
        }
        fn jacobian(&self, k: usize, x: &DVector<f64>) -> OMatrix<f64, U1, Dyn> {
            let h = self.0.jacobian(k, x);
            if self.1 == Wrong::Jacobian {
                let cols = h.ncols();
                h.insert_column(cols, 0.0)
            } else {
                h
            }
        }
        fn noise_cov(&self, k: usize, x: &DVector<f64>) -> Matrix1<f64> {
            self.0.noise_cov(k, x)
        }
        fn residual(&self, z: &Vector1<f64>, zhat: &Vector1<f64>) -> Vector1<f64> {
            self.0.residual(z, zhat)
        }
    }
    impl BearingSensor<Dyn> for Lying {
        fn selection(&self) -> OMatrix<f64, U2, Dyn> {
            let l = BearingSensor::selection(&self.0);
            if self.1 == Wrong::Selection {
                let cols = l.ncols();
                l.insert_column(cols, 0.0)
            } else {
                l
            }
        }
        fn shift(&self, k: usize) -> Vector2<f64> {
            BearingSensor::shift(&self.0, k)
        }
        fn reference(&self) -> BearingReference {
            BearingSensor::reference(&self.0)
        }
        fn variance(&self) -> f64 {
            BearingSensor::variance(&self.0)
        }
        fn translational_variance(&self) -> (f64, f64) {
            BearingSensor::translational_variance(&self.0)
        }
    }
    for wrong in [Wrong::Jacobian, Wrong::Selection] {
        let x0 = DVector::from_vec(vec![1.0, 2.0, 0.1, 0.1]);
        let p0 = DMatrix::identity(4, 4);
        let mut srf = Srf::new(dynamics(4), Lying(bearing(4, 1), wrong), x0, p0).unwrap();
        let (mean, cov) = (srf.mean().clone(), srf.covariance().clone());
        match srf.update(&Vector1::new(0.3)) {
            Err(FilterError::DimensionMismatch {
                expected, found, ..
            }) => assert_eq!((expected, found), (4, 5)),
            other => panic!("expected a dimension mismatch, got {other:?}"),
        }
        assert_eq!((srf.mean(), srf.covariance()), (&mean, &cov));
        assert!(srf.last_record().is_none());
    }
}
