//! The filters a smoother runs over, and the linearised ones (KF, EKF).

use std::sync::Arc;

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector};
use kalibra_models::{Dynamics, LinearDynamics, LinearMeasurement, Measurement};

use super::forward::{ForwardPass, record};
use super::linear;
use super::rts::smooth_in_place;
use super::{FixedLagSmoother, Smoothed, SmoothedStep};
use crate::{Ekf, Estimate, Filter, FilterError, Kf, SigmaSpace, Start};

/// A [`Filter`] that a Rauch-Tung-Striebel smoother runs over: its prediction says, besides
/// the prior, how the predicted state co-varies with the state before it.
///
/// Implemented by [`Kf`] and [`Ekf`] (checked algebra), [`crate::Ukf`] and the square-root
/// [`crate::SqrtKf`] and [`crate::SqrtUkf`]; the provided methods
/// run the filter and smooth in one call.
///
/// ```
/// use kalibra_filters::{Filter, Kf, Start, smooth::Smoothable};
/// use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
/// use kalibra_models::Kinematic;
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?;
/// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity())?);
/// let mut kf = Kf::new(&f, &h, Vector4::zeros(), Matrix4::identity() * 10.0)?;
/// let z = [Some(Vector2::new(1.0, 0.0)), None, Some(Vector2::new(3.0, 0.1))];
/// let smoothed = kf.smooth(z.iter().map(Option::as_ref), Start::PredictFirst)?;
/// // x0 at step 0 and the three steps of the sequence, the one without a measurement included.
/// assert_eq!(smoothed.steps().len(), 4);
/// // The last step is the filter's; the lag-one covariance starts at the second step.
/// assert_eq!(smoothed.steps()[3].mean(), kf.mean());
/// assert!(smoothed.steps()[0].lag_one().is_none() && smoothed.steps()[1].lag_one().is_some());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub trait Smoothable<N: Dim, M: Dim>: Filter<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Predicts from step `k` to `k + 1` as [`Filter::predict`] does, and returns the
    /// cross-covariance `C_k = Cov(x_k, x_{k+1})` of the estimate before the prediction and
    /// the prediction: `P_k F_k^T` with the prediction's own `F_k` for the KF and the EKF (its
    /// linearisation at the estimate), the sigma points' cross-covariance for the unscented
    /// prediction.
    ///
    /// # Errors
    /// As [`Filter::predict`]; the estimate is unchanged then.
    fn predict_with_cross(&mut self) -> Result<OMatrix<f64, N, N>, FilterError>;

    /// The state space whose residual and normalisation the smoother's mean goes through (the
    /// UKF's, [`crate::Ukf::with_state_space`]); `None`, plain arithmetic, by default.
    fn smoother_space(&self) -> Option<Arc<dyn SigmaSpace<N>>> {
        None
    }

    /// Runs the filter over a measurement sequence as [`Filter::run`] does and stores what the
    /// smoother needs: every step's filtered estimate (steps without a measurement included,
    /// and with [`Start::PredictFirst`] the initial estimate as a step of its own) and every
    /// prediction.
    ///
    /// # Errors
    /// The first [`FilterError`] of any step; the filter stays at that step.
    fn forward<'z, I>(
        &mut self,
        measurements: I,
        start: Start,
    ) -> Result<ForwardPass<N>, FilterError>
    where
        Self: Sized,
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        record(self, measurements, start)
    }

    /// Runs the filter over a measurement sequence and smooths it: [`Smoothable::forward`]
    /// then [`ForwardPass::smooth`].
    ///
    /// # Errors
    /// As [`Smoothable::forward`] and [`ForwardPass::smooth`].
    fn smooth<'z, I>(&mut self, measurements: I, start: Start) -> Result<Smoothed<N>, FilterError>
    where
        Self: Sized,
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        self.forward(measurements, start)?.smooth()
    }

    /// Runs the filter over a measurement sequence with the fixed-lag smoother
    /// ([`FixedLagSmoother`]), calling `visit` with every step in order, smoothed with the
    /// measurements up to `lag` steps later (the last `lag` steps with all of them).
    ///
    /// # Errors
    /// As [`Smoothable::smooth`].
    fn smooth_fixed_lag<'z, I>(
        &mut self,
        measurements: I,
        start: Start,
        lag: usize,
        mut visit: impl FnMut(&SmoothedStep<N>),
    ) -> Result<(), FilterError>
    where
        Self: Sized,
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        let mut smoother = FixedLagSmoother::new(self, lag, start);
        for z in measurements {
            smoother.step(z)?.iter().for_each(&mut visit);
        }
        smoother.finish()?.1.iter().for_each(visit);
        Ok(())
    }
}

impl<N: Dim, M: Dim, F: Smoothable<N, M> + ?Sized> Smoothable<N, M> for &mut F
where
    DefaultAllocator: Alloc<N, M>,
{
    fn predict_with_cross(&mut self) -> Result<OMatrix<f64, N, N>, FilterError> {
        (**self).predict_with_cross()
    }
    fn smoother_space(&self) -> Option<Arc<dyn SigmaSpace<N>>> {
        (**self).smoother_space()
    }
}

/// `P F^T` after a prediction with `F`: the covariance before it is taken first, and `F` is
/// evaluated again (with the arguments the prediction used, so the same matrix) only once the
/// prediction has succeeded and checked it.
pub(crate) fn linearised_cross<N: Dim, M: Dim, F: Filter<N, M> + ?Sized>(
    filter: &mut F,
    jacobian: impl FnOnce(&F, usize, &OVector<f64, N>) -> OMatrix<f64, N, N>,
) -> Result<OMatrix<f64, N, N>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (k, x, p) = (
        filter.step_index(),
        filter.mean().clone(),
        filter.covariance().clone(),
    );
    filter.predict()?;
    Ok(p * jacobian(&*filter, k, &x).transpose())
}

/// The smoother of the linearised filters (KF, EKF) without a [`ForwardPass`]: the filtered
/// estimates are stored once, as the smoothed steps they become, with the predicted ones
/// beside them, and the backward pass overwrites them in place; `C_k = P_k F_k^T` is formed
/// there from the stored `P_k` and `jacobian`, evaluated as [`linearised_cross`] does (at the
/// filtered mean, with the prediction's step), so the result is [`ForwardPass::smooth`]'s to
/// the bit. Nothing is cloned that is not kept, and a step allocates nothing on the
/// fixed-size path, because an allocation per step dominated the backward pass (`cargo
/// xtask bench smooth`).
fn smooth_linearised<'z, N: Dim, M: Dim, F: Filter<N, M>, I>(
    filter: &mut F,
    measurements: I,
    start: Start,
    jacobian: impl Fn(&F, usize, &OVector<f64, N>) -> OMatrix<f64, N, N>,
) -> Result<Smoothed<N>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
    I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
    OVector<f64, M>: 'z,
{
    let measurements = measurements.into_iter();
    let capacity = 1 + measurements.size_hint().0;
    let mut steps: Vec<SmoothedStep<N>> = Vec::with_capacity(capacity);
    let mut priors: Vec<Estimate<N>> = Vec::with_capacity(capacity);
    let here = |filter: &F, updated| SmoothedStep {
        step: filter.step_index(),
        updated,
        estimate: Estimate {
            mean: filter.mean().clone(),
            cov: filter.covariance().clone(),
        },
        lag_one: None,
    };
    // As `forward::Recorder` steps the filter.
    if start == Start::PredictFirst {
        steps.push(here(filter, false));
    }
    let mut started = false;
    for z in measurements {
        if started || start == Start::PredictFirst {
            filter.predict()?;
            priors.push(Estimate {
                mean: filter.mean().clone(),
                cov: filter.covariance().clone(),
            });
        }
        started = true;
        if let Some(z) = z {
            filter.update(z)?;
        }
        steps.push(here(filter, z.is_some()));
    }
    if steps.is_empty() {
        steps.push(here(filter, false));
    }
    let filter = &*filter;
    smooth_in_place(
        &mut steps,
        priors.len(),
        |i, current| {
            let f = jacobian(filter, current.step, &current.estimate.mean);
            (&current.estimate.cov * f.transpose(), &priors[i])
        },
        None,
    )?;
    Ok(Smoothed { steps })
}

impl<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>> Smoothable<N, M>
    for Kf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn predict_with_cross(&mut self) -> Result<OMatrix<f64, N, N>, FilterError> {
        linearised_cross(self, |kf, k, _| kf.dynamics().matrix(k))
    }

    /// As the provided method, without a [`ForwardPass`] in between: for fixed sizes and the
    /// Joseph update the KF's own pass (`smooth/linear.rs`), otherwise, or when a check fails
    /// there, the filter's steps (`smooth_linearised`); the same result to the bit either way,
    /// at less cost (`cargo xtask bench smooth`).
    fn smooth<'z, I>(&mut self, measurements: I, start: Start) -> Result<Smoothed<N>, FilterError>
    where
        Self: Sized,
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        // Collected, so that a run the KF's own pass sends back can run again on the checked
        // path.
        let zs: Vec<Option<&'z OVector<f64, M>>> = measurements.into_iter().collect();
        if let Some(smoothed) = linear::smooth(self, &zs, start) {
            return smoothed;
        }
        smooth_linearised(self, zs.iter().copied(), start, |kf, k, _| {
            kf.dynamics().matrix(k)
        })
    }
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Smoothable<N, M> for Ekf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn predict_with_cross(&mut self) -> Result<OMatrix<f64, N, N>, FilterError> {
        linearised_cross(self, |ekf, k, x| ekf.dynamics().jacobian(k, x))
    }

    /// As the [`Kf`]'s: without a [`ForwardPass`], the same result to the bit.
    fn smooth<'z, I>(&mut self, measurements: I, start: Start) -> Result<Smoothed<N>, FilterError>
    where
        Self: Sized,
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        smooth_linearised(self, measurements, start, |ekf, k, x| {
            ekf.dynamics().jacobian(k, x)
        })
    }
}
