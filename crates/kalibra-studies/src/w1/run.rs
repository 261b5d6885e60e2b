//! The W1 run: Monte Carlo over the scenario, per-step ANEES, NIS and RMSE.

use kalibra_filters::{Filter, Kf};
use kalibra_metrics::{ChiSquareBand, SquaredErrors, StepMean, time_average};
use kalibra_models::{Simulator, sample_with_factor};
use kalibra_sim::{ChaCha8Rng, MonteCarlo, Partial, Shard};
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

/// The study's accumulators: NEES / 4 and NIS / 2 per step, and the squared errors.
pub type Acc = (StepMean, StepMean, SquaredErrors);

/// Runs the study.
///
/// # Errors
/// [`StudyError`] if a run fails (it should not: the models are valid and the filter
/// consistent) or `config` asks for zero runs or steps.
pub fn run(config: &Config) -> Result<Report, StudyError> {
    let (mc, make, one) = study(config)?;
    finish(config, mc.accumulate(make, one)?)
}

/// Runs shard `shard` of the study: its partial result, which [`merge`] turns into the
/// report [`run`] gives, to the bit.
///
/// # Errors
/// As [`run`].
pub fn run_shard(config: &Config, shard: Shard) -> Result<Partial<Acc>, StudyError> {
    let (mc, make, one) = study(config)?;
    let id = study_id(config, &mc)?;
    Ok(mc.accumulate_shard(shard, &id, make, one)?)
}

/// The report from the partial results of every shard of the study of `config`.
///
/// # Errors
/// [`StudyError::Shard`] for parts of another configuration (their [`kalibra_sim::StudyId`]
/// differs from `config`'s), duplicates or gaps; as [`run`] otherwise.
pub fn merge(config: &Config, parts: Vec<Partial<Acc>>) -> Result<Report, StudyError> {
    let (mc, _, _) = study(config)?;
    let id = study_id(config, &mc)?;
    if let Some(other) = parts.iter().find(|p| p.study != id) {
        return Err(kalibra_sim::ShardError::OtherStudy {
            index: other.shard.index(),
            found: other.study.clone(),
            expected: id,
        }
        .into());
    }
    finish(config, kalibra_sim::merge(parts)?)
}

type Run = dyn Fn(usize, &mut ChaCha8Rng, &mut Acc) -> Result<(), StudyError> + Sync + Send;

/// The study's Monte Carlo, its empty accumulator and one run, shared by [`run`] and
/// [`run_shard`] so a shard computes exactly what the whole study computes.
#[allow(clippy::type_complexity)]
fn study(
    config: &Config,
) -> Result<(MonteCarlo, impl Fn() -> Acc + Sync + Send, Box<Run>), StudyError> {
    if config.runs == 0 || config.steps == 0 {
        return Err(StudyError::Metrics(
            kalibra_metrics::MetricsError::InvalidParameter {
                name: "runs or steps",
                value: 0.0,
            },
        ));
    }
    let (f, h) = models()?;
    let (m0, p0) = prior();
    let p0_factor = kalibra_linalg::PsdMatrix::new(p0)
        .map_err(kalibra_models::ModelError::from)?
        .factor()
        .clone_owned();
    let steps = config.steps;
    let mc = MonteCarlo::new(config.runs, config.seed).threads(config.threads);
    let make = move || {
        (
            StepMean::new(steps),
            StepMean::new(steps),
            SquaredErrors::new(steps, 4),
        )
    };
    let one = move |_run: usize, rng: &mut ChaCha8Rng, (nees_acc, nis_acc, err_acc): &mut Acc| {
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
    };
    Ok((mc, make, Box::new(one)))
}

/// The report from the study's accumulators.
fn finish(config: &Config, (nees_acc, nis_acc, err_acc): Acc) -> Result<Report, StudyError> {
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
