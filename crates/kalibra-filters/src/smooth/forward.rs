//! The forward pass a smoother runs backwards over: every step's filtered estimate, and what
//! each prediction computed.

use std::sync::Arc;

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector};

use super::{Smoothable, Smoothed, rts};
use crate::{Estimate, FilterError, SigmaSpace, Start};

/// The filtered estimate of one step of a [`ForwardPass`].
#[derive(Clone, Debug)]
pub struct FilteredStep<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) step: usize,
    pub(crate) updated: bool,
    pub(crate) estimate: Estimate<N>,
}

impl<N: Dim> FilteredStep<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The filter's current estimate.
    pub(crate) fn current<M: Dim, F: Smoothable<N, M> + ?Sized>(filter: &F, updated: bool) -> Self
    where
        DefaultAllocator: Alloc<N, M>,
    {
        Self {
            step: filter.step_index(),
            updated,
            estimate: Estimate {
                mean: filter.mean().clone(),
                cov: filter.covariance().clone(),
            },
        }
    }

    /// The step index `k`.
    pub fn step(&self) -> usize {
        self.step
    }
    /// Whether a measurement updated this step (then the estimate is the posterior `x+_k`,
    /// `P+_k`; otherwise the prediction, or the initial estimate).
    pub fn updated(&self) -> bool {
        self.updated
    }
    /// The filtered estimate: given the measurements up to this step.
    pub fn estimate(&self) -> &Estimate<N> {
        &self.estimate
    }
}

/// What the prediction from step `k` to `k + 1` computed, as the smoother needs it.
#[derive(Clone, Debug)]
pub struct Prediction<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    pub(crate) prior: Estimate<N>,
    pub(crate) cross: OMatrix<f64, N, N>,
}

impl<N: Dim> Prediction<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The prior `x-_{k+1}, P-_{k+1}` the filter predicted.
    pub fn prior(&self) -> &Estimate<N> {
        &self.prior
    }
    /// The cross-covariance `C_k = Cov(x_k, x_{k+1})` of the filtered state at `k` and the
    /// predicted one: `P_k F_k^T` for the KF and the EKF (with the `F_k` of the prediction),
    /// the sigma points' `sum W_i (X_i - x_k)(f(X_i) - x-_{k+1})^T` for the unscented
    /// prediction.
    pub fn cross_covariance(&self) -> &OMatrix<f64, N, N> {
        &self.cross
    }
}

/// A filter's run stored for smoothing: the filtered estimate of every step, and the
/// prediction between each pair of consecutive steps, including the steps without a
/// measurement ([`Smoothable::forward`] records it).
///
/// Smoothing it ([`ForwardPass::smooth`]) needs neither the filter nor its models, so a pass can
/// be kept and smoothed later, or smoothed again after a look at the filtered estimates.
#[derive(Clone, Debug)]
pub struct ForwardPass<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    // `predictions[i]` leads from `filtered[i]` to `filtered[i + 1]`: one fewer than the steps
    // (none for an empty pass); only `record` builds the two.
    pub(crate) filtered: Vec<FilteredStep<N>>,
    pub(crate) predictions: Vec<Prediction<N>>,
    pub(crate) space: Option<Arc<dyn SigmaSpace<N>>>,
}

impl<N: Dim> ForwardPass<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The filtered estimates, one per step, in step order.
    pub fn filtered(&self) -> &[FilteredStep<N>] {
        &self.filtered
    }
    /// The predictions: element `i` leads from step `filtered()[i]` to `filtered()[i + 1]`.
    pub fn predictions(&self) -> &[Prediction<N>] {
        &self.predictions
    }
    /// The Rauch-Tung-Striebel smoother over the pass (see the [module docs](crate::smooth)).
    ///
    /// # Errors
    /// [`FilterError::NotPositiveDefinite`] naming the step whose predicted covariance has no
    /// Cholesky factor; [`FilterError::NonFinite`] naming the step whose smoothed estimate
    /// overflowed.
    pub fn smooth(&self) -> Result<Smoothed<N>, FilterError> {
        let steps = rts::smooth_chain(&self.filtered, &self.predictions, self.space.as_deref())?;
        Ok(Smoothed { steps })
    }
}

/// What a [`Recorder`] hands over as the filter runs: a step's filtered estimate, or the
/// prediction leaving the last one (always followed by the next step's estimate).
pub(crate) enum Event<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    Filtered(FilteredStep<N>),
    Predicted(Prediction<N>),
}

/// Steps a filter one measurement at a time, handing each prediction and each step's
/// filtered estimate to `emit` as soon as it is known.
#[derive(Debug)]
pub(crate) struct Recorder {
    start: Start,
    started: bool,
    emitted: bool,
}

impl Recorder {
    /// A recorder for `filter` at its current estimate. With [`Start::PredictFirst`] the
    /// initial estimate is a step of its own (`x0` at step 0, smoothed as EM needs it), handed
    /// over now; with [`Start::UpdateFirst`] it is the prior of the first measurement's step.
    pub(crate) fn begin<N: Dim, M: Dim, F: Smoothable<N, M> + ?Sized>(
        filter: &F,
        start: Start,
        emit: &mut impl FnMut(Event<N>) -> Result<(), FilterError>,
    ) -> Result<Self, FilterError>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        let emitted = start == Start::PredictFirst;
        if emitted {
            emit(Event::Filtered(FilteredStep::current(filter, false)))?;
        }
        Ok(Self {
            start,
            started: false,
            emitted,
        })
    }

    /// One element of the measurement sequence, as [`crate::Filter::run`] steps it.
    pub(crate) fn step<N: Dim, M: Dim, F: Smoothable<N, M> + ?Sized>(
        &mut self,
        filter: &mut F,
        z: Option<&OVector<f64, M>>,
        emit: &mut impl FnMut(Event<N>) -> Result<(), FilterError>,
    ) -> Result<(), FilterError>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        if self.started || self.start == Start::PredictFirst {
            let cross = filter.predict_with_cross()?;
            let prior = Estimate {
                mean: filter.mean().clone(),
                cov: filter.covariance().clone(),
            };
            emit(Event::Predicted(Prediction { prior, cross }))?;
        }
        self.started = true;
        if let Some(z) = z {
            filter.update(z)?;
        }
        self.emitted = true;
        emit(Event::Filtered(FilteredStep::current(filter, z.is_some())))
    }

    /// Ends the sequence: an empty one started [`Start::UpdateFirst`] hands over the initial
    /// estimate as its one step.
    pub(crate) fn finish<N: Dim, M: Dim, F: Smoothable<N, M> + ?Sized>(
        self,
        filter: &F,
        emit: &mut impl FnMut(Event<N>) -> Result<(), FilterError>,
    ) -> Result<(), FilterError>
    where
        DefaultAllocator: Alloc<N, M>,
    {
        if self.emitted {
            return Ok(());
        }
        emit(Event::Filtered(FilteredStep::current(filter, false)))
    }
}

/// Runs `filter` over `measurements` as [`crate::Filter::run`] does and stores the pass.
pub(crate) fn record<'z, N: Dim, M: Dim, F: Smoothable<N, M> + ?Sized, I>(
    filter: &mut F,
    measurements: I,
    start: Start,
) -> Result<ForwardPass<N>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
    I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
    OVector<f64, M>: 'z,
{
    let measurements = measurements.into_iter();
    let capacity = 1 + measurements.size_hint().0;
    let (mut filtered, mut predictions) =
        (Vec::with_capacity(capacity), Vec::with_capacity(capacity));
    let mut emit = |event| {
        match event {
            Event::Filtered(step) => filtered.push(step),
            Event::Predicted(prediction) => predictions.push(prediction),
        }
        Ok(())
    };
    let mut recorder = Recorder::begin(filter, start, &mut emit)?;
    for z in measurements {
        recorder.step(filter, z, &mut emit)?;
    }
    recorder.finish(filter, &mut emit)?;
    Ok(ForwardPass {
        filtered,
        predictions,
        space: filter.smoother_space(),
    })
}
