//! Maximum likelihood for nonlinear models through the EKF or the UKF.
//!
//! # Method
//! A [`NonlinearNoiseProblem`] holds a model implementing kalibra's model traits (`f_k` and
//! its Jacobian through [`Dynamics`], `h_k`, its Jacobian and its residual through
//! [`Measurement`]), the filter that evaluates the likelihood ([`LikelihoodFilter`]: the
//! [`Ekf`], or the [`Ukf`] with a sigma set and, for angles, a state space and a measurement
//! mean), the initial estimate and the runs of measurements, and the same [`Parametrisation`]
//! of `Q = G Qw G^T` and `R` as the linear [`NoiseProblem`](crate::NoiseProblem). At a
//! candidate `theta` the filter runs over every run with the model's own noise replaced by the
//! candidate's `Q` and `R` ([`WithProcessNoise`], [`WithMeasurementNoise`]), and the
//! log-likelihood is the sum of [`StepRecord::log_likelihood`](kalibra_filters::StepRecord::log_likelihood)
//! over its updates: `-(m ln(2 pi) + ln det S_k + nu_k^T S_k^-1 nu_k) / 2`, the natural log
//! with the `2 pi` constant, with the filter's `nu_k` (through the measurement's residual, so
//! bearings wrap) and `S_k`. For a nonlinear model this is the likelihood of the Gaussian
//! approximation the filter makes (the quasi-likelihood of the prediction-error method), not
//! the exact one; on a linear model both filters give the Kalman filter's exact value.
//!
//! [`MaximumLikelihood::estimate_nonlinear`] maximises it with the same optimiser, starts,
//! information, intervals, identifiability and warnings as [`MaximumLikelihood::estimate`]
//! (one implementation serves both). A candidate at which the filter fails (a non-finite
//! value, an innovation covariance `S` that is not positive definite) is infeasible: the line
//! search backtracks from it; only a failure at the forms' given matrices is an error
//! ([`MlError::Start`]), since every start is measured from there.
//!
//! # What is replaced, and what is not
//! The model's [`Dynamics::noise_cov`] and [`Measurement::noise_cov`] are not read: the
//! candidate's `Q` and `R` take their place at every step, so a time-varying `Q_k` or a
//! state-dependent `R(x)` of the model is replaced by the constant candidate. Everything else
//! (`f_k`, `h_k`, their Jacobians, the residual and the normalisation of angles) is the
//! model's own.
//!
//! # Threads
//! The optimiser evaluates the `2 p` candidates of a finite-difference gradient side by side
//! on rayon's pool, so the models must be `Sync`; a model that calls into an interpreter must
//! let those threads in (release its lock while estimating).

use std::marker::PhantomData;
use std::sync::Arc;

use kalibra_filters::{
    Ekf, Filter, FilterError, SigmaSet, SigmaSpace, SigmaWeights, Start, Ukf, UkfPrediction,
};
use kalibra_linalg::{
    Alloc, DMatrix, DefaultAllocator, Definiteness, Dim, Dyn, OMatrix, OVector, check_covariance,
};
use kalibra_models::{Dynamics, Measurement};

use crate::likelihood::LikelihoodError;
use crate::problem::shape;
use crate::report::{CheckError, check_runs};
use crate::{MaximumLikelihood, MlError, MlEstimate, NoiseError, NoiseMatrices, Parametrisation};

/// Which filter evaluates the likelihood of a [`NonlinearNoiseProblem`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum LikelihoodFilter {
    /// The extended Kalman filter ([`Ekf`], Joseph update): `f_k` and `h_k` at the estimate,
    /// their Jacobians for the covariances.
    Ekf,
    /// The unscented Kalman filter ([`Ukf`]) with this sigma set (for instance
    /// [`SigmaSet::recommended`]); its prediction, state space and measurement mean are set on
    /// the problem ([`NonlinearNoiseProblem::with_ukf_prediction`],
    /// [`NonlinearNoiseProblem::with_state_space`],
    /// [`NonlinearNoiseProblem::with_measurement_mean`]).
    Ukf(SigmaSet),
}

impl LikelihoodFilter {
    fn name(self) -> &'static str {
        match self {
            LikelihoodFilter::Ekf => "EKF",
            LikelihoodFilter::Ukf(_) => "UKF",
        }
    }
}

/// Why a [`NonlinearNoiseProblem`] was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum NonlinearProblemError {
    /// A size, a value or a measurement is wrong (as for a linear
    /// [`NoiseProblem`](crate::NoiseProblem)).
    #[error(transparent)]
    Noise(#[from] NoiseError),
    /// The filter refuses the problem at the forms' given matrices: an initial covariance
    /// that is not positive semi-definite, a measurement model built for another state
    /// dimension, a sigma set or a sigma space invalid at this dimension.
    #[error("the {filter} refuses the problem: {source}")]
    Filter {
        /// `"EKF"` or `"UKF"`.
        filter: &'static str,
        /// Its error.
        #[source]
        source: FilterError,
    },
}

/// A dynamics model with its process noise replaced by a given `Q`: `f_k` and `F_k` are the
/// model's, [`Dynamics::noise_cov`] is `Q` at every step. What the EKF and the UKF of a
/// [`NonlinearNoiseProblem`] run on at each candidate, and how to run a filter with the
/// estimate.
///
/// ```
/// use kalibra_linalg::{DMatrix, Matrix2, U2};
/// use kalibra_models::{Dynamics, Kinematic};
/// use kalibra_tune::WithProcessNoise;
///
/// let cv = Kinematic::constant_velocity(1, 1.0)?.dynamics(U2)?;
/// let tuned = WithProcessNoise::new(&cv, &DMatrix::identity(2, 2) * 0.5)?;
/// assert_eq!(tuned.noise_cov(3), Matrix2::identity() * 0.5);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct WithProcessNoise<D, N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    model: D,
    q: OMatrix<f64, N, N>,
}

impl<D: Dynamics<N>, N: Dim> WithProcessNoise<D, N>
where
    DefaultAllocator: Alloc<N>,
{
    /// `model` with process noise `q` (`n`x`n`, symmetric positive semi-definite).
    ///
    /// # Errors
    /// [`NoiseError::Shape`] if `q` is not the model's `n`x`n`; [`NoiseError::Matrix`] if it
    /// is not finite, symmetric and positive semi-definite.
    pub fn new(model: D, q: DMatrix<f64>) -> Result<Self, NoiseError> {
        let n = model.state_dim();
        shape("Q", q.shape(), (n.value(), n.value()))?;
        check_covariance::<Dyn>(&q, "Q", Definiteness::SemiDefinite).map_err(|source| {
            NoiseError::Matrix {
                matrix: "Q",
                source,
            }
        })?;
        Ok(Self::unchecked(model, &q))
    }

    /// Without the checks: `q` has the model's size (checked when the problem was built) and
    /// is a parametrisation's candidate (finite and positive semi-definite by construction).
    fn unchecked(model: D, q: &DMatrix<f64>) -> Self {
        let n = model.state_dim();
        let q = OMatrix::<f64, N, N>::from_fn_generic(n, n, |i, j| q[(i, j)]);
        Self { model, q }
    }

    /// The model.
    pub fn model(&self) -> &D {
        &self.model
    }
}

impl<D: Dynamics<N>, N: Dim> Dynamics<N> for WithProcessNoise<D, N>
where
    DefaultAllocator: Alloc<N>,
{
    fn state_dim(&self) -> N {
        self.model.state_dim()
    }
    fn transition(&self, k: usize, x: &OVector<f64, N>) -> OVector<f64, N> {
        self.model.transition(k, x)
    }
    fn jacobian(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, N, N> {
        self.model.jacobian(k, x)
    }
    fn noise_cov(&self, _k: usize) -> OMatrix<f64, N, N> {
        self.q.clone()
    }
}

/// A measurement model with its noise replaced by a given `R`: `h_k`, `H_k`, the residual and
/// the normalisation are the model's, [`Measurement::noise_cov`] is `R` at every step and
/// state. The measurement side of [`WithProcessNoise`].
///
/// ```
/// use kalibra_linalg::{DMatrix, Matrix1, U1, U2, Vector2};
/// use kalibra_models::{Kinematic, Measurement};
/// use kalibra_tune::WithMeasurementNoise;
///
/// let cv = Kinematic::constant_velocity(1, 1.0)?;
/// let sensor = cv.position_measurement(U2, U1, Matrix1::new(1.0))?;
/// let tuned = WithMeasurementNoise::new(&sensor, DMatrix::from_element(1, 1, 4.0))?;
/// assert_eq!(tuned.noise_cov(0, &Vector2::zeros()), Matrix1::new(4.0));
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct WithMeasurementNoise<H, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    model: H,
    r: OMatrix<f64, M, M>,
    state: PhantomData<N>,
}

impl<H: Measurement<N, M>, N: Dim, M: Dim> WithMeasurementNoise<H, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// `model` with noise `r` (`m`x`m`, symmetric positive semi-definite).
    ///
    /// # Errors
    /// [`NoiseError::Shape`] if `r` is not the model's `m`x`m`; [`NoiseError::Matrix`] if it
    /// is not finite, symmetric and positive semi-definite.
    pub fn new(model: H, r: DMatrix<f64>) -> Result<Self, NoiseError> {
        let m = model.meas_dim();
        shape("R", r.shape(), (m.value(), m.value()))?;
        check_covariance::<Dyn>(&r, "R", Definiteness::SemiDefinite).map_err(|source| {
            NoiseError::Matrix {
                matrix: "R",
                source,
            }
        })?;
        Ok(Self::unchecked(model, &r))
    }

    /// As [`WithProcessNoise::unchecked`].
    fn unchecked(model: H, r: &DMatrix<f64>) -> Self {
        let m = model.meas_dim();
        let r = OMatrix::<f64, M, M>::from_fn_generic(m, m, |i, j| r[(i, j)]);
        Self {
            model,
            r,
            state: PhantomData,
        }
    }

    /// The model.
    pub fn model(&self) -> &H {
        &self.model
    }
}

impl<H: Measurement<N, M>, N: Dim, M: Dim> Measurement<N, M> for WithMeasurementNoise<H, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn meas_dim(&self) -> M {
        self.model.meas_dim()
    }
    fn expected_state_dim(&self) -> Option<usize> {
        self.model.expected_state_dim()
    }
    fn measure(&self, k: usize, x: &OVector<f64, N>) -> OVector<f64, M> {
        self.model.measure(k, x)
    }
    fn jacobian(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, M, N> {
        self.model.jacobian(k, x)
    }
    fn noise_cov(&self, _k: usize, _x: &OVector<f64, N>) -> OMatrix<f64, M, M> {
        self.r.clone()
    }
    fn residual(&self, z: &OVector<f64, M>, zhat: &OVector<f64, M>) -> OVector<f64, M> {
        self.model.residual(z, zhat)
    }
    fn normalize(&self, z: &mut OVector<f64, M>) {
        self.model.normalize(z)
    }
}

/// A shared sigma space, handed to every candidate's UKF without copying the user's.
#[derive(Debug)]
struct Shared<D: Dim>(Arc<dyn SigmaSpace<D>>)
where
    DefaultAllocator: Alloc<D>;

impl<D: Dim> SigmaSpace<D> for Shared<D>
where
    DefaultAllocator: Alloc<D>,
{
    fn mean(&self, points: &[OVector<f64, D>], weights: &SigmaWeights) -> OVector<f64, D> {
        self.0.mean(points, weights)
    }
    fn residual(&self, a: &OVector<f64, D>, b: &OVector<f64, D>) -> OVector<f64, D> {
        self.0.residual(a, b)
    }
    fn normalize(&self, x: &mut OVector<f64, D>) {
        self.0.normalize(x)
    }
    fn check(&self, dim: usize) -> Result<(), FilterError> {
        self.0.check(dim)
    }
}

/// The UKF of one candidate, on the problem's models with the candidate's noise.
type CandidateUkf<'a, N, M, D, H> =
    Ukf<N, M, WithProcessNoise<&'a D, N>, WithMeasurementNoise<&'a H, N, M>>;

/// One run of a nonlinear problem: one entry per step, `None` where there is no measurement
/// (with `Dyn` sizes, a [`Run`](crate::Run)).
pub type NonlinearRun<M> = Vec<Option<OVector<f64, M>>>;

/// What maximum likelihood through the EKF or the UKF works on, checked at construction: the
/// model `x_{k+1} = f_k(x_k) + w_k`, `z_k = h_k(x_k) + v_k` ([`Dynamics`] and [`Measurement`],
/// whose own noise covariances are replaced by the candidate's, see the module docs) with
/// `w_k ~ N(0, G Qw G^T)`, `v_k ~ N(0, R)` and the noise [`Parametrisation`]; the filter
/// ([`LikelihoodFilter`]); the initial estimate `x0`, `P0` and where it sits ([`Start`]); and
/// one or more runs of the same system, each started from `x0`, `P0` at step 0.
///
/// ```
/// use kalibra_filters::SigmaSet;
/// use kalibra_linalg::{DMatrix, DVector, Dyn};
/// use kalibra_models::{LinearGaussian, LinearObservation};
/// use kalibra_tune::{CovarianceForm, LikelihoodFilter, NonlinearNoiseProblem, Parametrisation,
///     Start};
///
/// // A scalar random walk: any model implementing the traits will do.
/// let one = |v: f64| DMatrix::from_element(1, 1, v);
/// let walk = LinearGaussian::new(one(1.0), one(1.0))?;
/// let sensor = LinearObservation::<Dyn, Dyn>::new(one(1.0), one(1.0))?;
/// let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)),
///     CovarianceForm::scaled(one(1.0)))?;
/// let run = [0.3, 0.1, 0.8].iter().map(|&z| Some(DVector::from_element(1, z))).collect();
/// let problem = NonlinearNoiseProblem::new(walk, sensor,
///     LikelihoodFilter::Ukf(SigmaSet::recommended(1)), DVector::zeros(1), one(1.0),
///     Start::PredictFirst, noise, vec![run])?;
/// assert_eq!(problem.measurement_count(), 3);
/// let ll = problem.log_likelihood(&[0.0, 0.0])?;
/// assert!(ll.is_finite());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct NonlinearNoiseProblem<N: Dim, M: Dim, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    dynamics: D,
    measurement: H,
    filter: LikelihoodFilter,
    prediction: UkfPrediction,
    state_space: Option<Arc<dyn SigmaSpace<N>>>,
    measurement_mean: Option<Arc<dyn SigmaSpace<M>>>,
    x0: OVector<f64, N>,
    p0: OMatrix<f64, N, N>,
    start: Start,
    noise: Parametrisation,
    runs: Vec<NonlinearRun<M>>,
    measurements: usize,
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> NonlinearNoiseProblem<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Checks sizes against the parametrisation (`n` states, `m` measurements), `x0`, `P0`
    /// and every measurement, and that the filter runs its construction at the forms' given
    /// matrices. The UKF predicts with [`UkfPrediction::Unscented`] unless
    /// [`NonlinearNoiseProblem::with_ukf_prediction`] says otherwise.
    ///
    /// # Errors
    /// [`NoiseError::Shape`] (in [`NonlinearProblemError::Noise`]) if the model's state or
    /// measurement dimension is not the parametrisation's, or `x0` is not `n` or `P0` not
    /// `n`x`n`; [`NoiseError::NonFinite`] for a non-finite `x0`; [`NoiseError::Matrix`] for a
    /// `P0` that is not symmetric positive semi-definite;
    /// [`NoiseError::MeasurementLength`], [`NoiseError::NonFiniteMeasurement`] (a missing
    /// measurement is `None`, never NaN) naming the run and step;
    /// [`NoiseError::NoMeasurements`]; [`NonlinearProblemError::Filter`] if the filter
    /// refuses the problem (a measurement model built for another state dimension, a sigma
    /// set invalid at `n`).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        dynamics: D,
        measurement: H,
        filter: LikelihoodFilter,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        start: Start,
        noise: Parametrisation,
        runs: Vec<NonlinearRun<M>>,
    ) -> Result<Self, NonlinearProblemError> {
        let (n, m) = (noise.state_dim(), noise.measurement_dim());
        let model_n = dynamics.state_dim().value();
        let model_m = measurement.meas_dim().value();
        shape(
            "Q (the model's state dimension)",
            (model_n, model_n),
            (n, n),
        )?;
        shape(
            "R (the model's measurement dimension)",
            (model_m, model_m),
            (m, m),
        )?;
        shape("x0", x0.shape(), (n, 1))?;
        shape("P0", p0.shape(), (n, n))?;
        if x0.iter().any(|v| !v.is_finite()) {
            return Err(NoiseError::NonFinite { what: "x0" }.into());
        }
        check_covariance(&p0, "P0", Definiteness::SemiDefinite).map_err(|source| {
            NoiseError::Matrix {
                matrix: "P0",
                source,
            }
        })?;
        let mut measurements = 0;
        for (r, run) in runs.iter().enumerate() {
            for (k, z) in run.iter().enumerate() {
                let Some(z) = z else { continue };
                if z.len() != m {
                    return Err(NoiseError::MeasurementLength {
                        run: r,
                        step: k,
                        expected: m,
                        found: z.len(),
                    }
                    .into());
                }
                if z.iter().any(|v| !v.is_finite()) {
                    return Err(NoiseError::NonFiniteMeasurement { run: r, step: k }.into());
                }
                measurements += 1;
            }
        }
        if measurements == 0 {
            return Err(NoiseError::NoMeasurements.into());
        }
        let problem = Self {
            dynamics,
            measurement,
            filter,
            prediction: UkfPrediction::default(),
            state_space: None,
            measurement_mean: None,
            x0,
            p0,
            start,
            noise,
            runs,
            measurements,
        };
        problem.check_filter()?;
        Ok(problem)
    }

    /// Builds the filter once at the forms' given matrices, so that what it refuses (a
    /// dimension mismatch, a sigma set or space) is an error of the problem, not of every
    /// candidate.
    fn check_filter(&self) -> Result<(), NonlinearProblemError> {
        let refused = |source| NonlinearProblemError::Filter {
            filter: self.filter.name(),
            source,
        };
        let matrices = self.noise.matrices(self.noise.start().as_slice())?;
        let (f, h) = self.models(&matrices);
        match self.filter {
            LikelihoodFilter::Ekf => Ekf::new(f, h, self.x0.clone(), self.p0.clone())
                .map(drop)
                .map_err(refused),
            LikelihoodFilter::Ukf(set) => self.ukf(f, h, set).map(drop).map_err(refused),
        }
    }

    /// The UKF predicts as `prediction` says (default [`UkfPrediction::Unscented`]); the EKF
    /// does not read it.
    #[must_use]
    pub fn with_ukf_prediction(mut self, prediction: UkfPrediction) -> Self {
        self.prediction = prediction;
        self
    }

    /// The UKF averages and subtracts states in `space` (angles in the state, see
    /// [`Ukf::with_state_space`]); the EKF does not read it.
    ///
    /// # Errors
    /// [`NonlinearProblemError::Filter`] if the space does not fit the state dimension.
    pub fn with_state_space(
        mut self,
        space: impl SigmaSpace<N> + 'static,
    ) -> Result<Self, NonlinearProblemError> {
        self.state_space = Some(Arc::new(space));
        self.check_filter()?;
        Ok(self)
    }

    /// The UKF forms the predicted measurement with `mean` (a circular mean of bearings, see
    /// [`Ukf::with_measurement_mean`]); the EKF does not read it.
    ///
    /// # Errors
    /// [`NonlinearProblemError::Filter`] if `mean` does not fit the measurement dimension.
    pub fn with_measurement_mean(
        mut self,
        mean: impl SigmaSpace<M> + 'static,
    ) -> Result<Self, NonlinearProblemError> {
        self.measurement_mean = Some(Arc::new(mean));
        self.check_filter()?;
        Ok(self)
    }

    fn models(
        &self,
        matrices: &NoiseMatrices,
    ) -> (WithProcessNoise<&D, N>, WithMeasurementNoise<&H, N, M>) {
        (
            WithProcessNoise::unchecked(&self.dynamics, &matrices.q),
            WithMeasurementNoise::unchecked(&self.measurement, &matrices.r),
        )
    }

    fn ukf<'a>(
        &self,
        f: WithProcessNoise<&'a D, N>,
        h: WithMeasurementNoise<&'a H, N, M>,
        set: SigmaSet,
    ) -> Result<CandidateUkf<'a, N, M, D, H>, FilterError> {
        let mut ukf =
            Ukf::new(f, h, self.x0.clone(), self.p0.clone(), set)?.with_prediction(self.prediction);
        if let Some(space) = &self.state_space {
            ukf = ukf.with_state_space(Shared(Arc::clone(space)))?;
        }
        if let Some(mean) = &self.measurement_mean {
            ukf = ukf.with_measurement_mean(Shared(Arc::clone(mean)))?;
        }
        Ok(ukf)
    }

    /// The log-likelihood of the measurements of every run at `theta`: the sum of
    /// [`StepRecord::log_likelihood`](kalibra_filters::StepRecord::log_likelihood) over the
    /// problem's filter run with the candidate's `Q = G Qw G^T` and `R` (natural log, `2 pi`
    /// constant), each run from `x0`, `P0`. On a linear model it is
    /// [`log_likelihood`](crate::log_likelihood)'s value.
    ///
    /// # Errors
    /// [`LikelihoodError::Noise`] for an invalid `theta`; [`LikelihoodError::Filter`] (a
    /// non-finite value, an `S` that is not positive definite, naming the run and the step)
    /// and [`LikelihoodError::NonFinite`] where the filter cannot run at the candidate.
    pub fn log_likelihood(&self, theta: &[f64]) -> Result<f64, LikelihoodError> {
        let matrices = self.noise.matrices(theta)?;
        self.log_likelihood_of(&matrices)
    }

    /// [`NonlinearNoiseProblem::log_likelihood`] at given matrices (`q` and `r` are used;
    /// `qw` is not read).
    ///
    /// # Errors
    /// As [`NonlinearNoiseProblem::log_likelihood`], without the parameter-vector errors, and
    /// [`LikelihoodError::Noise`] if `q` or `r` does not have the problem's size.
    pub fn log_likelihood_of(&self, matrices: &NoiseMatrices) -> Result<f64, LikelihoodError> {
        let (n, m) = (self.state_dim(), self.measurement_dim());
        shape("Q", matrices.q.shape(), (n, n))?;
        shape("R", matrices.r.shape(), (m, m))?;
        let mut total = 0.0;
        for (run, zs) in self.runs.iter().enumerate() {
            let (f, h) = self.models(matrices);
            let at_run = |source| LikelihoodError::Filter { run, source };
            total += match self.filter {
                LikelihoodFilter::Ekf => sum_log_likelihood(
                    Ekf::new(f, h, self.x0.clone(), self.p0.clone()).map_err(at_run)?,
                    zs,
                    self.start,
                    run,
                )?,
                LikelihoodFilter::Ukf(set) => {
                    sum_log_likelihood(self.ukf(f, h, set).map_err(at_run)?, zs, self.start, run)?
                }
            };
        }
        if !total.is_finite() {
            // Every step was finite but the sum overflowed.
            return Err(LikelihoodError::NonFinite {
                run: self.runs.len().saturating_sub(1),
                update: 0,
            });
        }
        Ok(total)
    }

    /// The problem's filter with `matrices` over every run, judged by the evaluation (the
    /// report's consistency check, `report::check_runs`).
    pub(crate) fn check_filter_at(
        &self,
        matrices: &NoiseMatrices,
        truth: Option<&[crate::Run]>,
    ) -> Result<crate::FilterCheck, CheckError> {
        let (n, m) = (self.state_dim(), self.measurement_dim());
        match self.filter {
            LikelihoodFilter::Ekf => check_runs(n, m, &self.runs, self.start, truth, || {
                let (f, h) = self.models(matrices);
                Ekf::new(f, h, self.x0.clone(), self.p0.clone())
            }),
            LikelihoodFilter::Ukf(set) => check_runs(n, m, &self.runs, self.start, truth, || {
                let (f, h) = self.models(matrices);
                self.ukf(f, h, set)
            }),
        }
    }

    /// The dynamics model.
    pub fn dynamics(&self) -> &D {
        &self.dynamics
    }

    /// The measurement model.
    pub fn measurement(&self) -> &H {
        &self.measurement
    }

    /// The filter that evaluates the likelihood.
    pub fn filter(&self) -> LikelihoodFilter {
        self.filter
    }

    /// The initial estimate `x0`.
    pub fn x0(&self) -> &OVector<f64, N> {
        &self.x0
    }

    /// The initial covariance `P0`.
    pub fn p0(&self) -> &OMatrix<f64, N, N> {
        &self.p0
    }

    /// Where `x0`, `P0` sit.
    pub fn start(&self) -> Start {
        self.start
    }

    /// The noise parametrisation.
    pub fn noise(&self) -> &Parametrisation {
        &self.noise
    }

    /// The runs.
    pub fn runs(&self) -> &[NonlinearRun<M>] {
        &self.runs
    }

    /// `n`, the states.
    pub fn state_dim(&self) -> usize {
        self.noise.state_dim()
    }

    /// `m`, the measurements.
    pub fn measurement_dim(&self) -> usize {
        self.noise.measurement_dim()
    }

    /// The measurements present, over all runs.
    pub fn measurement_count(&self) -> usize {
        self.measurements
    }
}

/// The sum of the log-densities of one run's updates.
fn sum_log_likelihood<N: Dim, M: Dim, F: Filter<N, M>>(
    mut filter: F,
    zs: &[Option<OVector<f64, M>>],
    start: Start,
    run: usize,
) -> Result<f64, LikelihoodError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let mut total = 0.0;
    let mut update = 0;
    let mut bad = None;
    filter
        .run(zs.iter().map(Option::as_ref), start, |rec| {
            let l = rec.log_likelihood();
            if !l.is_finite() && bad.is_none() {
                bad = Some(update);
            }
            total += l;
            update += 1;
        })
        .map_err(|source| LikelihoodError::Filter { run, source })?;
    match bad {
        Some(update) => Err(LikelihoodError::NonFinite { run, update }),
        None => Ok(total),
    }
}

impl MaximumLikelihood {
    /// Maximises the log-likelihood of a nonlinear model through its EKF or UKF
    /// ([`NonlinearNoiseProblem::log_likelihood`]) with the optimiser, starts and reports of
    /// [`MaximumLikelihood::estimate`]: estimates, standard errors and 95% intervals on the
    /// matrices' own scale from the observed information, identifiability, whether it
    /// converged and in how many iterations.
    ///
    /// ```
    /// use kalibra_linalg::{DMatrix, DVector, Dyn};
    /// use kalibra_models::{LinearGaussian, LinearObservation};
    /// use kalibra_tune::{CovarianceForm, LikelihoodFilter, MaximumLikelihood,
    ///     NonlinearNoiseProblem, Parametrisation, Start};
    ///
    /// // A scalar random walk observed in noise, both variances unknown, through the EKF.
    /// let one = |v: f64| DMatrix::from_element(1, 1, v);
    /// let zs = [0.1, 0.5, 0.2, 1.1, 1.6, 1.2, 2.3, 2.0, 2.9, 3.4, 2.8, 3.9, 4.4, 4.1, 5.2];
    /// let run = zs.iter().map(|&z| Some(DVector::from_element(1, z))).collect();
    /// let noise = Parametrisation::new(None, CovarianceForm::scaled(one(1.0)),
    ///     CovarianceForm::scaled(one(1.0)))?;
    /// let problem = NonlinearNoiseProblem::new(LinearGaussian::new(one(1.0), one(1.0))?,
    ///     LinearObservation::<Dyn, Dyn>::new(one(1.0), one(1.0))?, LikelihoodFilter::Ekf,
    ///     DVector::zeros(1), one(1.0), Start::PredictFirst, noise, vec![run])?;
    /// let est = MaximumLikelihood::new().estimate_nonlinear(&problem)?;
    /// assert!(est.converged);
    /// assert!(est.log_likelihood >= est.start_log_likelihood);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// # Errors
    /// [`MlError::NothingToEstimate`]; [`MlError::Start`] when the filter cannot run at the
    /// forms' given matrices (the message names the run and step). A failure at any other
    /// candidate is a backtrack of the optimiser; non-convergence, a parameter at a bound,
    /// unidentifiable parameters and local maxima are [`MlWarning`](crate::MlWarning)s.
    pub fn estimate_nonlinear<N: Dim, M: Dim, D, H>(
        &self,
        problem: &NonlinearNoiseProblem<N, M, D, H>,
    ) -> Result<MlEstimate, MlError>
    where
        DefaultAllocator: Alloc<N, M>,
        D: Dynamics<N>,
        H: Measurement<N, M>,
        // The models and the matrices (Sync for every `Const` or `Dyn` size).
        NonlinearNoiseProblem<N, M, D, H>: Sync,
    {
        self.estimate_with(problem.noise(), problem.measurement_count(), &|theta| {
            problem.log_likelihood(theta)
        })
    }
}
