//! The constant-gain Kalman filter (CGKF).

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector};
use kalibra_models::{Dynamics, Measurement};

use crate::core::KalmanCore;
use crate::kalman::{checked_core, jacobian_predict, measurement_update};
use crate::{Filter, FilterError, FilterOptions, StepRecord, steady_state};

/// The constant-gain Kalman filter: the [`Ekf`](crate::Ekf)'s prediction and innovation with a
/// fixed gain `K` instead of `P- H^T S^-1`: `x+ = f(x) + K (z - h(f(x)))`.
///
/// The gain is the user's, or the steady-state gain of a linear(ised) model
/// ([`ConstantGainKf::steady_state_gain`]). The covariance is propagated as the EKF does
/// (Jacobians at the estimate) and updated in Joseph form with the fixed gain,
/// `(I - K H) P- (I - K H)^T + K R K^T`, which on a linear model is the exact covariance of the
/// error under that gain, optimal or not. A constant gain saves the solve with `S` (it is still
/// factorised for the record's NIS), and it is the setting in which paper 004's surrogate
/// bounds are proven: the error is then an AR process with deterministic coefficients up to
/// the Jacobian.
///
/// ```
/// use kalibra_filters::{ConstantGainKf, Filter, Kf, Start};
/// use kalibra_models::Kinematic;
/// use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?;
/// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity() * 4.0)?);
/// let gain = ConstantGainKf::steady_state_gain(&f, &h, 0, &Vector4::zeros())?;
/// let mut cgkf = ConstantGainKf::new(&f, &h, Vector4::zeros(), Matrix4::identity(), gain)?;
/// let z: Vec<Vector2<f64>> = (0..50).map(|k| Vector2::new(k as f64, 0.5 * k as f64)).collect();
/// cgkf.run(z.iter().map(Some), Start::UpdateFirst, |rec| assert_eq!(*rec.gain(), gain))?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct ConstantGainKf<N: Dim, M: Dim, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    dynamics: D,
    measurement: H,
    gain: OMatrix<f64, N, M>,
    core: KalmanCore<N, M>,
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> ConstantGainKf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// A filter at step 0 with initial mean `x0`, covariance `p0` and the constant `gain`.
    ///
    /// # Errors
    /// [`FilterError::Initial`] if `x0`, `p0` or `gain` has the wrong size or is not finite,
    /// or `p0` is not symmetric positive semi-definite; [`FilterError::DimensionMismatch`] for
    /// a measurement model built for another state dimension (as [`crate::Kf::new`]).
    pub fn new(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        gain: OMatrix<f64, N, M>,
    ) -> Result<Self, FilterError> {
        Self::with_options(
            dynamics,
            measurement,
            x0,
            p0,
            gain,
            FilterOptions::default(),
        )
    }

    /// A filter with explicit [`FilterOptions`]; the update form is always Joseph (the
    /// standard form is the covariance only at the optimal gain).
    ///
    /// # Errors
    /// As [`ConstantGainKf::new`]; [`FilterError::Unsupported`] for
    /// [`InitialCheck::AsGiven`](crate::InitialCheck::AsGiven).
    pub fn with_options(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        gain: OMatrix<f64, N, M>,
        options: FilterOptions,
    ) -> Result<Self, FilterError> {
        let mut core = checked_core(
            &dynamics,
            &measurement,
            x0,
            p0,
            options,
            Some("the constant-gain KF with an as-given initial covariance"),
        )?;
        core.accept_fixed_gain(&gain)?;
        Ok(Self {
            dynamics,
            measurement,
            gain,
            core,
        })
    }

    /// The steady-state Kalman gain of the model linearised at `x_lin` and step `k` (`F`, `H`
    /// the Jacobians there, `Q_k`, `R_k(x_lin)`): the limit of the discrete Riccati recursion
    /// ([`steady_state`]). For a linear time-invariant model it is the KF's limiting gain.
    ///
    /// # Errors
    /// As [`steady_state`]; [`FilterError::DimensionMismatch`] for models built for different
    /// state dimensions or an `x_lin` of another size (`Dyn`), [`FilterError::NonFinite`] for a
    /// non-finite `x_lin`.
    pub fn steady_state_gain(
        dynamics: &D,
        measurement: &H,
        k: usize,
        x_lin: &OVector<f64, N>,
    ) -> Result<OMatrix<f64, N, M>, FilterError> {
        crate::kalman::check_model_sizes(dynamics, measurement)?;
        kalibra_linalg::check_dim(
            dynamics.state_dim().value(),
            x_lin.nrows(),
            "linearisation point",
        )
        .map_err(|e| FilterError::at(k, e))?;
        kalibra_linalg::check_finite(x_lin, "linearisation point")
            .map_err(|e| FilterError::at(k, e))?;
        Ok(steady_state(
            &dynamics.jacobian(k, x_lin),
            &measurement.jacobian(k, x_lin),
            &dynamics.noise_cov(k),
            &measurement.noise_cov(k, x_lin),
        )?
        .gain)
    }

    /// The constant gain.
    pub fn gain(&self) -> &OMatrix<f64, N, M> {
        &self.gain
    }

    /// The dynamics model.
    pub fn dynamics(&self) -> &D {
        &self.dynamics
    }

    /// The measurement model.
    pub fn measurement(&self) -> &H {
        &self.measurement
    }
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Filter<N, M>
    for ConstantGainKf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    crate::kalman::core_accessors!();

    fn predict(&mut self) -> Result<(), FilterError> {
        jacobian_predict::<false, _, _, _>(&mut self.core, &self.dynamics)
    }

    fn update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
        let measurement = &self.measurement;
        let h = |k, x: &OVector<f64, N>| measurement.jacobian(k, x);
        let gain = Some(&self.gain);
        measurement_update::<false, _, _, _>(&mut self.core, measurement, z, h, gain)
    }
}
