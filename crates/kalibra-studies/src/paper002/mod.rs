//! Paper 002: Minh, Luong, Bang, Toan, "Simulation and performance evaluation of EKF in
//! angular coordinate tracking of highly maneuvering targets".
//!
//! # What the paper specifies
//! The constant-acceleration angle model (eq 3) with angle-only measurements (eq 4), three
//! per-step process-noise sets `Q(1..3)` (eq 19, [`Q_SETS`]), `R = 0.25 deg^2`, acceleration input
//! noise `0.8 deg/s^2`, and the metrics: instantaneous error `e = x_hat - x` (eq 14), RMSE per
//! state (eq 15), forward sliding-window RMSE, bias and standard deviation with `W = 50`
//! (eqs 16-18). It claims that `Q(2)` has the lowest and most stable error, that in the
//! strongly oscillating phase `t = 6 .. 14 s` the angle RMSE of `Q(2)` is about 0.1 deg, of
//! `Q(1)` 0.15 deg and of `Q(3)` above 0.25 deg, that `Q(3)`'s local bias exceeds 0.1 deg at
//! times and its local std exceeds 0.2 deg in many segments.
//!
//! # Decisions (the paper is silent or garbled)
//! * Time step, duration, initial state and manoeuvre are not given. We use the spec's choice,
//!   [`target`]: `dt = 0.01 s`, 20 s, `+3 deg/s^2` on `[2, 4) s`, `-3` on
//!   `[4, 6)`, `10 sin(2 pi 0.5 (t - 6))` on `[6, 14)`, white input noise `0.8 deg/s^2` on the
//!   acceleration at every sample, `x0 = 0`.
//! * Filter: `x0 = 0`, `P0 = I`, first measurement at `k = 1`; the covariance update as printed
//!   (`P = (I - K H) P-`, eq 13). The model is linear, so this EKF is the Kalman filter (a test
//!   checks EKF = KF).
//! * Eq 18 as printed takes the root of a negative number whenever the window bias is
//!   negative; we use the intended `sqrt(sum (e - bias)^2 / (W - 1))`.
//! * RMSEs and windows run over the updated samples `k = 1 .. K` (`k = 0` is the prior). A
//!   window is placed at its first sample's time in the figures.
//! * "Angle RMSE in the 6-14 s phase" is the root mean square of the angle error over the
//!   samples with `6 <= t < 14`; the peak of the window RMSE over windows inside the phase is
//!   reported beside it.
//! * The default truth is Monte Carlo run 0; the Monte Carlo draws new input and measurement
//!   noise per truth (ChaCha8 stream `i`), the manoeuvre is the same.
//! * The amplitude sweep multiplies the whole manoeuvre profile (steps and oscillation) by a
//!   scale and reuses the same noise streams at every scale (common random numbers), so the
//!   curves differ by the manoeuvre only.
//! * The measurement-noise floor of a `Q` set is the stationary angle error standard deviation
//!   the steady-state filter would have from measurement noise alone: `Sigma = A Sigma A^T +
//!   K R K^T` with `A = (I - K H) F` and `K` the steady-state gain. Any manoeuvre adds to it.

mod claims;
mod figures;
mod report;
mod run;
mod scenario;

pub use claims::{MAGNITUDE_TOLERANCE, ORDERING_SHARE};
pub use run::{Config, FloorRow, QSetResult, Report, SweepRow, Windows, noise_floor, run};
pub use scenario::{
    PHASE, Q_SETS, QSet, QUOTED_BIAS, QUOTED_PHASE_RMSE, QUOTED_Q3_ABOVE, QUOTED_STD, R,
    STATE_NAMES, WINDOW, manoeuvre, models, target, target_params, track,
};

use crate::StudyError;
use crate::claims::Claim;
use crate::study::{NamedFigure, Study};

/// The report's template (prose with the numbers filled in from [`Report`]).
const TEMPLATE: &str = include_str!("report.md");

/// The study, as the registry lists it.
#[derive(Clone, Copy, Debug, Default)]
pub struct Paper002;

crate::study_config!(Config, seed);

impl Study for Paper002 {
    type Config = Config;
    type Report = Report;

    fn id(&self) -> &'static str {
        "002"
    }

    fn title(&self) -> &'static str {
        "Minh et al.: EKF angle tracking of a manoeuvring target"
    }

    fn paper(&self) -> Option<&'static str> {
        Some(
            "Minh, Luong, Bang, Toan, \"Simulation and performance evaluation of EKF in angular coordinate tracking of highly maneuvering targets\"",
        )
    }

    fn describe(&self, config: &Config) -> String {
        format!(
            "angle tracking, 3 Q sets, {} truths, amplitude sweep {} points x {} truths",
            config.truths,
            config.sweep_scales.len(),
            config.sweep_truths
        )
    }

    fn run(&self, config: &Config) -> Result<Report, StudyError> {
        run(config)
    }

    fn claims(&self, report: &Report) -> Vec<Claim> {
        report.claims.clone()
    }

    fn highlight(&self, config: &Config, report: &Report) -> Result<String, StudyError> {
        let phase = |n: &str| {
            report
                .q_sets
                .get(n)
                .map_or(f64::NAN, |r| r.rmse_theta_phase)
        };
        Ok(format!(
            "phase angle RMSE Q1 {:.3}, Q2 {:.3}, Q3 {:.3} deg (paper ~0.15, ~0.10, >0.25); Q2 < Q1 < Q3 in {:.1}% of {} truths; ordering first changes at amplitude {}",
            phase("Q1"),
            phase("Q2"),
            phase("Q3"),
            100.0 * report.fraction_ordering_holds,
            config.truths,
            report
                .first_reversal_amplitude
                .map_or("never (swept range)".to_string(), |a| format!(
                    "{a:.1} deg/s^2"
                )),
        ))
    }

    fn markdown(&self, config: &Config, report: &Report) -> Result<String, StudyError> {
        crate::template::render(
            "paper002/report.md",
            TEMPLATE,
            &report::Context::new(config, report),
        )
    }

    fn figures(&self, report: &Report) -> Vec<NamedFigure> {
        NamedFigure::from_pairs(figures::figures(report))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_template_renders_both_sweep_endings() {
        let config = Config {
            truths: 2,
            sweep_truths: 1,
            sweep_scales: vec![0.0, 8.0],
            floor_dts: vec![0.01],
            ..Config::quick()
        };
        let mut report = run(&config).unwrap();
        assert_eq!(report.claims.len(), 7);
        assert!(report.first_reversal_amplitude.is_some());
        Paper002.markdown(&config, &report).unwrap();
        report.first_reversal_amplitude = None;
        Paper002.markdown(&config, &report).unwrap();
    }
}
