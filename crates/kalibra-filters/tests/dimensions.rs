//! Issue 19, point 3: every `Dyn` size is checked where it enters. Filters built from models
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
