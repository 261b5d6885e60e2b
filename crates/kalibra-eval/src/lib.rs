//! Judge any Kalman-type filter from its logs.
//!
//! # What this crate is for
//! Most filters whose covariance needs checking run outside kalibra: in Python, MATLAB, C++,
//! on a vehicle. What their users have is a log. This crate holds such a log as arrays
//! ([`FilterLog`]: `R` runs by `K` steps, each cell optional) and evaluates it
//! ([`Evaluation`]) into a serialisable [`Report`]: per-step ANEES and ANIS with their
//! chi-square bands, the non-credibility index NCI, RMSE per component and group,
//! sliding-window RMSE/bias/std of one run, the whiteness of one run's normalised innovations,
//! `J1`/`J2`/`nq` when the model matrices are logged, and a summary with a verdict (consistent,
//! optimistic or pessimistic) with its evidence and the test behind it.
//!
//! It is the library the `kalibra` command line and the Python package call unchanged. It does
//! no I/O: reading CSV, NPZ or JSON belongs to its callers.
//!
//! Choosing `Q` and `R` (the `Q` sweep behind `kalibra tune`, and the estimators) is the job of
//! the `kalibra-tune` crate; this crate only judges logs.
//!
//! Every number comes from `kalibra-metrics` ([`kalibra_metrics::nees`],
//! [`kalibra_metrics::nis`], [`kalibra_metrics::StepMean`], [`kalibra_metrics::ChiSquareBand`],
//! [`kalibra_metrics::SquaredErrors`], [`kalibra_metrics::Credibility`],
//! [`kalibra_metrics::sliding_window`], [`kalibra_metrics::whiteness`],
//! [`kalibra_metrics::j_step`] and [`kalibra_metrics::JHorizon`]); this crate decides which
//! cells enter which statistic.
//!
//! # Notation
//! `x` the truth, `xhat` the estimate, `P` the filter's (posterior) covariance, all `n`-sized;
//! `nu` the innovation and `S` its covariance, `m`-sized. `NEES = e^T P^-1 e` with
//! `e = xhat - x`; `NIS = nu^T S^-1 nu`. Per step, `ANEES = mean over runs of NEES / n` and
//! `ANIS = mean over runs of NIS / m`, both 1 for a consistent filter; their bands are the
//! two-sided chi-square bands of a mean of as many samples as valid runs at that step. NCI is
//! Li and Zhao's non-credibility index in dB against the Monte Carlo mean-square-error matrix
//! (positive: optimistic), reported with at least 2 valid runs at a step. RMSE uses
//! `e = xhat - x` per component, and per group as `sqrt(mean over runs of sum_i e_i^2)`.
//!
//! # The verdict
//! The verdict rests on the ANEES when the truth is logged, else on the ANIS. With several
//! runs the runs' time averages of `NEES / n` are independent (whatever the correlation of
//! steps within a run), so a two-sided one-sample t-test of them against 1 decides:
//! consistent when `p >= 1 - confidence`, otherwise optimistic (covariance too small) when the
//! mean is above 1 and pessimistic when below. With one run the time average is held against
//! its chi-square band of `K n` degrees of freedom (Bar-Shalom, Li and Kirubarajan 2001, sec.
//! 5.4.2), which takes the steps as independent; the whiteness of the normalised innovations
//! (sample autocorrelation at lags `1..=L` with bands `+-z / sqrt(N_l m)`, and the Box-Pierce
//! test over all lags) checks exactly that assumption and is reported beside it.
//!
//! # Findings, not errors
//! A covariance that is NaN, asymmetric beyond rounding or not positive definite at a cell,
//! and a non-finite estimate or innovation, say something about the filter under test. The
//! evaluation counts such cells ([`Findings`]), names the first (run, step, reason), and leaves
//! them out of the statistics they would poison: a bad `P` leaves the cell out of NEES, NCI and
//! `J1`/`J2` (but not the RMSE, which does not use `P`); a non-finite estimate leaves it out of
//! everything on the state side. Bad shapes, a non-finite truth, non-finite model matrices and
//! bad options are [`EvalError`]s.
//!
//! # Numerical choices
//! Quadratic forms through Cholesky factors (in `kalibra-metrics`); full matrices in row-major
//! order (numpy's C order) so arrays pass through unchanged; chi-square bands computed once per
//! distinct (degrees of freedom, runs) pair. `J1`/`J2` use `A_k = H_k F_k P+_{k-1} F_k^T H_k^T`,
//! `B_k = H_k Q_k H_k^T` and `C_k = H_k P+_k H_k^T`, where `F_k`, `Q_k` are logged at the step
//! they predict into; they are averaged over every update of every run.
//!
//! # Where each job lives
//! * `log`: [`FilterLog`] and its arrays ([`Vectors`], [`Matrices`]), the log as held.
//! * `evaluate`: [`Evaluation`] and its options, the whole-log evaluation in parallel blocks
//!   of steps, and the report's statistics from the accumulated sums (bands, tests, verdict).
//! * `stream`: the cell-by-cell [`Evaluator`] that every evaluation runs on; in it `cell`
//!   (the cell types and their checks), `factor` and `fixed` (the NEES/NIS factorisation,
//!   `Dyn` and fixed-size), `j` (`J1`/`J2` over consecutive steps), `sides` (the state and
//!   innovation sides' sums), `per_run` (the runs' time-average sums) and `state`
//!   ([`EvaluatorState`], an evaluator as data for a shard).
//! * `report`: the serialisable [`Report`] and its parts.
//! * `error`: [`EvalError`].
//!
//! # Example
//! ```
//! use kalibra_eval::{Evaluation, FilterLog, Matrices, Vectors, VerdictKind};
//! // Two runs, three steps, a scalar state whose filter claims variance 1.
//! let truth = Vectors::dense(1, vec![0.0; 6]);
//! let estimate = Vectors::dense(1, vec![0.9, -1.1, 1.0, -0.8, 1.2, -1.0]);
//! let log = FilterLog::new(2, 3)?
//!     .with_truth(truth)?
//!     .with_estimate(estimate)?
//!     .with_covariance(Matrices::constant(1, 1, vec![1.0]))?;
//! let report = Evaluation::new().evaluate(&log)?;
//! assert!((report.anees_per_step[0].unwrap() - (0.81 + 0.64) / 2.0).abs() < 1e-12);
//! assert_eq!(report.summary.verdict.kind, VerdictKind::Consistent);
//! # Ok::<(), kalibra_eval::EvalError>(())
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod error;
mod evaluate;
mod log;
mod report;
mod stream;

pub use error::EvalError;
pub use evaluate::{Evaluation, Group};
pub use log::{FilterLog, MAX_DIM, Matrices, Scope, Vectors};
pub use report::{
    Band, ComponentWindow, ConsistencyTest, Finding, FindingCount, Findings, JReport, LagReport,
    Reason, Report, RmseSeries, SCHEMA_VERSION, Summary, TestMethod, Verdict, VerdictKind,
    WhitenessReport, WindowReport,
};
pub use stream::{
    Cell, Contents, Evaluator, EvaluatorState, MAX_RUNS, MAX_STEPS, MatrixCell, ModelCell,
    PreparedBatch,
};
