//! Fixtures shared by the filter tests: workload W1 (a 2-D constant-velocity target, positions
//! measured with R = 100 I), a seeded truth, and an initial covariance.

use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector4};
use kalibra_models::{Kinematic, LinearGaussian, LinearObservation, Truth, simulate};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;

pub fn w1() -> (LinearGaussian<U4>, LinearObservation<U4, U2>) {
    let cv = Kinematic::constant_velocity(2, 1.0).unwrap();
    (
        cv.dynamics(U4).unwrap(),
        cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)
            .unwrap(),
    )
}

pub fn truth(seed: u64, steps: usize) -> Truth<U4, U2> {
    let (f, h) = w1();
    simulate(
        &f,
        &h,
        Vector4::new(0.0, 0.0, 10.0, -5.0),
        steps,
        &mut ChaCha8Rng::seed_from_u64(seed),
    )
    .unwrap()
}

pub fn p0() -> Matrix4<f64> {
    Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0))
}
