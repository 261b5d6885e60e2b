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
    pub fn new(steps: usize) -> Self {
        Self {
            sum: vec![0.0; steps],
            count: vec![0; steps],
        }
    }

    /// The number of steps held.
    pub fn steps(&self) -> usize {
        self.sum.len()
    }

    /// Extends the horizon to `steps` steps, the new ones empty; no change if it is already
    /// that long. For a stream whose length is learnt as it is read (a log read row by row).
    pub fn extend_steps(&mut self, steps: usize) {
        if steps > self.steps() {
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
            return Err(MetricsError::NonFiniteSample {
                what: if value.is_finite() {
                    "step mean (sum beyond f64's range)"
                } else {
                    "step mean"
                },
                index: step,
            });
        }
        self.sum[step] = sum;
        self.count[step] += 1;
        Ok(())
    }

    /// Number of values pushed at `step` (0 beyond the horizon).
    pub fn count(&self, step: usize) -> u64 {
        self.count.get(step).copied().unwrap_or(0)
    }

    /// The mean at `step`, finite; `None` where nothing was pushed (and beyond the horizon).
    /// (Before issue 19 an empty step's mean was NaN, which looked like a number to every
    /// caller that did not test for it.)
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
        assert_eq!(
            self.steps(),
            other.steps(),
            "merging accumulators of different horizons"
        );
        for (a, b) in self.sum.iter_mut().zip(&other.sum) {
            *a += b;
        }
        for (a, b) in self.count.iter_mut().zip(&other.count) {
            *a += b;
        }
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
    pub fn new(steps: usize, dim: usize) -> Self {
        Self {
            dim,
            sum: vec![0.0; steps * dim],
            count: vec![0; steps],
        }
    }

    /// Number of steps held.
    pub fn steps(&self) -> usize {
        self.count.len()
    }

    /// Extends the horizon to `steps` steps, the new ones empty; no change if it is already
    /// that long (see [`StepMean::extend_steps`]).
    pub fn extend_steps(&mut self, steps: usize) {
        if steps > self.steps() {
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
            return Err(MetricsError::DimensionMismatch {
                what: "error vector",
                expected: self.dim,
                found: error.len(),
            });
        }
        let sums = &mut self.sum[step * self.dim..(step + 1) * self.dim];
        if !error
            .iter()
            .zip(sums.iter())
            .all(|(e, s)| (s + e * e).is_finite())
        {
            return Err(MetricsError::NonFiniteSample {
                what: if error.iter().all(|e| e.is_finite()) {
                    "squared errors (sum beyond f64's range)"
                } else {
                    "squared errors"
                },
                index: step,
            });
        }
        for (s, e) in sums.iter_mut().zip(error) {
            *s += e * e;
        }
        self.count[step] += 1;
        Ok(())
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
        assert_eq!(
            (self.steps(), self.dim),
            (other.steps(), other.dim),
            "merging accumulators of different shapes"
        );
        for (a, b) in self.sum.iter_mut().zip(&other.sum) {
            *a += b;
        }
        for (a, b) in self.count.iter_mut().zip(&other.count) {
            *a += b;
        }
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
/// [`MetricsError::Empty`] for an empty series (before issue 19 it was NaN);
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
}
