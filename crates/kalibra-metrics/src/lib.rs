//! Filter performance metrics for kalibra.
//!
//! # What this crate is for
//! Metrics take data, never filters: errors, covariances, innovations, or a filter's step
//! records, so they work on the logs of any filter, including filters outside kalibra.
//!
//! * [`nees`] and [`nis`]: normalised estimation error squared and normalised innovation
//!   squared; [`ChiSquareBand`]: their two-sided acceptance interval for the average over runs.
//! * Streaming accumulators for Monte Carlo studies: [`StepMean`] (average NEES, NIS, or any
//!   per-step scalar) and [`SquaredErrors`] (RMSE per step, per component, for groups such as
//!   position and velocity, and over time). They implement [`Merge`], so partial results from
//!   parallel runs combine in a fixed order.
//! * Innovation-covariance tuning metrics (Saha et al. 2012, 2014): [`j_step`] computes `J1k`,
//!   `J2k` and `tr(N_k)` of one update, [`JHorizon`] averages them over a horizon with the
//!   process-noise level `nq`, and [`crossover`] finds where `J1` and `J2` cross along a sweep
//!   of the process-noise scale.
//! * Monte Carlo credibility per step (paper 001): [`Credibility`] keeps every run's error and
//!   NEES and gives, per step ([`CredibilityStep`]), the ANEES, the non-credibility index NCI
//!   of Li and Zhao against the mean-square-error matrix (a pseudo-inverse where that matrix is
//!   singular) and the median NEES, with [`consistent_median_nees`] for reference, and their
//!   means over a range of steps ([`CredibilityAverage`]).
//! * [`itse`]: the integral of time-weighted squared error.
//! * Error series of one run (paper 002): [`instantaneous_errors`] (`e = xhat - x`, the
//!   estimate minus the truth, eq. 14), [`rmse`] and [`rmse_per_state`] over time (eq. 15), and
//!   [`sliding_window`]: the RMSE, bias and local standard deviation of every forward window of
//!   `W` samples ([`WindowStats`], eqs. 16-18), in `O(N)` and robust to large offsets.
//! * Whiteness of one run's normalised innovations ([`whiteness`], [`normalized_innovation`]):
//!   the sample autocorrelation at lags `1..=L` with its band (Bar-Shalom's test) and the
//!   Box-Pierce statistic over all lags ([`Whiteness`], [`LagCorrelation`]).
//! * Hypothesis tests on a series ([`hypothesis`], re-exported here): [`batch_means`] after a
//!   burn-in (streamed by [`BatchMeans`]), the Wald-Wolfowitz [`runs_test`] about the median, the matched-pair
//!   [`paired_t_test`] and the two-sample Kolmogorov-Smirnov test [`ks_two_sample`] (exact
//!   p-value, [`ks_two_sample_exact_p`], or the Kolmogorov limit [`ks_asymptotic_p`] beyond
//!   [`KS_EXACT_MAX_CELLS`]), each giving a [`TestResult`]. Paper 004 applies them to the batch
//!   means of one long trajectory to check that its error settles into a stationary
//!   distribution.
//!
//! # Notation
//! `e_k = x_k - x+_k` the estimation error of one run at step `k`, `P+_k` the filter's
//! covariance, `NEES_k = e^T P^-1 e` (chi-square with `n` degrees of freedom for a consistent
//! filter), `nu_k, S_k` the innovation and its covariance, `NIS_k = nu^T S^-1 nu` (chi-square with
//! `m`). Over `M` runs, ANEES is the mean NEES divided by `n` (paper 001's convention), whose
//! consistent value is 1; the average NEES without the division is also reported.
//!
//! # Numerical choices
//! Quadratic forms go through a Cholesky factor, never an inverse. Accumulators keep plain
//! sums in `f64` (the sums of at most millions of non-negative terms lose no meaningful
//! precision), which makes merging exact in a fixed order. Chi-square quantiles come from
//! statrs. Two-sided p-values are survival functions computed directly, never `1 - cdf`, so
//! small p-values keep their digits (which is why the t and Kolmogorov-Smirnov tests are not
//! statrs' own; see [`hypothesis`]).
//!
//! # Where statrs is called, and its limits
//! Each call stays inside the domain where statrs answers (a huge parameter can make its
//! series iterate without end, a probability of exactly 0 or 1 gives an infinite quantile);
//! outside it, an asymptotic form or a typed error (`tests/extreme_floats.rs` and
//! `tests/extreme_sizes.rs` drive every one):
//!
//! | function | statrs call | limit | beyond it |
//! |---|---|---|---|
//! | [`ChiSquareBand::for_mean`] | `ChiSquared(k).inverse_cdf(p)`, `k = samples dof` | `k` below [`WILSON_HILFERTY_FROM`] (1e7), `dof >= CHI_SQUARE_MIN_DOF`, `p = (1 -+ c)/2` strictly inside (0, 1) | Wilson-Hilferty, error `O(1/k)`: 3e-10 of the band's half-width at the switch; an `InvalidParameter` for a `p` that rounds to 0 or 1 |
//! | [`consistent_median_nees`] | `ChiSquared(dim).inverse_cdf(0.5)` | `dim` below [`WILSON_HILFERTY_FROM`] | Wilson-Hilferty median `(1 - 2/(9 dim))^3`, relative error about 1.3e-15 at the switch (statrs there: 2e-12) |
//! | [`paired_t_test`] | `StudentsT(n - 1).sf(t)` | `n` a slice length (held in memory); statrs' incomplete beta stops after 140 terms, so it returns for any `n` | none needed |
//! | [`whiteness()`] | `Normal.inverse_cdf((1 + c)/2)`, `gamma_ur(L/2, q/2)` | `(1 + c)/2 < 1`; `q > 0` (statrs panics at 0); `L` at most the series length (a larger `L` is `TooFewSamples` before statrs is called) | an `InvalidParameter` for a confidence whose `(1 + c)/2` rounds to 1; `p = 1` at `q = 0` |
//! | the two-sided normal p-values of [`runs_test`] and [`ks_asymptotic_p`] | `gamma_ur(1/2, x)` | none: a fixed shape | |
//!
//! # Where each job lives
//! * `consistency`: [`nees`], [`nis`] and the chi-square bands ([`ChiSquareBand`]).
//! * `accumulate`: the per-step accumulators [`StepMean`] and [`SquaredErrors`], [`Merge`],
//!   [`time_average`].
//! * `credibility`: the [`Credibility`] accumulator (ANEES, median NEES, per-step statistics);
//!   its `nci` module holds the NCI numerics (`Sigma`, its pseudo-inverse quadratic forms, the
//!   runs' log ratios), its `rows` module [`CredibilityRows`] (runs pushed run after run into
//!   one buffer, settled into the accumulator in blocks of steps).
//! * `innovation`: `J1`/`J2` ([`j_step`], [`JHorizon`]) and the sweep's [`crossover`].
//! * `whiteness`: the normalised innovations and their autocorrelation test.
//! * `window`: RMSE and sliding-window statistics of one run.
//! * `itse`: [`itse`].
//! * [`hypothesis`]: batch means, runs, t and Kolmogorov-Smirnov tests.
//! * [`packed`]: the byte-string serde form of the accumulators' arrays.
//! * `scale`: exact power-of-two scaling that keeps statistics of extreme values finite.
//! * `error`: [`MetricsError`].
//!
//! # Example
//! ```
//! use kalibra_metrics::{ChiSquareBand, StepMean};
//! let mut anees = StepMean::new(1);
//! for nees in [1.2, 3.1, 4.0, 0.5] {
//!     anees.push(0, nees / 2.0)?; // n = 2
//! }
//! let band = ChiSquareBand::for_normalized_mean(2.0, 4, 0.95)?;
//! assert!(anees.mean(0).is_some_and(|m| band.contains(m)));
//! # Ok::<(), kalibra_metrics::MetricsError>(())
//! ```

// Library code returns typed errors; an unwrap or expect must say why it cannot fail
// (an `#[allow]` with a comment), never be a hidden panic on data.
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]
mod accumulate;
mod consistency;
mod credibility;
mod error;
pub mod hypothesis;
mod innovation;
mod itse;
pub mod packed;
mod scale;
mod whiteness;
mod window;

pub use accumulate::{HORIZON_MAX, Merge, SquaredErrors, StepMean, time_average};
pub use consistency::{CHI_SQUARE_MIN_DOF, ChiSquareBand, WILSON_HILFERTY_FROM, nees, nis};
pub use credibility::{
    Credibility, CredibilityAverage, CredibilityRows, CredibilityStep, RESERVE_RUNS_MAX,
    consistent_median_nees, median,
};
pub use error::MetricsError;
pub use hypothesis::{
    BATCH_MAX, BatchMeans, KS_EXACT_MAX_CELLS, TestResult, batch_means, ks_asymptotic_p,
    ks_two_sample, ks_two_sample_exact_p, paired_t_test, runs_test,
};
pub use innovation::{Crossover, JHorizon, JStep, JSummary, SweepPoint, crossover, j_step};
pub use itse::itse;
pub use whiteness::{LagCorrelation, Whiteness, normalized_innovation, whiteness};
pub use window::{WindowStats, instantaneous_errors, rmse, rmse_per_state, sliding_window};
