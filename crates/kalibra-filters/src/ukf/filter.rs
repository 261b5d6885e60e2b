//! The scalar [`Ukf`]: its construction, options and the [`Filter`] interface; the prediction
//! is in `predict.rs`, the update in `update.rs`.

use std::sync::Arc;

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector, U1};
use kalibra_models::{Dynamics, Measurement};

use super::{KappaCriterion, KappaGrid, SigmaSet, SigmaSpace};
use crate::core::KalmanCore;
use crate::kalman::{checked_core, core_accessors, jacobian_predict};
use crate::{Filter, FilterError, FilterOptions, StepRecord};

/// How the UKF predicts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum UkfPrediction {
    /// Sigma points of the posterior through `f_k` (the general UKF).
    #[default]
    Unscented,
    /// `x- = f_k(x+)`, `P- = F P+ F^T + Q` with the Jacobian `F` (exact for linear dynamics, and
    /// what paper 001's Alg. 1 does: only the measurement statistics are unscented). Cheaper.
    Linearised,
}

/// What the scalar and the square-root UKF share beside their covariance: the sigma set, the
/// prediction, the optional non-Euclidean spaces, and scratch for the `2n` transformed points,
/// allocated once so that a step allocates nothing on the fixed-size path.
#[derive(Clone, Debug)]
pub(crate) struct Unscented<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) set: SigmaSet,
    pub(crate) prediction: UkfPrediction,
    pub(crate) scratch_x: Vec<OVector<f64, N>>,
    pub(crate) scratch_z: Vec<OVector<f64, M>>,
    // `None` keeps the plain arithmetic, bit for bit.
    pub(crate) state_space: Option<Arc<dyn SigmaSpace<N>>>,
    pub(crate) measurement_mean: Option<Arc<dyn SigmaSpace<M>>>,
}

impl<N: Dim, M: Dim> Unscented<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The construction both unscented filters share: the Kalman filters' checks
    /// ([`checked_core`], `as_given` naming the filter for an as-given `p0`), and a sigma set
    /// valid at the state's dimension, predicting with [`UkfPrediction::Unscented`].
    pub(crate) fn start<D: Dynamics<N>, H: Measurement<N, M>>(
        dynamics: &D,
        measurement: &H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        set: SigmaSet,
        options: FilterOptions,
        as_given: &'static str,
    ) -> Result<(KalmanCore<N, M>, Self), FilterError> {
        let core = checked_core(dynamics, measurement, x0, p0, options, Some(as_given))?;
        let (n, m) = (dynamics.state_dim(), measurement.meas_dim());
        set.weights(n.value())?;
        let zeros_z = OVector::<f64, M>::zeros_generic(m, U1);
        let zeros_x = OVector::<f64, N>::zeros_generic(n, U1);
        let sigma = Self {
            set,
            prediction: UkfPrediction::default(),
            scratch_x: vec![zeros_x; 2 * n.value()],
            scratch_z: vec![zeros_z; 2 * n.value()],
            state_space: None,
            measurement_mean: None,
        };
        Ok((core, sigma))
    }
}

/// The builder methods and accessors the [`Ukf`] and the [`SqrtUkf`](crate::SqrtUkf) share,
/// on their `sigma: Unscented` field.
macro_rules! unscented_builders {
    () => {
        /// The same filter with a non-Euclidean state space (FilterPy's `x_mean_fn` and
        /// `residual_x`): the unscented prediction averages its sigma points with
        /// [`SigmaSpace::mean`] and forms the covariance from [`SigmaSpace::residual`]s, and
        /// the updated mean `x- + K nu` is [`SigmaSpace::normalize`]d. With
        /// [`AngleComponents`](crate::AngleComponents) an angle in the state near `+-pi`
        /// averages to near `pi`, where the plain mean gives about 0. A prediction with a
        /// space collects its sigma points in a fresh `Vec` (one allocation per step); without
        /// one the filter keeps its allocation-free path, bit for bit.
        ///
        /// # Errors
        /// [`SigmaSpace::check`]'s error if the space does not fit the state dimension.
        pub fn with_state_space(
            mut self,
            space: impl SigmaSpace<N> + 'static,
        ) -> Result<Self, FilterError> {
            space.check(self.dynamics.state_dim().value())?;
            self.sigma.state_space = Some(Arc::new(space));
            Ok(self)
        }

        /// The same filter forming the predicted measurement `zhat` with `mean` (FilterPy's
        /// `z_mean_fn`) from the sigma points' measurements, for instance the circular mean
        /// of [`AngleComponents`](crate::AngleComponents). By default `zhat` is the central
        /// measurement plus the mean of the others' residuals from it, which handles angles
        /// through the model's residual; the option serves models whose residual does not
        /// wrap, or a circular mean by choice.
        ///
        /// # Errors
        /// [`SigmaSpace::check`]'s error if `mean` does not fit the measurement dimension.
        pub fn with_measurement_mean(
            mut self,
            mean: impl SigmaSpace<M> + 'static,
        ) -> Result<Self, FilterError> {
            mean.check(self.measurement.meas_dim().value())?;
            self.sigma.measurement_mean = Some(Arc::new(mean));
            Ok(self)
        }

        /// The same filter predicting as `prediction` says.
        #[must_use]
        pub fn with_prediction(mut self, prediction: UkfPrediction) -> Self {
            self.sigma.prediction = prediction;
            self
        }

        /// The sigma set (its kappa is the one of the prediction, and of the update when
        /// kappa is not adapted).
        pub fn sigma_set(&self) -> SigmaSet {
            self.sigma.set
        }

        /// The dynamics model.
        pub fn dynamics(&self) -> &D {
            &self.dynamics
        }

        /// The measurement model.
        pub fn measurement(&self) -> &H {
            &self.measurement
        }

        /// The prediction and the state space, for the unscented smoother
        /// (`smooth::unscented`).
        pub(crate) fn smoother_parts(&self) -> (UkfPrediction, Option<&Arc<dyn SigmaSpace<N>>>) {
            (self.sigma.prediction, self.sigma.state_space.as_ref())
        }
    };
}
pub(crate) use unscented_builders;

/// The unscented Kalman filter (Julier and Uhlmann), paper 001 eqs 16-22.
///
/// Update: the `2n + 1` sigma points of the prior through `h_k`, each measurement taken as a
/// residual from the central point's (so sigma bearings are unwrapped around the central
/// bearing and never straddle +-pi), `zhat = Z_0 + sum W_i (Z_i - Z_0)`,
/// `Pz = sum W_i (Z_i - zhat)(Z_i - zhat)^T + R`, `Pxz = sum W_i (X_i - x-)(Z_i - zhat)^T`,
/// `K = Pxz Pz^-1`, `x+ = x- + K nu`, `P+ = P- - K Pz K^T` (eq 7), symmetrised. `R` is the
/// model's `R_k` at the prior mean.
///
/// With [`Ukf::with_adaptive_kappa`] the update is computed for every kappa of a grid and
/// the one minimising a [`KappaCriterion`] is kept (UKF-ML, UKF-MPP); ties go to the smallest
/// kappa and kappas whose criterion is not finite are never chosen.
///
/// The step record is the Kalman filter's: `S = Pz`, `K`, and as `H` the statistical
/// linearisation `Pxz^T P-^-1` (equal to `H` for a linear measurement; the model's Jacobian at
/// the prior mean when `P-` is singular). On linear-Gaussian models the UKF equals the KF for
/// any valid sigma set (tested).
///
/// ```
/// use kalibra_filters::{Filter, SigmaSet, Ukf};
/// use kalibra_models::{Bearing, BearingReference, Kinematic, Stationary};
/// use kalibra_linalg::{Matrix4, U4, Vector1, Vector2, Vector4};
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?.dynamics(U4)?;
/// let sensor = Bearing::new(U4, [0, 1], BearingReference::XAxis, 1e-4, Stationary(Vector2::zeros()))?;
/// let x0 = Vector4::new(100.0, 10.0, -1.0, 0.0);
/// let mut ukf = Ukf::new(cv, sensor, x0, Matrix4::identity() * 10.0, SigmaSet::recommended(4))?;
/// ukf.predict()?;
/// let record = ukf.update(&Vector1::new(0.11))?;
/// // NIS = nu^2 / S for a scalar measurement, from the record's innovation and S.
/// let direct = record.innovation()[0].powi(2) / record.s_matrix()[(0, 0)];
/// assert!((record.nis() - direct).abs() <= 1e-12 * direct);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct Ukf<N: Dim, M: Dim, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(super) dynamics: D,
    pub(super) measurement: H,
    pub(super) core: KalmanCore<N, M>,
    pub(super) sigma: Unscented<N, M>,
    pub(super) adaptive: Option<(KappaCriterion, KappaGrid)>,
    pub(super) last_kappa: Option<f64>,
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Ukf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// A UKF at step 0 with initial mean `x0`, covariance `p0` and sigma set `set`, predicting
    /// with [`UkfPrediction::Unscented`].
    ///
    /// # Errors
    /// [`FilterError::Initial`] for a bad initial estimate (as [`crate::Kf::new`]),
    /// [`FilterError::DimensionMismatch`] for a measurement model built for another state
    /// dimension (as [`crate::Kf::new`]), [`FilterError::InvalidParameter`] for a sigma set
    /// invalid at this dimension.
    pub fn new(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        set: SigmaSet,
    ) -> Result<Self, FilterError> {
        Self::with_options(dynamics, measurement, x0, p0, set, FilterOptions::default())
    }

    /// As [`Ukf::new`] with [`FilterOptions`] (the first step and the initial check; the
    /// update form is always eq 7's `P- - K Pz K^T`, since the UKF has no `H` for a Joseph
    /// form).
    ///
    /// # Errors
    /// As [`Ukf::new`]; [`FilterError::Unsupported`] for
    /// [`InitialCheck::AsGiven`](crate::InitialCheck::AsGiven).
    pub fn with_options(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        set: SigmaSet,
        options: FilterOptions,
    ) -> Result<Self, FilterError> {
        let (core, sigma) = Unscented::start(
            &dynamics,
            &measurement,
            x0,
            p0,
            set,
            options,
            "the UKF with an as-given initial covariance (sigma points need P's square root)",
        )?;
        Ok(Self {
            dynamics,
            measurement,
            core,
            sigma,
            adaptive: None,
            last_kappa: None,
        })
    }

    unscented_builders!();

    /// The same filter choosing kappa at every update: the value of `grid` minimising
    /// `criterion` (UKF-ML, UKF-MPP of paper 001). The prediction keeps the set's own kappa.
    ///
    /// # Errors
    /// [`FilterError::InvalidParameter`] if a grid value gives an invalid sigma set.
    pub fn with_adaptive_kappa(
        mut self,
        criterion: KappaCriterion,
        grid: KappaGrid,
    ) -> Result<Self, FilterError> {
        let n = self.dynamics.state_dim().value();
        for &kappa in grid.values() {
            self.sigma.set.with_kappa(kappa).weights(n)?;
        }
        self.adaptive = Some((criterion, grid));
        Ok(self)
    }

    /// The kappa of the last update (the chosen one when adapting); `None` before the first.
    pub fn last_kappa(&self) -> Option<f64> {
        self.last_kappa
    }
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Filter<N, M> for Ukf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    core_accessors!();

    fn predict(&mut self) -> Result<(), FilterError> {
        match self.sigma.prediction {
            UkfPrediction::Unscented => self.unscented_predict(),
            UkfPrediction::Linearised => {
                jacobian_predict::<false, _, _, _>(&mut self.core, &self.dynamics)
            }
        }
    }

    fn update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
        self.unscented_update(z)
    }
}
