//! The `Filter` trait and running a filter over a measurement sequence.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector};

use crate::{FilterError, StepRecord};

/// Where a filter's initial estimate sits relative to the first measurement of a sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Start {
    /// The initial estimate is the prior at the first measurement's step: update first
    /// (paper 001's problems start this way).
    UpdateFirst,
    /// The initial estimate is one step before the first measurement: predict first (papers
    /// 000 and 003 start from `x_0` and measure `y_1`).
    PredictFirst,
}

/// A recursive state estimator stepped by `predict` (from step `k` to `k + 1`) and `update`
/// (with the measurement at the current step).
///
/// Implementors write the four required methods; running over a whole sequence is provided.
/// The filter owns (or borrows, since `&model` is a model) its dynamics and measurement models.
pub trait Filter<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The step index of the current estimate.
    fn step_index(&self) -> usize;

    /// The current mean.
    fn mean(&self) -> &OVector<f64, N>;

    /// The current covariance.
    fn covariance(&self) -> &OMatrix<f64, N, N>;

    /// Predicts the estimate from step `k` to `k + 1`.
    ///
    /// # Errors
    /// A [`FilterError`] for non-finite model output; the estimate is unchanged then.
    fn predict(&mut self) -> Result<(), FilterError>;

    /// Updates the estimate with the measurement `z` at the current step and returns the step
    /// record.
    ///
    /// # Errors
    /// [`FilterError::DimensionMismatch`] for a measurement of the wrong length (`Dyn` sizes),
    /// [`FilterError::NonFinite`] for NaN or infinite input or model output,
    /// [`FilterError::NotPositiveDefinite`] for a singular innovation covariance. The estimate
    /// is unchanged then.
    fn update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError>;

    /// The record of the last update, if any.
    fn last_record(&self) -> Option<&StepRecord<N, M>>;

    /// Runs the filter over a measurement sequence (`None` where a step has no measurement:
    /// the filter predicts through it), calling `visit` with each update's record. Measurement
    /// `i` belongs to step `step_index() + i` with [`Start::UpdateFirst`], and
    /// `step_index() + 1 + i` with [`Start::PredictFirst`].
    ///
    /// The records are not stored, so a long run needs no memory beyond the filter; see
    /// [`Filter::run_collect`] to keep them.
    ///
    /// # Errors
    /// The first [`FilterError`] of any step; the filter stays at that step.
    fn run<'z, I>(
        &mut self,
        measurements: I,
        start: Start,
        mut visit: impl FnMut(&StepRecord<N, M>),
    ) -> Result<(), FilterError>
    where
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        for (i, z) in measurements.into_iter().enumerate() {
            if i > 0 || start == Start::PredictFirst {
                self.predict()?;
            }
            if let Some(z) = z {
                visit(self.update(z)?);
            }
        }
        Ok(())
    }

    /// As [`Filter::run`], returning every update's record.
    ///
    /// # Errors
    /// As [`Filter::run`].
    fn run_collect<'z, I>(
        &mut self,
        measurements: I,
        start: Start,
    ) -> Result<Vec<StepRecord<N, M>>, FilterError>
    where
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        let mut records = Vec::new();
        self.run(measurements, start, |r| records.push(r.clone()))?;
        Ok(records)
    }
}
