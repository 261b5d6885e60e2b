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
/// Implementors write the required methods; running over a whole sequence is provided.
/// The filter owns (or borrows, since `&model` is a model) its dynamics and measurement models.
///
/// # Trait objects
/// The trait is dyn-compatible, so a bank of different filters fits in one
/// `Vec<Box<dyn Filter<N, M>>>`. The provided methods that run a sequence are generic (over the
/// measurement iterator and the visitor), so they require `Self: Sized`; `Box<F>` and `&mut F`
/// implement `Filter` for any `F: Filter + ?Sized`, so they run on a boxed filter as well.
///
/// ```
/// use kalibra_filters::{Ekf, Filter, Kf, SigmaSet, Start, Ukf};
/// use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
/// use kalibra_models::Kinematic;
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?;
/// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity())?);
/// let (x0, p0) = (Vector4::zeros(), Matrix4::identity());
/// let mut bank: Vec<Box<dyn Filter<U4, U2> + '_>> = vec![
///     Box::new(Kf::new(&f, &h, x0, p0)?),
///     Box::new(Ekf::new(&f, &h, x0, p0)?),
///     Box::new(Ukf::new(&f, &h, x0, p0, SigmaSet::recommended(4))?),
/// ];
/// let z = [Vector2::new(1.0, 2.0), Vector2::new(2.0, 4.0)];
/// for filter in &mut bank {
///     filter.run(z.iter().map(Some), Start::UpdateFirst, |_| {})?;
/// }
/// assert!((bank[0].mean() - bank[2].mean()).amax() < 1e-9);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
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
        Self: Sized,
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
        Self: Sized,
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        let mut records = Vec::new();
        self.run(measurements, start, |r| records.push(r.clone()))?;
        Ok(records)
    }
}

/// Forwards every required method, so that a filter behind a pointer (`Box<dyn Filter>`,
/// `&mut dyn Filter`) runs sequences through the provided methods.
macro_rules! forward_filter {
    ($($ptr:tt)*) => {
        impl<N: Dim, M: Dim, F: Filter<N, M> + ?Sized> Filter<N, M> for $($ptr)*
        where
            DefaultAllocator: Alloc<N, M>,
        {
            fn step_index(&self) -> usize {
                (**self).step_index()
            }
            fn mean(&self) -> &OVector<f64, N> {
                (**self).mean()
            }
            fn covariance(&self) -> &OMatrix<f64, N, N> {
                (**self).covariance()
            }
            fn predict(&mut self) -> Result<(), FilterError> {
                (**self).predict()
            }
            fn update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
                (**self).update(z)
            }
            fn last_record(&self) -> Option<&StepRecord<N, M>> {
                (**self).last_record()
            }
        }
    };
}

forward_filter!(Box<F>);
forward_filter!(&mut F);
