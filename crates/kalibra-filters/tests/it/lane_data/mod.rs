//! The per-lane scenario the batched EKF and UKF tests share (`tests/batch_ekf.rs`,
//! `tests/batch_ukf.rs`): deterministic truths on paper 004's nonlinear axis, different per
//! lane, the odd lanes placed so that their bearings cross +-pi.

use std::f64::consts::PI;

use kalibra_linalg::{Matrix3, Vector1, Vector3};

/// Where lane `lane`'s target sits: the odd lanes to the left of and below the even ones.
fn offset(lane: usize) -> (f64, f64) {
    if lane % 2 == 1 {
        (-6.0, -1.0)
    } else {
        (0.0, 0.0)
    }
}

/// Lane `lane`'s truth at step `k`.
pub fn truth(k: usize, lane: usize) -> Vector3<f64> {
    let t = k as f64 * 0.05;
    let l = lane as f64;
    let (side, up) = offset(lane);
    Vector3::new(
        side + (t + l).sin(),
        up + 0.3 * (1.7 * t - l).cos(),
        0.5 * (0.9 * t * (l + 1.0)).sin(),
    )
}

/// The bearing `z` of lane `lane` at step `k` with a deterministic error of size `amplitude`,
/// wrapped back into (-pi, pi].
pub fn measured(k: usize, lane: usize, mut z: Vector1<f64>, amplitude: f64) -> Vector1<f64> {
    z[0] += amplitude * (3.1 * k as f64 * 0.05 + lane as f64).sin();
    if z[0] > PI {
        z[0] -= 2.0 * PI;
    } else if z[0] <= -PI {
        z[0] += 2.0 * PI;
    }
    z
}

/// Lane `lane`'s initial estimate: its target's offset, and one covariance for all lanes.
pub fn prior(lane: usize) -> (Vector3<f64>, Matrix3<f64>) {
    let (side, up) = offset(lane);
    (
        Vector3::new(side, up, 0.0),
        Matrix3::from_diagonal(&Vector3::new(1.0, 0.5, 0.25)),
    )
}
