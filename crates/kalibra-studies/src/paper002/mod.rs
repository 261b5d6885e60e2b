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
//!   [`ManoeuvringTarget::default`]: `dt = 0.01 s`, 20 s, `+3 deg/s^2` on `[2, 4) s`, `-3` on
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

mod figures;

use crate::study::{NamedFigure, Options, Size, Study};
use std::collections::BTreeMap;

use kalibra_filters::{Ekf, Filter, FilterOptions, Start, UpdateForm, steady_state};
use kalibra_linalg::{Matrix1, Matrix3, Vector1, Vector3, discrete_lyapunov, propagate};
use kalibra_metrics::{instantaneous_errors, rmse, rmse_per_state, sliding_window};
use kalibra_models::{AngularTarget, ManoeuvringTarget};
use kalibra_sim::MonteCarlo;
use serde::Serialize;

use crate::StudyError;
use crate::claims::{Claim, Verdict, claims_table};

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
/// Relative tolerance on the quoted "about" magnitudes (they are read off a figure).
pub const MAGNITUDE_TOLERANCE: f64 = 0.25;
/// The level `Q3`'s local bias is said to exceed (deg).
pub const QUOTED_BIAS: f64 = 0.1;
/// The level `Q3`'s local std is said to exceed "in many segments" (deg).
pub const QUOTED_STD: f64 = 0.2;
/// Share of Monte Carlo truths in which the ordering must hold to count as reproduced.
pub const ORDERING_SHARE: f64 = 0.9;

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

fn models(dt: f64) -> Result<Vec<AngularTarget>, StudyError> {
    Q_SETS
        .iter()
        .map(|s| Ok(AngularTarget::diagonal(dt, s.diag)?))
        .collect()
}

fn outcome(
    target: &ManoeuvringTarget,
    models: &[AngularTarget],
    rng: &mut kalibra_sim::ChaCha8Rng,
) -> Result<Outcome, StudyError> {
    let truth = target.truth(rng);
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

fn ordering(v: &[f64; 3]) -> String {
    let mut idx = [0, 1, 2];
    idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    idx.map(|i| Q_SETS[i].name).join(" < ")
}

/// The set with the largest mean window std of the angle.
fn largest_mean_std(q_sets: &BTreeMap<&'static str, QSetResult>) -> &'static str {
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

/// The canonical ordering the paper reports.
const PAPER_ORDERING: &str = "Q2 < Q1 < Q3";

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
    let target = ManoeuvringTarget::default();
    let dt = target.dt();
    let models = models(dt)?;
    let times = target.times();

    let mc = MonteCarlo::new(config.truths, config.seed).threads(config.threads);
    let outcomes = mc.map(|_, rng| outcome(&target, &models, rng))?;

    // The default truth: run 0's draws, in full detail.
    let mut rng = mc.rng(0);
    let truth = target.truth(&mut rng);
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

fn claims(r: &Report) -> Vec<Claim> {
    let q = |name: &str| &r.q_sets[name];
    let mut out = Vec::new();
    for (name, quoted) in QUOTED_PHASE_RMSE {
        let ours = q(name).rmse_theta_phase;
        out.push(Claim {
            id: if name == "Q1" {
                "q1-phase-rmse"
            } else {
                "q2-phase-rmse"
            },
            claim: format!("{name} angle RMSE in the 6-14 s phase"),
            published: format!("about {quoted:.2} deg"),
            ours: format!(
                "{ours:.3} deg (Monte Carlo mean {:.3}; noise floor {:.3})",
                q(name).mc_mean_rmse_theta_phase,
                q(name).noise_floor_theta
            ),
            tolerance: format!("{:.0}% relative", 100.0 * MAGNITUDE_TOLERANCE),
            verdict: Verdict::from_bool((ours - quoted).abs() <= MAGNITUDE_TOLERANCE * quoted),
            section: "magnitudes",
        });
    }
    let q3 = q("Q3").rmse_theta_phase;
    out.push(Claim {
        id: "q3-phase-rmse",
        claim: "Q3 angle RMSE in the 6-14 s phase".into(),
        published: format!("above {QUOTED_Q3_ABOVE:.2} deg"),
        ours: format!(
            "{q3:.3} deg (peak window RMSE {:.3})",
            q("Q3").peak_window_rmse_theta_phase
        ),
        tolerance: "strict inequality".into(),
        verdict: Verdict::from_bool(q3 > QUOTED_Q3_ABOVE),
        section: "magnitudes",
    });
    out.push(Claim {
        id: "ordering",
        claim: "Ordering of the phase angle RMSE".into(),
        published: PAPER_ORDERING.into(),
        ours: format!(
            "default truth {}; holds in {:.1}% of {} truths (Q2 best in {:.1}%)",
            r.ordering_default_truth,
            100.0 * r.fraction_ordering_holds,
            r.config.truths,
            100.0 * r.fraction_q2_best
        ),
        tolerance: format!("in at least {:.0}% of truths", 100.0 * ORDERING_SHARE),
        verdict: Verdict::from_bool(r.fraction_ordering_holds >= ORDERING_SHARE),
        section: "monte-carlo",
    });
    let best_states: Vec<&str> = (0..3)
        .filter(|&s| {
            let m = |n: &str| q(n).mc_mean_rmse[s];
            m("Q2") < m("Q1") && m("Q2") < m("Q3")
        })
        .map(|s| STATE_NAMES[s])
        .collect();
    out.push(Claim {
        id: "q2-lowest-all-states",
        claim: "Q2 gives the lowest RMSE (every state)".into(),
        published: "Q2 lowest".into(),
        ours: format!(
            "Q2 lowest Monte Carlo mean RMSE for: {}",
            if best_states.is_empty() {
                "no state".to_string()
            } else {
                best_states.join(", ")
            }
        ),
        tolerance: "lowest mean over truths, per state".into(),
        verdict: Verdict::from_bool(best_states.len() == 3),
        section: "monte-carlo",
    });
    let bias = q("Q3").max_abs_window_bias_theta;
    out.push(Claim {
        id: "q3-bias",
        claim: "Q3 local angle bias exceeds 0.1 deg at times".into(),
        published: format!("|bias| > {QUOTED_BIAS} deg"),
        ours: format!("largest |window bias| {bias:.3} deg (default truth)"),
        tolerance: "strict inequality".into(),
        verdict: Verdict::from_bool(bias > QUOTED_BIAS),
        section: "windows",
    });
    let std_share = q("Q3").share_windows_std_above_quoted;
    out.push(Claim {
        id: "q3-std",
        claim: "Q3 local angle std exceeds 0.2 deg in many segments".into(),
        published: format!("std > {QUOTED_STD} deg in many segments"),
        ours: format!(
            "{:.1}% of windows (largest mean std of the three sets: {})",
            100.0 * std_share,
            largest_mean_std(&r.q_sets)
        ),
        tolerance: "\"many\" is not a number: at least 10% of windows".into(),
        verdict: Verdict::from_bool(std_share >= 0.1),
        section: "windows",
    });
    out
}

/// State names in the paper's order.
pub const STATE_NAMES: [&str; 3] = ["angle", "rate", "acceleration"];

impl Report {
    /// The claim with identifier `id`.
    pub fn claim(&self, id: &str) -> Option<&Claim> {
        self.claims.iter().find(|c| c.id == id)
    }

    /// The report as Markdown.
    pub fn to_markdown(&self) -> String {
        use std::fmt::Write;
        let c = &self.config;
        let mut s = String::new();
        let q = |name: &str| &self.q_sets[name];
        let _ = writeln!(
            s,
            "# Paper 002: EKF tracking of a manoeuvring target's angle, rate and acceleration\n"
        );
        let _ = writeln!(
            s,
            "Minh, Luong, Bang, Toan. Three process-noise sets on one manoeuvring truth; RMSE and \
             sliding-window (W = {WINDOW}) RMSE, bias and std. Seed {}, {} Monte Carlo truths, \
             {} truths per sweep point.\n",
            c.seed, c.truths, c.sweep_truths
        );
        let _ = writeln!(s, "## Claims\n\n{}", claims_table(&self.claims));

        let _ = writeln!(s, "<a id=\"setup\"></a>\n## Set-up and readings\n");
        let _ = writeln!(
            s,
            "- Filter model: eq 3 (constant acceleration, dt = {} s), Q per step as printed, \
             R = {R} deg^2, x0 = 0, P0 = I, measurements from k = 1, covariance update as \
             printed ((I - K H) P). The model is linear: the paper's EKF is the Kalman filter.\n\
             - Truth (not given in the paper; the spec's choice): {} s, +3 deg/s^2 on [2, 4) s, -3 \
             on [4, 6), 10 sin(2 pi 0.5 (t - 6)) on [6, 14), white acceleration input noise \
             0.8 deg/s^2 at every sample, x0 = 0.\n\
             - Eq 18 as printed is the root of a negative number whenever the window bias is \
             negative; we use sqrt(sum (e - bias)^2 / (W - 1)). Check: RMSE^2 = bias^2 + \
             (W - 1)/W std^2 in every window.\n\
             - Phase RMSE: root mean square of the angle error over 6 <= t < 14 s.\n",
            self.dt,
            self.steps as f64 * self.dt
        );

        let _ = writeln!(s, "<a id=\"default-truth\"></a>\n## Default truth\n");
        let _ = writeln!(
            s,
            "| set | Q diagonal | RMSE angle / rate / acc | phase angle RMSE | peak window RMSE in phase | noise floor | steady gain |\n|---|---|---|---|---|---|---|"
        );
        for set in &Q_SETS {
            let r = q(set.name);
            let _ = writeln!(
                s,
                "| {} | {:?} | {:.3} / {:.3} / {:.3} | {:.3} | {:.3} | {:.3} | [{:.3}, {:.3}, {:.3}] |",
                set.name,
                r.q,
                r.rmse[0],
                r.rmse[1],
                r.rmse[2],
                r.rmse_theta_phase,
                r.peak_window_rmse_theta_phase,
                r.noise_floor_theta,
                r.steady_gain[0],
                r.steady_gain[1],
                r.steady_gain[2]
            );
        }
        let _ = writeln!(
            s,
            "\nOrdering of the phase angle RMSE on this truth: {}. Figures: \
             [angle](fig1_angle.svg), [rate](fig1_rate.svg), [acceleration](fig1_acceleration.svg) \
             (states and estimates); [errors](fig2_errors_angle.svg), \
             [rate errors](fig2_errors_rate.svg), [acceleration errors](fig2_errors_acceleration.svg); \
             window [RMSE](fig3_window_rmse.svg), [bias](fig3_window_bias.svg), \
             [std](fig3_window_std.svg).\n",
            self.ordering_default_truth
        );

        let _ = writeln!(
            s,
            "<a id=\"windows\"></a>\n## Sliding-window statistics (angle)\n"
        );
        let _ = writeln!(
            s,
            "| set | largest abs(bias) | mean bias | mean std | windows with std > {QUOTED_STD} |\n|---|---|---|---|---|"
        );
        for set in &Q_SETS {
            let r = q(set.name);
            let _ = writeln!(
                s,
                "| {} | {:.3} | {:+.4} | {:.3} | {:.1}% |",
                set.name,
                r.max_abs_window_bias_theta,
                r.mean_window_bias_theta,
                r.mean_window_std_theta,
                100.0 * r.share_windows_std_above_quoted
            );
        }
        let largest_std = largest_mean_std(&self.q_sets);
        let largest_bias = Q_SETS
            .iter()
            .map(|set| q(set.name).mean_window_bias_theta.abs())
            .fold(0.0, f64::max);
        let _ = writeln!(
            s,
            "\nThe mean window bias of every set is within {largest_bias:.4} deg of zero (the paper: \
             biases fluctuate around zero). The set with the largest mean window std is \
             {largest_std} (the paper: Q3).\n"
        );

        let _ = writeln!(
            s,
            "<a id=\"monte-carlo\"></a>\n## Monte Carlo over {} truths\n",
            c.truths
        );
        let _ = writeln!(
            s,
            "| set | phase angle RMSE mean (std) | RMSE angle | RMSE rate | RMSE acc | best in |\n|---|---|---|---|---|---|"
        );
        for set in &Q_SETS {
            let r = q(set.name);
            let _ = writeln!(
                s,
                "| {} | {:.4} ({:.4}) | {:.4} ({:.4}) | {:.3} ({:.3}) | {:.3} ({:.3}) | {:.1}% |",
                set.name,
                r.mc_mean_rmse_theta_phase,
                r.mc_std_rmse_theta_phase,
                r.mc_mean_rmse[0],
                r.mc_std_rmse[0],
                r.mc_mean_rmse[1],
                r.mc_std_rmse[1],
                r.mc_mean_rmse[2],
                r.mc_std_rmse[2],
                100.0 * r.share_best
            );
        }
        let _ = writeln!(
            s,
            "\nQ2 < Q1 < Q3 holds in {:.1}% of truths; Q2 is best in {:.1}%.\n",
            100.0 * self.fraction_ordering_holds,
            100.0 * self.fraction_q2_best
        );

        let _ = writeln!(
            s,
            "<a id=\"magnitudes\"></a>\n## Why the magnitudes do not reproduce\n"
        );
        let _ = writeln!(
            s,
            "The paper quotes about 0.1 deg (Q2), 0.15 (Q1) and above 0.25 (Q3) in the phase. \
             Measurement noise alone sets a floor under each filter's angle error: the \
             stationary error of the steady-state filter driven by R only. With dt = {} s the \
             floors are Q1 {:.3}, Q2 {:.3}, Q3 {:.3} deg, and no manoeuvre can take a filter \
             below its floor. Q2's floor is above the quoted 0.1 at every time step we tried:\n",
            self.dt,
            q("Q1").noise_floor_theta,
            q("Q2").noise_floor_theta,
            q("Q3").noise_floor_theta
        );
        let _ = writeln!(
            s,
            "| dt (s) | floor Q1 | floor Q2 | floor Q3 |\n|---|---|---|---|"
        );
        for row in &self.floor_vs_dt {
            let _ = writeln!(
                s,
                "| {} | {:.4} | {:.4} | {:.4} |",
                row.dt, row.floor[0], row.floor[1], row.floor[2]
            );
        }
        let max_ratio = self
            .sweep
            .iter()
            .map(|r| r.q3_over_q2)
            .fold(f64::NEG_INFINITY, f64::max);
        let _ = writeln!(
            s,
            "\nThe quoted Q3/Q2 ratio (above 2.5) is also out of reach: the largest Q3/Q2 ratio of \
             the mean phase RMSE over the amplitude sweep is {max_ratio:.2}. The ordering, not \
             the magnitudes, is what reproduces.\n"
        );

        let _ = writeln!(s, "<a id=\"sweep\"></a>\n## Manoeuvre amplitude sweep\n");
        let _ = writeln!(
            s,
            "The whole profile scaled; amplitude = the oscillation's peak (deg/s^2), steps = 0.3 x \
             amplitude. {} truths per point, the same noise at every point.\n",
            c.sweep_truths
        );
        let _ = writeln!(
            s,
            "| amplitude | mean phase RMSE Q1 / Q2 / Q3 | ordering | Q2 best | Q3 best | Q3/Q2 |\n|---|---|---|---|---|---|"
        );
        for row in &self.sweep {
            let _ = writeln!(
                s,
                "| {:.1} | {:.4} / {:.4} / {:.4} | {} | {:.0}% | {:.0}% | {:.3} |",
                row.amplitude,
                row.mean_rmse_theta_phase[0],
                row.mean_rmse_theta_phase[1],
                row.mean_rmse_theta_phase[2],
                row.ordering,
                100.0 * row.share_q2_best,
                100.0 * row.share_q3_best,
                row.q3_over_q2
            );
        }
        let _ = writeln!(
            s,
            "\n{} Figure: [sweep](fig4_sweep.svg).\n",
            match (
                self.first_reversal_amplitude,
                self.sweep.first(),
                self.sweep.last()
            ) {
                (Some(a), Some(first), Some(last)) => format!(
                    "The paper's ordering first fails at amplitude {a:.1} deg/s^2. At the \
                     smallest amplitude ({:.1}) the ordering is {}; at the largest ({:.1}) it is {}.",
                    first.amplitude, first.ordering, last.amplitude, last.ordering
                ),
                _ => "The paper's ordering holds at every swept amplitude.".to_string(),
            }
        );
        s
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
        let truth = target.truth(&mut rng);
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

/// The study, as the registry lists it.
#[derive(Clone, Copy, Debug, Default)]
pub struct Paper002;

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

    fn config(&self, options: &Options) -> Config {
        let mut config = match options.size {
            Size::Paper => Config::paper(),
            Size::Quick => Config::quick(),
        };
        if let Some(seed) = options.seed {
            config.seed = seed;
        }
        config.threads = options.threads;
        config
    }

    fn seed(&self, config: &Config) -> Option<u64> {
        Some(config.seed)
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

    fn markdown(&self, _config: &Config, report: &Report) -> Result<String, StudyError> {
        Ok(report.to_markdown())
    }

    fn figures(&self, report: &Report) -> Vec<NamedFigure> {
        NamedFigure::from_pairs(figures::figures(report))
    }
}
