//! Streaming accumulators: a Monte Carlo study pushes each run's per-step values and never holds
//! the runs themselves.
//!
//! Accumulators hold plain sums, merged element by element ([`Merge`]), so a study that merges
//! partial accumulators in a fixed order gets bit-identical results whatever the thread count.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OVector};

use crate::MetricsError;

/// Combining two partial results of the same study. Merging is plain addition of sums, so the
/// result depends only on the order of merges, which the caller fixes.
pub trait Merge {
    /// Adds `other`'s contents to `self`.
    ///
    /// # Panics
    /// If the two accumulators were built with different shapes (a programming error: partial
    /// accumulators of one study come from one constructor).
    fn merge(&mut self, other: &Self);

    /// Whether `other` has this accumulator's shape, so [`Merge::merge`] would not panic.
    /// Partial accumulators read from outside (a shard's file) are checked with it before
    /// they are merged. The default says yes: an accumulator of one shape only (or one that
    /// never panics in `merge`) needs nothing else.
    fn fits(&self, _other: &Self) -> bool {
        true
    }
}

/// The check every shaped accumulator's [`Merge::merge`] makes first: panics unless `other`
/// [`Merge::fits`] `acc`.
#[track_caller]
pub(crate) fn assert_fits<A: Merge>(acc: &A, other: &A) {
    assert!(acc.fits(other), "merging accumulators of different shapes");
}

/// Adds `other`'s per-step sums and counts to `sum` and `count`, entry by entry: the merge of
/// [`StepMean`] and [`SquaredErrors`].
fn add_sums(sum: &mut [f64], count: &mut [u64], other_sum: &[f64], other_count: &[u64]) {
    for (a, b) in sum.iter_mut().zip(other_sum) {
        *a += b;
    }
    for (a, b) in count.iter_mut().zip(other_count) {
        *a += b;
    }
}

impl<A: Merge, B: Merge> Merge for (A, B) {
    fn merge(&mut self, other: &Self) {
        self.0.merge(&other.0);
        self.1.merge(&other.1);
    }

    fn fits(&self, other: &Self) -> bool {
        self.0.fits(&other.0) && self.1.fits(&other.1)
    }
}

impl<A: Merge, B: Merge, C: Merge> Merge for (A, B, C) {
    fn merge(&mut self, other: &Self) {
        self.0.merge(&other.0);
        self.1.merge(&other.1);
        self.2.merge(&other.2);
    }

    fn fits(&self, other: &Self) -> bool {
        self.0.fits(&other.0) && self.1.fits(&other.1) && self.2.fits(&other.2)
    }
}

/// Refuses every live lane with `e`: a lane-wise push whose lanes all fail alike (a step
/// beyond the horizon, a wrong dimension).
#[cold]
fn refuse_live<const L: usize>(
    live: &mut [bool; L],
    e: MetricsError,
    mut refused: impl FnMut(usize, MetricsError),
) {
    for (lane, l) in live.iter_mut().enumerate() {
        if *l {
            *l = false;
            refused(lane, e.clone());
        }
    }
}

/// An error vector of `found` components where the accumulator has `expected`.
fn dim_mismatch(expected: usize, found: usize) -> MetricsError {
    MetricsError::DimensionMismatch {
        what: "error vector",
        expected,
        found,
    }
}

/// Why [`StepMean::push`] refuses `value` at `step` (the step's sum would not be finite).
#[cold]
fn refused_mean(step: usize, value: f64) -> MetricsError {
    MetricsError::NonFiniteSample {
        what: if value.is_finite() {
            "step mean (sum beyond f64's range)"
        } else {
            "step mean"
        },
        index: step,
    }
}

/// Why [`SquaredErrors::push_slice`] refuses an error whose components are `error` at `step`.
#[cold]
fn refused_squares(step: usize, mut error: impl Iterator<Item = f64>) -> MetricsError {
    MetricsError::NonFiniteSample {
        what: if error.all(f64::is_finite) {
            "squared errors (sum beyond f64's range)"
        } else {
            "squared errors"
        },
        index: step,
    }
}

/// The most components [`SquaredErrors::push_slice`] adds in one pass (keeping the old sums
/// on the stack); larger states are tested first and added after.
const ONE_PASS: usize = 8;

/// The most cells (steps times components) a [`StepMean`], [`SquaredErrors`] or
/// [`Credibility`](crate::Credibility) holds: 2^32, 32 GiB of sums, beyond the memory of any
/// machine these studies run on (kalibra-eval's 2^24 steps of a 256-component state fit). A
/// horizon is allocated whole when the accumulator is made, so a count from data is checked
/// against this before anything is reserved (`tests/extreme_sizes.rs`), where `usize::MAX`
/// steps would be a "capacity overflow" panic and `2^40` an allocation failure that aborts
/// the process.
pub const HORIZON_MAX: usize = 1 << 32;

/// Checks a horizon of `steps` steps of `dim` components against [`HORIZON_MAX`].
pub(crate) fn check_horizon(steps: usize, dim: usize) -> Result<(), MetricsError> {
    match steps.checked_mul(dim.max(1)) {
        Some(cells) if cells <= HORIZON_MAX => Ok(()),
        _ => Err(MetricsError::InvalidParameter {
            name: "horizon: steps times components above HORIZON_MAX",
            value: steps as f64,
        }),
    }
}

/// [`check_horizon`] for the infallible constructors: a documented panic with the message.
pub(crate) fn assert_horizon(steps: usize, dim: usize, what: &str) {
    if let Err(e) = check_horizon(steps, dim) {
        panic!("{what}: {e} ({HORIZON_MAX}); the try_new constructor checks a count from data");
    }
}

fn check_step(step: usize, steps: usize) -> Result<(), MetricsError> {
    if step < steps {
        Ok(())
    } else {
        Err(MetricsError::StepOutOfRange { step, steps })
    }
}

/// The mean over runs of a scalar at each step (NEES, NIS, any per-step statistic).
///
/// Serialised (serde, for a Monte Carlo shard's partial result) as its sums and counts per
/// step, `{"sum": [...], "count": [...]}` (in binary formats each array is one byte string of
/// little-endian 8-byte values); deserialising checks that the two have one length and
/// the sums are finite.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "StepMeanData")]
pub struct StepMean {
    #[serde(with = "crate::packed")]
    sum: Vec<f64>,
    #[serde(with = "crate::packed")]
    count: Vec<u64>,
}

/// [`StepMean`] as read, before its invariants are checked.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct StepMeanData {
    #[serde(with = "crate::packed")]
    sum: Vec<f64>,
    #[serde(with = "crate::packed")]
    count: Vec<u64>,
}

impl TryFrom<StepMeanData> for StepMean {
    type Error = String;

    fn try_from(d: StepMeanData) -> Result<Self, String> {
        if d.sum.len() != d.count.len() {
            return Err(format!(
                "a step mean with {} sums and {} counts",
                d.sum.len(),
                d.count.len()
            ));
        }
        check_finite_sums(&d.sum)?;
        Ok(Self {
            sum: d.sum,
            count: d.count,
        })
    }
}

fn check_finite_sums(sums: &[f64]) -> Result<(), String> {
    match sums.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(format!("sum {i} is not finite")),
        None => Ok(()),
    }
}

impl StepMean {
    /// An empty accumulator over `steps` steps.
    ///
    /// # Panics
    /// If `steps` is above [`HORIZON_MAX`] (checked before anything is allocated); use
    /// [`StepMean::try_new`] for a count that comes from data.
    pub fn new(steps: usize) -> Self {
        assert_horizon(steps, 1, "StepMean::new");
        Self {
            sum: vec![0.0; steps],
            count: vec![0; steps],
        }
    }

    /// [`StepMean::new`], with the horizon checked.
    ///
    /// # Errors
    /// [`MetricsError::InvalidParameter`] for `steps` above [`HORIZON_MAX`].
    pub fn try_new(steps: usize) -> Result<Self, MetricsError> {
        check_horizon(steps, 1)?;
        Ok(Self::new(steps))
    }

    /// The number of steps held.
    pub fn steps(&self) -> usize {
        self.sum.len()
    }

    /// Extends the horizon to `steps` steps, the new ones empty; no change if it is already
    /// that long. For a stream whose length is learnt as it is read (a log read row by row).
    ///
    /// # Panics
    /// If `steps` is above [`HORIZON_MAX`], as [`StepMean::new`].
    pub fn extend_steps(&mut self, steps: usize) {
        if steps > self.steps() {
            assert_horizon(steps, 1, "StepMean::extend_steps");
            self.sum.resize(steps, 0.0);
            self.count.resize(steps, 0);
        }
    }

    /// Adds one run's value at `step`.
    ///
    /// # Errors
    /// [`MetricsError::StepOutOfRange`] beyond the horizon;
    /// [`MetricsError::NonFiniteSample`] (index: the step) for a NaN or infinite value, which
    /// would poison every later mean at the step, and for a value that would take the step's
    /// sum beyond f64's range (the mean stays finite). Nothing is stored on error.
    #[inline]
    pub fn push(&mut self, step: usize, value: f64) -> Result<(), MetricsError> {
        check_step(step, self.steps())?;
        let sum = self.sum[step] + value;
        if !sum.is_finite() {
            return Err(refused_mean(step, value));
        }
        self.sum[step] = sum;
        self.count[step] += 1;
        Ok(())
    }

    /// Adds, at `step`, the value `values[i]` of every lane `i` with `live[i]` (one run per
    /// lane of a batch of runs stepped together), lane 0 first: what [`StepMean::push`] of
    /// each live lane's value, one after the other, would do, to the bit. A study stepping
    /// its runs in lanes adds them to the sums in the order the one-run loop does, with one
    /// call per step instead of one per run.
    ///
    /// A value [`StepMean::push`] would refuse is not stored: its lane is cleared in `live`
    /// and `refused(lane, error)` called with the error `push` would return (in lane order,
    /// off the common path), and the later lanes are still pushed. On return `live` holds the
    /// lanes pushed, ready for the next accumulator of the same runs.
    ///
    /// ```
    /// use kalibra_metrics::StepMean;
    /// let mut m = StepMean::new(1);
    /// let mut refused = Vec::new();
    /// let mut live = [true, true, true, false];
    /// m.push_lanes(0, &[1.0, f64::NAN, 2.0, 9.0], &mut live, |lane, _| refused.push(lane));
    /// assert_eq!(refused, [1]);
    /// assert_eq!(live, [true, false, true, false]);
    /// assert_eq!((m.mean(0), m.count(0)), (Some(1.5), 2));
    /// ```
    #[inline]
    pub fn push_lanes<const L: usize>(
        &mut self,
        step: usize,
        values: &[f64; L],
        live: &mut [bool; L],
        mut refused: impl FnMut(usize, MetricsError),
    ) {
        if let Err(e) = check_step(step, self.steps()) {
            return refuse_live(live, e, refused);
        }
        // Every live lane added in order; if the sum is then finite, so was every partial
        // sum (a NaN or infinite sum stays so whatever is added to it), so pushing lane by
        // lane would have refused nothing: the same sum, without a test per lane.
        let (mut sum, mut count) = (self.sum[step], self.count[step]);
        let mut all = sum;
        let every = live.iter().all(|l| *l);
        for lane in 0..L {
            // (Without a test per lane when every lane is live, the usual case.)
            if every || live[lane] {
                all += values[lane];
            }
        }
        if all.is_finite() {
            self.sum[step] = all;
            self.count[step] += live.iter().filter(|l| **l).count() as u64;
            return;
        }
        for lane in 0..L {
            if !live[lane] {
                continue;
            }
            let next = sum + values[lane];
            if next.is_finite() {
                sum = next;
                count += 1;
            } else {
                live[lane] = false;
                refused(lane, refused_mean(step, values[lane]));
            }
        }
        self.sum[step] = sum;
        self.count[step] = count;
    }

    /// Number of values pushed at `step` (0 beyond the horizon).
    pub fn count(&self, step: usize) -> u64 {
        self.count.get(step).copied().unwrap_or(0)
    }

    /// The mean at `step`, finite; `None` where nothing was pushed (and beyond the horizon),
    /// rather than a NaN that would look like a number to a caller that did not test for it.
    ///
    /// ```
    /// use kalibra_metrics::StepMean;
    /// let mut m = StepMean::new(2);
    /// m.push(0, 3.0)?;
    /// m.push(0, 5.0)?;
    /// assert_eq!(m.mean(0), Some(4.0));
    /// assert_eq!(m.mean(1), None);
    /// assert_eq!(m.means(), vec![Some(4.0), None]);
    /// # Ok::<(), kalibra_metrics::MetricsError>(())
    /// ```
    pub fn mean(&self, step: usize) -> Option<f64> {
        match self.count.get(step) {
            Some(&c) if c > 0 => Some(self.sum[step] / c as f64),
            _ => None,
        }
    }

    /// The means at every step, `None` where nothing was pushed.
    pub fn means(&self) -> Vec<Option<f64>> {
        (0..self.steps()).map(|k| self.mean(k)).collect()
    }
}

impl Merge for StepMean {
    fn fits(&self, other: &Self) -> bool {
        self.steps() == other.steps()
    }

    fn merge(&mut self, other: &Self) {
        assert_fits(self, other);
        add_sums(&mut self.sum, &mut self.count, &other.sum, &other.count);
    }
}

/// Squared estimation errors per step and state component, summed over runs: the RMSE per
/// component, for groups of components (position, velocity), per step and over time.
///
/// ```
/// use kalibra_metrics::SquaredErrors;
/// let mut acc = SquaredErrors::new(1, 4);
/// acc.push_slice(0, &[3.0, 4.0, 1.0, 0.0])?;
/// acc.push_slice(0, &[3.0, 4.0, 1.0, 0.0])?;
/// assert_eq!(acc.rmse_group(0, &[0, 1])?, 5.0); // sqrt(mean over runs of 3^2 + 4^2)
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// Serialised (serde) as `{"dim": n, "sum": [...], "count": [...]}`, the sums step-major (in
/// binary formats each array is one byte string of little-endian 8-byte values);
/// deserialising checks the lengths (`sum` holds `dim` values per step) and finiteness.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "SquaredErrorsData")]
pub struct SquaredErrors {
    dim: usize,
    #[serde(with = "crate::packed")]
    sum: Vec<f64>,
    #[serde(with = "crate::packed")]
    count: Vec<u64>,
}

/// [`SquaredErrors`] as read, before its invariants are checked.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct SquaredErrorsData {
    dim: usize,
    #[serde(with = "crate::packed")]
    sum: Vec<f64>,
    #[serde(with = "crate::packed")]
    count: Vec<u64>,
}

impl TryFrom<SquaredErrorsData> for SquaredErrors {
    type Error = String;

    fn try_from(d: SquaredErrorsData) -> Result<Self, String> {
        if d.count.len().checked_mul(d.dim) != Some(d.sum.len()) {
            return Err(format!(
                "squared errors of dimension {} with {} sums for {} steps",
                d.dim,
                d.sum.len(),
                d.count.len()
            ));
        }
        check_finite_sums(&d.sum)?;
        Ok(Self {
            dim: d.dim,
            sum: d.sum,
            count: d.count,
        })
    }
}

impl SquaredErrors {
    /// An empty accumulator over `steps` steps of a `dim`-component state.
    ///
    /// # Panics
    /// If `steps * dim` is above [`HORIZON_MAX`] (checked before anything is allocated); use
    /// [`SquaredErrors::try_new`] for counts that come from data.
    pub fn new(steps: usize, dim: usize) -> Self {
        assert_horizon(steps, dim, "SquaredErrors::new");
        Self {
            dim,
            sum: vec![0.0; steps * dim],
            count: vec![0; steps],
        }
    }

    /// [`SquaredErrors::new`], with the horizon checked.
    ///
    /// # Errors
    /// [`MetricsError::InvalidParameter`] for `steps * dim` above [`HORIZON_MAX`].
    pub fn try_new(steps: usize, dim: usize) -> Result<Self, MetricsError> {
        check_horizon(steps, dim)?;
        Ok(Self::new(steps, dim))
    }

    /// Number of steps held.
    pub fn steps(&self) -> usize {
        self.count.len()
    }

    /// Extends the horizon to `steps` steps, the new ones empty; no change if it is already
    /// that long (see [`StepMean::extend_steps`]).
    ///
    /// # Panics
    /// If `steps * dim` is above [`HORIZON_MAX`], as [`SquaredErrors::new`].
    pub fn extend_steps(&mut self, steps: usize) {
        if steps > self.steps() {
            assert_horizon(steps, self.dim, "SquaredErrors::extend_steps");
            self.sum.resize(steps * self.dim, 0.0);
            self.count.resize(steps, 0);
        }
    }

    /// Number of components.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Number of errors pushed at `step` (0 beyond the horizon).
    pub fn count(&self, step: usize) -> u64 {
        self.count.get(step).copied().unwrap_or(0)
    }

    /// Adds one run's error at `step`.
    ///
    /// # Errors
    /// [`MetricsError::StepOutOfRange`] beyond the horizon, [`MetricsError::DimensionMismatch`]
    /// for a wrong length, [`MetricsError::NonFiniteSample`] (index: the step) for a NaN or
    /// infinite component, or one whose square would take the step's sum beyond f64's range
    /// (the MSE stays finite). Nothing is stored on error.
    #[inline]
    pub fn push_slice(&mut self, step: usize, error: &[f64]) -> Result<(), MetricsError> {
        check_step(step, self.steps())?;
        if error.len() != self.dim {
            return Err(dim_mismatch(self.dim, error.len()));
        }
        let sums = &mut self.sum[step * self.dim..(step + 1) * self.dim];
        if sums.len() > ONE_PASS {
            return Self::push_two_pass(sums, &mut self.count[step], step, error);
        }
        // One pass over a small state, keeping the old sums to put back on error: a finite
        // total means every new sum is finite (finite sums plus squares cannot reach -inf),
        // so only a non-finite total looks further (`cargo xtask bench w1`'s library loop
        // under callgrind shows the saving over testing before adding).
        let mut old = [0.0; ONE_PASS];
        let mut total = 0.0;
        for ((s, o), e) in sums.iter_mut().zip(old.iter_mut()).zip(error) {
            *o = *s;
            *s += e * e;
            total += *s;
        }
        if !total.is_finite() && sums.iter().any(|s| !s.is_finite()) {
            sums.copy_from_slice(&old[..sums.len()]);
            return Err(refused_squares(step, error.iter().copied()));
        }
        self.count[step] += 1;
        Ok(())
    }

    /// [`SquaredErrors::push_slice`] for more than [`ONE_PASS`] components: every new sum
    /// tested before any is stored.
    fn push_two_pass(
        sums: &mut [f64],
        count: &mut u64,
        step: usize,
        error: &[f64],
    ) -> Result<(), MetricsError> {
        if !error
            .iter()
            .zip(sums.iter())
            .all(|(e, s)| (s + e * e).is_finite())
        {
            return Err(refused_squares(step, error.iter().copied()));
        }
        for (s, e) in sums.iter_mut().zip(error) {
            *s += e * e;
        }
        *count += 1;
        Ok(())
    }

    /// Adds, at `step`, the error of every lane `i` with `live[i]`, lane 0 first, where
    /// `errors[c][i]` is component `c` of lane `i`'s error (one run per lane of a batch of
    /// runs stepped together, components as rows): what [`SquaredErrors::push_slice`] of each
    /// live lane's error, one after the other, would do, to the bit.
    ///
    /// An error [`SquaredErrors::push_slice`] would refuse is not stored: its lane is cleared
    /// in `live` and `refused(lane, error)` called with the error `push_slice` would return
    /// (in lane order), and the later lanes are still pushed. On return `live` holds the
    /// lanes pushed.
    ///
    /// ```
    /// use kalibra_metrics::SquaredErrors;
    /// let mut acc = SquaredErrors::new(1, 2);
    /// // Lanes 0 and 1 are runs with errors (3, 4) and (6, 8); lane 2 is not live.
    /// let errors = [[3.0, 6.0, 1.0], [4.0, 8.0, 1.0]];
    /// let mut live = [true, true, false];
    /// acc.push_lanes(0, &errors, &mut live, |lane, e| panic!("{lane}: {e}"));
    /// assert_eq!(acc.count(0), 2);
    /// assert_eq!(acc.rmse_group(0, &[0, 1])?, 62.5f64.sqrt());
    /// # Ok::<(), kalibra_metrics::MetricsError>(())
    /// ```
    #[inline]
    pub fn push_lanes<const L: usize, const D: usize>(
        &mut self,
        step: usize,
        errors: &[[f64; L]; D],
        live: &mut [bool; L],
        mut refused: impl FnMut(usize, MetricsError),
    ) {
        if let Err(e) = check_step(step, self.steps()) {
            return refuse_live(live, e, refused);
        }
        let dim = self.dim;
        let Ok(sums) = <&mut [f64; D]>::try_from(&mut self.sum[step * dim..(step + 1) * dim])
        else {
            return refuse_live(live, dim_mismatch(dim, D), refused);
        };
        // As in `StepMean::push_lanes`: if each component's sum over every live lane is
        // finite, pushing lane by lane would have refused nothing (each component's sum sees
        // the lanes in the same order either way).
        let mut next = *sums;
        let every = live.iter().all(|l| *l);
        for lane in 0..L {
            if every || live[lane] {
                for c in 0..D {
                    next[c] += errors[c][lane] * errors[c][lane];
                }
            }
        }
        if next.iter().all(|s| s.is_finite()) {
            *sums = next;
            self.count[step] += live.iter().filter(|l| **l).count() as u64;
            return;
        }
        let mut count = self.count[step];
        for lane in 0..L {
            if !live[lane] {
                continue;
            }
            if errors
                .iter()
                .zip(sums.iter())
                .all(|(e, s)| (s + e[lane] * e[lane]).is_finite())
            {
                for (s, e) in sums.iter_mut().zip(errors) {
                    *s += e[lane] * e[lane];
                }
                count += 1;
            } else {
                live[lane] = false;
                refused(lane, refused_squares(step, errors.iter().map(|e| e[lane])));
            }
        }
        self.count[step] = count;
    }

    /// Adds one run's error vector at `step`.
    ///
    /// # Errors
    /// As [`SquaredErrors::push_slice`].
    pub fn push<N: Dim>(&mut self, step: usize, error: &OVector<f64, N>) -> Result<(), MetricsError>
    where
        DefaultAllocator: Alloc<N>,
    {
        self.push_slice(step, error.as_slice())
    }

    /// Mean squared error of component `i` at `step`.
    ///
    /// # Errors
    /// [`MetricsError::StepOutOfRange`], [`MetricsError::DimensionMismatch`] for a component
    /// beyond the state, [`MetricsError::Empty`] for a step where nothing was pushed (the mean
    /// of nothing is not a number to return).
    pub fn mse(&self, step: usize, i: usize) -> Result<f64, MetricsError> {
        check_step(step, self.steps())?;
        if i >= self.dim {
            return Err(MetricsError::DimensionMismatch {
                what: "component index",
                expected: self.dim,
                found: i,
            });
        }
        match self.count[step] {
            0 => Err(MetricsError::Empty {
                what: "squared errors at the step",
            }),
            c => Ok(self.sum[step * self.dim + i] / c as f64),
        }
    }

    /// RMSE of component `i` at `step`.
    ///
    /// # Errors
    /// As [`SquaredErrors::mse`].
    pub fn rmse(&self, step: usize, i: usize) -> Result<f64, MetricsError> {
        Ok(self.mse(step, i)?.sqrt())
    }

    /// RMSE of a group of components at `step`: `sqrt(mean over runs of sum_{i in group} e_i^2)`
    /// (the position RMSE of paper 001 for `group = [x, y]`).
    ///
    /// # Errors
    /// As [`SquaredErrors::mse`].
    pub fn rmse_group(&self, step: usize, group: &[usize]) -> Result<f64, MetricsError> {
        let mses = group
            .iter()
            .map(|&i| self.mse(step, i))
            .collect::<Result<Vec<f64>, _>>()?;
        Ok(root_sum(&mses))
    }

    /// The group RMSE at every step.
    ///
    /// # Errors
    /// As [`SquaredErrors::mse`].
    pub fn rmse_series(&self, group: &[usize]) -> Result<Vec<f64>, MetricsError> {
        (0..self.steps())
            .map(|k| self.rmse_group(k, group))
            .collect()
    }

    /// RMSE over runs and over the steps `range`: `sqrt(mean over steps of MSE_k)`.
    ///
    /// # Errors
    /// As [`SquaredErrors::mse`]; [`MetricsError::InvalidParameter`] for an empty range.
    pub fn rmse_over_time(
        &self,
        group: &[usize],
        range: std::ops::Range<usize>,
    ) -> Result<f64, MetricsError> {
        if range.is_empty() {
            return Err(MetricsError::InvalidParameter {
                name: "step range length",
                value: 0.0,
            });
        }
        let len = range.len() as f64;
        let rmses = range
            .map(|k| self.rmse_group(k, group))
            .collect::<Result<Vec<f64>, _>>()?;
        Ok(root_mean_square(&rmses, len))
    }
}

/// `sqrt(sum_i v_i)` of non-negative finite values (a group's MSEs), computed the plain way
/// and, only where the sum leaves f64's range, with the largest value divided out first, so
/// that a finite answer comes back finite.
fn root_sum(values: &[f64]) -> f64 {
    let plain = values.iter().fold(0.0, |t, v| t + v).sqrt();
    if plain.is_finite() {
        return plain;
    }
    let big = values.iter().fold(0.0f64, |m, &v| m.max(v));
    big.sqrt() * values.iter().map(|v| v / big).sum::<f64>().sqrt()
}

/// `sqrt(sum_i v_i^2 / len)` of non-negative finite values (RMSEs over steps), plain and, only
/// where a square leaves f64's range, with the largest value divided out first.
fn root_mean_square(values: &[f64], len: f64) -> f64 {
    let plain = (values.iter().fold(0.0, |t, v| t + v * v) / len).sqrt();
    if plain.is_finite() {
        return plain;
    }
    let big = values.iter().fold(0.0f64, |m, &v| m.max(v));
    big * (values.iter().map(|v| (v / big) * (v / big)).sum::<f64>() / len).sqrt()
}

impl Merge for SquaredErrors {
    fn fits(&self, other: &Self) -> bool {
        (self.steps(), self.dim) == (other.steps(), other.dim)
    }

    fn merge(&mut self, other: &Self) {
        assert_fits(self, other);
        add_sums(&mut self.sum, &mut self.count, &other.sum, &other.count);
    }
}

/// Plain mean of a series (a time average of per-step statistics), computed without
/// overflow: the terms are divided by the length before they are summed, so a series of values
/// near `f64::MAX` has its finite mean.
///
/// ```
/// use kalibra_metrics::time_average;
/// assert_eq!(time_average(&[1.0, 2.0, 6.0])?, 3.0);
/// assert_eq!(time_average(&[f64::MAX, f64::MAX])?, f64::MAX);
/// assert!(time_average(&[]).is_err());
/// assert!(time_average(&[1.0, f64::NAN]).is_err());
/// # Ok::<(), kalibra_metrics::MetricsError>(())
/// ```
///
/// # Errors
/// [`MetricsError::Empty`] for an empty series (rather than a NaN mean);
/// [`MetricsError::NonFiniteSample`] naming the first NaN or infinite value.
pub fn time_average(series: &[f64]) -> Result<f64, MetricsError> {
    if series.is_empty() {
        return Err(MetricsError::Empty {
            what: "series to average",
        });
    }
    if let Some(index) = series.iter().position(|v| !v.is_finite()) {
        return Err(MetricsError::NonFiniteSample {
            what: "time average",
            index,
        });
    }
    let n = series.len() as f64;
    let sum: f64 = series.iter().sum();
    if sum.is_finite() {
        return Ok(sum / n);
    }
    // Beyond f64's range only as a sum: halve and divide first, so the sum stays within
    // range, then double; the mean of finite values is finite, and where the doubling rounds
    // past f64::MAX the mean is within rounding of it.
    let half: f64 = series.iter().map(|v| 0.5 * v / n).sum();
    Ok((2.0 * half).clamp(-f64::MAX, f64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Credibility;

    /// A horizon learnt while reading gives what the full horizon from the start gives.
    #[test]
    fn extending_the_horizon_equals_building_it_whole() {
        let pushes = [
            (0, [1.0, -2.0]),
            (2, [0.5, 0.25]),
            (1, [3.0, 1.0]),
            (2, [-1.0, 2.0]),
        ];
        let mut whole = (
            StepMean::new(3),
            SquaredErrors::new(3, 2),
            Credibility::new(3, 2),
        );
        let mut grown = (
            StepMean::new(0),
            SquaredErrors::new(0, 2),
            Credibility::new(0, 2),
        );
        for (step, e) in pushes {
            grown.0.extend_steps(step + 1);
            grown.1.extend_steps(step + 1);
            grown.2.extend_steps(step + 1);
            for acc in [&mut whole, &mut grown] {
                acc.0.push(step, e[0]).unwrap();
                acc.1.push_slice(step, &e).unwrap();
                acc.2.push_nees(step, &e, e[0].abs()).unwrap();
            }
        }
        // Shrinking is never done: a shorter request leaves the horizon as it is.
        grown.0.extend_steps(1);
        grown.1.extend_steps(1);
        grown.2.extend_steps(1);
        assert_eq!(whole, grown);
    }

    /// A NaN or an infinity is refused and leaves the accumulator as it was; the mean of a
    /// step without samples is an error, not NaN.
    #[test]
    fn non_finite_samples_and_empty_steps() {
        let mut mean = StepMean::new(2);
        let mut squared = SquaredErrors::new(2, 2);
        mean.push(0, 1.5).unwrap();
        squared.push_slice(0, &[1.0, 2.0]).unwrap();
        let (m0, s0) = (mean.clone(), squared.clone());
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(matches!(
                mean.push(0, bad),
                Err(MetricsError::NonFiniteSample { index: 0, .. })
            ));
            assert!(matches!(
                squared.push_slice(0, &[0.0, bad]),
                Err(MetricsError::NonFiniteSample { index: 0, .. })
            ));
        }
        assert_eq!((mean, squared.clone()), (m0, s0));
        assert_eq!(squared.rmse_group(0, &[0, 1]).unwrap(), 5f64.sqrt());
        assert!(matches!(squared.mse(1, 0), Err(MetricsError::Empty { .. })));
        assert!(matches!(
            squared.rmse_series(&[0]),
            Err(MetricsError::Empty { .. })
        ));
    }

    /// Lane-wise pushes equal pushing the live lanes one after the other, to the bit: sums
    /// with rounding in them, lanes left out, values refused (NaN, infinite, or taking a sum
    /// beyond f64's range) with the error the one-by-one push returns, a step beyond the
    /// horizon and a wrong dimension.
    #[test]
    fn lanewise_pushes_equal_pushing_lane_by_lane() {
        // Two state sizes.
        lanewise_pushes::<3>();
        lanewise_pushes::<9>();
    }

    fn lanewise_pushes<const D: usize>() {
        let dim = D;
        use rand::{RngExt, SeedableRng};
        const L: usize = 8;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let steps = 3;
        let mut lanes = (StepMean::new(steps), SquaredErrors::new(steps, dim));
        let mut one = lanes.clone();
        let specials = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e308, 1.5e154];
        for round in 0..400 {
            // Steps 0 .. steps - 1, and now and then one beyond the horizon.
            let step = if round % 50 == 49 {
                steps
            } else {
                round % steps
            };
            let value = |rng: &mut rand_chacha::ChaCha8Rng| {
                if rng.random::<f64>() < 0.05 {
                    specials[rng.random_range(0..specials.len())]
                } else {
                    rng.random::<f64>() * 10f64.powi(rng.random_range(-3..4))
                }
            };
            let values: [f64; L] = std::array::from_fn(|_| value(&mut rng));
            let errors: [[f64; L]; D] =
                std::array::from_fn(|_| std::array::from_fn(|_| value(&mut rng)));
            // All lanes, none, or a random subset.
            let live: [bool; L] = match round % 7 {
                0 => [true; L],
                1 => [false; L],
                _ => std::array::from_fn(|_| rng.random::<bool>()),
            };
            let mut got = vec![];
            let (mut live0, mut live1) = (live, live);
            lanes
                .0
                .push_lanes(step, &values, &mut live0, |lane, e| got.push((0, lane, e)));
            lanes
                .1
                .push_lanes(step, &errors, &mut live1, |lane, e| got.push((1, lane, e)));
            let mut want = vec![];
            for (acc, lane) in [0, 1].into_iter().flat_map(|a| (0..L).map(move |l| (a, l))) {
                if !live[lane] {
                    continue;
                }
                let e: Vec<f64> = errors.iter().map(|row| row[lane]).collect();
                let pushed = match acc {
                    0 => one.0.push(step, values[lane]),
                    _ => one.1.push_slice(step, &e),
                };
                if let Err(e) = pushed {
                    want.push((acc, lane, e));
                }
            }
            assert_eq!(got, want, "round {round}");
            // The lanes left live are those pushed.
            for (acc, after) in [live0, live1].into_iter().enumerate() {
                for lane in 0..L {
                    let refused = want.iter().any(|w| (w.0, w.1) == (acc, lane));
                    assert_eq!(after[lane], live[lane] && !refused, "round {round}");
                }
            }
            // PartialEq on f64 sums: equal values (no NaN is ever stored), compared by bits too.
            assert_eq!(lanes, one, "round {round}");
            assert!(
                lanes
                    .0
                    .sum
                    .iter()
                    .zip(&one.0.sum)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
            assert!(
                lanes
                    .1
                    .sum
                    .iter()
                    .zip(&one.1.sum)
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
        }
        // Something was stored and something was refused, or the test tested little.
        assert!(lanes.0.count(0) > 100 && lanes.1.count(0) > 100);
        let mut refused = vec![];
        let mut all = [true; L];
        lanes
            .0
            .push_lanes(0, &[f64::NAN; L], &mut all, |lane, _| refused.push(lane));
        assert_eq!(refused, (0..L).collect::<Vec<_>>());
        assert_eq!(all, [false; L]);
        // A wrong dimension fails every live lane and stores nothing.
        let before = lanes.1.clone();
        let mut wrong = vec![];
        let mut every_other = std::array::from_fn(|lane| lane % 2 == 0);
        lanes
            .1
            .push_lanes(0, &[[1.0; L]; 2], &mut every_other, |lane, e| {
                wrong.push((lane, e))
            });
        assert_eq!(every_other, [false; L]);
        let expected = MetricsError::DimensionMismatch {
            what: "error vector",
            expected: dim,
            found: 2,
        };
        let want: Vec<_> = (0..L)
            .step_by(2)
            .map(|lane| (lane, expected.clone()))
            .collect();
        assert_eq!(wrong, want);
        assert_eq!(lanes.1, before);
    }
}
