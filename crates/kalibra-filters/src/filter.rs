//! The `Filter` trait and running a filter over a measurement sequence.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector};

use crate::{Estimate, FilterError, StepRecord};

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

    /// Runs the filter over a measurement sequence as [`Filter::run`] does, and returns its
    /// [`Trajectory`]: the initial estimate, then the estimate at every step of the sequence,
    /// with or without a measurement (the posterior where there was one, with its record; the
    /// prediction where there was none).
    ///
    /// ```
    /// use kalibra_filters::{Filter, Kf, Start};
    /// use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
    /// use kalibra_models::Kinematic;
    ///
    /// let cv = Kinematic::constant_velocity(2, 1.0)?;
    /// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity())?);
    /// let mut kf = Kf::new(&f, &h, Vector4::zeros(), Matrix4::identity())?;
    /// let z = [Some(Vector2::new(1.0, 0.0)), None, Some(Vector2::new(3.0, 0.1))];
    /// let trajectory = kf.run_all(z.iter().map(Option::as_ref), Start::PredictFirst)?;
    /// let steps: Vec<(usize, bool)> =
    ///     trajectory.entries().iter().map(|e| (e.step(), e.updated())).collect();
    /// assert_eq!(steps, [(0, false), (1, true), (2, false), (3, true)]);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// As [`Filter::run`]; the entries up to the failing step are dropped with it.
    fn run_all<'z, I>(
        &mut self,
        measurements: I,
        start: Start,
    ) -> Result<Trajectory<N, M>, FilterError>
    where
        Self: Sized,
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        let measurements = measurements.into_iter();
        let mut entries = Vec::with_capacity(1 + measurements.size_hint().0);
        entries.push(TrajectoryEntry::current(self, None));
        for (i, z) in measurements.enumerate() {
            if i > 0 || start == Start::PredictFirst {
                self.predict()?;
            }
            let record = match z {
                Some(z) => Some(self.update(z)?.clone()),
                None => None,
            };
            entries.push(TrajectoryEntry::current(self, record));
        }
        Ok(Trajectory { entries })
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

/// The estimate of one step of a [`Trajectory`], with the record of the update that produced it
/// when there was one.
#[derive(Clone, Debug)]
pub struct TrajectoryEntry<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    step: usize,
    estimate: Estimate<N>,
    record: Option<StepRecord<N, M>>,
}

impl<N: Dim, M: Dim> TrajectoryEntry<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The filter's current estimate, with the record of the update that produced it if any.
    fn current<F: Filter<N, M> + ?Sized>(filter: &F, record: Option<StepRecord<N, M>>) -> Self {
        Self {
            step: filter.step_index(),
            estimate: Estimate {
                mean: filter.mean().clone(),
                cov: filter.covariance().clone(),
            },
            record,
        }
    }

    /// The step index `k` of the estimate.
    pub fn step(&self) -> usize {
        self.step
    }
    /// Whether a measurement updated the estimate at this step (then [`TrajectoryEntry::record`]
    /// is its record and the estimate is the posterior); otherwise the estimate is the
    /// prediction, or the initial estimate.
    pub fn updated(&self) -> bool {
        self.record.is_some()
    }
    /// The estimate: the posterior `x+_k, P+_k` after an update, else the prior `x-_k, P-_k`.
    pub fn estimate(&self) -> &Estimate<N> {
        &self.estimate
    }
    /// The mean of [`TrajectoryEntry::estimate`].
    pub fn mean(&self) -> &OVector<f64, N> {
        &self.estimate.mean
    }
    /// The covariance of [`TrajectoryEntry::estimate`].
    pub fn covariance(&self) -> &OMatrix<f64, N, N> {
        &self.estimate.cov
    }
    /// The update's record, if a measurement updated this step.
    pub fn record(&self) -> Option<&StepRecord<N, M>> {
        self.record.as_ref()
    }
}

/// Every estimate of a run over a sequence ([`Filter::run_all`]), in step order: the initial
/// estimate first, then one entry per element of the measurement sequence.
///
/// With [`Start::PredictFirst`] each entry has its own step index. With [`Start::UpdateFirst`]
/// the first two entries share one: the initial estimate (the prior at that step) and the
/// estimate after the first element of the sequence.
#[derive(Clone, Debug)]
pub struct Trajectory<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    entries: Vec<TrajectoryEntry<N, M>>,
}

impl<N: Dim, M: Dim> Trajectory<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The entries, the initial estimate first (never empty).
    pub fn entries(&self) -> &[TrajectoryEntry<N, M>] {
        &self.entries
    }
    /// The initial estimate, before the sequence.
    pub fn initial(&self) -> &TrajectoryEntry<N, M> {
        &self.entries[0]
    }
    /// The estimate after the whole sequence (the initial one for an empty sequence).
    pub fn last(&self) -> &TrajectoryEntry<N, M> {
        &self.entries[self.entries.len() - 1]
    }
    /// The records of the updates, in order (what [`Filter::run_collect`] returns).
    pub fn records(&self) -> impl Iterator<Item = &StepRecord<N, M>> {
        self.entries.iter().filter_map(TrajectoryEntry::record)
    }
    /// Consumes the trajectory, returning its entries.
    pub fn into_entries(self) -> Vec<TrajectoryEntry<N, M>> {
        self.entries
    }
}

impl<'a, N: Dim, M: Dim> IntoIterator for &'a Trajectory<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    type Item = &'a TrajectoryEntry<N, M>;
    type IntoIter = std::slice::Iter<'a, TrajectoryEntry<N, M>>;
    fn into_iter(self) -> Self::IntoIter {
        self.entries.iter()
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
