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

mod run;
mod scenario;

pub use run::{
    Acc, Band, Config, Report, merge, run, run_batched, run_batched_per_lane, run_scalar, run_shard,
};
pub use scenario::{models, prior};

use crate::StudyError;
use crate::claims::Claim;
use crate::study::{NamedFigure, Study};

/// The W1 study, as the registry lists it.
#[derive(Clone, Copy, Debug, Default)]
pub struct W1;

/// The report's template (prose with the numbers filled in from [`Report`]).
const TEMPLATE: &str = include_str!("report.md");

/// Steps the report's table samples (those past the end of a short run are left out).
const SHOWN_STEPS: [usize; 10] = [0, 1, 2, 5, 10, 20, 50, 100, 200, 500];

crate::study_config!(Config, seed, simd);

impl Study for W1 {
    type Config = Config;
    type Report = Report;

    fn id(&self) -> &'static str {
        "w1"
    }

    fn title(&self) -> &'static str {
        "W1: consistency of a correctly tuned Kalman filter"
    }

    fn paper(&self) -> Option<&'static str> {
        None
    }

    fn describe(&self, config: &Config) -> String {
        format!(
            "consistency study, {} runs x {} steps",
            config.runs, config.steps
        )
    }

    fn run(&self, config: &Config) -> Result<Report, StudyError> {
        run(config)
    }

    fn sharded(&self) -> bool {
        true
    }

    fn run_shard(&self, config: &Config, shard: kalibra_sim::Shard) -> Result<Vec<u8>, StudyError> {
        crate::study::write_partial(&run_shard(config, shard)?)
    }

    fn merge_shards(&self, config: &Config, parts: Vec<Vec<u8>>) -> Result<Report, StudyError> {
        merge(config, crate::study::read_partials(self.id(), parts)?)
    }

    fn claims(&self, _report: &Report) -> Vec<Claim> {
        Vec::new()
    }

    fn highlight(&self, _config: &Config, report: &Report) -> Result<String, StudyError> {
        Ok(format!(
            "ANEES {:.3} ({:.1}% of steps in 95% band), NIS/2 {:.3} ({:.1}% in band)",
            report.anees_time_average,
            100.0 * report.anees_inside,
            report.anis_time_average,
            100.0 * report.anis_inside,
        ))
    }

    fn markdown(&self, config: &Config, report: &Report) -> Result<String, StudyError> {
        let n = report.anees.len();
        let mut shown: Vec<usize> = SHOWN_STEPS.iter().copied().filter(|&k| k < n).collect();
        shown.extend(n.checked_sub(1));
        shown.dedup();
        let rows: Vec<_> = shown
            .into_iter()
            .map(|k| {
                serde_json::json!({
                    "step": k,
                    "anees": report.anees[k],
                    "anis": report.anis[k],
                    "rmse_position": report.rmse_position[k],
                    "rmse_velocity": report.rmse_velocity[k],
                })
            })
            .collect();
        crate::template::render(
            "w1/report.md",
            TEMPLATE,
            &serde_json::json!({ "config": config, "report": report, "rows": rows }),
        )
    }

    fn figures(&self, _report: &Report) -> Vec<NamedFigure> {
        Vec::new()
    }
}
