//! The paper 004 run: per reading, the surrogate and the Table 1 tests from long trajectories,
//! and the Table 2 quantiles from independent replicates.

use kalibra_bounds::{ErgodicAverage, Surrogate, gaussian_half_widths};
use kalibra_filters::batch::{BATCH, EkfBatch, Isa, Lanes};
use kalibra_linalg::nalgebra::SMatrix;
use kalibra_linalg::{Alloc, Const, DefaultAllocator, DimName, Matrix3, OMatrix, U3, U9, Vector3};
use kalibra_metrics::MetricsError;
use kalibra_metrics::hypothesis::{
    BatchMeans, TestResult, ks_two_sample, paired_t_test, runs_test,
};
use kalibra_models::lanes::{LaneDynamics, lane, set_lane_vector};
use kalibra_models::{AccelAxis, Dynamics, LinearObservation, Measurement, Target3d};
use kalibra_sim::{ChaCha8Rng, MonteCarlo, RunFailure};
use pulp::{Simd, WithSimd};
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
    /// Instruction set of the batched EKF (`None`: detected at run time). It changes the
    /// results only by rounding, and is not part of the report.
    #[serde(skip)]
    pub simd: Option<Isa>,
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
            simd: None,
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
struct AxisSetup<const M: usize> {
    dynamics: AccelAxis,
    measurement: LinearObservation<U3, Const<M>>,
}

/// What one axis of one trajectory yields.
struct AxisTrajectory<const M: usize> {
    averages: ErgodicAverage<U3, Const<M>>,
    /// Errors `x - x_hat` of steps `1 ..= n` per component of the axis.
    errors: [BatchMeans; 3],
}

/// The batched EKF of one axis, on borrowed models: the axis's dynamics and its linear
/// observation evaluate their lanes together (SIMD sine and cosine for the dynamics).
type AxisEkf<'a, const M: usize> =
    EkfBatch<3, M, &'a AccelAxis, &'a LinearObservation<U3, Const<M>>>;

/// The truths of a batch one step on, `x = f(x)` lane-wise (the noise is added per lane
/// after), as a pulp operation on the batch's instruction set.
struct Advance<'a> {
    dynamics: &'a AccelAxis,
    k: usize,
    x: &'a mut [Lanes; 3],
}

impl WithSimd for Advance<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        self.dynamics.transition_lanes(simd, self.k, self.x);
    }
}

/// The Jacobian `J = df/dx` at every lane's estimate, as a pulp operation.
struct JacobianAt<'a> {
    dynamics: &'a AccelAxis,
    x: &'a [Lanes; 3],
    f: &'a mut [[Lanes; 3]; 3],
}

impl WithSimd for JacobianAt<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        self.dynamics.jacobian_lanes(simd, self.x, self.f);
    }
}

/// Runs one axis for `steps` steps from fresh truths, for the runs of `rngs` together (lane
/// `l` is run `first + l`, drawing from `rngs[l]` exactly what the one-run study drew: its
/// initial state, then per step its process noise and its measurement noise), calling
/// `visit(k, truths, ekf)` after each update. Lanes beyond `rngs` carry zeros and are ignored.
///
/// The truths step lane-wise (`f(x)` on the batch's instruction set, its sine within 2 ulp of
/// glibc's), then each lane adds its own draws: run `i`'s truth is the one-run study's to
/// rounding, whatever the batch it falls in.
fn run_axis<const M: usize>(
    axis: &AxisSetup<M>,
    steps: usize,
    isa: Isa,
    first: usize,
    rngs: &mut [ChaCha8Rng],
    mut visit: impl FnMut(usize, &[Lanes; 3], &AxisEkf<'_, M>),
) -> Result<(), RunFailure<StudyError>> {
    let fail = |l: usize, source: StudyError| RunFailure {
        run: first + l,
        source,
    };
    let mut x = [[0.0; BATCH]; 3];
    for (l, rng) in rngs.iter_mut().enumerate() {
        let x0 = kalibra_models::standard_normal(U3, rng);
        set_lane_vector(&mut x, l, &x0);
    }
    let mut ekf = EkfBatch::new(
        isa,
        &axis.dynamics,
        &axis.measurement,
        Vector3::zeros(),
        Matrix3::identity(),
    )
    .map_err(|e| fail(0, e.into()))?;
    let mut z = [[0.0; BATCH]; M];
    for k in 1..=steps {
        isa.dispatch(Advance {
            dynamics: &axis.dynamics,
            k: k - 1,
            x: &mut x,
        });
        for (l, rng) in rngs.iter_mut().enumerate() {
            let w = axis
                .dynamics
                .sample_noise(k - 1, rng)
                .map_err(|e| fail(l, e.into()))?;
            for (xi, wi) in x.iter_mut().zip(w.iter()) {
                xi[l] += wi;
            }
            let xl = lane(&x, l);
            let v = axis
                .measurement
                .sample_noise(k, &xl, rng)
                .map_err(|e| fail(l, e.into()))?;
            let zl = axis.measurement.measure(k, &xl) + v;
            for i in 0..M {
                z[i][l] = zl[i];
            }
        }
        let step = ekf.predict_update(&z, &x);
        for l in 0..rngs.len() {
            step.nis(l).map_err(|e| fail(l, e.into()))?;
        }
        visit(k, &x, &ekf);
    }
    Ok(())
}

/// One axis of the trajectories of `rngs`: per lane the batch means of its errors, and the sums
/// of the gains and of the Jacobians at the estimates after the burn-in, added lane-wise in
/// the order [`ErgodicAverage::push`] adds them.
fn trajectory_axis<const M: usize>(
    axis: &AxisSetup<M>,
    config: &Config,
    isa: Isa,
    first: usize,
    rngs: &mut [ChaCha8Rng],
) -> Result<Vec<AxisTrajectory<M>>, RunFailure<StudyError>> {
    let batches = || BatchMeans::new(config.batch, config.burn_in);
    let mut errors: Vec<[BatchMeans; 3]> = rngs
        .iter()
        .map(|_| Ok([batches()?, batches()?, batches()?]))
        .collect::<Result<_, MetricsError>>()
        .map_err(|e| RunFailure {
            run: first,
            source: e.into(),
        })?;
    let mut gain_sum = [[[0.0; BATCH]; M]; 3];
    let mut jacobian_sum = [[[0.0; BATCH]; 3]; 3];
    let mut jacobian = [[[0.0; BATCH]; 3]; 3];
    let mut count = 0;
    run_axis(axis, config.trajectory, isa, first, rngs, |k, x, ekf| {
        let post = ekf.means();
        for (l, run) in errors.iter_mut().enumerate() {
            for (i, e) in run.iter_mut().enumerate() {
                e.push(x[i][l] - post[i][l]);
            }
        }
        if k > config.burn_in {
            isa.dispatch(JacobianAt {
                dynamics: &axis.dynamics,
                x: post,
                f: &mut jacobian,
            });
            add_lanes(&mut gain_sum, ekf.gains());
            add_lanes(&mut jacobian_sum, &jacobian);
            count += 1;
        }
    })?;
    errors
        .into_iter()
        .enumerate()
        .map(|(l, errors)| {
            let gains = SMatrix::<f64, 3, M>::from_fn(|i, j| gain_sum[i][j][l]);
            let jacobians = SMatrix::<f64, 3, 3>::from_fn(|i, j| jacobian_sum[i][j][l]);
            let averages =
                ErgodicAverage::from_sums(gains, jacobians, count).map_err(|e| RunFailure {
                    run: first + l,
                    source: e.into(),
                })?;
            Ok(AxisTrajectory { averages, errors })
        })
        .collect()
}

/// `sum += add`, lane by lane.
fn add_lanes<const R: usize, const C: usize>(sum: &mut [[Lanes; C]; R], add: &[[Lanes; C]; R]) {
    for (sum, add) in sum.iter_mut().flatten().zip(add.iter().flatten()) {
        for (s, a) in sum.iter_mut().zip(add) {
            *s += a;
        }
    }
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
fn tests(means: BatchMeans) -> Result<([TestResult; 3], usize), StudyError> {
    let means = means.finish()?;
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

/// Trajectories `first ..` of the runs of `rngs`, together: the three axes in turn (each
/// lane's stream continuing from axis to axis, as one run's does), then each trajectory's
/// surrogate and tests.
fn trajectories<const M: usize, M9: DimName>(
    axes: &[AxisSetup<M>; 3],
    full: &LinearObservation<U9, M9>,
    target: &Target3d,
    config: &Config,
    isa: Isa,
    first: usize,
    rngs: &mut [ChaCha8Rng],
) -> Result<Vec<TrajectoryOutcome>, RunFailure<StudyError>>
where
    DefaultAllocator: Alloc<U9, M9>,
{
    let xs = trajectory_axis(&axes[0], config, isa, first, rngs)?;
    let ys = trajectory_axis(&axes[1], config, isa, first, rngs)?;
    let zs = trajectory_axis(&axes[2], config, isa, first, rngs)?;
    xs.into_iter()
        .zip(ys)
        .zip(zs)
        .enumerate()
        .map(|(l, ((x, y), z))| {
            trajectory([x, y, z], full, target).map_err(|source| RunFailure {
                run: first + l,
                source,
            })
        })
        .collect()
}

/// The surrogate and the tests of one trajectory from its three axes.
fn trajectory<const M: usize, M9: DimName>(
    runs: [AxisTrajectory<M>; 3],
    full: &LinearObservation<U9, M9>,
    target: &Target3d,
) -> Result<TrajectoryOutcome, StudyError>
where
    DefaultAllocator: Alloc<U9, M9>,
{
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
    let k9: OMatrix<f64, U9, M9> =
        block_diagonal::<Const<M>, M9>([&gains[0], &gains[1], &gains[2]]);
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
    for (a, run) in runs.into_iter().enumerate() {
        for (i, errors) in run.errors.into_iter().enumerate() {
            let (t, means) = tests(errors)?;
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

/// One replicate's `e_steps` and the EKF's own variances `P_ii` at that step.
type Replicate = ([f64; 9], [f64; 9]);

/// `e_steps` and the EKF's own variances `P_ii` of the replicates of `rngs` (`first ..`),
/// stepped together axis by axis.
fn replicates<const M: usize>(
    axes: &[AxisSetup<M>; 3],
    steps: usize,
    isa: Isa,
    first: usize,
    rngs: &mut [ChaCha8Rng],
) -> Result<Vec<Replicate>, RunFailure<StudyError>> {
    let mut out = vec![([0.0; 9], [0.0; 9]); rngs.len()];
    for (a, axis) in axes.iter().enumerate() {
        run_axis(axis, steps, isa, first, rngs, |k, x, ekf| {
            if k == steps {
                for (l, (e, var)) in out.iter_mut().enumerate() {
                    let (mean, cov) = (ekf.mean(l), ekf.cov(l));
                    for i in 0..3 {
                        e[3 * a + i] = x[i][l] - mean[i];
                        var[3 * a + i] = cov[(i, i)];
                    }
                }
            }
        })?;
    }
    Ok(out)
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
fn study<const M: usize, M9: DimName>(
    reading: &Reading,
    make_axes: impl Fn() -> Result<[AxisSetup<M>; 3], StudyError> + Sync,
    make_full: impl Fn() -> Result<LinearObservation<U9, M9>, StudyError> + Sync,
    config: &Config,
) -> Result<ReadingReport, StudyError>
where
    DefaultAllocator: Alloc<U9, M9>,
{
    let target = Target3d::new(reading.params())?;
    let isa = config.simd.unwrap_or_else(Isa::detect);
    // A model that cannot be built fails every run alike: blame the first of the group.
    let build = |first: usize, e: StudyError| RunFailure {
        run: first,
        source: e,
    };
    let trajectories_mc =
        MonteCarlo::new(config.trajectories + 1, config.seed).threads(config.threads);
    let outcomes = trajectories_mc.map_batched(|runs, rngs| {
        let axes = make_axes().map_err(|e| build(runs.start, e))?;
        let full = make_full().map_err(|e| build(runs.start, e))?;
        trajectories(&axes, &full, &target, config, isa, runs.start, rngs)
    })?;
    let first = &outcomes[0];
    let rest = &outcomes[1..];

    let replicates_mc =
        MonteCarlo::new(config.replicates, config.seed.wrapping_add(1)).threads(config.threads);
    let reps = replicates_mc.map_batched(|runs, rngs| {
        let axes = make_axes().map_err(|e| build(runs.start, e))?;
        replicates(&axes, config.steps, isa, runs.start, rngs)
    })?;

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

fn axes_positions(reading: &Reading) -> Result<[AxisSetup<1>; 3], StudyError> {
    let params = reading.params();
    let make = |a| -> Result<_, StudyError> {
        Ok(AxisSetup {
            dynamics: AccelAxis::new(params, a)?,
            measurement: AccelAxis::position_measurement(reading.r)?,
        })
    };
    Ok([make(0)?, make(1)?, make(2)?])
}

fn axes_positions_velocities(reading: &Reading) -> Result<[AxisSetup<2>; 3], StudyError> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_filters::{Ekf, Filter};

    /// Per step of one run: truth, mean, covariance and gain.
    type Trace<const M: usize> =
        Vec<(Vector3<f64>, Vector3<f64>, Matrix3<f64>, SMatrix<f64, 3, M>)>;

    /// One axis of one run through the scalar EKF, as the study ran before it was batched.
    fn scalar_axis<const M: usize>(
        axis: &AxisSetup<M>,
        steps: usize,
        rng: &mut ChaCha8Rng,
    ) -> Trace<M> {
        let mut x: Vector3<f64> = kalibra_models::standard_normal(U3, rng);
        let mut ekf = Ekf::new(
            &axis.dynamics,
            &axis.measurement,
            Vector3::zeros(),
            Matrix3::identity(),
        )
        .unwrap();
        let mut out = Vec::new();
        for k in 1..=steps {
            x = axis.dynamics.transition(k - 1, &x)
                + axis.dynamics.sample_noise(k - 1, rng).unwrap();
            let z = axis.measurement.measure(k, &x)
                + axis.measurement.sample_noise(k, &x, rng).unwrap();
            ekf.predict().unwrap();
            let rec = ekf.update(&z).unwrap();
            let post = rec.posterior();
            out.push((x, post.mean, post.cov, *rec.gain()));
        }
        out
    }

    fn agree<const M: usize>(axes: &[AxisSetup<M>; 3]) {
        // Five runs: a group shorter than BATCH, whose spare lanes must not matter.
        let (runs, steps) = (5, 400);
        let mc = MonteCarlo::new(runs, 11);
        for isa in Isa::available() {
            let mut rngs: Vec<_> = (0..runs).map(|r| mc.rng(r)).collect();
            let mut scalar_rngs = rngs.clone();
            let mut worst = 0.0f64;
            for axis in axes {
                let mut batched: Vec<Trace<M>> = vec![Vec::new(); runs];
                run_axis(axis, steps, isa, 0, &mut rngs, |_, x, ekf| {
                    for (l, trace) in batched.iter_mut().enumerate() {
                        trace.push((lane(x, l), ekf.mean(l), ekf.cov(l), ekf.gain(l)));
                    }
                })
                .unwrap();
                for (rng, trace) in scalar_rngs.iter_mut().zip(&batched) {
                    let scalar = scalar_axis(axis, steps, rng);
                    for (a, b) in trace.iter().zip(&scalar) {
                        // The same draws; the truths agree to rounding (the batch steps f
                        // lane-wise, its sine within 2 ulp of glibc's).
                        worst = worst
                            .max((a.0 - b.0).amax() / b.0.amax().max(1e-300))
                            .max((a.1 - b.1).amax() / b.1.amax().max(1e-300))
                            .max((a.2 - b.2).amax() / b.2.amax())
                            .max((a.3 - b.3).amax() / b.3.amax());
                    }
                }
            }
            assert!(worst <= 1e-12, "{isa}: {worst:e}");
        }
    }

    #[test]
    fn the_batched_axes_agree_with_the_scalar_ekf_run_by_run() {
        agree(&axes_positions(&READINGS[0]).unwrap());
        agree(&axes_positions_velocities(&READINGS[1]).unwrap());
    }
}
