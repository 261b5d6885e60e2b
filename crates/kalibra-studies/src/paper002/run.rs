//! The paper 002 run: every `Q` set on the default truth in detail, over the Monte Carlo
//! truths, along the manoeuvre-amplitude sweep, and the measurement-noise floor against the
//! time step.

use std::collections::BTreeMap;

use kalibra_filters::steady_state;
use kalibra_linalg::{Matrix1, Matrix3, Vector3, discrete_lyapunov, propagate};
use kalibra_metrics::{instantaneous_errors, rmse, rmse_per_state, sliding_window};
use kalibra_models::{AngularTarget, ManoeuvringTarget};
use kalibra_sim::MonteCarlo;
use serde::Serialize;

use super::claims::claims;
use super::scenario::{
    PAPER_ORDERING, PHASE, Q_SETS, QUOTED_STD, R, WINDOW, models, target, track,
};
use crate::StudyError;
use crate::claims::Claim;

/// Size and seed of the study.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Config {
    /// Seed; truth `i` uses ChaCha8 stream `i`.
    pub seed: u64,
    /// Threads (0: all cores); results do not depend on it.
    pub threads: usize,
    /// Monte Carlo truths at the default manoeuvre.
    pub truths: usize,
    /// Truths per point of the amplitude sweep.
    pub sweep_truths: usize,
    /// Scales of the manoeuvre profile in the sweep.
    pub sweep_scales: Vec<f64>,
    /// Time steps at which the measurement-noise floor is computed.
    pub floor_dts: Vec<f64>,
}

impl Config {
    /// The full study: 200 truths, 200 per sweep point.
    pub fn paper() -> Self {
        Self {
            seed: 2025,
            threads: 0,
            truths: 200,
            sweep_truths: 200,
            sweep_scales: vec![0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0],
            floor_dts: vec![0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1],
        }
    }

    /// Reduced size for tests: the same 200 truths, a coarse sweep of 20 truths per point.
    pub fn quick() -> Self {
        Self {
            sweep_truths: 20,
            sweep_scales: vec![0.0, 1.0, 4.0, 8.0],
            floor_dts: vec![0.001, 0.01],
            ..Self::paper()
        }
    }
}

/// Sliding-window statistics of one error series (entry `i`: samples `1 + i .. i + W`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Windows {
    /// Time of each window's first sample (s).
    pub start_time: Vec<f64>,
    /// Window RMSE (eq 16).
    pub rmse: Vec<f64>,
    /// Window bias (eq 17).
    pub bias: Vec<f64>,
    /// Window standard deviation (eq 18, corrected).
    pub std: Vec<f64>,
}

/// The results of one `Q` set.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct QSetResult {
    /// The diagonal of `Q`.
    pub q: [f64; 3],
    /// Default truth: RMSE per state over `k = 1 .. K` (angle, rate, acceleration).
    pub rmse: [f64; 3],
    /// Default truth: angle RMSE over `6 <= t < 14`.
    pub rmse_theta_phase: f64,
    /// Default truth: largest window RMSE of the angle over windows inside the phase.
    pub peak_window_rmse_theta_phase: f64,
    /// Default truth: largest `|window bias|` of the angle.
    pub max_abs_window_bias_theta: f64,
    /// Default truth: mean of the angle window bias over the run.
    pub mean_window_bias_theta: f64,
    /// Default truth: share of windows whose angle std exceeds 0.2 deg.
    pub share_windows_std_above_quoted: f64,
    /// Default truth: mean of the angle window std over the run.
    pub mean_window_std_theta: f64,
    /// Monte Carlo mean of the phase angle RMSE.
    pub mc_mean_rmse_theta_phase: f64,
    /// Monte Carlo standard deviation of the phase angle RMSE.
    pub mc_std_rmse_theta_phase: f64,
    /// Monte Carlo mean of the full-run RMSE per state.
    pub mc_mean_rmse: [f64; 3],
    /// Monte Carlo standard deviation of the full-run RMSE per state.
    pub mc_std_rmse: [f64; 3],
    /// Share of truths in which this set has the lowest phase angle RMSE.
    pub share_best: f64,
    /// Measurement-noise floor of the angle error (deg) at the default `dt`.
    pub noise_floor_theta: f64,
    /// Steady-state gain at the default `dt`.
    pub steady_gain: [f64; 3],
    /// Default truth: estimates `x_hat_0 .. x_hat_K` (the prior at `k = 0`).
    pub estimates: Vec<[f64; 3]>,
    /// Default truth: errors `e_k = x_hat_k - x_k`, `k = 0 .. K` (not serialised: the
    /// estimates minus the truth).
    #[serde(skip)]
    pub errors: Vec<[f64; 3]>,
    /// Default truth: window statistics of the angle error.
    pub windows_theta: Windows,
}

/// One point of the manoeuvre-amplitude sweep.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SweepRow {
    /// Scale of the default profile.
    pub scale: f64,
    /// Amplitude of the oscillation (deg/s^2): `10 * scale`.
    pub amplitude: f64,
    /// Mean phase angle RMSE of `Q1`, `Q2`, `Q3` over the sweep's truths.
    pub mean_rmse_theta_phase: [f64; 3],
    /// The sets ordered by mean phase angle RMSE, as `"Q2 < Q1 < Q3"`.
    pub ordering: String,
    /// Share of truths in which `Q2` is best.
    pub share_q2_best: f64,
    /// Share of truths in which `Q3` is best.
    pub share_q3_best: f64,
    /// Ratio of the means, `Q3 / Q2`.
    pub q3_over_q2: f64,
}

/// The measurement-noise floor of each set at one time step.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FloorRow {
    /// Time step (s).
    pub dt: f64,
    /// Angle floor (deg) of `Q1`, `Q2`, `Q3`.
    pub floor: [f64; 3],
}

/// The results of the study.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// The configuration run.
    pub config: Config,
    /// Time step (s).
    pub dt: f64,
    /// Steps `K` per run.
    pub steps: usize,
    /// Sample times `t_0 .. t_K`.
    pub times: Vec<f64>,
    /// Default truth `x_0 .. x_K`.
    pub truth: Vec<[f64; 3]>,
    /// Per-set results.
    pub q_sets: BTreeMap<&'static str, QSetResult>,
    /// Share of Monte Carlo truths in which `Q2` has the lowest phase angle RMSE.
    pub fraction_q2_best: f64,
    /// Share of truths in which `Q2 < Q1 < Q3` holds for the phase angle RMSE.
    pub fraction_ordering_holds: f64,
    /// The ordering on the default truth.
    pub ordering_default_truth: String,
    /// The amplitude sweep.
    pub sweep: Vec<SweepRow>,
    /// The smallest swept amplitude (deg/s^2) at which the mean ordering is no longer
    /// `Q2 < Q1 < Q3`, if any.
    pub first_reversal_amplitude: Option<f64>,
    /// Measurement-noise floor against the time step.
    pub floor_vs_dt: Vec<FloorRow>,
    /// The paper's claims and our verdicts.
    pub claims: Vec<Claim>,
}

/// The angle-error measurement-noise floor and the steady-state gain of one set at `dt`.
///
/// # Errors
/// [`StudyError`] if the Riccati or Lyapunov iteration fails (it does not for these models).
pub fn noise_floor(dt: f64, q: [f64; 3]) -> Result<(f64, Vector3<f64>), StudyError> {
    let model = AngularTarget::diagonal(dt, q)?;
    let h = kalibra_linalg::nalgebra::Matrix1x3::new(1.0, 0.0, 0.0);
    let r = Matrix1::new(R);
    let ss = steady_state(model.f(), &h, model.q(), &r)?;
    let a = (Matrix3::identity() - ss.gain * h) * model.f();
    let sigma = discrete_lyapunov(&a, &propagate(&ss.gain, &r))?;
    Ok((sigma[(0, 0)].sqrt(), ss.gain))
}

fn in_phase(t: f64) -> bool {
    PHASE.0 <= t && t < PHASE.1
}

/// Angle RMSE over the phase, from errors `e_0 .. e_K` at `times`.
fn phase_rmse(times: &[f64], errors: &[Vector3<f64>]) -> Result<f64, StudyError> {
    let phase: Vec<f64> = times
        .iter()
        .zip(errors)
        .skip(1)
        .filter(|(t, _)| in_phase(**t))
        .map(|(_, e)| e[0])
        .collect();
    Ok(rmse(&phase)?)
}

/// What one truth gives each set.
struct Outcome {
    /// Full-run RMSE per state, per set.
    rmse: [[f64; 3]; 3],
    /// Phase angle RMSE per set.
    phase: [f64; 3],
}

fn outcome(
    target: &ManoeuvringTarget,
    models: &[AngularTarget],
    rng: &mut kalibra_sim::ChaCha8Rng,
) -> Result<Outcome, StudyError> {
    let truth = target.truth(rng)?;
    let z = ManoeuvringTarget::measurements(&truth, R, rng)?;
    let times = target.times();
    let mut out = Outcome {
        rmse: [[0.0; 3]; 3],
        phase: [0.0; 3],
    };
    for (i, model) in models.iter().enumerate() {
        let errors = instantaneous_errors(&track(model, &z)?, &truth)?;
        let r = rmse_per_state(&errors[1..])?;
        out.rmse[i] = [r[0], r[1], r[2]];
        out.phase[i] = phase_rmse(&times, &errors)?;
    }
    Ok(out)
}

pub(super) fn ordering(v: &[f64; 3]) -> String {
    let mut idx = [0, 1, 2];
    idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    idx.map(|i| Q_SETS[i].name).join(" < ")
}

/// The set with the largest mean window std of the angle.
pub(super) fn largest_mean_std(q_sets: &BTreeMap<&'static str, QSetResult>) -> &'static str {
    Q_SETS
        .iter()
        .max_by(|a, b| {
            q_sets[a.name]
                .mean_window_std_theta
                .total_cmp(&q_sets[b.name].mean_window_std_theta)
        })
        .map_or("none", |set| set.name)
}

fn share(outcomes: &[Outcome], pred: impl Fn(&Outcome) -> bool) -> f64 {
    outcomes.iter().filter(|o| pred(o)).count() as f64 / outcomes.len() as f64
}

/// Runs the study.
///
/// # Errors
/// [`StudyError`] if a model, filter or metric fails, or `config` asks for fewer than two
/// truths.
pub fn run(config: &Config) -> Result<Report, StudyError> {
    if config.truths < 2 || config.sweep_truths < 1 {
        return Err(StudyError::Harness(
            "need at least two truths and one per sweep point".into(),
        ));
    }
    let target = target();
    let dt = target.dt();
    let models = models(dt)?;
    let times = target.times();

    let mc = MonteCarlo::new(config.truths, config.seed).threads(config.threads);
    let outcomes = mc.map(|_, rng| outcome(&target, &models, rng))?;

    // The default truth: run 0's draws, in full detail.
    let mut rng = mc.rng(0);
    let truth = target.truth(&mut rng)?;
    let z = ManoeuvringTarget::measurements(&truth, R, &mut rng)?;

    let mut q_sets = BTreeMap::new();
    let mut phase_default = [0.0; 3];
    for (i, (set, model)) in Q_SETS.iter().zip(&models).enumerate() {
        let estimates = track(model, &z)?;
        let errors = instantaneous_errors(&estimates, &truth)?;
        let r = rmse_per_state(&errors[1..])?;
        let theta: Vec<f64> = errors[1..].iter().map(|e| e[0]).collect();
        let w = sliding_window(&theta, WINDOW)?;
        let start_time: Vec<f64> = times[1..].iter().take(w.rmse.len()).copied().collect();
        let window_end = |j: usize| times[j + WINDOW];
        let peak = (0..w.rmse.len())
            .filter(|&j| in_phase(start_time[j]) && window_end(j) < PHASE.1)
            .map(|j| w.rmse[j])
            .fold(0.0, f64::max);
        let phase = phase_rmse(&times, &errors)?;
        phase_default[i] = phase;
        let (floor, gain) = noise_floor(dt, set.diag)?;
        let (mc_phase_mean, mc_phase_std) = crate::mean_std(outcomes.iter().map(|o| o.phase[i]));
        let state_stats: Vec<(f64, f64)> = (0..3)
            .map(|s| crate::mean_std(outcomes.iter().map(move |o| o.rmse[i][s])))
            .collect();
        let n_windows = w.rmse.len() as f64;
        q_sets.insert(
            set.name,
            QSetResult {
                q: set.diag,
                rmse: [r[0], r[1], r[2]],
                rmse_theta_phase: phase,
                peak_window_rmse_theta_phase: peak,
                max_abs_window_bias_theta: w.bias.iter().fold(0.0, |m, b| m.max(b.abs())),
                mean_window_bias_theta: w.bias.iter().sum::<f64>() / n_windows,
                share_windows_std_above_quoted: w.std.iter().filter(|&&s| s > QUOTED_STD).count()
                    as f64
                    / n_windows,
                mean_window_std_theta: w.std.iter().sum::<f64>() / n_windows,
                mc_mean_rmse_theta_phase: mc_phase_mean,
                mc_std_rmse_theta_phase: mc_phase_std,
                mc_mean_rmse: std::array::from_fn(|s| state_stats[s].0),
                mc_std_rmse: std::array::from_fn(|s| state_stats[s].1),
                share_best: share(&outcomes, |o| crate::argmin(&o.phase) == i),
                noise_floor_theta: floor,
                steady_gain: [gain[0], gain[1], gain[2]],
                estimates: estimates.iter().map(|x| [x[0], x[1], x[2]]).collect(),
                errors: errors.iter().map(|e| [e[0], e[1], e[2]]).collect(),
                windows_theta: Windows {
                    start_time,
                    rmse: w.rmse,
                    bias: w.bias,
                    std: w.std,
                },
            },
        );
    }
    let fraction_q2_best = share(&outcomes, |o| crate::argmin(&o.phase) == 1);
    let fraction_ordering_holds = share(&outcomes, |o| ordering(&o.phase) == PAPER_ORDERING);

    // The amplitude sweep, on common random numbers.
    let sweep_mc = MonteCarlo::new(config.sweep_truths, config.seed).threads(config.threads);
    let mut sweep = Vec::with_capacity(config.sweep_scales.len());
    for &scale in &config.sweep_scales {
        let scaled = target.clone().with_profile(target.profile().scaled(scale)?);
        let outs = sweep_mc.map(|_, rng| outcome(&scaled, &models, rng))?;
        let mean: [f64; 3] = std::array::from_fn(|i| {
            outs.iter().map(|o| o.phase[i]).sum::<f64>() / outs.len() as f64
        });
        sweep.push(SweepRow {
            scale,
            amplitude: 10.0 * scale,
            ordering: ordering(&mean),
            share_q2_best: share(&outs, |o| crate::argmin(&o.phase) == 1),
            share_q3_best: share(&outs, |o| crate::argmin(&o.phase) == 2),
            q3_over_q2: mean[2] / mean[1],
            mean_rmse_theta_phase: mean,
        });
    }
    let first_reversal_amplitude = sweep
        .iter()
        .find(|r| r.ordering != PAPER_ORDERING)
        .map(|r| r.amplitude);

    let floor_vs_dt = config
        .floor_dts
        .iter()
        .map(|&dt| {
            let mut floor = [0.0; 3];
            for (f, set) in floor.iter_mut().zip(&Q_SETS) {
                *f = noise_floor(dt, set.diag)?.0;
            }
            Ok(FloorRow { dt, floor })
        })
        .collect::<Result<Vec<_>, StudyError>>()?;

    let mut report = Report {
        config: config.clone(),
        dt,
        steps: target.steps(),
        times,
        truth: truth.iter().map(|x| [x[0], x[1], x[2]]).collect(),
        ordering_default_truth: ordering(&phase_default),
        q_sets,
        fraction_q2_best,
        fraction_ordering_holds,
        sweep,
        first_reversal_amplitude,
        floor_vs_dt,
        claims: Vec::new(),
    };
    report.claims = claims(&report);
    Ok(report)
}

impl Report {
    /// The claim with identifier `id`.
    pub fn claim(&self, id: &str) -> Option<&Claim> {
        self.claims.iter().find(|c| c.id == id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_floor_matches_a_noise_only_simulation() {
        // A truth with no manoeuvre and no input noise: the filter error is measurement noise
        // only, so its stationary RMSE is the floor (up to Monte Carlo error).
        let target = ManoeuvringTarget::new(kalibra_models::ManoeuvringTargetParams {
            dt: 0.01,
            duration: 200.0,
            profile: kalibra_models::ManoeuvreProfile::none(),
            sigma_input: 0.0,
            x0: Vector3::zeros(),
        })
        .unwrap();
        let model = AngularTarget::diagonal(0.01, Q_SETS[1].diag).unwrap();
        let mut rng = MonteCarlo::new(1, 7).rng(0);
        let truth = target.truth(&mut rng).unwrap();
        let z = ManoeuvringTarget::measurements(&truth, R, &mut rng).unwrap();
        let errors = instantaneous_errors(&track(&model, &z).unwrap(), &truth).unwrap();
        // Skip the transient (10 s).
        let theta: Vec<f64> = errors[1000..].iter().map(|e| e[0]).collect();
        let empirical = rmse(&theta).unwrap();
        let (floor, _) = noise_floor(0.01, Q_SETS[1].diag).unwrap();
        // 19 000 correlated samples: a few percent of sampling error.
        assert!(
            (empirical / floor - 1.0).abs() < 0.05,
            "{empirical} vs {floor}"
        );
    }

    #[test]
    fn ordering_and_argmin() {
        assert_eq!(ordering(&[0.15, 0.1, 0.3]), PAPER_ORDERING);
        assert_eq!(ordering(&[0.2, 0.3, 0.1]), "Q3 < Q1 < Q2");
        assert_eq!(crate::argmin(&[0.2, 0.3, 0.1]), 2);
    }
}
