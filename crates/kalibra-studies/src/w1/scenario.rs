//! The W1 scenario: a 2-D constant-velocity target whose filter matches the truth exactly.

use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector4};
use kalibra_models::{Kinematic, LinearGaussian, LinearObservation, ProcessNoise};

use crate::StudyError;

/// The W1 dynamics and sensor.
///
/// # Errors
/// Never for these constants; the `Result` carries the models' construction checks.
pub fn models() -> Result<(LinearGaussian<U4>, LinearObservation<U4, U2>), StudyError> {
    let cv = Kinematic::constant_velocity(2, 1.0)?.noise(ProcessNoise::Discrete { q: 1.0 });
    Ok((
        cv.dynamics(U4)?,
        cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)?,
    ))
}

/// The prior of the initial state, `(m0, P0)`.
pub fn prior() -> (Vector4<f64>, Matrix4<f64>) {
    (
        Vector4::new(0.0, 0.0, 10.0, -5.0),
        Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0)),
    )
}
