//! The W1 run: Monte Carlo over the scenario, per-step ANEES, NIS and RMSE.

use std::sync::Arc;

use kalibra_filters::batch::{BATCH, BatchModel, Isa, KfBatch, KfSchedule};
use kalibra_filters::{Filter, Kf};
use kalibra_metrics::{ChiSquareBand, SquaredErrors, StepMean, time_average};
use kalibra_models::Dynamics;
use kalibra_models::{
    LinearDynamics, LinearMeasurement, Measurement, Simulator, sample_with_factor,
};
use kalibra_sim::{
    ChaCha8Lanes, ChaCha8Rng, LinearTruthBatch, MonteCarlo, Partial, RunFailure, Shard,
};
use serde::Serialize;

use super::scenario::{models, prior};
use crate::StudyError;
use crate::study::study_id;

/// Size and seed of a W1 study.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Config {
    /// Monte Carlo runs.
    pub runs: usize,
    /// Steps per run (`k = 0 .. steps - 1`).
    pub steps: usize,
    /// Seed; run `i` uses ChaCha8 stream `i`.
    pub seed: u64,
    /// Threads (0: all cores). Does not change the results.
    pub threads: usize,
    /// Confidence of the chi-square bands.
    pub confidence: f64,
    /// Instruction set of [`run_batched`] when [`run`] calls it (`None`: detected at run
    /// time). It changes the results only by rounding, and is not part of the report.
    #[serde(skip)]
    pub simd: Option<Isa>,
}

impl Config {
    /// The full size: 1000 runs of 1000 steps.
    pub fn paper() -> Self {
        Self {
            runs: 1000,
            steps: 1000,
            seed: 2012,
            threads: 0,
            confidence: 0.95,
            simd: None,
        }
    }

    /// A reduced size for tests: 200 runs of 200 steps.
    pub fn quick() -> Self {
        Self {
            runs: 200,
            steps: 200,
            ..Self::paper()
        }
    }
}

/// A two-sided band, serialisable.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Band {
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// Coverage probability of the band for a consistent filter.
    pub confidence: f64,
}

impl From<ChiSquareBand> for Band {
    fn from(b: ChiSquareBand) -> Self {
        Self {
            lower: b.lower,
            upper: b.upper,
            confidence: b.confidence,
        }
    }
}

/// The results of a W1 study.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Report {
    /// The configuration run.
    pub config: Config,
    /// ANEES per step (mean NEES / 4).
    pub anees: Vec<f64>,
    /// Average NIS per step, divided by 2.
    pub anis: Vec<f64>,
    /// Band for `anees`.
    pub anees_band: Band,
    /// Band for `anis`.
    pub anis_band: Band,
    /// Fraction of steps whose ANEES is inside its band.
    pub anees_inside: f64,
    /// Fraction of steps whose normalised NIS average is inside its band.
    pub anis_inside: f64,
    /// Time average of `anees`.
    pub anees_time_average: f64,
    /// Time average of `anis`.
    pub anis_time_average: f64,
    /// Position RMSE per step.
    pub rmse_position: Vec<f64>,
    /// Velocity RMSE per step.
    pub rmse_velocity: Vec<f64>,
}

/// Runs the study batched ([`run_batched`]) on `config.simd`, or on the instruction set the
/// CPU has.
///
/// # Errors
/// As [`run_batched`].
pub fn run(config: &Config) -> Result<Report, StudyError> {
    run_batched(config, config.simd.unwrap_or_else(Isa::detect))
}

fn check(config: &Config) -> Result<(), StudyError> {
    if config.runs == 0 || config.steps == 0 {
        return Err(StudyError::Metrics(
            kalibra_metrics::MetricsError::InvalidParameter {
                name: "runs or steps",
                value: 0.0,
            },
        ));
    }
    Ok(())
}

/// The accumulators of a W1 study: per-step NEES / 4, NIS / 2, and squared errors (a
/// shard's partial result holds them block by block).
pub type Acc = (StepMean, StepMean, SquaredErrors);

/// Empty accumulators over `steps` steps.
fn empty(steps: usize) -> Acc {
    (
        StepMean::new(steps),
        StepMean::new(steps),
        SquaredErrors::new(steps, 4),
    )
}

/// The factor `L0` of the prior covariance, from which every run draws its initial state.
fn prior_factor(
    p0: &kalibra_linalg::Matrix4<f64>,
) -> Result<kalibra_linalg::Matrix4<f64>, StudyError> {
    Ok(kalibra_linalg::PsdMatrix::new(*p0)
        .map_err(kalibra_models::ModelError::from)?
        .factor()
        .clone_owned())
}

/// Runs the study one filter at a time: the scalar [`Kf`] over [`Simulator`] truths, the
/// reference the batched path is checked against.
///
/// # Errors
/// [`StudyError`] if a run fails (it should not: the models are valid and the filter
/// consistent) or `config` asks for zero runs or steps.
pub fn run_scalar(config: &Config) -> Result<Report, StudyError> {
    check(config)?;
    let (f, h) = models()?;
    let (m0, p0) = prior();
    let p0_factor = prior_factor(&p0)?;
    let steps = config.steps;
    let mc = MonteCarlo::new(config.runs, config.seed).threads(config.threads);
    let (nees_acc, nis_acc, err_acc) = mc.accumulate(
        || empty(steps),
        |_run, rng, (nees_acc, nis_acc, err_acc)| {
            let x0 = m0 + sample_with_factor(&p0_factor, rng);
            let mut truth = Simulator::new(&f, &h, x0, 0)?;
            let mut kf = Kf::new(&f, &h, m0, p0)?;
            for k in 0..steps {
                let (x, z) = truth.step(rng)?;
                if k > 0 {
                    kf.predict()?;
                }
                let rec = kf.update(&z)?;
                let e = x - rec.posterior().mean;
                nees_acc.push(k, rec.nees(&e)? / 4.0)?;
                nis_acc.push(k, rec.nis() / 2.0)?;
                err_acc.push(k, &e)?;
            }
            Ok::<(), StudyError>(())
        },
    )?;
    report(config, nees_acc, nis_acc, err_acc)
}

/// Runs the study [`BATCH`] runs at a time through [`KfBatch`] on instruction set `isa`, with
/// [`LinearTruthBatch`] truths: run `i` draws what it draws in [`run_scalar`] (the initial state
/// from its generator, the steps' noise from its lane of a [`ChaCha8Lanes`], the same stream's
/// numbers), so the two agree per run to rounding, and the per-step sums add the runs in the
/// same order.
///
/// # Errors
/// As [`run_scalar`]; [`StudyError::Filter`] with
/// [`FilterError::Unsupported`](kalibra_filters::FilterError::Unsupported) if the CPU does not
/// run `isa`.
pub fn run_batched(config: &Config, isa: Isa) -> Result<Report, StudyError> {
    let (mc, make, group) = batched(config, isa, Covariances::Scheduled)?;
    let (nees_acc, nis_acc, err_acc) = mc.accumulate_batched(make, group)?;
    report(config, nees_acc, nis_acc, err_acc)
}

/// [`run_batched`] with every batch computing its lanes' covariances itself
/// ([`KfBatch::new`]) instead of following the covariance schedule the runs share: the same
/// report, to the bit, at the cost of the dense per-lane kernel (for the bench, which times
/// both).
///
/// # Errors
/// As [`run_batched`].
pub fn run_batched_per_lane(config: &Config, isa: Isa) -> Result<Report, StudyError> {
    let (mc, make, group) = batched(config, isa, Covariances::PerLane)?;
    let (nees_acc, nis_acc, err_acc) = mc.accumulate_batched(make, group)?;
    report(config, nees_acc, nis_acc, err_acc)
}

/// Where a batch's covariances come from.
#[derive(Clone, Copy, PartialEq)]
enum Covariances {
    /// A [`KfSchedule`] computed once for every group.
    Scheduled,
    /// Each batch's own kernel.
    PerLane,
}

/// Runs shard `shard` of the batched study on `config.simd` (or the detected instruction
/// set): its partial result, which [`merge`] turns into the report [`run`] gives, to the bit.
///
/// The partial's [`kalibra_sim::StudyId`] names the arithmetic the instruction set does:
/// AVX2, AVX-512 and NEON fuse multiply-adds and agree to the bit (a test compares AVX2 with
/// AVX-512), while the scalar fallback rounds products and sums apart. Shards of the two kinds
/// refuse to merge rather than mix results that differ in the last bits.
///
/// # Errors
/// As [`run_batched`].
pub fn run_shard(config: &Config, shard: Shard) -> Result<Partial<Acc>, StudyError> {
    let isa = config.simd.unwrap_or_else(Isa::detect);
    let (mc, make, group) = batched(config, isa, Covariances::Scheduled)?;
    Ok(mc.accumulate_batched_shard(shard, &shard_id(config, &mc, isa)?, make, group)?)
}

/// The report from the partial results of every shard of the study of `config`.
///
/// # Errors
/// [`StudyError::Shard`] for parts of another configuration or arithmetic (their
/// [`kalibra_sim::StudyId`] differs from `config`'s), duplicates or gaps; as [`run`]
/// otherwise.
pub fn merge(config: &Config, parts: Vec<Partial<Acc>>) -> Result<Report, StudyError> {
    check(config)?;
    let mc = MonteCarlo::new(config.runs, config.seed);
    let Some(first) = parts.first() else {
        return Err(kalibra_sim::ShardError::Empty.into());
    };
    // The arithmetic the shards ran with, from the first shard's identity; every other field
    // must be this configuration's.
    let mut expected = shard_id(config, &mc, config.simd.unwrap_or_else(Isa::detect))?;
    for isa in [Isa::Avx2, Isa::Scalar] {
        let id = shard_id(config, &mc, isa)?;
        if id == first.study {
            expected = id;
        }
    }
    if let Some(other) = parts.iter().find(|p| p.study != expected) {
        return Err(kalibra_sim::ShardError::OtherStudy {
            index: other.shard.index(),
            found: other.study.clone(),
            expected,
        }
        .into());
    }
    let (nees_acc, nis_acc, err_acc) = kalibra_sim::merge(parts)?;
    report(config, nees_acc, nis_acc, err_acc)
}

/// The identity of the study's shards: [`study_id`] with the arithmetic of `isa` in its
/// version label.
fn shard_id(
    config: &Config,
    mc: &MonteCarlo,
    isa: Isa,
) -> Result<kalibra_sim::StudyId, StudyError> {
    let mut id = study_id(config, mc)?;
    let arithmetic = match isa {
        Isa::Scalar => "batched, separate multiply and add",
        _ => "batched, fused multiply-add",
    };
    id.version = format!("{}, {arithmetic}", id.version);
    Ok(id)
}

type Group = dyn Fn(std::ops::Range<usize>, &mut [ChaCha8Rng], &mut Acc) -> Result<(), RunFailure<StudyError>>
    + Sync
    + Send;

/// The batched study's Monte Carlo, its empty accumulator and one group of runs, shared by
/// [`run_batched`] and [`run_shard`] so that a shard computes what the whole study computes.
#[allow(clippy::type_complexity)]
fn batched(
    config: &Config,
    isa: Isa,
    covariances: Covariances,
) -> Result<(MonteCarlo, impl Fn() -> Acc + Sync + Send, Box<Group>), StudyError> {
    check(config)?;
    let (f, h) = models()?;
    let (m0, p0) = prior();
    let p0_factor = prior_factor(&p0)?;
    let model = BatchModel::new(
        f.matrix(0),
        f.noise_cov(0),
        h.matrix(0),
        h.noise_cov(0, &m0),
    )?;
    // Every run starts from the same prior on the same linear model, so every run's
    // covariances are the same sequence: computed once here, for every group to follow.
    // (Without one, a schedule of no updates: each batch computes every step itself.)
    let updates = match covariances {
        Covariances::Scheduled => config.steps,
        Covariances::PerLane => 0,
    };
    let schedule = Arc::new(KfSchedule::new(isa, model, p0, updates)?);
    // Checked once here rather than in every group.
    KfBatch::scheduled(schedule.clone(), m0)?;
    let steps = config.steps;
    let mc = MonteCarlo::new(config.runs, config.seed).threads(config.threads);
    let make = move || empty(steps);
    let group = move |runs: std::ops::Range<usize>,
                      rngs: &mut [ChaCha8Rng],
                      (nees_acc, nis_acc, err_acc): &mut Acc| {
        let first = runs.start;
        let to_study = |e: RunFailure<kalibra_models::ModelError>| RunFailure {
            run: e.run,
            source: StudyError::from(e.source),
        };
        let mut truth = LinearTruthBatch::new(&f, &h, first, rngs, |rng| {
            m0 + sample_with_factor(&p0_factor, rng)
        })
        .map_err(to_study)?
        .with_isa(isa);
        // The steps' draws, from where the initial states left each run's stream.
        let mut draws = ChaCha8Lanes::for_batch(isa, rngs).map_err(|e| RunFailure {
            run: first,
            source: e.into(),
        })?;
        let mut kf = KfBatch::scheduled(schedule.clone(), m0).map_err(|e| RunFailure {
            run: first,
            source: e.into(),
        })?;
        // A run stops at its first error, as the scalar run does; the others go on.
        // `running`: the lanes of runs that have not failed (lanes past the group's runs
        // never run).
        let mut failed: [Option<StudyError>; BATCH] = std::array::from_fn(|_| None);
        let mut running: [bool; BATCH] = std::array::from_fn(|lane| lane < runs.len());
        for k in 0..steps {
            // A diverging truth fails its run (the scalar run's error); the others go on.
            // The step names the lowest failing lane: a higher one failing too cannot be
            // the group's lowest failure.
            if let Err(e) = truth.step(&mut draws) {
                let lane = e.run - first;
                if running[lane] {
                    running[lane] = false;
                    failed[lane] = Some(to_study(e).source);
                }
            }
            let step = if k == 0 {
                kf.update(truth.measurement(), truth.state())
            } else {
                kf.predict_update(truth.measurement(), truth.state())
            };
            // The lanes to push: runs that have not stopped and whose update and NEES
            // succeeded; a run whose step failed stops with the step's error.
            let ok = step.ok();
            let mut live = [false; BATCH];
            for lane in 0..BATCH {
                live[lane] = running[lane] & ok[lane];
            }
            if live != running {
                for lane in 0..BATCH {
                    if running[lane] && !live[lane] {
                        running[lane] = false;
                        failed[lane] = step.nees(lane).err().map(StudyError::from);
                    }
                }
            }
            // Each accumulator adds the lanes in order, as pushing run after run does; a
            // refused value stops its run (it leaves `live`) before its later pushes, as in
            // the scalar run.
            let nees = step.nees_lanes().map(|v| v / 4.0);
            let nis = step.nis_lanes().map(|v| v / 2.0);
            let mut stop = |lane: usize, e: kalibra_metrics::MetricsError| {
                running[lane] = false;
                failed[lane] = Some(e.into());
            };
            nees_acc.push_lanes(k, &nees, &mut live, &mut stop);
            nis_acc.push_lanes(k, &nis, &mut live, &mut stop);
            err_acc.push_lanes(k, step.errors(), &mut live, &mut stop);
        }
        // The lowest failing run of the group.
        match failed
            .into_iter()
            .enumerate()
            .find_map(|(l, e)| e.map(|e| (l, e)))
        {
            Some((lane, source)) => Err(RunFailure {
                run: first + lane,
                source,
            }),
            None => Ok(()),
        }
    };
    Ok((mc, make, Box::new(group)))
}

/// The report of a study's accumulators.
fn report(
    config: &Config,
    nees_acc: StepMean,
    nis_acc: StepMean,
    err_acc: SquaredErrors,
) -> Result<Report, StudyError> {
    let anees_band = ChiSquareBand::for_normalized_mean(4.0, config.runs, config.confidence)?;
    let anis_band = ChiSquareBand::for_normalized_mean(2.0, config.runs, config.confidence)?;
    // Every run pushes every step, so no step's mean is missing.
    let complete = |means: Vec<Option<f64>>, what| {
        means
            .into_iter()
            .collect::<Option<Vec<f64>>>()
            .ok_or(kalibra_metrics::MetricsError::Empty { what })
    };
    let anees = complete(nees_acc.means(), "NEES at a step")?;
    let anis = complete(nis_acc.means(), "NIS at a step")?;
    let inside = |v: &[f64], b: &ChiSquareBand| {
        v.iter().filter(|x| b.contains(**x)).count() as f64 / v.len() as f64
    };
    Ok(Report {
        config: *config,
        anees_inside: inside(&anees, &anees_band),
        anis_inside: inside(&anis, &anis_band),
        anees_time_average: time_average(&anees)?,
        anis_time_average: time_average(&anis)?,
        anees_band: anees_band.into(),
        anis_band: anis_band.into(),
        anees,
        anis,
        rmse_position: err_acc.rmse_series(&[0, 1])?,
        rmse_velocity: err_acc.rmse_series(&[2, 3])?,
    })
}
