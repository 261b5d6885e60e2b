//! Workload W1: the consistency of a correctly tuned Kalman filter.
//!
//! # Set-up
//! State `[x, y, vx, vy]`, `T = 1`, `F = [[1,0,T,0],[0,1,0,T],[0,0,1,0],[0,0,0,1]]`,
//! `Q = G G^T` with `G = [[T^2/2,0],[0,T^2/2],[T,0],[0,T]]`, `H = [I2 0]`, `R = 100 I2`.
//! Each run draws the true initial state from `N(m0, P0)` with `m0 = [0, 0, 10, -5]`,
//! `P0 = diag(100, 100, 25, 25)`, and the filter starts from `(m0, P0)` and updates with `z_0`
//! first: filter and truth agree in every respect, so the filter is consistent by
//! construction and the study checks the machinery (simulation, filter, metrics, harness).
//!
//! # Outputs
//! Per step, over the runs: ANEES (mean NEES divided by n = 4) and average NIS divided by
//! m = 2, each with its two-sided 95% chi-square band (`chi2(runs n)/(runs n)` quantiles);
//! the fraction of steps inside each band (about 95% for a consistent filter, with
//! step-to-step correlation widening the spread); position and velocity RMSE per step.

use kalibra_filters::{Filter, Kf};
use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector4};
use kalibra_metrics::{ChiSquareBand, SquaredErrors, StepMean, time_average};
use kalibra_models::{
    Kinematic, LinearGaussian, LinearObservation, ProcessNoise, Simulator, sample_with_factor,
};
use kalibra_sim::MonteCarlo;
use serde::Serialize;

use crate::StudyError;

/// The W1 dynamics and sensor.
///
/// # Errors
/// Never for these constants; the `Result` carries the models' construction checks.
pub fn models() -> Result<(LinearGaussian<U4>, LinearObservation<U4, U2>), StudyError> {
    let cv = Kinematic::constant_velocity(2, 1.0)?.noise(ProcessNoise::Discrete { q: 1.0 });
    Ok((
        cv.dynamics(U4)?,
        cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)?,
    ))
}

/// The prior of the initial state, `(m0, P0)`.
pub fn prior() -> (Vector4<f64>, Matrix4<f64>) {
    (
        Vector4::new(0.0, 0.0, 10.0, -5.0),
        Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0)),
    )
}

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

/// Runs the study.
///
/// # Errors
/// [`StudyError`] if a run fails (it should not: the models are valid and the filter
/// consistent) or `config` asks for zero runs or steps.
pub fn run(config: &Config) -> Result<Report, StudyError> {
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
    let (nees_acc, nis_acc, err_acc) = mc.accumulate(
        || {
            (
                StepMean::new(steps),
                StepMean::new(steps),
                SquaredErrors::new(steps, 4),
            )
        },
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
    let anees_band = ChiSquareBand::for_normalized_mean(4.0, config.runs, config.confidence)?;
    let anis_band = ChiSquareBand::for_normalized_mean(2.0, config.runs, config.confidence)?;
    let anees = nees_acc.means();
    let anis = nis_acc.means();
    let inside = |v: &[f64], b: &ChiSquareBand| {
        v.iter().filter(|x| b.contains(**x)).count() as f64 / v.len() as f64
    };
    Ok(Report {
        config: *config,
        anees_inside: inside(&anees, &anees_band),
        anis_inside: inside(&anis, &anis_band),
        anees_time_average: time_average(&anees),
        anis_time_average: time_average(&anis),
        anees_band: anees_band.into(),
        anis_band: anis_band.into(),
        anees,
        anis,
        rmse_position: err_acc.rmse_series(&[0, 1])?,
        rmse_velocity: err_acc.rmse_series(&[2, 3])?,
    })
}

impl Report {
    /// The report as Markdown: set-up, summary table, and a sample of the per-step values.
    pub fn to_markdown(&self) -> String {
        use std::fmt::Write;
        let c = &self.config;
        let mut s = String::new();
        let _ = writeln!(s, "# W1: consistency of a correctly tuned Kalman filter\n");
        let _ = writeln!(
            s,
            "2-D constant-velocity target (`[x, y, vx, vy]`, T = 1, Q = G G^T), positions measured with R = 100 I2; \
             Kalman filter with Joseph update, initialised from the truth's prior. {} runs x {} steps, seed {}.\n",
            c.runs, c.steps, c.seed
        );
        let _ = writeln!(
            s,
            "| statistic | time average | {:.0}% band (per step) | steps inside band |",
            c.confidence * 100.0
        );
        let _ = writeln!(s, "|---|---|---|---|");
        let _ = writeln!(
            s,
            "| ANEES (mean NEES / 4) | {:.4} | [{:.4}, {:.4}] | {:.1}% |",
            self.anees_time_average,
            self.anees_band.lower,
            self.anees_band.upper,
            100.0 * self.anees_inside
        );
        let _ = writeln!(
            s,
            "| average NIS / 2 | {:.4} | [{:.4}, {:.4}] | {:.1}% |\n",
            self.anis_time_average,
            self.anis_band.lower,
            self.anis_band.upper,
            100.0 * self.anis_inside
        );
        let _ = writeln!(
            s,
            "A consistent filter has both averages near 1 and about {:.0}% of steps inside each band; \
             the steps are correlated in time, so the fraction varies more than a binomial would.\n",
            c.confidence * 100.0
        );
        let _ = writeln!(
            s,
            "| step | ANEES | NIS / 2 | RMSE position | RMSE velocity |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|");
        let n = self.anees.len();
        let mut shown: Vec<usize> = vec![0, 1, 2, 5, 10, 20, 50, 100, 200, 500, n - 1];
        shown.retain(|&k| k < n);
        shown.dedup();
        for k in shown {
            let _ = writeln!(
                s,
                "| {k} | {:.3} | {:.3} | {:.2} | {:.3} |",
                self.anees[k], self.anis[k], self.rmse_position[k], self.rmse_velocity[k]
            );
        }
        let _ = writeln!(
            s,
            "\nPer-step arrays are in `results.json` (`anees`, `anis`, `rmse_position`, `rmse_velocity`)."
        );
        s
    }
}
