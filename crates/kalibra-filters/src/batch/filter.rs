//! [`BatchFilter`]: what every batched filter offers, for code written once against all three.

use kalibra_linalg::{SMatrix, SVector};

use super::{
    BatchStep, EkfBatch, KfBatch, LaneDynamics, LaneMeasurement, LaneSigmaMeasurement, Lanes,
    UkfBatch,
};
use crate::FilterError;

/// What every batched filter offers ([`KfBatch`], [`EkfBatch`], [`UkfBatch`]): restart a
/// lane, update or predict and update all lanes, read a lane's estimate. Code that steps a
/// study's runs through any of them (a Monte Carlo loop, a bench) is written once against it;
/// each method is the filter's own method of the same name.
pub trait BatchFilter<const N: usize, const M: usize> {
    /// Restarts lane `lane` from its own estimate `(x, P)`.
    ///
    /// # Errors
    /// [`FilterError::Initial`] for a bad estimate; the lane is then unchanged.
    fn set_lane(
        &mut self,
        lane: usize,
        x: SVector<f64, N>,
        p: SMatrix<f64, N, N>,
    ) -> Result<(), FilterError>;
    /// Updates every lane at the current step (NEES against `truth`).
    fn update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N>;
    /// Predicts every lane one step, then updates it.
    fn predict_update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N>;
    /// Lane `lane`'s current mean.
    fn mean(&self, lane: usize) -> SVector<f64, N>;
    /// Lane `lane`'s current covariance.
    fn cov(&self, lane: usize) -> SMatrix<f64, N, N>;
}

/// [`BatchFilter`] for a filter type whose inherent methods of the same names it forwards to.
macro_rules! batch_filter {
    ($ty:ty, $($bounds:tt)*) => {
        impl<const N: usize, const M: usize, $($bounds)*> BatchFilter<N, M> for $ty {
            fn set_lane(
                &mut self,
                lane: usize,
                x: SVector<f64, N>,
                p: SMatrix<f64, N, N>,
            ) -> Result<(), FilterError> {
                <$ty>::set_lane(self, lane, x, p)
            }
            fn update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
                <$ty>::update(self, z, truth)
            }
            fn predict_update(&mut self, z: &[Lanes; M], truth: &[Lanes; N]) -> &BatchStep<N> {
                <$ty>::predict_update(self, z, truth)
            }
            fn mean(&self, lane: usize) -> SVector<f64, N> {
                <$ty>::mean(self, lane)
            }
            fn cov(&self, lane: usize) -> SMatrix<f64, N, N> {
                <$ty>::cov(self, lane)
            }
        }
    };
}

batch_filter!(KfBatch<N, M>,);
batch_filter!(EkfBatch<N, M, D, H>, D: LaneDynamics<N>, H: LaneMeasurement<N, M>);
batch_filter!(UkfBatch<N, M, D, H>, D: LaneDynamics<N>, H: LaneSigmaMeasurement<N, M>);
