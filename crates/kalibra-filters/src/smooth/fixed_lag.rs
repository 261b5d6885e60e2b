//! The fixed-lag smoother: each step smoothed with the measurements up to `lag` steps later,
//! in memory that does not grow with the log.

use std::collections::VecDeque;
use std::sync::Arc;

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OVector};

use super::Smoothable;
use super::forward::{Event, FilteredStep, Prediction, Recorder};
use super::rts::{SmoothedStep, smooth_chain};
use crate::{FilterError, SigmaSpace, Start};

/// The last `lag + 2` steps of a forward pass and what has left them.
#[derive(Clone, Debug)]
struct Window<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    lag: usize,
    filtered: VecDeque<FilteredStep<N>>,
    // `predictions[i]` leaves `filtered[i]`; one fewer than the steps, or as many while the
    // newest step's prediction has arrived before the step after it.
    predictions: VecDeque<Prediction<N>>,
    // Whether the front step was emitted already (it stays for the next one's lag-one
    // covariance).
    front_emitted: bool,
    space: Option<Arc<dyn SigmaSpace<N>>>,
}

impl<N: Dim> Window<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The window smoothed from its newest step back to its front.
    fn smooth(&mut self) -> Result<Vec<SmoothedStep<N>>, FilterError> {
        let filtered = self.filtered.make_contiguous();
        let predictions = self.predictions.make_contiguous();
        let links = predictions.len().min(filtered.len().saturating_sub(1));
        smooth_chain(filtered, &predictions[..links], self.space.as_deref())
    }

    /// Takes what the filter handed over, and returns the step `lag` steps before a new one,
    /// smoothed, once there is one.
    fn push(&mut self, event: Event<N>) -> Result<Option<SmoothedStep<N>>, FilterError> {
        let step = match event {
            Event::Predicted(prediction) => {
                self.predictions.push_back(prediction);
                return Ok(None);
            }
            Event::Filtered(step) => step,
        };
        self.filtered.push_back(step);
        let target = usize::from(self.front_emitted);
        // `len < target + lag + 1`, written so that a lag of `usize::MAX` cannot overflow
        // (`len >= 1` after the push, `target <= 1`).
        if self.filtered.len() - target <= self.lag {
            return Ok(None);
        }
        let smoothed = self.smooth()?.swap_remove(target);
        if self.front_emitted {
            self.filtered.pop_front();
            self.predictions.pop_front();
        }
        self.front_emitted = true;
        Ok(Some(smoothed))
    }

    /// The steps not yet emitted, smoothed: with no later measurement left, these equal the
    /// full smoother's.
    fn finish(mut self) -> Result<Vec<SmoothedStep<N>>, FilterError> {
        let mut steps = self.smooth()?;
        Ok(steps.split_off(usize::from(self.front_emitted).min(steps.len())))
    }
}

/// The fixed-lag Rauch-Tung-Striebel smoother for long logs, streaming: feed it one
/// measurement at a time ([`FixedLagSmoother::step`]) and it returns step `k` smoothed with
/// the measurements up to step `k + lag`, in memory for `lag + 2` steps whatever the log's
/// length.
///
/// Its estimate of step `k` is the full smoother's ([`Smoothable::smooth`]) over the log cut
/// after step `k + lag`, to the bit (the backward recursion from `k + lag` to `k` is the same
/// arithmetic), lag-one covariance included; [`FixedLagSmoother::finish`] returns the last
/// `lag` steps, which are the full smoother's over the whole log. Each step costs one backward
/// sweep over the window, `lag + 1` Cholesky solves.
///
/// ```
/// use kalibra_filters::{Kf, Start, smooth::{FixedLagSmoother, Smoothable}};
/// use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
/// use kalibra_models::Kinematic;
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?;
/// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity())?);
/// let z: Vec<_> = (0..20).map(|k| Some(Vector2::new(k as f64, 0.5 * k as f64))).collect();
///
/// let kf = Kf::new(&f, &h, Vector4::zeros(), Matrix4::identity() * 10.0)?;
/// let mut lagged = FixedLagSmoother::new(kf, 3, Start::UpdateFirst);
/// let mut steps = Vec::new();
/// for zk in &z {
///     steps.extend(lagged.step(zk.as_ref())?);
/// }
/// let (_, tail) = lagged.finish()?;
/// steps.extend(tail);
///
/// // The last steps equal the full smoother's.
/// let mut kf = Kf::new(&f, &h, Vector4::zeros(), Matrix4::identity() * 10.0)?;
/// let full = kf.smooth(z.iter().map(Option::as_ref), Start::UpdateFirst)?;
/// assert_eq!(steps.len(), 20);
/// assert_eq!(steps[19].mean(), full.steps()[19].mean());
/// assert_eq!(steps[17].covariance(), full.steps()[17].covariance());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct FixedLagSmoother<N: Dim, M: Dim, F>
where
    DefaultAllocator: Alloc<N, M>,
{
    filter: F,
    start: Start,
    // `None` until the first measurement: the recorder begins then, with the filter as given.
    recorder: Option<Recorder>,
    window: Window<N>,
    measurement: std::marker::PhantomData<M>,
}

/// The most steps [`FixedLagSmoother::new`] reserves its window for; a longer lag's window
/// grows as the steps arrive.
const LAG_RESERVE_MAX: usize = 1024;

impl<N: Dim, M: Dim, F: Smoothable<N, M>> FixedLagSmoother<N, M, F>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// A smoother running `filter` from its current estimate, `start` saying where that
    /// estimate sits relative to the first measurement (as [`crate::Filter::run`]), smoothing
    /// each step with the measurements up to `lag` steps later (`lag = 0`: the filtered
    /// estimates, with their lag-one covariances).
    pub fn new(filter: F, lag: usize, start: Start) -> Self {
        let window = Window {
            lag,
            // The window holds `lag + 2` steps once full; reserved up to a bound, since a lag
            // from data may be `usize::MAX` (`tests/extreme_sizes.rs`), and grown past it.
            filtered: VecDeque::with_capacity(lag.saturating_add(2).min(LAG_RESERVE_MAX)),
            predictions: VecDeque::with_capacity(lag.saturating_add(2).min(LAG_RESERVE_MAX)),
            front_emitted: false,
            space: filter.smoother_space(),
        };
        Self {
            filter,
            start,
            recorder: None,
            window,
            measurement: std::marker::PhantomData,
        }
    }

    /// The filter, at the newest step.
    pub fn filter(&self) -> &F {
        &self.filter
    }

    /// Steps the filter with the next element of the measurement sequence (`None`: no
    /// measurement at this step), and returns the steps that now have `lag` later steps,
    /// smoothed: the one `lag` steps back, once there is one (and with [`Start::PredictFirst`]
    /// and `lag = 0`, the initial estimate's step before it at the first call).
    ///
    /// # Errors
    /// The filter's [`FilterError`] (then the smoother must not be stepped further), or the
    /// smoother's as [`super::ForwardPass::smooth`].
    pub fn step(
        &mut self,
        z: Option<&OVector<f64, M>>,
    ) -> Result<Vec<SmoothedStep<N>>, FilterError> {
        let mut ready = Vec::new();
        let window = &mut self.window;
        let mut emit = |event| {
            ready.extend(window.push(event)?);
            Ok(())
        };
        let recorder = match &mut self.recorder {
            Some(recorder) => recorder,
            None => self
                .recorder
                .insert(Recorder::begin(&self.filter, self.start, &mut emit)?),
        };
        recorder.step(&mut self.filter, z, &mut emit)?;
        Ok(ready)
    }

    /// Ends the log: returns the filter and the steps not yet returned, smoothed with every
    /// measurement (the full smoother's last steps).
    ///
    /// # Errors
    /// As [`FixedLagSmoother::step`].
    pub fn finish(self) -> Result<(F, Vec<SmoothedStep<N>>), FilterError> {
        let Self {
            filter,
            start,
            recorder,
            mut window,
            ..
        } = self;
        let mut steps = Vec::new();
        let mut emit = |event| {
            steps.extend(window.push(event)?);
            Ok(())
        };
        let recorder = match recorder {
            Some(recorder) => recorder,
            None => Recorder::begin(&filter, start, &mut emit)?,
        };
        recorder.finish(&filter, &mut emit)?;
        steps.extend(window.finish()?);
        Ok((filter, steps))
    }
}
