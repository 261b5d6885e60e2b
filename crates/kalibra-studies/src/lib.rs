//! The reproduced studies, beside the library: what `cargo xtask reproduce` runs, as tested
//! code.
//!
//! # What this crate is for
//! The five papers that specify kalibra, and the W1 consistency workload, each re-run end to
//! end and set beside the published numbers. The library crates carry no paper; a paper's
//! scenario, published values, grids and readings of its typos live here, in its folder.
//!
//! | id | module | study |
//! |---|---|---|
//! | `w1` | [`w1`] | a correctly tuned KF is consistent: ANEES and NIS per step in their bands |
//! | `000` | [`paper000`] | Saha, Goswami, Ghosh 2012: J1/J2 of a KF and an EKF along `Q = 10^p Q_nom` (Table I) |
//! | `001` | [`paper001`] | local filters in bearings-only tracking: EKF, UKF, adaptive UKF, SRF on three problems |
//! | `002` | [`paper002`] | Minh et al.: an EKF tracking a manoeuvring angle under three Q sets, sliding windows |
//! | `003` | [`paper003`] | Saha, Ghosh, Goswami 2014: J1/J2 for the EKF, the crossover, initial tuning, CRLB |
//! | `004` | [`paper004`] | Spall and Wei 2023: surrogate bounds from one trajectory, batch-means tests |
//!
//! # How a study is built
//! Every study implements [`study::Study`] (identifier, title, citation, configuration for the
//! published or quick size, run, claims, highlight, Markdown report, figures) and is listed
//! once in [`REGISTRY`]. A study's folder holds `scenario.rs` (the paper's set-up), `run.rs`
//! (configuration, report types, the run), `claims.rs` (each published claim beside ours with
//! a verdict), `report.md` (the report's prose as a template, rendered by [`template`]) with
//! `report.rs` (what the template needs beyond the report's fields), `figures.rs` (figure data,
//! [`figure::Figure`]) and `mod.rs` (the module docs, where every reading of the paper is
//! recorded, and the `Study` impl). The crate computes and renders text; it writes no files
//! (xtask does). Every report records its seed and size, and its numbers do not depend on the
//! thread count.

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
pub mod claims;
pub mod figure;
pub mod paper000;
pub mod paper001;
pub mod paper002;
pub mod paper003;
pub mod paper004;
pub mod reentry;
pub mod study;
pub mod template;
pub mod w1;

use kalibra_filters::FilterError;
use kalibra_metrics::MetricsError;
use kalibra_models::ModelError;

use crate::study::Reproduce;

/// Every study, in the order `cargo xtask reproduce` runs them. Adding a study is its folder
/// and one line here.
pub static REGISTRY: &[&dyn Reproduce] = &[
    &w1::W1,
    &paper000::Paper000,
    &paper001::Paper001,
    &paper002::Paper002,
    &paper003::Paper003,
    &paper004::Paper004,
];

/// The registered study with identifier `id`.
///
/// # Errors
/// [`StudyError::UnknownStudy`], listing the known identifiers, when none matches.
pub fn find(id: &str) -> Result<&'static dyn Reproduce, StudyError> {
    REGISTRY
        .iter()
        .copied()
        .find(|s| s.id() == id)
        .ok_or_else(|| StudyError::UnknownStudy {
            id: id.to_string(),
            known: REGISTRY
                .iter()
                .map(|s| s.id())
                .collect::<Vec<_>>()
                .join(", "),
        })
}

/// Why a study failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StudyError {
    /// A model could not be built or simulated.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A filter step failed.
    #[error(transparent)]
    Filter(#[from] FilterError),
    /// A metric could not be computed.
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    /// Lane-wise random draws could not be set up (too many lanes, an instruction set the
    /// CPU lacks).
    #[error(transparent)]
    Lanes(#[from] kalibra_sim::LanesError),
    /// A tuning helper failed (sweep grid, `P_ad`, `Q_ad`).
    #[error(transparent)]
    Tuning(#[from] kalibra_tune::TuningError),
    /// A linear-algebra computation failed (a Lyapunov or Riccati limit).
    #[error(transparent)]
    Linalg(#[from] kalibra_linalg::LinalgError),
    /// A bound failed (CRLB, observability).
    #[error(transparent)]
    Bounds(#[from] kalibra_bounds::BoundsError),
    /// A Monte Carlo run failed.
    #[error("Monte Carlo run {run} failed: {message}")]
    Run {
        /// The run index.
        run: usize,
        /// The error, rendered.
        message: String,
    },
    /// The Monte Carlo harness failed.
    #[error("Monte Carlo harness: {0}")]
    Harness(String),
    /// A report template did not render (names the template and line).
    #[error("report template {0}")]
    Template(String),
    /// A report lacks a part its summary needs, or does not serialise.
    #[error("report: {0}")]
    Report(String),
    /// No study has this identifier.
    #[error("unknown study {id:?}; the studies are: {known}")]
    UnknownStudy {
        /// The identifier asked for.
        id: String,
        /// The registered identifiers, comma-separated.
        known: String,
    },
    /// The study cannot run as shards (it has no Monte Carlo worth cutting, or not yet).
    #[error("study {0} does not run as shards; the studies that do: {1}")]
    NotSharded(&'static str, String),
    /// Shards could not be merged (other studies, duplicates, gaps), or a partial result did
    /// not read.
    #[error(transparent)]
    Shard(#[from] kalibra_sim::ShardError),
    /// A shard's partial result is not the study's (it does not deserialise).
    #[error("shard {shard}: not a partial result of study {study}: {message}")]
    Partial {
        /// The study.
        study: &'static str,
        /// Which shard (`i/S`, or `?` when the file does not say).
        shard: String,
        /// What did not read.
        message: String,
    },
}

/// Mean and sample standard deviation (divisor `n - 1`, at least 1) of a Monte Carlo sample.
pub(crate) fn mean_std(values: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let n = values.clone().count() as f64;
    let mean = values.clone().sum::<f64>() / n;
    let var = values.map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, var.sqrt())
}

/// Index of the smallest value (ties: the first; NaN never wins), 0 for an empty slice.
pub(crate) fn argmin(values: &[f64]) -> usize {
    (0..values.len()).fold(0, |best, i| if values[i] < values[best] { i } else { best })
}

impl From<kalibra_sim::SimError<StudyError>> for StudyError {
    fn from(e: kalibra_sim::SimError<StudyError>) -> Self {
        match e {
            kalibra_sim::SimError::Run { run, source } => StudyError::Run {
                run,
                message: source.to_string(),
            },
            other => StudyError::Harness(other.to_string()),
        }
    }
}
