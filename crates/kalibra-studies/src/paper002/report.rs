//! What the report template needs beyond the report's own fields: the set-up's constants and
//! the few summaries the prose quotes.

use serde::Serialize;

use super::run::{Config, Report, largest_mean_std};
use super::scenario::{Q_SETS, QSet, QUOTED_STD, R, WINDOW};

/// The template's context.
#[derive(Serialize)]
pub(super) struct Context<'a> {
    config: &'a Config,
    report: &'a Report,
    /// The sets in the paper's order (the report keys them by name).
    q_sets: [QSet; 3],
    window: usize,
    r: f64,
    quoted_std: f64,
    /// Duration of the default truth (s).
    duration: f64,
    /// Largest `|mean window bias|` over the sets.
    largest_bias: f64,
    /// The set with the largest mean window std.
    largest_std: &'static str,
    /// Largest `Q3 / Q2` ratio over the amplitude sweep.
    max_ratio: f64,
}

impl<'a> Context<'a> {
    /// The context of `report` run with `config`.
    pub(super) fn new(config: &'a Config, report: &'a Report) -> Self {
        Self {
            config,
            report,
            q_sets: Q_SETS,
            window: WINDOW,
            r: R,
            quoted_std: QUOTED_STD,
            duration: report.steps as f64 * report.dt,
            largest_bias: Q_SETS
                .iter()
                .map(|set| report.q_sets[set.name].mean_window_bias_theta.abs())
                .fold(0.0, f64::max),
            largest_std: largest_mean_std(&report.q_sets),
            max_ratio: report
                .sweep
                .iter()
                .map(|r| r.q3_over_q2)
                .fold(f64::NEG_INFINITY, f64::max),
        }
    }
}
