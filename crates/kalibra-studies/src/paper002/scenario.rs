//! Paper 002's set-up: the printed process-noise sets and noise levels, the quoted magnitudes,
//! the spec's reading of the unstated truth (time step, duration, manoeuvre), and the paper's
//! filter (EKF from `x0 = 0`, `P0 = I`, covariance update as printed).

use kalibra_filters::{Ekf, Filter, FilterOptions, Start, UpdateForm};
use kalibra_linalg::{Matrix3, Vector1, Vector3};
use kalibra_models::{
    AngularTarget, Manoeuvre, ManoeuvreProfile, ManoeuvringTarget, ManoeuvringTargetParams,
};
use serde::Serialize;

use crate::StudyError;

/// One printed process-noise set (eq 19): the diagonal of `Q`, per step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct QSet {
    /// `Q1`, `Q2`, `Q3`.
    pub name: &'static str,
    /// `[sigma_theta^2 (deg^2), sigma_rate^2 ((deg/s)^2), sigma_acc^2 ((deg/s^2)^2)]`.
    pub diag: [f64; 3],
}

/// The three printed sets.
pub const Q_SETS: [QSet; 3] = [
    QSet {
        name: "Q1",
        diag: [0.01, 0.1, 0.5],
    },
    QSet {
        name: "Q2",
        diag: [0.005, 0.05, 0.2],
    },
    QSet {
        name: "Q3",
        diag: [0.02, 0.2, 1.0],
    },
];

/// State names in the paper's order.
pub const STATE_NAMES: [&str; 3] = ["angle", "rate", "acceleration"];

/// Measurement noise variance (deg^2).
pub const R: f64 = 0.25;
/// Window length of the sliding-window metrics.
pub const WINDOW: usize = 50;
/// The strongly oscillating phase (s), half-open.
pub const PHASE: (f64, f64) = (6.0, 14.0);
/// The quoted phase angle RMSE of `Q1`, `Q2` (deg): "increases to 0.15", "around 0.1".
pub const QUOTED_PHASE_RMSE: [(&str, f64); 2] = [("Q1", 0.15), ("Q2", 0.10)];
/// The quoted lower bound of `Q3`'s phase angle RMSE (deg): "exceeds 0.25".
pub const QUOTED_Q3_ABOVE: f64 = 0.25;
/// The level `Q3`'s local bias is said to exceed (deg).
pub const QUOTED_BIAS: f64 = 0.1;
/// The level `Q3`'s local std is said to exceed "in many segments" (deg).
pub const QUOTED_STD: f64 = 0.2;
/// The ordering of the phase angle RMSE the paper reports.
pub(super) const PAPER_ORDERING: &str = "Q2 < Q1 < Q3";

/// Standard deviation of the white acceleration input noise (deg/s^2), printed.
const SIGMA_INPUT: f64 = 0.8;
/// Time step (s): not printed; the spec's choice.
const DT: f64 = 0.01;
/// Duration (s): not printed; the spec's choice.
const DURATION: f64 = 20.0;

/// The spec's reading of the unstated manoeuvre: `+3` deg/s^2 on `[2, 4)` s, `-3` on `[4, 6)`,
/// `10 sin(2 pi 0.5 (t - 6))` on `[6, 14)` (the "strongly oscillating" phase the paper
/// discusses), zero elsewhere.
pub fn manoeuvre() -> ManoeuvreProfile {
    ManoeuvreProfile::new(vec![
        Manoeuvre::Step {
            start: 2.0,
            end: 4.0,
            acceleration: 3.0,
        },
        Manoeuvre::Step {
            start: 4.0,
            end: 6.0,
            acceleration: -3.0,
        },
        Manoeuvre::Sine {
            start: 6.0,
            end: 14.0,
            amplitude: 10.0,
            frequency: 0.5,
        },
    ])
    .unwrap_or_else(|_| unreachable!("finite pieces with end >= start"))
}

/// The parameters of the default truth: `dt = 0.01` s, 20 s, [`manoeuvre`], input noise
/// `0.8` deg/s^2 (printed), `x0 = 0`.
pub fn target_params() -> ManoeuvringTargetParams {
    ManoeuvringTargetParams {
        dt: DT,
        duration: DURATION,
        profile: manoeuvre(),
        sigma_input: SIGMA_INPUT,
        x0: Vector3::zeros(),
    }
}

/// The default truth, [`target_params`].
pub fn target() -> ManoeuvringTarget {
    ManoeuvringTarget::new(target_params())
        .unwrap_or_else(|_| unreachable!("dt, duration and input noise are valid constants"))
}

/// The filter model of each set in [`Q_SETS`] at time step `dt`.
///
/// # Errors
/// [`StudyError::Model`] unless `dt` is finite and positive.
pub fn models(dt: f64) -> Result<Vec<AngularTarget>, StudyError> {
    Q_SETS
        .iter()
        .map(|s| Ok(AngularTarget::diagonal(dt, s.diag)?))
        .collect()
}

/// Runs the Kalman filter (the paper's EKF on a linear model, update as printed) over the
/// measurements of samples `1 ..= K` and returns the estimates `x_hat_0 .. x_hat_K`.
///
/// # Errors
/// [`StudyError::Filter`] if a step fails.
pub fn track(model: &AngularTarget, z: &[Vector1<f64>]) -> Result<Vec<Vector3<f64>>, StudyError> {
    let options = FilterOptions {
        update: UpdateForm::Standard,
        ..FilterOptions::default()
    };
    let h = AngularTarget::angle_measurement(R)?;
    let mut ekf = Ekf::with_options(model, &h, Vector3::zeros(), Matrix3::identity(), options)?;
    let mut estimates = Vec::with_capacity(z.len() + 1);
    estimates.push(Vector3::zeros());
    ekf.run(z.iter().map(Some), Start::PredictFirst, |rec| {
        estimates.push(rec.posterior().mean)
    })?;
    Ok(estimates)
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_sim::MonteCarlo;

    #[test]
    fn the_manoeuvre_is_half_open_and_scales() {
        let p = manoeuvre();
        assert_eq!(p.acceleration(1.999), 0.0);
        assert_eq!(p.acceleration(2.0), 3.0);
        assert_eq!(p.acceleration(4.0), -3.0);
        assert_eq!(p.acceleration(6.0), 0.0); // sin(0)
        assert!((p.acceleration(6.5) - 10.0).abs() < 1e-12);
        assert_eq!(p.acceleration(14.0), 0.0);
        let s = p.scaled(2.0).unwrap();
        assert!((s.acceleration(6.5) - 20.0).abs() < 1e-12);
        assert_eq!(s.acceleration(3.0), 6.0);
    }

    #[test]
    fn the_default_truth_has_2000_steps() {
        let target = target();
        assert_eq!(target.steps(), 2000);
        assert_eq!(target.dt(), 0.01);
        assert_eq!(target.sigma_input(), 0.8);
        assert_eq!(target.profile(), &manoeuvre());
        let mut rng = MonteCarlo::new(1, 1).rng(0);
        let truth = target.truth(&mut rng).unwrap();
        assert_eq!(truth.len(), 2001);
        let z = ManoeuvringTarget::measurements(&truth, R, &mut rng).unwrap();
        assert_eq!(z.len(), 2000);
        assert_eq!(track(&models(0.01).unwrap()[1], &z).unwrap().len(), 2001);
    }
}
