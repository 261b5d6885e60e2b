//! Judging a filter from its log, through the library: the arrays a filter writes (truth,
//! estimates, covariances, innovations and their covariances, `R` runs of `K` steps) go into a
//! `FilterLog`, and `Evaluation::evaluate` returns the report `kalibra eval` writes: ANEES and
//! ANIS per step with their bands, NCI, RMSE, and a verdict with its evidence.
//!
//! The log is built in memory here, from two Kalman filters on a 2-D constant-velocity target:
//! one told the truth's process noise, one told a tenth of it. The second trusts its
//! predictions more than it should, and the evaluation calls it optimistic. A filter outside
//! kalibra would hand over the same flat arrays (numpy's C order); `kalibra eval` reads them
//! from CSV, NPZ or JSON files and `kalibra.evaluate` from numpy.
//!
//! Run with `cargo run --example judge_log`.

#![allow(clippy::print_stdout)]

use kalibra::linalg::PsdMatrix;
use kalibra::models::sample_with_factor;
use kalibra::prelude::*;

const RUNS: usize = 40;
const STEPS: usize = 100;

/// One filter's log as flat arrays: per run, per step, a cell's values together, matrices row
/// by row (shapes `(R, K, 4)`, `(R, K, 4, 4)`, `(R, K, 2)` and `(R, K, 2, 2)`).
#[derive(Default)]
struct Arrays {
    truth: Vec<f64>,
    estimate: Vec<f64>,
    covariance: Vec<f64>,
    innovation: Vec<f64>,
    innovation_cov: Vec<f64>,
}

/// Row-major values of a matrix (nalgebra stores columns; the log's arrays are numpy's rows).
fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> impl Iterator<Item = f64> {
    m.transpose()
        .into_iter()
        .copied()
        .collect::<Vec<_>>()
        .into_iter()
}

/// Runs a KF that assumes process-noise intensity `assumed_q` on truths of intensity 1.
fn filter_log(assumed_q: f64) -> Result<Arrays, kalibra::Error> {
    let cv = Kinematic::constant_velocity(2, 1.0)?;
    let truth_model = cv.noise(ProcessNoise::Discrete { q: 1.0 }).dynamics(U4)?;
    let assumed = cv
        .noise(ProcessNoise::Discrete { q: assumed_q })
        .dynamics(U4)?;
    let sensor = cv.position_measurement(U4, U2, Matrix2::identity() * 25.0)?;
    let prior_mean = Vector4::new(0.0, 0.0, 5.0, 2.0);
    let prior_cov = Matrix4::from_diagonal(&Vector4::new(25.0, 25.0, 4.0, 4.0));
    let prior_factor = PsdMatrix::new(prior_cov)?.factor().clone_owned();

    let mc = MonteCarlo::new(RUNS, 7);
    let mut log = Arrays::default();
    for run in 0..RUNS {
        let mut rng = mc.rng(run);
        // The truth starts from a draw of the filter's prior, as a consistent filter assumes.
        let x0 = prior_mean + sample_with_factor(&prior_factor, &mut rng);
        let truth = simulate(&truth_model, &sensor, x0, STEPS, &mut rng)?;
        let mut kf = Kf::new(&assumed, &sensor, prior_mean, prior_cov)?;
        let records = kf.run_collect(truth.measurements.iter().map(Some), Start::UpdateFirst)?;
        for (record, x) in records.iter().zip(&truth.states) {
            log.truth.extend(x.iter());
            log.estimate.extend(record.posterior().mean.iter());
            log.covariance.extend(rows(&record.posterior().cov));
            log.innovation.extend(record.innovation().iter());
            log.innovation_cov.extend(rows(record.s_matrix()));
        }
    }
    Ok(log)
}

fn main() -> Result<(), kalibra::Error> {
    println!("{RUNS} runs x {STEPS} steps of a KF on a 2-D constant-velocity target (true q = 1)");
    for assumed_q in [1.0, 0.1] {
        let arrays = filter_log(assumed_q)?;
        let log = FilterLog::new(RUNS, STEPS)?
            .with_truth(Vectors::dense(4, arrays.truth))?
            .with_estimate(Vectors::dense(4, arrays.estimate))?
            .with_covariance(Matrices::dense(4, 4, arrays.covariance))?
            .with_innovation(Vectors::dense(2, arrays.innovation))?
            .with_innovation_cov(Matrices::dense(2, 2, arrays.innovation_cov))?;
        let report = Evaluation::new().evaluate(&log)?;
        let summary = &report.summary;
        let show = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
        println!(
            "\nfilter assuming q = {assumed_q}: {:?}\n  ANEES {} ({} of steps inside the band), \
             ANIS {}, NCI {} dB\n  {}\n  test: {}",
            summary.verdict.kind,
            show(summary.anees),
            summary
                .anees_fraction_inside
                .map_or("-".to_string(), |f| format!("{:.0}%", 100.0 * f)),
            show(summary.anis),
            show(summary.nci),
            summary.verdict.evidence,
            summary.verdict.test,
        );
    }
    Ok(())
}
