//! Monte Carlo credibility of a filter's covariance, per step (paper 001): ANEES, the
//! non-credibility index NCI of Li and Zhao, and the median NEES. Definitions, numerical
//! choices and memory are documented at [`Credibility`], the accumulator that computes them.

use std::ops::Range;

use kalibra_linalg::{Alloc, DMatrix, DefaultAllocator, Dim, LinalgError, OMatrix, OVector};
use statrs::distribution::{ChiSquared, ContinuousCDF};

use crate::accumulate::assert_fits;
use crate::{Merge, MetricsError, nees};

mod nci;
mod rows;
use nci::{mse_matrix, nci_of_step};
pub use rows::CredibilityRows;

/// Per-step credibility of a filter over Monte Carlo runs: ANEES, the non-credibility index
/// NCI of Li and Zhao, and the median NEES.
///
/// Each run pushes its error and covariance ([`Credibility::push`]), or its error and an
/// already computed NEES ([`Credibility::push_nees`]), at every step;
/// [`Credibility::step_summary`] and [`Credibility::summaries`] then give the statistics of
/// each step ([`CredibilityStep`]), [`Credibility::over_time`] their means over a range of
/// steps. Partial accumulators of one study combine with [`Merge`], which appends the other's
/// runs after this one's.
///
/// # Definitions
/// At step `k`, run `i` of `M` has the error `e_i = x_i - xhat_i` (an `n`-vector) and the
/// filter's covariance `P_i`, so `NEES_i = e_i^T P_i^-1 e_i`. Then
///
/// * `ANEES_k = (1 / (n M)) sum_i NEES_i`, 1 for a consistent filter;
/// * `Sigma_k = (1 / M) sum_i e_i e_i^T`, the Monte Carlo mean-square-error matrix (no mean
///   removed: a bias counts as error);
/// * `NCI_k = (1 / M) sum_i [10 log10(e_i^T P_i^-1 e_i) - 10 log10(e_i^T Sigma_k^-1 e_i)]`
///   (X. R. Li and Z. Zhao, "Measuring estimator's credibility: noncredibility index", FUSION
///   2006), in decibels: 0 for a filter whose covariance matches the actual mean-square error,
///   positive for an optimistic filter (`P` too small), negative for a pessimistic one. Scaling
///   every `P_i` by `1 / c` adds exactly `10 log10 c`. For a consistent filter NCI is about
///   `(10 / ln 10) (ANEES - 1)`, so it fluctuates with a standard deviation of about
///   `4.34 sqrt(2 / (n M))` dB;
/// * the median over runs of `NEES_i / n`, a companion of ANEES that a few diverged runs cannot
///   move; a consistent filter gives the median of `chi-square(n) / n`
///   ([`consistent_median_nees`]).
///
/// # Singular `Sigma_k`, and runs without a logarithm
/// `Sigma_k` is singular when every run's error lies in a subspace, for example at the first
/// step of a problem whose initial error comes from one scalar noise. `Sigma_k^-1` is then the
/// Moore-Penrose pseudo-inverse `Sigma_k^+` ([`CredibilityStep::mse_rank`] reports the rank
/// kept). Every `e_i` lies in the range of `Sigma_k`, so `e_i^T Sigma_k^+ e_i` is `M` times
/// the leverage of run `i` (the diagonal of the projector onto the span of the errors) and
/// sums to `M rank(Sigma_k)` over the runs.
///
/// A run whose `NEES_i` or `e_i^T Sigma_k^+ e_i` is exactly 0 (an error of exactly zero) has no
/// logarithm: it is left out of NCI, which then averages over the other runs, and counted in
/// [`CredibilityStep::nci_skipped`]. It still counts in ANEES, the median and `Sigma_k`. If no
/// run is left, NCI is NaN, never `-inf`.
///
/// # Numerical choices
/// * NEES goes through a Cholesky factor of `P_i` ([`nees`]).
/// * The pseudo-inverse is taken of `Sigma_k` scaled to unit diagonal (a correlation matrix),
///   through its symmetric eigen-decomposition: eigenvalues at or below `n eps lambda_max`
///   (`eps` the `f64` machine epsilon, `lambda_max >= 1` the largest eigenvalue of the
///   correlation matrix) count as zero, the others are inverted. A component that is exactly 0
///   in every run takes no part. The scaling changes no `e_i^T Sigma_k^+ e_i` (the projector
///   onto the span of the errors does not depend on the units of the components), but it makes
///   the tolerance independent of them: unscaled, a component whose variance is below about
///   `1e-15` times the largest would be thrown away, whatever its units. A direction kept
///   although it is only rounding noise (an eigenvalue of order `eps` instead of 0) changes the
///   quadratic forms by a relative `O(eps)` only, since the errors' components along it are
///   themselves rounding.
/// * The errors are divided by their largest magnitude per component before any product, so
///   the quadratic forms of NCI neither overflow nor underflow; `Sigma_k` itself is reported
///   in the caller's units ([`CredibilityStep::mse`]), and overflows for errors beyond about
///   `1e154`.
/// * The runs' `log10 NEES_i - log10(e_i^T Sigma_k^+ e_i)` are summed as `log10` of the
///   ratio of the two products over the runs, each product kept as a mantissa and a power of
///   two so that it neither overflows nor underflows: two logarithms per step instead of two
///   per run, with one rounding per run as before.
/// * Every sum runs over the runs in the order they were pushed and merged, so a study that
///   merges partial accumulators in a fixed order gets bit-identical summaries whatever the
///   thread count.
///
/// # Memory
/// Unlike the other accumulators, `Credibility` keeps every run: `Sigma_k` is known only after
/// the last run, and NCI needs every run's error against it. It holds `n + 1` numbers per run
/// and step, `O(steps M n)`: 1000 runs of 51 steps of a 4-state filter take 2.0 MB (1.6 MB of
/// errors, 0.4 MB of NEES). Pushing run after run stores to a vector per step, far apart;
/// [`CredibilityRows`] buffers such pushes in one vector and settles them in blocks of steps.
///
/// # Example
/// ```
/// use kalibra_linalg::{Matrix2, Vector2};
/// use kalibra_metrics::Credibility;
/// let mut cred = Credibility::new(1, 2);
/// // Four runs whose mean-square-error matrix is Sigma = 0.5 I, with a filter that reports
/// // P = 0.25 I: half the actual error, so 3 dB optimistic.
/// let p = Matrix2::identity() * 0.25;
/// for e in [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]] {
///     cred.push(0, &Vector2::from(e), &p)?;
/// }
/// let s = cred.step_summary(0)?;
/// assert_eq!((s.runs, s.mse_rank, s.nci_skipped), (4, 2, 0));
/// assert!((s.anees - 2.0).abs() < 1e-15);
/// assert!((s.median_nees - 2.0).abs() < 1e-15);
/// assert!((s.nci - 10.0 * 2f64.log10()).abs() < 1e-12);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// Serialised (serde) as `{"dim": n, "errors": [[...], ...], "nees": [[...], ...]}`, per step
/// the runs' errors (`dim` values each) and their NEES; deserialising checks that the lengths
/// agree and every value is finite.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "CredibilityData")]
pub struct Credibility {
    dim: usize,
    /// Per step, the errors of the runs pushed there, one after the other (`dim` values each).
    errors: Vec<Vec<f64>>,
    /// Per step, the NEES of the same runs, in the same order.
    nees: Vec<Vec<f64>>,
}

/// [`Credibility`] as read, before its invariants are checked.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct CredibilityData {
    dim: usize,
    errors: Vec<Vec<f64>>,
    nees: Vec<Vec<f64>>,
}

impl TryFrom<CredibilityData> for Credibility {
    type Error = String;

    fn try_from(d: CredibilityData) -> Result<Self, String> {
        if d.errors.len() != d.nees.len() {
            return Err(format!(
                "credibility with {} steps of errors and {} of NEES",
                d.errors.len(),
                d.nees.len()
            ));
        }
        for (k, (e, n)) in d.errors.iter().zip(&d.nees).enumerate() {
            if n.len().checked_mul(d.dim) != Some(e.len()) {
                return Err(format!(
                    "credibility step {k}: {} error values for {} runs of dimension {}",
                    e.len(),
                    n.len(),
                    d.dim
                ));
            }
            if e.iter().chain(n).any(|v| !v.is_finite()) {
                return Err(format!("credibility step {k}: a value is not finite"));
            }
        }
        Ok(Self {
            dim: d.dim,
            errors: d.errors,
            nees: d.nees,
        })
    }
}

/// The credibility statistics of one step (see [`Credibility`]).
#[derive(Clone, Debug, PartialEq)]
pub struct CredibilityStep {
    /// Number of runs `M` at the step.
    pub runs: usize,
    /// `ANEES = mean NEES / n`; 1 for a consistent filter.
    pub anees: f64,
    /// The non-credibility index in decibels, averaged over the runs not skipped; NaN if every
    /// run was skipped.
    pub nci: f64,
    /// Runs left out of NCI because their NEES or `e^T Sigma^+ e` is exactly 0.
    pub nci_skipped: usize,
    /// The median over runs of `NEES / n` (the mean of the two middle values for an even
    /// count); [`consistent_median_nees`] gives its value for a consistent filter.
    pub median_nees: f64,
    /// The mean-square-error matrix `Sigma = (1 / M) sum_i e_i e_i^T`, `n x n`, exactly
    /// symmetric.
    pub mse: DMatrix<f64>,
    /// The rank of `Sigma` used for its pseudo-inverse: `n` unless the errors span a subspace.
    pub mse_rank: usize,
}

/// Plain means over a range of steps of the per-step statistics ([`Credibility::over_time`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CredibilityAverage {
    /// Number of steps averaged.
    pub steps: usize,
    /// Mean of the per-step ANEES.
    pub anees: f64,
    /// Mean of the per-step NCI, in decibels (NaN if a step's NCI is NaN).
    pub nci: f64,
    /// Mean of the per-step median of `NEES / n`.
    pub median_nees: f64,
}

impl CredibilityAverage {
    /// Plain means of the statistics of `steps`, each step weighing the same whatever its
    /// number of runs. A NaN NCI (a step where every run was skipped) gives a NaN mean NCI.
    ///
    /// # Errors
    /// [`MetricsError::Empty`] for no steps.
    pub fn from_steps(steps: &[CredibilityStep]) -> Result<Self, MetricsError> {
        if steps.is_empty() {
            return Err(MetricsError::Empty {
                what: "credibility steps",
            });
        }
        let len = steps.len() as f64;
        let mean = |f: fn(&CredibilityStep) -> f64| steps.iter().map(f).sum::<f64>() / len;
        Ok(Self {
            steps: steps.len(),
            anees: mean(|s| s.anees),
            nci: mean(|s| s.nci),
            median_nees: mean(|s| s.median_nees),
        })
    }
}

/// The most runs [`Credibility::reserve_runs`] reserves room for at a step: kalibra-eval's
/// largest run count.
pub const RESERVE_RUNS_MAX: usize = 1 << 24;

impl Credibility {
    /// An empty accumulator over `steps` steps of a `dim`-component state.
    ///
    /// # Panics
    /// If `steps * dim` is above [`HORIZON_MAX`](crate::HORIZON_MAX) (checked before anything
    /// is allocated); use [`Credibility::try_new`] for counts that come from data.
    pub fn new(steps: usize, dim: usize) -> Self {
        crate::accumulate::assert_horizon(steps, dim, "Credibility::new");
        Self {
            dim,
            errors: vec![Vec::new(); steps],
            nees: vec![Vec::new(); steps],
        }
    }

    /// [`Credibility::new`], with the horizon checked.
    ///
    /// # Errors
    /// [`MetricsError::InvalidParameter`] for `steps * dim` above
    /// [`HORIZON_MAX`](crate::HORIZON_MAX).
    pub fn try_new(steps: usize, dim: usize) -> Result<Self, MetricsError> {
        crate::accumulate::check_horizon(steps, dim)?;
        Ok(Self::new(steps, dim))
    }

    /// Number of steps held.
    pub fn steps(&self) -> usize {
        self.nees.len()
    }

    /// Extends the horizon to `steps` steps, the new ones empty; no change if it is already
    /// that long (see [`crate::StepMean::extend_steps`]).
    ///
    /// # Panics
    /// If `steps * dim` is above [`HORIZON_MAX`](crate::HORIZON_MAX), as [`Credibility::new`].
    pub fn extend_steps(&mut self, steps: usize) {
        if steps > self.steps() {
            crate::accumulate::assert_horizon(steps, self.dim, "Credibility::extend_steps");
            self.errors.resize(steps, Vec::new());
            self.nees.resize(steps, Vec::new());
        }
    }

    /// Number of state components `n`.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Number of runs pushed at `step` (0 beyond the horizon).
    pub fn runs(&self, step: usize) -> usize {
        self.nees.get(step).map_or(0, Vec::len)
    }

    /// Adds one run's error `e = x - xhat` and covariance `P` at `step`, computing its NEES
    /// through a Cholesky factor of `P` ([`nees`]). Nothing is stored on failure.
    ///
    /// # Errors
    /// [`MetricsError::StepOutOfRange`] beyond the horizon; [`MetricsError::DimensionMismatch`]
    /// if the error does not have `dim` components; [`MetricsError::InvalidParameter`] for an
    /// accumulator of dimension 0; [`MetricsError::Linalg`] if the error is not finite, or `P`
    /// is not finite, symmetric and positive definite, or (`Dyn`) its size differs from the
    /// error's.
    pub fn push<N: Dim>(
        &mut self,
        step: usize,
        error: &OVector<f64, N>,
        cov: &OMatrix<f64, N, N>,
    ) -> Result<(), MetricsError>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.check(step, error.as_slice())?;
        let value = nees(error, cov)?;
        self.store(step, error.as_slice(), value);
        Ok(())
    }

    /// Adds one run's error and its NEES, when the caller has computed the NEES already (from
    /// a filter's own factor of `P`, say). Nothing is stored on failure.
    ///
    /// # Errors
    /// As [`Credibility::push`] for the step and the error; [`MetricsError::InvalidParameter`]
    /// for a NEES that is negative or not finite.
    #[inline]
    pub fn push_nees(&mut self, step: usize, error: &[f64], nees: f64) -> Result<(), MetricsError> {
        self.check(step, error)?;
        Self::check_nees(nees)?;
        self.store(step, error, nees);
        Ok(())
    }

    /// Checks a NEES given by the caller: finite and non-negative.
    #[inline]
    fn check_nees(nees: f64) -> Result<(), MetricsError> {
        if !(nees.is_finite() && nees >= 0.0) {
            return Err(MetricsError::InvalidParameter {
                name: "NEES",
                value: nees,
            });
        }
        Ok(())
    }

    /// Checks what both pushes need: the step, the error's length and finiteness.
    #[inline]
    fn check(&self, step: usize, error: &[f64]) -> Result<(), MetricsError> {
        self.check_step(step)?;
        if self.dim == 0 {
            return Err(MetricsError::InvalidParameter {
                name: "state dimension",
                value: 0.0,
            });
        }
        if error.len() != self.dim {
            return Err(MetricsError::DimensionMismatch {
                what: "error vector",
                expected: self.dim,
                found: error.len(),
            });
        }
        // Non-short-circuiting, as `kalibra_linalg::all_finite`: no data-dependent branch.
        if !error.iter().fold(true, |ok, v| ok & v.is_finite()) {
            return Err(LinalgError::NonFinite {
                what: "error vector",
            }
            .into());
        }
        Ok(())
    }

    fn check_step(&self, step: usize) -> Result<(), MetricsError> {
        if step < self.steps() {
            Ok(())
        } else {
            Err(MetricsError::StepOutOfRange {
                step,
                steps: self.steps(),
            })
        }
    }

    #[inline]
    fn store(&mut self, step: usize, error: &[f64], nees: f64) {
        self.errors[step].extend_from_slice(error);
        self.nees[step].push(nees);
    }

    /// The statistics of `step` over the runs pushed there (definitions at [`Credibility`]).
    /// Costs `O(M n^2 + n^3)` and a sort of the `M` NEES values.
    ///
    /// # Errors
    /// [`MetricsError::StepOutOfRange`] beyond the horizon; [`MetricsError::Empty`] if no run
    /// was pushed at `step`; [`MetricsError::Linalg`] with [`LinalgError::NotConvergent`] if
    /// the eigen-decomposition of `Sigma` does not converge (not seen in practice), or with
    /// [`LinalgError::NonFinite`] if the MSE matrix lies beyond f64's range (errors near
    /// `1e308`).
    pub fn step_summary(&self, step: usize) -> Result<CredibilityStep, MetricsError> {
        self.check_step(step)?;
        let (errors, nees) = (&self.errors[step], &self.nees[step]);
        let runs = nees.len();
        if runs == 0 {
            return Err(MetricsError::Empty {
                what: "runs at this step",
            });
        }
        let n = self.dim as f64;
        let nci = nci_of_step(errors, nees, self.dim)?;
        let mse = mse_matrix(errors, self.dim);
        // Errors near 1e308 have squares, and so an MSE, beyond f64's range
        // (`tests/extreme_floats.rs`): an error rather than an infinity inside `Ok`.
        kalibra_linalg::check_finite(&mse, "per-step MSE matrix (beyond f64's range)")?;
        Ok(CredibilityStep {
            runs,
            // Without overflow for NEES values near f64::MAX (a plain sum gave inf).
            anees: crate::time_average(nees)? / n,
            nci: nci.value,
            nci_skipped: nci.skipped,
            median_nees: median(nees)? / n,
            mse,
            mse_rank: nci.rank,
        })
    }

    /// The non-credibility index of `step` alone: [`Credibility::step_summary`]'s `nci`, to
    /// the bit, without the median (a sort of the runs' NEES), the ANEES and the MSE matrix,
    /// for a caller that reports NCI only (the evaluation's per-step NCI; the test
    /// `step_nci_is_the_summary_nci_to_the_bit` checks the two agree).
    ///
    /// # Errors
    /// As [`Credibility::step_summary`].
    pub fn step_nci(&self, step: usize) -> Result<f64, MetricsError> {
        self.check_step(step)?;
        let (errors, nees) = (&self.errors[step], &self.nees[step]);
        if nees.is_empty() {
            return Err(MetricsError::Empty {
                what: "runs at this step",
            });
        }
        Ok(nci_of_step(errors, nees, self.dim)?.value)
    }

    /// Reserves room for `runs` more runs at each of `steps` (those within the horizon), so
    /// pushing them does not grow the per-step storage one reallocation at a time. A hint:
    /// at most [`RESERVE_RUNS_MAX`] runs are reserved, so that a count from data cannot ask
    /// for more memory than exists (`tests/extreme_sizes.rs`); more runs still fit, growing
    /// as they are pushed.
    pub fn reserve_runs(&mut self, runs: usize, steps: Range<usize>) {
        let runs = runs.min(RESERVE_RUNS_MAX);
        let steps = steps.start.min(self.steps())..steps.end.min(self.steps());
        for (e, n) in self.errors[steps.clone()]
            .iter_mut()
            .zip(&mut self.nees[steps])
        {
            e.reserve(runs.saturating_mul(self.dim));
            n.reserve(runs);
        }
    }

    /// [`Merge::merge`] of an accumulator given away: a step that `self` holds no run of
    /// takes `other`'s storage as it is instead of a copy (an evaluation cut into blocks of
    /// steps merges accumulators that share no step).
    ///
    /// # Panics
    /// As [`Merge::merge`], for accumulators of different shapes.
    pub fn append(&mut self, other: Credibility) {
        assert_fits(self, &other);
        append_runs(&mut self.errors, other.errors);
        append_runs(&mut self.nees, other.nees);
    }

    /// The statistics of every step.
    ///
    /// # Errors
    /// As [`Credibility::step_summary`], for the first step that fails (an empty one, say).
    pub fn summaries(&self) -> Result<Vec<CredibilityStep>, MetricsError> {
        (0..self.steps()).map(|k| self.step_summary(k)).collect()
    }

    /// Plain means of the per-step statistics over the steps `range`
    /// ([`CredibilityAverage::from_steps`]).
    ///
    /// # Errors
    /// [`MetricsError::InvalidParameter`] for an empty range;
    /// [`MetricsError::StepOutOfRange`] if it reaches beyond the horizon; as
    /// [`Credibility::step_summary`] for each step of the range.
    pub fn over_time(&self, range: Range<usize>) -> Result<CredibilityAverage, MetricsError> {
        if range.is_empty() {
            return Err(MetricsError::InvalidParameter {
                name: "step range length",
                value: 0.0,
            });
        }
        // The whole range is checked before any step is summarised.
        self.check_step(range.end - 1)?;
        let steps = range
            .map(|k| self.step_summary(k))
            .collect::<Result<Vec<_>, _>>()?;
        CredibilityAverage::from_steps(&steps)
    }
}

impl Merge for Credibility {
    fn fits(&self, other: &Self) -> bool {
        (self.steps(), self.dim) == (other.steps(), other.dim)
    }

    /// Appends `other`'s runs after this accumulator's, step by step.
    fn merge(&mut self, other: &Self) {
        assert_fits(self, other);
        for (a, b) in self.errors.iter_mut().zip(&other.errors) {
            a.extend_from_slice(b);
        }
        for (a, b) in self.nees.iter_mut().zip(&other.nees) {
            a.extend_from_slice(b);
        }
    }
}

/// Appends each step's runs of `theirs` after those of `mine`, taking a step's storage as it
/// is where `mine` holds no run there ([`Credibility::append`]).
fn append_runs(mine: &mut [Vec<f64>], theirs: Vec<Vec<f64>>) {
    for (a, b) in mine.iter_mut().zip(theirs) {
        if a.is_empty() {
            *a = b;
        } else {
            a.extend_from_slice(&b);
        }
    }
}

/// The median of `chi-square(dim) / dim`: the value of [`CredibilityStep::median_nees`] for a
/// consistent filter with many runs (`ln 2 = 0.693` for `dim = 2`; it tends to 1 as `dim`
/// grows). From statrs's chi-square quantile.
///
/// ```
/// let m = kalibra_metrics::consistent_median_nees(2)?;
/// assert!((m - 2f64.ln()).abs() < 1e-9);
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Numerical choices
/// statrs' inverse chi-square CDF below [`WILSON_HILFERTY_FROM`](crate::WILSON_HILFERTY_FROM)
/// degrees of freedom, and from there the Wilson-Hilferty median `(1 - 2/(9 dim))^3`, as
/// [`ChiSquareBand::for_mean`](crate::ChiSquareBand::for_mean) does: statrs' series for the
/// incomplete gamma function takes about `sqrt(dim)` terms and, from `2^53` on, where adding 1
/// to the term index no longer changes it, never ends. The approximation's relative error
/// falls as `1/dim^2`: about `1.3e-15` at the switch, where statrs' own inversion is off by
/// about `2e-12` (the test `consistent_median_nees_switch` holds both against the median's
/// asymptotic series).
///
/// # Errors
/// [`MetricsError::InvalidParameter`] for `dim == 0`.
pub fn consistent_median_nees(dim: usize) -> Result<f64, MetricsError> {
    let invalid = MetricsError::InvalidParameter {
        name: "degrees of freedom",
        value: dim as f64,
    };
    if dim == 0 {
        return Err(invalid);
    }
    let k = dim as f64;
    if k >= crate::WILSON_HILFERTY_FROM {
        // The median of chi-square(k) / k: z = 0 in `(1 - a + z sqrt(a))^3`, `a = 2 / (9 k)`.
        return Ok((1.0 - 2.0 / (9.0 * k)).powi(3));
    }
    let chi2 = ChiSquared::new(k).map_err(|_| invalid)?;
    Ok(chi2.inverse_cdf(0.5) / k)
}

/// The median of a sample, with the even-length convention of numpy and most texts (the mean
/// of the two middle values). Sorts a copy by `total_cmp`.
///
/// ```
/// use kalibra_metrics::median;
/// assert_eq!(median(&[5.0, 1.0, 3.0])?, 3.0);
/// assert_eq!(median(&[5.0, 1.0, 3.0, 7.0])?, 4.0);
/// assert!(median(&[]).is_err());
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::Empty`] for an empty sample and [`MetricsError::NonFiniteSample`] for a
/// NaN or infinite value, so that neither passes for a number.
pub fn median(values: &[f64]) -> Result<f64, MetricsError> {
    if values.is_empty() {
        return Err(MetricsError::Empty { what: "sample" });
    }
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(MetricsError::NonFiniteSample {
            what: "median",
            index,
        });
    }
    let mut sorted = values.to_vec();
    sorted.sort_unstable_by(f64::total_cmp);
    let mid = sorted.len() / 2;
    Ok(if sorted.len() % 2 == 1 {
        sorted[mid]
    } else {
        // Halving each term cannot overflow, and equals halving the sum for normal numbers.
        0.5 * sorted[mid - 1] + 0.5 * sorted[mid]
    })
}

#[cfg(test)]
mod tests {
    use super::nci::pinv_quad_forms;
    use super::*;
    use crate::StepMean;
    use kalibra_linalg::{DVector, Matrix2, Matrix3, Matrix4, Vector2, Vector3, Vector4};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    fn normal(rng: &mut ChaCha8Rng) -> f64 {
        StandardNormal.sample(rng)
    }

    /// At the switch both forms agree with the median's asymptotic series
    /// `k - 2/3 + 8/(405 k)` (Wilson-Hilferty to 1e-14 relative, statrs' bisection to 1e-11),
    /// and the largest counts come back at once, at or just below 1.
    #[test]
    fn consistent_median_nees_switch() {
        let series = |k: f64| (k - 2.0 / 3.0 + 8.0 / (405.0 * k)) / k;
        let below = crate::WILSON_HILFERTY_FROM as usize - 1;
        let exact = consistent_median_nees(below).unwrap();
        let want = series(below as f64);
        assert!((exact / want - 1.0).abs() < 1e-11, "{exact} vs {want}");
        let at = consistent_median_nees(below + 1).unwrap();
        let want = series((below + 1) as f64);
        assert!((at / want - 1.0).abs() < 1e-14, "{at} vs {want}");
        for dim in [usize::MAX / 2, usize::MAX] {
            let m = consistent_median_nees(dim).unwrap();
            assert!(m <= 1.0 && m > 1.0 - 1e-15, "{dim}: {m}");
        }
    }

    /// `m` correlated 3-D errors of different scales per component, spanning the space.
    fn errors3(seed: u64, m: usize) -> Vec<Vector3<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mix = Matrix3::new(2.0, 0.0, 0.0, 0.7, 0.5, 0.0, -1.0, 0.3, 0.1);
        (0..m)
            .map(|_| mix * Vector3::from_fn(|_, _| normal(&mut rng)))
            .collect()
    }

    /// A random symmetric positive definite 3 x 3 matrix, `A A^T + 0.1 I`.
    fn random_cov3(rng: &mut ChaCha8Rng) -> Matrix3<f64> {
        let a = Matrix3::from_fn(|_, _| normal(rng));
        a * a.transpose() + Matrix3::identity() * 0.1
    }

    /// `Sigma = (1 / M) sum e e^T`, computed independently of the module.
    fn sigma_by_hand<N: Dim>(errors: &[OVector<f64, N>]) -> OMatrix<f64, N, N>
    where
        DefaultAllocator: Alloc<N>,
    {
        let (n, _) = errors[0].shape_generic();
        let mut sigma = OMatrix::<f64, N, N>::zeros_generic(n, n);
        for e in errors {
            sigma += e * e.transpose();
        }
        sigma / errors.len() as f64
    }

    #[test]
    fn step_nci_is_the_summary_nci_to_the_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let errors = errors3(2, 40);
        let mut cred = Credibility::new(3, 3);
        cred.reserve_runs(40, 0..3);
        for (i, e) in errors.iter().enumerate() {
            // Step 0 takes every run, step 1 every other one, step 2 none.
            for step in [0, 1].into_iter().filter(|&k| k == 0 || i % 2 == 0) {
                cred.push(step, e, &random_cov3(&mut rng)).unwrap();
            }
        }
        for step in 0..2 {
            let nci = cred.step_nci(step).unwrap();
            assert!(nci.is_finite() && nci != 0.0, "{nci}");
            assert_eq!(
                nci.to_bits(),
                cred.step_summary(step).unwrap().nci.to_bits()
            );
        }
        assert_eq!(cred.step_nci(2), cred.step_summary(2).map(|s| s.nci));
        assert!(cred.step_nci(2).is_err());
        assert!(cred.step_nci(3).is_err());
    }

    #[test]
    fn nci_is_zero_when_p_equals_sigma() {
        let errors = errors3(1, 50);
        let sigma = sigma_by_hand(&errors);
        let mut cred = Credibility::new(1, 3);
        for e in &errors {
            cred.push(0, e, &sigma).unwrap();
        }
        let s = cred.step_summary(0).unwrap();
        assert_eq!((s.runs, s.mse_rank, s.nci_skipped), (50, 3, 0));
        assert!(s.nci.abs() < 1e-12, "nci {}", s.nci);
        // sum_i e_i^T Sigma^-1 e_i = M tr(Sigma^-1 Sigma) = M n: ANEES is 1 exactly.
        assert!((s.anees - 1.0).abs() < 1e-12, "anees {}", s.anees);
        for (a, b) in s.mse.iter().zip(sigma.iter()) {
            assert!((a - b).abs() <= 1e-14 * b.abs().max(1.0));
        }
        assert_eq!(s.mse, s.mse.transpose());
    }

    #[test]
    fn nci_shifts_by_ten_log10_c_when_p_is_scaled() {
        let errors = errors3(2, 40);
        let sigma = sigma_by_hand(&errors);
        for c in [1e-3, 0.1, 0.5, 2.0, 10.0, 1e4] {
            let mut cred = Credibility::new(1, 3);
            for e in &errors {
                cred.push(0, e, &(sigma / c)).unwrap();
            }
            let s = cred.step_summary(0).unwrap();
            let expected = 10.0 * c.log10();
            assert!((s.nci - expected).abs() < 1e-12, "c {c}: {}", s.nci);
            assert!((s.anees - c).abs() < 1e-12 * c, "c {c}: {}", s.anees);
        }
    }

    #[test]
    fn anees_matches_step_mean_of_nees_over_n() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut cred = Credibility::new(2, 3);
        let mut mean = StepMean::new(2);
        for (i, e) in errors3(4, 60).iter().enumerate() {
            let p = random_cov3(&mut rng);
            let k = i % 2;
            cred.push(k, e, &p).unwrap();
            mean.push(k, nees(e, &p).unwrap() / 3.0).unwrap();
        }
        for k in 0..2 {
            let anees = cred.step_summary(k).unwrap().anees;
            let m = mean.mean(k).unwrap();
            assert!((anees - m).abs() <= 1e-14 * m);
        }
    }

    #[test]
    fn singular_sigma_uses_the_pseudo_inverse() {
        // Errors e_i = a_i u along one direction: Sigma = mean(a^2) u u^T has rank 1, and
        // e_i^T Sigma^+ e_i = a_i^2 / mean(a^2). The run with a = 0 is skipped.
        let u = Vector2::new(0.6, 0.8);
        let a = [1.5, -0.3, 2.0, 0.0, -1.1, 0.7, 0.05];
        let mean_a2 = a.iter().map(|x| x * x).sum::<f64>() / a.len() as f64;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut cred = Credibility::new(1, 2);
        let (mut hand, mut used) = (0.0, 0);
        for &ai in &a {
            let (p11, p22, r) = (
                0.5 + normal(&mut rng).abs(),
                0.5 + normal(&mut rng).abs(),
                0.5 * normal(&mut rng).tanh(),
            );
            let p12 = r * (p11 * p22).sqrt();
            let e = u * ai;
            cred.push(0, &e, &Matrix2::new(p11, p12, p12, p22)).unwrap();
            if ai != 0.0 {
                // e^T P^-1 e from the explicit 2 x 2 inverse.
                let nees = (p22 * e.x * e.x - 2.0 * p12 * e.x * e.y + p11 * e.y * e.y)
                    / (p11 * p22 - p12 * p12);
                hand += 10.0 * nees.log10() - 10.0 * (ai * ai / mean_a2).log10();
                used += 1;
            }
        }
        let s = cred.step_summary(0).unwrap();
        assert_eq!((s.mse_rank, s.nci_skipped, used), (1, 1, 6));
        assert!(s.nci.is_finite());
        assert!(
            (s.nci - hand / used as f64).abs() < 1e-10,
            "{} vs {}",
            s.nci,
            hand / 6.0
        );
    }

    #[test]
    fn quadratic_forms_sum_to_runs_times_rank() {
        // sum_i e_i^T Sigma^+ e_i = M tr(Sigma^+ Sigma) = M rank(Sigma).
        let full: Vec<f64> = errors3(6, 30)
            .iter()
            .flat_map(|e| e.iter().copied())
            .collect();
        // Rank 2 in 3-D: the third component is the sum of the first two.
        let rank2: Vec<f64> = errors3(7, 30)
            .iter()
            .flat_map(|e| [e.x, e.y, e.x + e.y])
            .collect();
        for (errors, rank) in [(&full, 3), (&rank2, 2)] {
            let (quad, r) = pinv_quad_forms(errors, 3).unwrap();
            assert_eq!(r, rank);
            let total: f64 = quad.iter().sum();
            assert!((total - 30.0 * rank as f64).abs() < 1e-11, "{total}");
            assert!(quad.iter().all(|&q| q > 0.0));
        }
    }

    #[test]
    fn nci_does_not_depend_on_units() {
        // e -> T e and P -> T P T^T leave every NEES and e^T Sigma^+ e unchanged. With
        // T = diag(1e10, 1, 1e-10) the variances are 1e40 apart: an unscaled tolerance would drop
        // the third component.
        let t = Matrix3::from_diagonal(&Vector3::new(1e10, 1.0, 1e-10));
        let full = errors3(8, 25);
        let rank2: Vec<Vector3<f64>> = errors3(9, 25)
            .iter()
            .map(|e| Vector3::new(e.x, e.y, e.x - 2.0 * e.y))
            .collect();
        for (errors, rank) in [(full, 3), (rank2, 2)] {
            let mut rng = ChaCha8Rng::seed_from_u64(10);
            let mut plain = Credibility::new(1, 3);
            let mut scaled = Credibility::new(1, 3);
            for e in &errors {
                let p = random_cov3(&mut rng);
                plain.push(0, e, &p).unwrap();
                scaled.push(0, &(t * e), &(t * p * t)).unwrap();
            }
            let (a, b) = (
                plain.step_summary(0).unwrap(),
                scaled.step_summary(0).unwrap(),
            );
            assert_eq!((a.mse_rank, b.mse_rank), (rank, rank));
            assert!((a.nci - b.nci).abs() < 1e-10, "{} vs {}", a.nci, b.nci);
            assert!((a.anees - b.anees).abs() < 1e-10 * a.anees);
        }
    }

    #[test]
    fn zero_errors_are_skipped_not_minus_infinity() {
        let mut cred = Credibility::new(1, 2);
        for _ in 0..4 {
            cred.push(0, &Vector2::zeros(), &Matrix2::identity())
                .unwrap();
        }
        let s = cred.step_summary(0).unwrap();
        assert!(s.nci.is_nan());
        assert_eq!((s.nci_skipped, s.mse_rank), (4, 0));
        assert_eq!((s.anees, s.median_nees), (0.0, 0.0));
        assert_eq!(s.mse, DMatrix::zeros(2, 2));
        // Either factor at 0 skips the run: a zero NEES passed with a non-zero error, and a
        // zero error passed with a positive NEES.
        let mut cred = Credibility::new(1, 1);
        cred.push_nees(0, &[1.0], 0.0).unwrap();
        cred.push_nees(0, &[-1.0], 2.0).unwrap();
        cred.push_nees(0, &[0.0], 3.0).unwrap();
        let s = cred.step_summary(0).unwrap();
        assert_eq!(s.nci_skipped, 2);
        // The remaining run: e^T Sigma^+ e = 1 / (2 / 3), NEES 2.
        assert!(
            (s.nci - 10.0 * (2.0f64 / 1.5).log10()).abs() < 1e-12,
            "{}",
            s.nci
        );
        assert!((s.anees - 5.0 / 3.0).abs() < 1e-15);
    }

    #[test]
    fn median_by_hand_odd_and_even() {
        let mut cred = Credibility::new(1, 2);
        for (e, v) in [(1.0, 5.0), (2.0, 1.0), (3.0, 3.0)] {
            cred.push_nees(0, &[e, 0.0], v).unwrap();
        }
        // Sorted NEES 1, 3, 5: median 3, over n = 2.
        assert_eq!(cred.step_summary(0).unwrap().median_nees, 1.5);
        cred.push_nees(0, &[4.0, 0.0], 7.0).unwrap();
        // 1, 3, 5, 7: (3 + 5) / 2 = 4, over 2.
        let s = cred.step_summary(0).unwrap();
        assert_eq!(s.median_nees, 2.0);
        assert_eq!(s.anees, 2.0);
        assert_eq!(median(&[2.0]), Ok(2.0));
        assert!(median(&[]).is_err());
        assert!(median(&[1.0, f64::NAN, 2.0]).is_err());
    }

    #[test]
    fn consistent_median_matches_closed_forms() {
        // chi-square(2) is exponential with mean 2: median 2 ln 2, over n = 2.
        let m2 = consistent_median_nees(2).unwrap();
        assert!((m2 - 2f64.ln()).abs() < 1e-9, "{m2}");
        // chi-square(1) is a squared standard normal: median 0.6744897501960817^2.
        let m1 = consistent_median_nees(1).unwrap();
        assert!(
            (m1 - 0.674_489_750_196_081_7f64.powi(2)).abs() < 1e-9,
            "{m1}"
        );
        // Below 1 and rising towards it (the mean) as n grows.
        let m4 = consistent_median_nees(4).unwrap();
        assert!(m2 < m4 && m4 < 1.0);
        assert!(matches!(
            consistent_median_nees(0),
            Err(MetricsError::InvalidParameter { .. })
        ));
    }

    /// A study of `runs` runs over `steps` steps with a different covariance per run and step.
    fn push_runs(cred: &mut Credibility, runs: Range<usize>, steps: usize) {
        for i in runs {
            let mut rng = ChaCha8Rng::seed_from_u64(1000 + i as u64);
            for k in 0..steps {
                let p = random_cov3(&mut rng);
                let e = Vector3::from_fn(|_, _| normal(&mut rng)) * (1.0 + k as f64);
                cred.push(k, &e, &p).unwrap();
            }
        }
    }

    #[test]
    fn merging_chunks_in_order_is_bit_identical() {
        let (steps, runs) = (3, 37);
        let mut whole = Credibility::new(steps, 3);
        push_runs(&mut whole, 0..runs, steps);
        let mut merged = Credibility::new(steps, 3);
        let mut start = 0;
        for len in [5, 11, 0, 21] {
            let mut part = Credibility::new(steps, 3);
            push_runs(&mut part, start..start + len, steps);
            merged.merge(&part);
            start += len;
        }
        assert_eq!(start, runs);
        assert_eq!(merged, whole);
        let (a, b) = (merged.summaries().unwrap(), whole.summaries().unwrap());
        assert_eq!(a, b);
        assert!(a.iter().all(|s| s.runs == runs && s.nci.is_finite()));
        assert_eq!(
            merged.over_time(0..3).unwrap(),
            whole.over_time(0..3).unwrap()
        );
    }

    #[test]
    #[should_panic(expected = "different shapes")]
    fn merging_different_shapes_panics() {
        Credibility::new(2, 3).merge(&Credibility::new(2, 4));
    }

    #[test]
    fn over_time_is_the_plain_mean_of_steps() {
        let mut cred = Credibility::new(3, 1);
        // One run per step with e = 1 (Sigma = 1, e^T Sigma^+ e = 1): NCI = 10 log10 NEES.
        for (k, v) in [1.0, 10.0, 100.0].into_iter().enumerate() {
            cred.push_nees(k, &[1.0], v).unwrap();
        }
        let avg = cred.over_time(0..3).unwrap();
        assert_eq!(avg.steps, 3);
        assert!((avg.anees - 37.0).abs() < 1e-12);
        assert!((avg.median_nees - 37.0).abs() < 1e-12);
        assert!((avg.nci - 10.0).abs() < 1e-12);
        let tail = cred.over_time(1..3).unwrap();
        assert!((tail.nci - 15.0).abs() < 1e-12);
    }

    #[test]
    fn consistent_filter_has_nci_near_zero() {
        // e_i ~ N(0, P) with the filter reporting the true P, M = 2000 runs, n = 4, at five
        // independent steps with different P.
        //
        // Bounds. To first order in Sigma - P, NCI = (10 / ln 10) (ANEES - 1), and ANEES is a
        // mean of M chi-square(n) / n variables: sd(NCI) = (10 / ln 10) sqrt(2 / (n M)) =
        // 0.069 dB here (measured over 400 seeds: 0.067, largest |NCI| 0.17). Per step the bound
        // is 4.5 sd, 0.31 dB; the mean over the five steps has sd 0.031 dB and the bound
        // 0.15 dB (4.9 sd). The same expansion makes NCI - 10 log10(ANEES) second order:
        // measured mean -0.0016 dB, sd 0.0016 dB, largest 0.008 dB; bound 0.015 dB. The sample
        // median of chi-square(4) / 4 has sd 1 / (8 f(m) sqrt(M)) = 0.018 with f the
        // chi-square(4) density at its median m = 3.357 (measured 0.017); bound 0.08.
        let (n, runs, steps) = (4, 2000, 5);
        let base = Matrix4::new(
            4.0, 1.0, 0.5, 0.0, //
            1.0, 3.0, 0.2, 0.1, //
            0.5, 0.2, 0.5, 0.05, //
            0.0, 0.1, 0.05, 0.2,
        );
        let mut rng = ChaCha8Rng::seed_from_u64(2024);
        let mut cred = Credibility::new(steps, n);
        for k in 0..steps {
            // Rescale the components differently at each step.
            let t = Matrix4::from_diagonal(&Vector4::new(1.0, 2.0 + k as f64, 0.1, 10.0));
            let p = t * base * t;
            let l = p.cholesky().unwrap().l();
            for _ in 0..runs {
                let e = l * Vector4::from_fn(|_, _| normal(&mut rng));
                cred.push(k, &e, &p).unwrap();
            }
        }
        let reference = consistent_median_nees(n).unwrap();
        for s in cred.summaries().unwrap() {
            assert_eq!((s.runs, s.mse_rank, s.nci_skipped), (runs, n, 0));
            assert!(s.nci.abs() < 0.31, "nci {}", s.nci);
            let second_order = s.nci - 10.0 * s.anees.log10();
            assert!(second_order.abs() < 0.015, "{second_order}");
            assert!(
                (s.median_nees - reference).abs() < 0.08,
                "{}",
                s.median_nees
            );
        }
        let avg = cred.over_time(0..steps).unwrap();
        assert!(avg.nci.abs() < 0.15, "mean nci {}", avg.nci);
    }

    #[test]
    fn errors_are_typed_and_store_nothing() {
        let mut cred = Credibility::new(2, 2);
        let p = Matrix2::identity();
        assert_eq!(
            cred.push(2, &Vector2::new(1.0, 0.0), &p),
            Err(MetricsError::StepOutOfRange { step: 2, steps: 2 })
        );
        assert!(matches!(
            cred.push_nees(5, &[1.0, 0.0], 1.0),
            Err(MetricsError::StepOutOfRange { .. })
        ));
        assert_eq!(
            cred.push(0, &Vector3::new(1.0, 0.0, 0.0), &Matrix3::identity()),
            Err(MetricsError::DimensionMismatch {
                what: "error vector",
                expected: 2,
                found: 3
            })
        );
        assert!(matches!(
            cred.push_nees(0, &[1.0], 1.0),
            Err(MetricsError::DimensionMismatch { found: 1, .. })
        ));
        // A `Dyn` covariance of the wrong size.
        assert!(matches!(
            cred.push(
                0,
                &DVector::from_vec(vec![1.0, 0.0]),
                &DMatrix::identity(3, 3)
            ),
            Err(MetricsError::Linalg(LinalgError::DimensionMismatch { .. }))
        ));
        for bad in [f64::NAN, f64::INFINITY] {
            assert!(matches!(
                cred.push(0, &Vector2::new(1.0, bad), &p),
                Err(MetricsError::Linalg(LinalgError::NonFinite { .. }))
            ));
            assert!(matches!(
                cred.push_nees(0, &[bad, 0.0], 1.0),
                Err(MetricsError::Linalg(LinalgError::NonFinite { .. }))
            ));
        }
        assert!(matches!(
            cred.push(
                0,
                &Vector2::new(1.0, 0.0),
                &Matrix2::new(1.0, 2.0, 2.0, 1.0)
            ),
            Err(MetricsError::Linalg(
                LinalgError::NotPositiveDefinite { .. }
            ))
        ));
        for bad in [-1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                cred.push_nees(0, &[1.0, 0.0], bad),
                Err(MetricsError::InvalidParameter { name: "NEES", .. })
            ));
        }
        assert!(matches!(
            Credibility::new(1, 0).push_nees(0, &[], 1.0),
            Err(MetricsError::InvalidParameter { .. })
        ));
        assert_eq!(cred, Credibility::new(2, 2));
        assert_eq!((cred.runs(0), cred.runs(9)), (0, 0));

        assert!(matches!(
            cred.step_summary(0),
            Err(MetricsError::Empty { .. })
        ));
        assert_eq!(
            cred.step_summary(2),
            Err(MetricsError::StepOutOfRange { step: 2, steps: 2 })
        );
        cred.push(0, &Vector2::new(1.0, 0.0), &p).unwrap();
        assert_eq!(cred.runs(0), 1);
        // Step 1 is still empty.
        assert!(matches!(cred.summaries(), Err(MetricsError::Empty { .. })));
        assert!(matches!(
            cred.over_time(0..2),
            Err(MetricsError::Empty { .. })
        ));
        assert!(matches!(
            cred.over_time(1..1),
            Err(MetricsError::InvalidParameter { .. })
        ));
        assert!(cred.over_time(0..1).is_ok());
        assert_eq!(
            cred.over_time(0..3),
            Err(MetricsError::StepOutOfRange { step: 2, steps: 2 })
        );
        assert!(matches!(
            CredibilityAverage::from_steps(&[]),
            Err(MetricsError::Empty { .. })
        ));
    }
}
