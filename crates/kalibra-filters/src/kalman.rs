//! The linear Kalman filter and the extended Kalman filter.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector};
use kalibra_models::{Dynamics, LinearDynamics, LinearMeasurement, Measurement};

use std::marker::PhantomData;

use crate::core::{KalmanCore, check_model_output, reject_as_given};
use crate::{
    AsGiven, Checked, Checking, Filter, FilterError, FilterOptions, InitialCheck, StepRecord,
};

/// The Kalman filter on linear models: `x- = F x + u`, `P- = F P F^T + Q`,
/// `K = P- H^T S^-1`, `x+ = x- + K (z - H x-)`, Joseph-form covariance update by default.
///
/// It asks for [`LinearDynamics`] and [`LinearMeasurement`], and uses their matrices `F_k`, `H_k`
/// (not Jacobians at the estimate); on linear models it equals the [`Ekf`] (tested to 1e-12).
///
/// ```
/// use kalibra_filters::{Filter, Kf, Start};
/// use kalibra_models::{Kinematic, simulate};
/// use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector4};
/// use rand_chacha::{ChaCha8Rng, rand_core::SeedableRng};
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?;
/// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)?);
/// let x0 = Vector4::new(0.0, 0.0, 10.0, 5.0);
/// let truth = simulate(&f, &h, x0, 100, &mut ChaCha8Rng::seed_from_u64(1))?;
///
/// let mut kf = Kf::new(&f, &h, x0, Matrix4::identity() * 100.0)?;
/// let mut nis = 0.0;
/// kf.run(truth.measurements.iter().map(Some), Start::UpdateFirst, |rec| nis += rec.nis())?;
/// assert!(nis / 100.0 < 4.0); // two degrees of freedom on average
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct Kf<N: Dim, M: Dim, D, H, C = Checked>
where
    DefaultAllocator: Alloc<N, M>,
{
    dynamics: D,
    measurement: H,
    core: KalmanCore<N, M>,
    checking: PhantomData<C>,
}

/// The extended Kalman filter: the [`Kf`] with `f_k`, `h_k` evaluated at the estimate and
/// `F_{k-1}` linearised at the previous posterior mean, `H_k` at the prior mean.
/// The innovation goes through the measurement's residual, so bearings wrap.
#[derive(Clone, Debug)]
pub struct Ekf<N: Dim, M: Dim, D, H, C = Checked>
where
    DefaultAllocator: Alloc<N, M>,
{
    dynamics: D,
    measurement: H,
    core: KalmanCore<N, M>,
    checking: PhantomData<C>,
}

macro_rules! constructors {
    ($name:ident, $dyn_bound:ident, $meas_bound:ident) => {
        impl<N: Dim, M: Dim, D: $dyn_bound<N>, H: $meas_bound<N, M>> $name<N, M, D, H>
        where
            DefaultAllocator: Alloc<N, M>,
        {
            /// A filter at step 0 with initial mean `x0` and covariance `p0`, Joseph update.
            ///
            /// # Errors
            /// [`FilterError::Initial`] if `x0` or `p0` has the wrong size, is not finite, or
            /// `p0` is not symmetric positive semi-definite;
            /// [`FilterError::DimensionMismatch`] if the measurement model is built for
            /// another state dimension than the dynamics ([`Measurement::expected_state_dim`]).
            pub fn new(
                dynamics: D,
                measurement: H,
                x0: OVector<f64, N>,
                p0: OMatrix<f64, N, N>,
            ) -> Result<Self, FilterError> {
                Self::with_options(dynamics, measurement, x0, p0, FilterOptions::default())
            }

            /// A filter with explicit [`FilterOptions`].
            ///
            /// # Errors
            /// As `new`, with the initial check the options choose;
            /// [`FilterError::Unsupported`] for [`InitialCheck::AsGiven`], which has its own
            /// constructor, `as_given`.
            pub fn with_options(
                dynamics: D,
                measurement: H,
                x0: OVector<f64, N>,
                p0: OMatrix<f64, N, N>,
                options: FilterOptions,
            ) -> Result<Self, FilterError> {
                reject_as_given(
                    &options,
                    "InitialCheck::AsGiven in with_options (the as_given constructor opts in)",
                )?;
                Self::build(dynamics, measurement, x0, p0, options)
            }
        }

        impl<N: Dim, M: Dim, D: $dyn_bound<N>, H: $meas_bound<N, M>> $name<N, M, D, H, AsGiven>
        where
            DefaultAllocator: Alloc<N, M>,
        {
            /// The explicit opt-in to a filter started from `p0` as given, asymmetric or
            /// indefinite (paper 000's printed `P0`): only sizes and finiteness are checked,
            /// and the filter runs [`InitialCheck::AsGiven`]'s algebra (nothing symmetrised,
            /// the gain by LU), which every record reports. `options.initial_check` is
            /// ignored (it is [`InitialCheck::AsGiven`]); `first_step` and `update` apply.
            ///
            /// # Errors
            /// [`FilterError::Initial`] if `x0` or `p0` has the wrong size or is not finite;
            /// [`FilterError::DimensionMismatch`] as `new`.
            pub fn as_given(
                dynamics: D,
                measurement: H,
                x0: OVector<f64, N>,
                p0: OMatrix<f64, N, N>,
                options: FilterOptions,
            ) -> Result<Self, FilterError> {
                let options = FilterOptions {
                    initial_check: InitialCheck::AsGiven,
                    ..options
                };
                Self::build(dynamics, measurement, x0, p0, options)
            }
        }

        impl<N: Dim, M: Dim, D: $dyn_bound<N>, H: $meas_bound<N, M>, C: Checking>
            $name<N, M, D, H, C>
        where
            DefaultAllocator: Alloc<N, M>,
        {
            fn build(
                dynamics: D,
                measurement: H,
                x0: OVector<f64, N>,
                p0: OMatrix<f64, N, N>,
                options: FilterOptions,
            ) -> Result<Self, FilterError> {
                let core = checked_core(&dynamics, &measurement, x0, p0, options, None)?;
                Ok(Self {
                    dynamics,
                    measurement,
                    core,
                    checking: PhantomData,
                })
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
    };
}

constructors!(Kf, LinearDynamics, LinearMeasurement);
constructors!(Ekf, Dynamics, Measurement);

impl<N: Dim, M: Dim, D, H> Kf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The filter's core, for the KF smoother's own pass (`smooth/linear.rs`).
    pub(crate) fn core(&self) -> &KalmanCore<N, M> {
        &self.core
    }

    /// The filter's core, for the KF smoother to put it where its pass ended.
    pub(crate) fn core_mut(&mut self) -> &mut KalmanCore<N, M> {
        &mut self.core
    }
}

/// Checks that the measurement model is built for the dynamics' state: a
/// `Dyn` model of another state size is a [`FilterError::DimensionMismatch`] naming both sizes
/// at construction, not a panic inside nalgebra at the first step. Models that do not say
/// their state size ([`Measurement::expected_state_dim`] is `None`) pass.
pub(crate) fn check_model_sizes<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>>(
    dynamics: &D,
    measurement: &H,
) -> Result<(), FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    match measurement.expected_state_dim() {
        Some(found) if found != dynamics.state_dim().value() => {
            Err(FilterError::DimensionMismatch {
                what: "measurement model's state (the dynamics' state dimension expected)",
                expected: dynamics.state_dim().value(),
                found,
            })
        }
        _ => Ok(()),
    }
}

/// The construction every Kalman-type filter shares, so that all check the same things in
/// the same order: [`InitialCheck::AsGiven`] refused with `refuse_as_given`'s wording (`None`
/// for the filters with an as-given form, whose public constructors decide), the models'
/// sizes ([`check_model_sizes`]), then the initial estimate's sizes, finiteness and the
/// options' initial check (the core's).
pub(crate) fn checked_core<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>>(
    dynamics: &D,
    measurement: &H,
    x0: OVector<f64, N>,
    p0: OMatrix<f64, N, N>,
    options: FilterOptions,
    refuse_as_given: Option<&'static str>,
) -> Result<KalmanCore<N, M>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    if let Some(what) = refuse_as_given {
        reject_as_given(&options, what)?;
    }
    check_model_sizes(dynamics, measurement)?;
    KalmanCore::new(
        dynamics.state_dim(),
        measurement.meas_dim(),
        x0,
        p0,
        options,
    )
}

/// The update shared by the KF and the EKF; they differ only in where `H_k` comes from.
pub(crate) fn measurement_update<'a, const AS_GIVEN: bool, N: Dim, M: Dim, H: Measurement<N, M>>(
    core: &'a mut KalmanCore<N, M>,
    measurement: &H,
    z: &OVector<f64, M>,
    h_matrix: impl FnOnce(usize, &OVector<f64, N>) -> OMatrix<f64, M, N>,
    fixed_gain: Option<&OMatrix<f64, N, M>>,
) -> Result<&'a StepRecord<N, M>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let m = measurement.meas_dim().value();
    core.check_measurement(m, z)?;
    let saved = core.begin_update();
    match update_from_prior::<AS_GIVEN, _, _, _>(core, measurement, z, h_matrix, fixed_gain) {
        Ok(()) => Ok(core.updated_record()),
        Err(e) => {
            if let Some(saved) = saved {
                core.undo_begin_update(saved);
            }
            Err(e)
        }
    }
}

/// [`measurement_update`] once the prior sits in the record's prior field
/// ([`KalmanCore::begin_update`]).
#[inline(always)]
fn update_from_prior<const AS_GIVEN: bool, N: Dim, M: Dim, H: Measurement<N, M>>(
    core: &mut KalmanCore<N, M>,
    measurement: &H,
    z: &OVector<f64, M>,
    h_matrix: impl FnOnce(usize, &OVector<f64, N>) -> OMatrix<f64, M, N>,
    fixed_gain: Option<&OMatrix<f64, N, M>>,
) -> Result<(), FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let k = core.step();
    let m = measurement.meas_dim().value();
    let x = &core.prior().mean;
    let n = x.nrows();
    let zhat = measurement.measure(k, x);
    check_model_output("predicted measurement h(x)", &zhat, (m, 1), k)?;
    let nu = measurement.residual(z, &zhat);
    check_model_output("measurement residual", &nu, (m, 1), k)?;
    let h = h_matrix(k, x);
    check_model_output("measurement matrix H", &h, (m, n), k)?;
    let r = measurement.noise_cov(k, x);
    check_model_output("measurement noise covariance R", &r, (m, m), k)?;
    core.update::<AS_GIVEN>(zhat, nu, h, r, fixed_gain)
}

/// The prediction of the filters that linearise `f` at the estimate (EKF, constant-gain KF).
pub(crate) fn jacobian_predict<const AS_GIVEN: bool, N: Dim, M: Dim, D: Dynamics<N>>(
    core: &mut KalmanCore<N, M>,
    dynamics: &D,
) -> Result<(), FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let k = core.step();
    let x = core.mean();
    let x_pred = dynamics.transition(k, x);
    let (f, q) = (dynamics.jacobian(k, x), dynamics.noise_cov(k));
    check_prediction(k, x.nrows(), &x_pred, &f, &q)?;
    core.predict::<AS_GIVEN>(x_pred, f, q)
}

/// Checks the sizes of a dynamics model's answers: `f(x)`, `F` and `Q` for a state of `n`.
fn check_prediction<N: Dim>(
    k: usize,
    n: usize,
    x_pred: &OVector<f64, N>,
    f: &OMatrix<f64, N, N>,
    q: &OMatrix<f64, N, N>,
) -> Result<(), FilterError>
where
    DefaultAllocator: Alloc<N>,
{
    check_model_output("predicted mean f(x)", x_pred, (n, 1), k)?;
    check_model_output("transition matrix F", f, (n, n), k)?;
    check_model_output("process noise covariance Q", q, (n, n), k)
}

/// The prediction of the filters with linear dynamics (KF, SRF): `F_k` is the model's matrix.
/// The phase is tested once: the usual prediction, after an update, reads the posterior at
/// its fixed place inline; a second prediction without an update goes out of line.
#[inline(always)]
pub(crate) fn linear_predict<const AS_GIVEN: bool, N: Dim, M: Dim, D: LinearDynamics<N>>(
    core: &mut KalmanCore<N, M>,
    dynamics: &D,
) -> Result<(), FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    if core.is_prior() {
        return linear_predict_again::<AS_GIVEN, _, _, _>(core, dynamics);
    }
    let k = core.step();
    let x = &core.posterior().mean;
    let x_pred = dynamics.transition(k, x);
    let (f, q) = (dynamics.matrix(k), dynamics.noise_cov(k));
    check_prediction(k, x.nrows(), &x_pred, &f, &q)?;
    core.predict_after_update::<AS_GIVEN>(x_pred, f, q)
}

/// [`linear_predict`] with a prediction since the last update, out of line.
#[cold]
#[inline(never)]
fn linear_predict_again<const AS_GIVEN: bool, N: Dim, M: Dim, D: LinearDynamics<N>>(
    core: &mut KalmanCore<N, M>,
    dynamics: &D,
) -> Result<(), FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let k = core.step();
    let x = core.mean();
    let x_pred = dynamics.transition(k, x);
    let (f, q) = (dynamics.matrix(k), dynamics.noise_cov(k));
    check_prediction(k, x.nrows(), &x_pred, &f, &q)?;
    core.predict::<AS_GIVEN>(x_pred, f, q)
}

/// The accessors both filters forward to their core.
macro_rules! core_accessors {
    () => {
        $crate::kalman::core_accessors!(M);
    };
    ($m:ty) => {
        fn step_index(&self) -> usize {
            self.core.step()
        }
        fn mean(&self) -> &OVector<f64, N> {
            self.core.mean()
        }
        fn covariance(&self) -> &OMatrix<f64, N, N> {
            self.core.cov()
        }
        fn last_record(&self) -> Option<&StepRecord<N, $m>> {
            self.core.record()
        }
    };
}
pub(crate) use core_accessors;

impl<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>, C: Checking> Filter<N, M>
    for Kf<N, M, D, H, C>
where
    DefaultAllocator: Alloc<N, M>,
{
    core_accessors!();

    fn predict(&mut self) -> Result<(), FilterError> {
        if C::AS_GIVEN {
            return linear_predict::<true, _, _, _>(&mut self.core, &self.dynamics);
        }
        linear_predict::<false, _, _, _>(&mut self.core, &self.dynamics)
    }

    fn update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
        let measurement = &self.measurement;
        let h = |k, _: &OVector<f64, N>| measurement.matrix(k);
        if C::AS_GIVEN {
            return measurement_update::<true, _, _, _>(&mut self.core, measurement, z, h, None);
        }
        measurement_update::<false, _, _, _>(&mut self.core, measurement, z, h, None)
    }
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>, C: Checking> Filter<N, M>
    for Ekf<N, M, D, H, C>
where
    DefaultAllocator: Alloc<N, M>,
{
    core_accessors!();

    fn predict(&mut self) -> Result<(), FilterError> {
        if C::AS_GIVEN {
            return jacobian_predict::<true, _, _, _>(&mut self.core, &self.dynamics);
        }
        jacobian_predict::<false, _, _, _>(&mut self.core, &self.dynamics)
    }

    fn update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
        let measurement = &self.measurement;
        let h = |k, x: &OVector<f64, N>| measurement.jacobian(k, x);
        if C::AS_GIVEN {
            return measurement_update::<true, _, _, _>(&mut self.core, measurement, z, h, None);
        }
        measurement_update::<false, _, _, _>(&mut self.core, measurement, z, h, None)
    }
}
