//! The paper 004 run: per reading, the surrogate and the Table 1 tests from long trajectories,
//! and the Table 2 quantiles from independent replicates.

use kalibra_bounds::{ErgodicAverage, Surrogate, gaussian_half_widths};
use kalibra_filters::{Ekf, Filter};
use kalibra_linalg::nalgebra::SMatrix;
use kalibra_linalg::{Alloc, DefaultAllocator, DimName, Matrix3, OMatrix, U3, U9, Vector3};
use kalibra_metrics::hypothesis::{
    TestResult, batch_means, ks_two_sample, paired_t_test, runs_test,
};
use kalibra_models::{AccelAxis, Dynamics, LinearObservation, Measurement, Target3d};
use kalibra_sim::{ChaCha8Rng, MonteCarlo};
use serde::Serialize;

use super::claims::claims;
use super::scenario::{CONFIDENCE, LEVEL, READINGS, Reading, TABLE2_EMPIRICAL, TABLE2_SURROGATE};
use crate::StudyError;
use crate::claims::Claim;
use crate::paper000::Entry;

/// Size and seed of the study.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Config {
    /// Seed of the trajectories; the replicates use `seed + 1`.
    pub seed: u64,
    /// Threads (0: all cores); results do not depend on it.
    pub threads: usize,
    /// Independent replicates for the empirical quantiles of `e_steps`.
    pub replicates: usize,
    /// Steps per replicate (the paper's 1000).
    pub steps: usize,
    /// Length of a trajectory for the surrogate and the tests.
    pub trajectory: usize,
    /// Burn-in dropped from a trajectory.
    pub burn_in: usize,
    /// Batch size of the batch means.
    pub batch: usize,
    /// Further trajectories for the rejection rates.
    pub trajectories: usize,
    /// Bins of the density figures.
    pub density_bins: usize,
}

impl Config {
    /// The paper's sizes.
    pub fn paper() -> Self {
        Self {
            seed: 2023,
            threads: 0,
            replicates: 10_000,
            steps: 1000,
            trajectory: 100_000,
            burn_in: 10_000,
            batch: 250,
            trajectories: 100,
            density_bins: 60,
        }
    }

    /// Reduced sizes for tests.
    pub fn quick() -> Self {
        Self {
            replicates: 1000,
            trajectory: 20_000,
            burn_in: 2000,
            batch: 100,
            trajectories: 10,
            ..Self::paper()
        }
    }
}

/// Table 1 of one reading.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Table1 {
    /// Batch means per component.
    pub batch_means: usize,
    /// Runs-test p-values of trajectory 0.
    pub p_runs: [f64; 9],
    /// Matched-pair t-test p-values of trajectory 0.
    pub p_t: [f64; 9],
    /// KS p-values of trajectory 0.
    pub p_ks: [f64; 9],
    /// Rejection rate at level 0.05 over the further trajectories, per test
    /// (`runs`, `t`, `ks`) and component.
    pub rejection_rate: RejectionRates,
    /// Trajectories behind the rejection rates.
    pub trajectories: usize,
}

/// Rejection rates per test and component.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RejectionRates {
    /// Runs test.
    pub runs: [f64; 9],
    /// Matched-pair t-test.
    pub t: [f64; 9],
    /// KS test.
    pub ks: [f64; 9],
    /// Mean over the three tests and nine components.
    pub overall: f64,
}

/// A density curve for a figure.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Density {
    /// Bin centres.
    pub x: Vec<f64>,
    /// Empirical density of `e_steps` over the replicates.
    pub empirical: Vec<f64>,
    /// Surrogate `N(0, P_bar_ii)` density at the centres.
    pub surrogate: Vec<f64>,
}

/// The results of one reading.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReadingReport {
    /// The reading.
    pub reading: Reading,
    /// Spectral radius of the surrogate's `C`.
    pub spectral_radius: f64,
    /// Surrogate 95% half-widths (trajectory 0).
    pub surrogate_halfwidth: [f64; 9],
    /// Spread of the surrogate half-widths over the further trajectories: standard deviation
    /// relative to the mean, per component.
    pub surrogate_halfwidth_rel_spread: [f64; 9],
    /// Empirical 2.5% quantiles of `e_steps`.
    pub empirical_q025: [f64; 9],
    /// Empirical 97.5% quantiles.
    pub empirical_q975: [f64; 9],
    /// The EKF's own `N(0, P_steps)` 95% half-widths, mean over replicates.
    pub ekf_p_halfwidth: [f64; 9],
    /// Share of replicates inside the surrogate interval.
    pub coverage_surrogate: [f64; 9],
    /// Share of replicates inside their own `N(0, P)` interval.
    pub coverage_ekf_p: [f64; 9],
    /// Surrogate half-width against Table 2's.
    pub surrogate_vs_paper: Vec<Entry>,
    /// Empirical quantiles against Table 2's (2.5% then 97.5% per component).
    pub quantiles_vs_paper: Vec<(Entry, Entry)>,
    /// Table 1.
    pub table1: Table1,
    /// Densities per component.
    pub densities: Vec<Density>,
}

/// The results of the study.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// The configuration run.
    pub config: Config,
    /// Per reading.
    pub readings: Vec<ReadingReport>,
    /// The paper's claims and our verdicts.
    pub claims: Vec<Claim>,
}

/// One axis's models.
struct AxisSetup<MA: DimName>
where
    DefaultAllocator: Alloc<U3, MA>,
{
    dynamics: AccelAxis,
    measurement: LinearObservation<U3, MA>,
}

/// What one axis of one trajectory yields.
struct AxisTrajectory<MA: DimName>
where
    DefaultAllocator: Alloc<U3, MA>,
{
    averages: ErgodicAverage<U3, MA>,
    /// Errors `x - x_hat` of steps `1 ..= n` per component of the axis.
    errors: [Vec<f64>; 3],
}

/// Runs one axis for `steps` steps from a fresh truth, calling `visit(k, x, x_hat, P, K, J)`.
fn run_axis<MA: DimName>(
    axis: &AxisSetup<MA>,
    steps: usize,
    rng: &mut ChaCha8Rng,
    mut visit: impl FnMut(usize, &Vector3<f64>, &kalibra_filters::StepRecord<U3, MA>),
) -> Result<(), StudyError>
where
    DefaultAllocator: Alloc<U3, MA>,
{
    let mut x: Vector3<f64> = kalibra_models::standard_normal(U3, rng);
    let mut ekf = Ekf::new(
        &axis.dynamics,
        &axis.measurement,
        Vector3::zeros(),
        Matrix3::identity(),
    )?;
    for k in 1..=steps {
        x = axis.dynamics.transition(k - 1, &x) + axis.dynamics.sample_noise(k - 1, rng)?;
        let z = axis.measurement.measure(k, &x) + axis.measurement.sample_noise(k, &x, rng)?;
        ekf.predict()?;
        let rec = ekf.update(&z)?;
        visit(k, &x, rec);
    }
    Ok(())
}

fn trajectory_axis<MA: DimName>(
    axis: &AxisSetup<MA>,
    config: &Config,
    rng: &mut ChaCha8Rng,
) -> Result<AxisTrajectory<MA>, StudyError>
where
    DefaultAllocator: Alloc<U3, MA>,
{
    let mut averages = ErgodicAverage::new(U3, MA::name());
    let mut errors: [Vec<f64>; 3] = std::array::from_fn(|_| Vec::with_capacity(config.trajectory));
    let mut failure = None;
    run_axis(axis, config.trajectory, rng, |k, x, rec| {
        let post = &rec.posterior().mean;
        for (i, e) in errors.iter_mut().enumerate() {
            e.push(x[i] - post[i]);
        }
        if k > config.burn_in {
            let j = axis.dynamics.jacobian(k, post);
            if let Err(e) = averages.push(rec.gain(), &j) {
                failure.get_or_insert(e);
            }
        }
    })?;
    if let Some(e) = failure {
        return Err(e.into());
    }
    Ok(AxisTrajectory { averages, errors })
}

/// The 9-state block-diagonal matrix from three per-axis `3 x c` blocks.
fn block_diagonal<C: DimName, C9: DimName>(
    blocks: [&OMatrix<f64, U3, C>; 3],
) -> OMatrix<f64, U9, C9>
where
    DefaultAllocator: Alloc<U3, C> + Alloc<U9, C9>,
{
    let mut out = OMatrix::<f64, U9, C9>::zeros();
    let c = C::dim();
    for (a, block) in blocks.iter().enumerate() {
        for i in 0..3 {
            for j in 0..c {
                out[(3 * a + i, c * a + j)] = block[(i, j)];
            }
        }
    }
    out
}

/// The three tests on the batch means of one error series, and the number of batch means.
fn tests(series: &[f64], config: &Config) -> Result<([TestResult; 3], usize), StudyError> {
    let means = batch_means(series, config.batch, config.burn_in)?;
    let half = means.len() / 2;
    Ok((
        [
            runs_test(&means)?,
            paired_t_test(&means[..half], &means[half..2 * half])?,
            ks_two_sample(&means[..half], &means[half..2 * half])?,
        ],
        means.len(),
    ))
}

/// What one full trajectory yields: the surrogate half-widths and the test p-values.
struct TrajectoryOutcome {
    half_widths: [f64; 9],
    p: [[f64; 3]; 9],
    batch_means: usize,
    spectral_radius: f64,
}

fn trajectory<MA: DimName, M9: DimName>(
    axes: &[AxisSetup<MA>; 3],
    full: &LinearObservation<U9, M9>,
    target: &Target3d,
    config: &Config,
    rng: &mut ChaCha8Rng,
) -> Result<TrajectoryOutcome, StudyError>
where
    DefaultAllocator: Alloc<U3, MA> + Alloc<U9, M9>,
{
    let runs = [
        trajectory_axis(&axes[0], config, rng)?,
        trajectory_axis(&axes[1], config, rng)?,
        trajectory_axis(&axes[2], config, rng)?,
    ];
    let gains = [
        runs[0].averages.gain()?,
        runs[1].averages.gain()?,
        runs[2].averages.gain()?,
    ];
    let jacobians = [
        runs[0].averages.jacobian()?,
        runs[1].averages.jacobian()?,
        runs[2].averages.jacobian()?,
    ];
    let k9: OMatrix<f64, U9, M9> = block_diagonal::<MA, M9>([&gains[0], &gains[1], &gains[2]]);
    let j9: SMatrix<f64, 9, 9> =
        block_diagonal::<U3, U9>([&jacobians[0], &jacobians[1], &jacobians[2]]);
    let x0 = OMatrix::<f64, U9, kalibra_linalg::U1>::zeros();
    let surrogate = Surrogate::new(
        &k9,
        &j9,
        &full.jacobian(0, &x0),
        &target.noise_cov(0),
        &full.noise_cov(0, &x0),
    )?;
    let hw = surrogate.half_widths(CONFIDENCE)?;
    let mut p = [[0.0; 3]; 9];
    let mut count = 0;
    for (a, run) in runs.iter().enumerate() {
        for i in 0..3 {
            let (t, means) = tests(&run.errors[i], config)?;
            p[3 * a + i] = [t[0].p_value, t[1].p_value, t[2].p_value];
            count = means;
        }
    }
    Ok(TrajectoryOutcome {
        half_widths: std::array::from_fn(|i| hw[i]),
        p,
        batch_means: count,
        spectral_radius: surrogate.spectral_radius(),
    })
}

/// `e_steps` and the EKF's own variances `P_ii` of one replicate.
fn replicate<MA: DimName>(
    axes: &[AxisSetup<MA>; 3],
    steps: usize,
    rng: &mut ChaCha8Rng,
) -> Result<([f64; 9], [f64; 9]), StudyError>
where
    DefaultAllocator: Alloc<U3, MA>,
{
    let mut e = [0.0; 9];
    let mut var = [0.0; 9];
    for (a, axis) in axes.iter().enumerate() {
        run_axis(axis, steps, rng, |k, x, rec| {
            if k == steps {
                let post = rec.posterior();
                for i in 0..3 {
                    e[3 * a + i] = x[i] - post.mean[i];
                    var[3 * a + i] = post.cov[(i, i)];
                }
            }
        })?;
    }
    Ok((e, var))
}

/// The empirical quantile with linear interpolation between order statistics (numpy's
/// default, "type 7").
fn quantile(sorted: &[f64], p: f64) -> f64 {
    let h = (sorted.len() - 1) as f64 * p;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

fn density(values: &[f64], sd: f64, bins: usize) -> Density {
    let lo = -4.0 * sd;
    let width = 8.0 * sd / bins as f64;
    let mut counts = vec![0usize; bins];
    for v in values {
        let b = ((v - lo) / width).floor();
        if b >= 0.0 && (b as usize) < bins {
            counts[b as usize] += 1;
        }
    }
    let x: Vec<f64> = (0..bins).map(|b| lo + (b as f64 + 0.5) * width).collect();
    let n = values.len() as f64;
    Density {
        empirical: counts.iter().map(|&c| c as f64 / (n * width)).collect(),
        surrogate: x
            .iter()
            .map(|x| (-0.5 * (x / sd).powi(2)).exp() / (sd * (2.0 * std::f64::consts::PI).sqrt()))
            .collect(),
        x,
    }
}

/// Runs one reading. The models are built inside each Monte Carlo task from the `make_*`
/// functions (they are cheap), so no nalgebra buffer of a generic size has to be `Sync`.
fn study<MA: DimName, M9: DimName>(
    reading: &Reading,
    make_axes: impl Fn() -> Result<[AxisSetup<MA>; 3], StudyError> + Sync,
    make_full: impl Fn() -> Result<LinearObservation<U9, M9>, StudyError> + Sync,
    config: &Config,
) -> Result<ReadingReport, StudyError>
where
    DefaultAllocator: Alloc<U3, MA> + Alloc<U9, M9>,
{
    let target = Target3d::new(reading.params())?;
    let trajectories =
        MonteCarlo::new(config.trajectories + 1, config.seed).threads(config.threads);
    let outcomes = trajectories
        .map(|_, rng| trajectory(&make_axes()?, &make_full()?, &target, config, rng))?;
    let first = &outcomes[0];
    let rest = &outcomes[1..];

    let replicates =
        MonteCarlo::new(config.replicates, config.seed.wrapping_add(1)).threads(config.threads);
    let reps = replicates.map(|_, rng| replicate(&make_axes()?, config.steps, rng))?;

    let mut q025 = [0.0; 9];
    let mut q975 = [0.0; 9];
    let mut ekf_hw = [0.0; 9];
    let mut cov_s = [0.0; 9];
    let mut cov_p = [0.0; 9];
    let mut densities = Vec::with_capacity(9);
    let n = reps.len() as f64;
    // The standard normal quantile of the intervals (1.959964 at 95%).
    let zq = gaussian_half_widths(&kalibra_linalg::Matrix1::new(1.0), CONFIDENCE)?[0];
    let sd = first.half_widths.map(|h| h / zq);
    for i in 0..9 {
        let mut e: Vec<f64> = reps.iter().map(|(e, _)| e[i]).collect();
        cov_s[i] = e.iter().filter(|v| v.abs() <= first.half_widths[i]).count() as f64 / n;
        cov_p[i] = reps
            .iter()
            .filter(|(e, var)| e[i].abs() <= zq * var[i].sqrt())
            .count() as f64
            / n;
        ekf_hw[i] = reps.iter().map(|(_, var)| zq * var[i].sqrt()).sum::<f64>() / n;
        densities.push(density(&e, sd[i], config.density_bins));
        e.sort_by(f64::total_cmp);
        q025[i] = quantile(&e, 0.025);
        q975[i] = quantile(&e, 0.975);
    }
    let rates = |t: usize| -> [f64; 9] {
        std::array::from_fn(|i| {
            rest.iter().filter(|o| o.p[i][t] < LEVEL).count() as f64 / rest.len().max(1) as f64
        })
    };
    let (runs, t, ks) = (rates(0), rates(1), rates(2));
    let overall = (runs.iter().chain(&t).chain(&ks).sum::<f64>()) / 27.0;
    let spread: [f64; 9] = std::array::from_fn(|i| {
        if rest.len() < 2 {
            return f64::NAN;
        }
        let (mean, sd) = crate::mean_std(rest.iter().map(|o| o.half_widths[i]));
        sd / mean
    });
    Ok(ReadingReport {
        reading: *reading,
        spectral_radius: first.spectral_radius,
        surrogate_halfwidth: first.half_widths,
        surrogate_halfwidth_rel_spread: spread,
        empirical_q025: q025,
        empirical_q975: q975,
        ekf_p_halfwidth: ekf_hw,
        coverage_surrogate: cov_s,
        coverage_ekf_p: cov_p,
        surrogate_vs_paper: (0..9)
            .map(|i| Entry::new(TABLE2_SURROGATE[i], first.half_widths[i]))
            .collect(),
        quantiles_vs_paper: (0..9)
            .map(|i| {
                (
                    Entry::new(TABLE2_EMPIRICAL[i].0, q025[i]),
                    Entry::new(TABLE2_EMPIRICAL[i].1, q975[i]),
                )
            })
            .collect(),
        table1: Table1 {
            batch_means: first.batch_means,
            p_runs: first.p.map(|p| p[0]),
            p_t: first.p.map(|p| p[1]),
            p_ks: first.p.map(|p| p[2]),
            rejection_rate: RejectionRates {
                runs,
                t,
                ks,
                overall,
            },
            trajectories: rest.len(),
        },
        densities,
    })
}

fn axes_positions(reading: &Reading) -> Result<[AxisSetup<kalibra_linalg::U1>; 3], StudyError> {
    let params = reading.params();
    let make = |a| -> Result<_, StudyError> {
        Ok(AxisSetup {
            dynamics: AccelAxis::new(params, a)?,
            measurement: AccelAxis::position_measurement(reading.r)?,
        })
    };
    Ok([make(0)?, make(1)?, make(2)?])
}

fn axes_positions_velocities(
    reading: &Reading,
) -> Result<[AxisSetup<kalibra_linalg::U2>; 3], StudyError> {
    let params = reading.params();
    let make = |a| -> Result<_, StudyError> {
        Ok(AxisSetup {
            dynamics: AccelAxis::new(params, a)?,
            measurement: AccelAxis::position_velocity_measurement(reading.r)?,
        })
    };
    Ok([make(0)?, make(1)?, make(2)?])
}

/// Runs one reading.
///
/// # Errors
/// [`StudyError`] if a model, filter, test or the surrogate fails.
pub fn run_reading(reading: &Reading, config: &Config) -> Result<ReadingReport, StudyError> {
    if reading.observe_velocity {
        study(
            reading,
            || axes_positions_velocities(reading),
            || Ok(Target3d::position_velocity_measurement(reading.r)?),
            config,
        )
    } else {
        study(
            reading,
            || axes_positions(reading),
            || Ok(Target3d::position_measurement(reading.r)?),
            config,
        )
    }
}

/// Runs the study over every reading.
///
/// # Errors
/// [`StudyError`] if a reading fails or `config` is degenerate.
pub fn run(config: &Config) -> Result<Report, StudyError> {
    if config.replicates < 2 || config.trajectory <= config.burn_in + 2 * config.batch {
        return Err(StudyError::Harness(
            "need two replicates and at least two batches after the burn-in".into(),
        ));
    }
    let readings = READINGS
        .iter()
        .map(|r| run_reading(r, config))
        .collect::<Result<Vec<_>, _>>()?;
    let claims = claims(&readings);
    Ok(Report {
        config: *config,
        readings,
        claims,
    })
}

impl Report {
    /// The report of reading `name`.
    pub fn reading(&self, name: &str) -> Option<&ReadingReport> {
        self.readings.iter().find(|r| r.reading.name == name)
    }
}
