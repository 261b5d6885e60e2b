//! `cargo xtask bench w2`: paper 001's problem III (bearings-only tracking), EKF and UKF,
//! through the library's public API and through hand-written nalgebra loops, in one process.
//!
//! Problem III: state `[x, y]`, `x_{k+1} = diag(0.9, 1) x_k + w_k`,
//! `Q = [[0.1, 0.01], [0.01, 0.1]]`, platform at `(cos k, sin k)` (`k` in radians), bearing
//! `z_k = atan2(y - sin k, x - cos k) + v_k`, `R = 0.025`, wrapped to (-pi, pi]; truth
//! `x_0 ~ N([20, 5], 0.1 I)`; the filters start from `[20, 5]`, `0.1 I` and update with `z_0`
//! first, then predict and update for `k = 1..50`.
//!
//! The truths are simulated once, outside the timed region; every timed pass filters the same
//! stored bearings and sums, per step, the NEES `e^T P+^-1 e` (`e` = truth - posterior mean)
//! over the runs, which both sides compute and the check compares. Each filter is also run
//! batched (`EkfBatch`, `UkfBatch`: eight runs per group) on the scenario's lane-wise models
//! and on the scalar models called per lane, timed against the hand loop beside it.

use std::f64::consts::PI;

use anyhow::{Context, Result, bail};
use kalibra_filters::batch::{
    BATCH, BatchFilter, EkfBatch, Isa, LaneDynamics, LaneMeasurement, LaneSigmaMeasurement,
    PerLane, UkfBatch,
};
use kalibra_filters::{Ekf, Filter, SigmaSet, Ukf, UkfPrediction};
use kalibra_linalg::{U1, U2};
use kalibra_sim::{MAX_BLOCKS, MonteCarlo};
use kalibra_studies::paper001::{BotRun, BotScenario};
use nalgebra::{Matrix2, RowVector2, Vector2};
use rayon::prelude::*;

use super::{Args, Best, Figures, best_of, timed};

/// Seed of the simulated truths (run `i` on ChaCha8 stream `i`, as every kalibra study).
const SEED: u64 = 2012;

/// Largest relative difference between the library's and the hand loop's per-step mean NEES
/// accepted as "the same arithmetic".
const TOLERANCE: f64 = 1e-9;

/// Which filter a pass runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Ekf,
    Ukf,
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Ekf => "EKF",
            Kind::Ukf => "UKF",
        }
    }
}

/// What one filter's measurements gave.
struct Outcome {
    kind: Kind,
    lib_nees: Vec<f64>,
    hand_nees: Vec<f64>,
    /// Best parallel time and its result, with more than one thread.
    parallel: Option<(f64, Vec<f64>)>,
}

/// Runs W2, prints its figures and returns them.
pub(crate) fn run(args: &Args) -> Result<Figures> {
    let threads = match args.threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        t => t,
    };
    let scenario = BotScenario::problem_iii()?;
    let steps = scenario.steps;
    let title = format!(
        "paper 001 problem III (bearings-only, [x, y], platform on the unit circle), EKF (Joseph) and UKF \
         (kappa = 1, linearised prediction), {} runs x {} steps, per-step mean NEES over runs (best of {})",
        args.runs, steps, args.repeats
    );
    println!("W2: {title}");
    let mut figures = Figures::new("w2", title);
    let mc = MonteCarlo::new(args.runs, SEED);
    let (t_truths, runs) = timed(|| {
        (0..args.runs)
            .map(|i| scenario.simulate(&mut mc.rng(i)))
            .collect::<Result<Vec<_>, _>>()
    });
    let runs = runs?;
    println!("  truths simulated once, outside the timed region (seed {SEED}): {t_truths:.3} s");
    let pool = if threads > 1 {
        Some(
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?,
        )
    } else {
        None
    };

    let total = (args.runs * steps) as f64;
    let mut outcomes = Vec::new();
    for kind in [Kind::Ekf, Kind::Ukf] {
        let library = |pool: Option<&rayon::ThreadPool>| {
            per_step_means(args.runs, steps, pool, |i, sums| match kind {
                Kind::Ekf => lib_ekf(&scenario, &runs[i], sums),
                Kind::Ukf => lib_ukf(&scenario, &runs[i], sums),
            })
        };
        let hand = || match kind {
            Kind::Ekf => hand_ekf(&runs, steps),
            Kind::Ukf => hand_ukf(&runs, steps),
        };
        // A pass takes milliseconds: warm caches, branch predictors and the pool's threads
        // with one untimed pass of each variant first.
        library(None)?;
        hand()?;
        if let Some(pool) = &pool {
            library(Some(pool))?;
        }
        // Interleave the two so that machine noise hits both alike.
        let mut lib_best = Best::default();
        let mut hand_best = Best::default();
        let mut lib_nees = Vec::new();
        let mut hand_nees = Vec::new();
        for _ in 0..args.repeats {
            lib_nees = lib_best.time(|| library(None))?;
            hand_nees = hand_best.time(hand)?;
        }
        let (lib_best, hand_best) = (lib_best.seconds(), hand_best.seconds());
        let parallel = match &pool {
            Some(pool) => Some(best_of(args.repeats, || library(Some(pool)))?),
            None => None,
        };
        let lib_rate = total / lib_best;
        let hand_rate = total / hand_best;
        let name = kind.name();
        println!("  {name} library,      1 thread : {lib_rate:>12.0} steps/s ({lib_best:.4} s)");
        println!("  {name} hand-written, 1 thread : {hand_rate:>12.0} steps/s ({hand_best:.4} s)");
        println!(
            "  {name} ratio library / hand-written (1 thread): {:.3}",
            lib_rate / hand_rate
        );
        figures.push(format!("{name} library, 1 thread"), lib_rate, "steps/s");
        figures.push(
            format!("{name} hand-written loop, 1 thread"),
            hand_rate,
            "steps/s",
        );
        figures.push(
            format!("{name} library / hand-written"),
            lib_rate / hand_rate,
            "x",
        );
        if let Some((t_par, _)) = &parallel {
            let par_rate = total / t_par;
            println!(
                "  {name} library, {threads} threads   : {par_rate:>12.0} steps/s ({t_par:.4} s), speed-up {:.2}x over 1 thread",
                par_rate / lib_rate
            );
        }
        {
            // The batched filter (eight runs per group), with the scenario's lane-wise models
            // (the bearing's arctangent in SIMD) and with the scalar models called per lane,
            // interleaved with the hand loop again so that noise hits all alike.
            let isa = super::isa()?;
            let (d, m) = (&scenario.dynamics, &scenario.measurement);
            let lane_wise = || match kind {
                Kind::Ekf => batched_ekf(d, m, &runs, steps, isa),
                Kind::Ukf => batched_ukf(d, m, &runs, steps, isa),
            };
            let per_lane = || match kind {
                Kind::Ekf => batched_ekf(PerLane(d), PerLane(m), &runs, steps, isa),
                Kind::Ukf => batched_ukf(PerLane(d), PerLane(m), &runs, steps, isa),
            };
            lane_wise()?;
            per_lane()?;
            let mut timers = [Best::default(); 3];
            let mut results = [Vec::new(), Vec::new()];
            for _ in 0..args.repeats {
                results[0] = timers[0].time(lane_wise)?;
                results[1] = timers[1].time(per_lane)?;
                timers[2].time(hand)?;
            }
            let best = timers.map(Best::seconds);
            for (i, what) in ["lane-wise models", "models per lane"].iter().enumerate() {
                let rate = total / best[i];
                let diff = max_relative_difference(&results[i], &hand_nees);
                println!(
                    "  {name} batched, {what} ({isa}, {} lanes per vector), 1 thread: {rate:>12.0} steps/s ({:.4} s), {:.2}x the hand-written loop timed beside it ({:.4} s); max relative difference of per-step mean NEES {diff:.2e}",
                    isa.lanes(),
                    best[i],
                    best[2] / best[i],
                    best[2]
                );
                if diff.is_nan() || diff > TOLERANCE {
                    bail!(
                        "W2 batched {name} ({what}): disagrees with the hand-written loop ({diff:.2e})"
                    );
                }
                figures.push(format!("{name} batched, {what}, {isa}"), rate, "steps/s");
                figures.push(
                    format!("{name} batched, {what}, {isa} / hand-written"),
                    best[2] / best[i],
                    "x",
                );
            }
        }
        outcomes.push(Outcome {
            kind,
            lib_nees,
            hand_nees,
            parallel,
        });
    }

    let averages: Vec<String> = outcomes
        .iter()
        .map(|o| {
            let mean = o.lib_nees.iter().sum::<f64>() / o.lib_nees.len() as f64;
            format!("{} {mean:.3}", o.kind.name())
        })
        .collect();
    println!(
        "  time-averaged mean NEES (2 for a consistent filter): {}",
        averages.join(", ")
    );
    let diffs: Vec<(Kind, f64)> = outcomes
        .iter()
        .map(|o| (o.kind, max_relative_difference(&o.lib_nees, &o.hand_nees)))
        .collect();
    println!(
        "  same arithmetic check: max |library - hand-written| / |hand-written| over per-step mean NEES = {}",
        diffs
            .iter()
            .map(|(k, d)| format!("{} {d:.2e}", k.name()))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if threads > 1 {
        let same: Vec<bool> = outcomes
            .iter()
            .map(|o| {
                o.parallel
                    .as_ref()
                    .is_some_and(|(_, par)| bit_identical(par, &o.lib_nees))
            })
            .collect();
        println!(
            "  thread check: {threads} threads give {} results as 1 thread",
            outcomes
                .iter()
                .zip(&same)
                .map(|(o, s)| format!(
                    "{} {}",
                    o.kind.name(),
                    if *s { "bit-identical" } else { "DIFFERENT" }
                ))
                .collect::<Vec<_>>()
                .join(", ")
        );
        if same.contains(&false) {
            bail!("W2 results depend on the thread count");
        }
    } else {
        println!("  thread check: skipped (--threads 1)");
    }
    for (kind, diff) in diffs {
        // A NaN fails too.
        if diff.is_nan() || diff > TOLERANCE {
            bail!(
                "W2 {}: library and hand-written loop disagree (max relative difference {diff:.2e} > {TOLERANCE:.0e})",
                kind.name()
            );
        }
    }
    Ok(figures)
}

fn max_relative_difference(a: &[f64], b: &[f64]) -> f64 {
    if a.len() != b.len() {
        return f64::INFINITY;
    }
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / y.abs())
        // Unlike `f64::max`, a NaN wins.
        .fold(0.0, |m: f64, d| if d.is_nan() || d > m { d } else { m })
}

fn bit_identical(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Per-step means over the runs of what `one(run, sums)` adds to `sums`. The runs are cut into
/// at most [`MAX_BLOCKS`] contiguous blocks fixed by the number of runs; each block sums its
/// runs in order and the blocks are merged in block order, so the floating-point operations
/// are the same on one thread (`pool: None`, the blocks one after the other here) and on any
/// pool.
fn per_step_means(
    runs: usize,
    steps: usize,
    pool: Option<&rayon::ThreadPool>,
    one: impl Fn(usize, &mut [f64]) -> Result<()> + Sync,
) -> Result<Vec<f64>> {
    let blocks = runs.clamp(1, MAX_BLOCKS);
    let block = |b: usize| -> Result<Vec<f64>> {
        let mut sums = vec![0.0; steps];
        for run in (b * runs / blocks)..((b + 1) * runs / blocks) {
            one(run, &mut sums)?;
        }
        Ok(sums)
    };
    let parts: Vec<Vec<f64>> = match pool {
        None => (0..blocks).map(block).collect::<Result<_>>()?,
        Some(pool) => pool.install(|| {
            (0..blocks)
                .into_par_iter()
                .map(block)
                .collect::<Result<_>>()
        })?,
    };
    let mut total = vec![0.0; steps];
    for part in parts {
        for (t, p) in total.iter_mut().zip(part) {
            *t += p;
        }
    }
    let n = runs as f64;
    Ok(total.into_iter().map(|s| s / n).collect())
}

/// One run of a library filter over the stored bearings: update with `z_0`, then predict and
/// update; adds each posterior's NEES to `sums`.
fn lib_filter(mut filter: impl Filter<U2, U1>, run: &BotRun<U2>, sums: &mut [f64]) -> Result<()> {
    for (k, (x, z)) in run.states.iter().zip(&run.measurements).enumerate() {
        if k > 0 {
            filter.predict()?;
        }
        let rec = filter.update(z)?;
        sums[k] += rec.nees(&(x - rec.posterior().mean))?;
    }
    Ok(())
}

fn lib_ekf(scenario: &BotScenario<U2>, run: &BotRun<U2>, sums: &mut [f64]) -> Result<()> {
    let ekf = Ekf::new(
        &scenario.dynamics,
        &scenario.measurement,
        run.init_mean,
        run.init_cov,
    )?;
    lib_filter(ekf, run, sums)
}

fn lib_ukf(scenario: &BotScenario<U2>, run: &BotRun<U2>, sums: &mut [f64]) -> Result<()> {
    let ukf = Ukf::new(
        &scenario.dynamics,
        &scenario.measurement,
        run.init_mean,
        run.init_cov,
        SigmaSet::recommended(2),
    )?
    .with_prediction(UkfPrediction::Linearised);
    lib_filter(ukf, run, sums)
}

/// The EKF of [`lib_ekf`] through [`EkfBatch`] on the models `dynamics` and `measurement`
/// (the scenario's, lane-wise, or [`PerLane`] of them), [`BATCH`] runs per group, each lane
/// from its run's own prior; per-step sums over runs in run order, as [`hand_ekf`] adds them.
fn batched_ekf<D: LaneDynamics<2> + Clone, H: LaneMeasurement<2, 1> + Clone>(
    dynamics: D,
    measurement: H,
    runs: &[BotRun<U2>],
    steps: usize,
    isa: Isa,
) -> Result<Vec<f64>> {
    per_step_nees(runs, steps, |first| {
        Ok(EkfBatch::new(
            isa,
            dynamics.clone(),
            measurement.clone(),
            first.init_mean,
            first.init_cov,
        )?)
    })
}

/// The UKF of [`lib_ukf`] through [`UkfBatch`] on the models `dynamics` and `measurement`
/// (the scenario's, lane-wise, or [`PerLane`] of them), as [`batched_ekf`] runs the EKF.
fn batched_ukf<D: LaneDynamics<2> + Clone, H: LaneSigmaMeasurement<2, 1> + Clone>(
    dynamics: D,
    measurement: H,
    runs: &[BotRun<U2>],
    steps: usize,
    isa: Isa,
) -> Result<Vec<f64>> {
    per_step_nees(runs, steps, |first| {
        Ok(UkfBatch::new(
            isa,
            dynamics.clone(),
            measurement.clone(),
            first.init_mean,
            first.init_cov,
            SigmaSet::recommended(2),
            UkfPrediction::Linearised,
        )?)
    })
}

/// The per-step mean NEES over `runs` of a batched filter that `make` builds for each group
/// of [`BATCH`] runs (from the group's first run; each lane then starts from its own run).
fn per_step_nees<B: BatchFilter<2, 1>>(
    runs: &[BotRun<U2>],
    steps: usize,
    make: impl Fn(&BotRun<U2>) -> Result<B>,
) -> Result<Vec<f64>> {
    let mut sums = vec![0.0; steps];
    for group in runs.chunks(BATCH) {
        let mut filter = make(&group[0])?;
        for (lane, run) in group.iter().enumerate() {
            filter.set_lane(lane, run.init_mean, run.init_cov)?;
        }
        let mut z = [[0.0; BATCH]; 1];
        let mut truth = [[0.0; BATCH]; 2];
        for (k, sum) in sums.iter_mut().enumerate() {
            for (lane, run) in group.iter().enumerate() {
                z[0][lane] = run.measurements[k][0];
                truth[0][lane] = run.states[k][0];
                truth[1][lane] = run.states[k][1];
            }
            let step = if k == 0 {
                filter.update(&z, &truth)
            } else {
                filter.predict_update(&z, &truth)
            };
            for lane in 0..group.len() {
                *sum += step.nees(lane)?;
            }
        }
    }
    let n = runs.len() as f64;
    Ok(sums.into_iter().map(|s| s / n).collect())
}

// ---------------------------------------------------------------------------------------
// Hand-written loops: problem III in plain nalgebra, as a user without kalibra would write it.
// ---------------------------------------------------------------------------------------

/// Problem III's constants, written out.
struct Problem {
    f: Matrix2<f64>,
    q: Matrix2<f64>,
    r: f64,
    x0: Vector2<f64>,
    p0: Matrix2<f64>,
    /// Platform position per step, `(cos k, sin k)`.
    platform: Vec<Vector2<f64>>,
}

impl Problem {
    fn new(steps: usize) -> Self {
        Self {
            f: Matrix2::new(0.9, 0.0, 0.0, 1.0),
            q: Matrix2::new(0.1, 0.01, 0.01, 0.1),
            r: 0.025,
            x0: Vector2::new(20.0, 5.0),
            p0: Matrix2::identity() * 0.1,
            platform: (0..steps)
                .map(|k| Vector2::new((k as f64).cos(), (k as f64).sin()))
                .collect(),
        }
    }

    /// `x- = F x`, `P- = F P F^T + Q`, symmetrised.
    #[inline(always)]
    fn predict(&self, x: &mut Vector2<f64>, p: &mut Matrix2<f64>) {
        *x = self.f * *x;
        *p = self.f * *p * self.f.transpose() + self.q;
        sym2(p);
    }
}

/// Wraps an angle into (-pi, pi].
#[inline(always)]
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(2.0 * PI);
    if w > PI { w - 2.0 * PI } else { w }
}

#[inline(always)]
fn sym2(p: &mut Matrix2<f64>) {
    *p = (*p + p.transpose()) * 0.5;
}

/// `e^T P^-1 e` through the Cholesky factor of `P`.
#[inline(always)]
fn nees2(e: &Vector2<f64>, p: &Matrix2<f64>) -> Result<f64> {
    let chol = p.cholesky().context("posterior P not positive definite")?;
    let w = chol
        .l_dirty()
        .solve_lower_triangular(e)
        .context("singular factor of P")?;
    Ok(w.norm_squared())
}

/// The EKF: bearing Jacobian at the prior mean, innovation wrapped, Joseph update,
/// symmetrised after every prediction and update. Returns the per-step mean NEES.
fn hand_ekf(runs: &[BotRun<U2>], steps: usize) -> Result<Vec<f64>> {
    let m = Problem::new(steps);
    let mut sums = vec![0.0; steps];
    for run in runs {
        let (mut x, mut p) = (m.x0, m.p0);
        for (k, sum) in sums.iter_mut().enumerate() {
            if k > 0 {
                m.predict(&mut x, &mut p);
            }
            let d = x - m.platform[k];
            let zhat = d.y.atan2(d.x);
            let r2 = d.x * d.x + d.y * d.y;
            let h = RowVector2::new(-d.y / r2, d.x / r2);
            let pht = p * h.transpose();
            let s = h.dot(&pht.transpose()) + m.r;
            let gain = pht / s;
            x += gain * wrap(run.measurements[k][0] - zhat);
            let ikh = Matrix2::identity() - gain * h;
            p = ikh * p * ikh.transpose() + gain * gain.transpose() * m.r;
            sym2(&mut p);
            *sum += nees2(&(run.states[k] - x), &p)?;
        }
    }
    let n = runs.len() as f64;
    Ok(sums.into_iter().map(|s| s / n).collect())
}

/// The UKF with the symmetric sigma set, kappa = 1 (`3 - n`), the lower Cholesky factor of the
/// prior, sigma bearings as wrapped residuals from the central bearing, `P+ = P- - K Pz K^T`
/// symmetrised; the prediction is the linear one (exact here). Returns the per-step mean NEES.
fn hand_ukf(runs: &[BotRun<U2>], steps: usize) -> Result<Vec<f64>> {
    let m = Problem::new(steps);
    let (n, kappa) = (2.0, 1.0);
    let spread = f64::sqrt(n + kappa);
    let w0 = kappa / (n + kappa);
    let wi = 0.5 / (n + kappa);
    let mut sums = vec![0.0; steps];
    for run in runs {
        let (mut x, mut p) = (m.x0, m.p0);
        for (k, sum) in sums.iter_mut().enumerate() {
            if k > 0 {
                m.predict(&mut x, &mut p);
            }
            let platform = m.platform[k];
            let bearing = |s: Vector2<f64>| {
                let d = s - platform;
                d.y.atan2(d.x)
            };
            let l = p
                .cholesky()
                .context("prior P not positive definite")?
                .unpack();
            let z0 = bearing(x);
            // Sigma bearings x + spread L_j (j = 0, 1), then x - spread L_j, from the centre.
            let mut dz = [0.0; 4];
            for j in 0..2 {
                let step = l.column(j) * spread;
                dz[j] = wrap(bearing(x + step) - z0);
                dz[2 + j] = wrap(bearing(x - step) - z0);
            }
            let mut dbar = 0.0;
            for d in dz {
                dbar += d * wi;
            }
            let mut pz = dbar * dbar * w0;
            for d in dz {
                pz += (d - dbar) * (d - dbar) * wi;
            }
            pz += m.r;
            // The central point has no state deviation and dbar cancels in each pair.
            let mut pxz = Vector2::zeros();
            for j in 0..2 {
                pxz += l.column(j) * (dz[j] - dz[2 + j]) * (spread * wi);
            }
            let zhat = wrap(z0 + dbar);
            let gain = pxz / pz;
            x += gain * wrap(run.measurements[k][0] - zhat);
            p -= gain * gain.transpose() * pz;
            sym2(&mut p);
            *sum += nees2(&(run.states[k] - x), &p)?;
        }
    }
    let n = runs.len() as f64;
    Ok(sums.into_iter().map(|s| s / n).collect())
}
