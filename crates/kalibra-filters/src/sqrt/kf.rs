//! The square-root Kalman filter: the [`Kf`](crate::Kf) propagating a Cholesky factor.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, LinalgError, OMatrix, OVector, all_finite,
    check_finite, symmetrize,
};
use kalibra_models::{LinearDynamics, LinearMeasurement};

use crate::core::{KalmanCore, UpdateParts, check_model_output};
use crate::kalman::{checked_core, core_accessors};
use crate::smooth::Smoothed;
use crate::sqrt::noise_root::NoiseRoot;
use crate::sqrt::qr::{Array, lower_root, lower_root_of_sum};
use crate::sqrt::smooth::{FactorLink, FactorStep, smooth_factors};
use crate::{Estimate, Filter, FilterError, FilterOptions, Start, StepRecord, UpdateForm};

/// The square-root Kalman filter on linear models: the [`Kf`](crate::Kf)'s estimate, computed
/// from a lower-triangular Cholesky factor `S` of the covariance (`P = S S^T`) that only
/// orthogonal transformations touch, so the covariance it stands for stays symmetric positive
/// semi-definite in any arithmetic (see the [module docs](crate::sqrt) for the two steps).
///
/// The filter behind the [`Filter`] trait is the [`Kf`](crate::Kf)'s: the same [`StepRecord`],
/// with `P+ = S+ S+^T`, `S = S_z S_z^T`, the gain `K = Kbar S_z^-1` and the prior split as the
/// KF records it (`F P+ F^T` and `Q`), so every metric works unchanged;
/// [`Filter::covariance`] is the matrix of the record. The factor itself is
/// [`SqrtKf::factor`]. Where both filters work they agree (a property test over random stable
/// models checks 1e-10, relative); where the covariance loses its definiteness in the
/// [`Kf`](crate::Kf) (a near-perfect measurement against a large prior), this one carries on
/// (the test `tests/sqrt_ill_conditioned.rs`).
///
/// ```
/// use kalibra_filters::{Filter, Kf, SqrtKf};
/// use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
/// use kalibra_models::Kinematic;
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?;
/// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity())?);
/// let p0 = Matrix4::identity() * 100.0;
/// let mut kf = Kf::new(&f, &h, Vector4::zeros(), p0)?;
/// let mut sqrt = SqrtKf::new(&f, &h, Vector4::zeros(), p0)?;
/// for z in [Vector2::new(1.0, 2.0), Vector2::new(2.5, 3.0)] {
///     kf.predict()?;
///     sqrt.predict()?;
///     kf.update(&z)?;
///     sqrt.update(&z)?;
/// }
/// assert!((kf.mean() - sqrt.mean()).amax() < 1e-12);
/// // The factor is lower triangular and stands for the covariance.
/// let s = sqrt.factor();
/// assert_eq!(s[(0, 1)], 0.0);
/// assert!((s * s.transpose() - sqrt.covariance()).amax() < 1e-12);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct SqrtKf<N: Dim, M: Dim, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    dynamics: D,
    measurement: H,
    core: KalmanCore<N, M>,
    /// Lower triangular, `factor factor^T` the current (prior or posterior) covariance.
    factor: OMatrix<f64, N, N>,
    q_root: NoiseRoot<N>,
    r_root: NoiseRoot<M>,
    /// The QR work array, sized at construction for the update's `(m + n)^2`.
    scratch: Vec<f64>,
}

impl<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>> SqrtKf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// A filter at step 0 with initial mean `x0` and covariance `p0` (the factor is `p0`'s
    /// Cholesky factor, or for a singular `p0` its pivoted semi-definite factor made
    /// triangular).
    ///
    /// # Errors
    /// As [`Kf::new`](crate::Kf::new).
    pub fn new(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
    ) -> Result<Self, FilterError> {
        Self::with_options(dynamics, measurement, x0, p0, FilterOptions::default())
    }

    /// A filter with explicit [`FilterOptions`] (the first step and the initial check).
    ///
    /// # Errors
    /// As [`Kf::with_options`](crate::Kf::with_options); [`FilterError::Unsupported`] for
    /// [`InitialCheck::AsGiven`](crate::InitialCheck::AsGiven) (a factor needs a semi-definite
    /// `p0`) and for [`UpdateForm::Standard`] (the update is the array form, not a choice of
    /// covariance formula). [`FilterError::Initial`] for a `p0` that passes
    /// [`InitialCheck::SymmetricOnly`](crate::InitialCheck::SymmetricOnly) but is indefinite
    /// (it has no factor).
    pub fn with_options(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        options: FilterOptions,
    ) -> Result<Self, FilterError> {
        if options.update != UpdateForm::Joseph {
            return Err(FilterError::Unsupported {
                what: "UpdateForm::Standard in the square-root KF (its update is the array form)",
            });
        }
        let (n, m) = (dynamics.state_dim(), measurement.meas_dim());
        let (nv, mv) = (n.value(), m.value());
        let core = checked_core(
            &dynamics,
            &measurement,
            x0,
            p0,
            options,
            Some(SQRT_AS_GIVEN),
        )?;
        let (factor, scratch) = initial_factor(&core, (nv + mv).pow(2).max(2 * nv * nv))?;
        Ok(Self {
            dynamics,
            measurement,
            core,
            factor,
            q_root: NoiseRoot::new(n),
            r_root: NoiseRoot::new(m),
            scratch,
        })
    }

    /// The lower-triangular factor `S` of the current covariance (`P = S S^T`), the
    /// posterior's after an update, the prior's after a prediction.
    pub fn factor(&self) -> &OMatrix<f64, N, N> {
        &self.factor
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

impl<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>> SqrtKf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The square-root Rauch-Tung-Striebel smoother ([`Smoothable::smooth`] for this filter):
    /// the forward pass as [`Smoothable::forward`] steps it, keeping every step's factor, the
    /// predictions' `F_k` and noise roots, then the backward pass on factors
    /// (`sqrt/smooth.rs`).
    ///
    /// [`Smoothable::smooth`]: crate::smooth::Smoothable::smooth
    /// [`Smoothable::forward`]: crate::smooth::Smoothable::forward
    pub(crate) fn smooth_factors<'z, I>(
        &mut self,
        measurements: I,
        start: Start,
    ) -> Result<Smoothed<N>, FilterError>
    where
        I: IntoIterator<Item = Option<&'z OVector<f64, M>>>,
        OVector<f64, M>: 'z,
    {
        let measurements = measurements.into_iter();
        let capacity = 1 + measurements.size_hint().0;
        let (mut steps, mut links) = (Vec::with_capacity(capacity), Vec::with_capacity(capacity));
        let here = |kf: &Self, updated| FactorStep {
            step: kf.core.step(),
            updated,
            estimate: Estimate {
                mean: kf.core.mean().clone(),
                cov: kf.core.cov().clone(),
            },
            factor: kf.factor.clone(),
        };
        if start == Start::PredictFirst {
            steps.push(here(self, false));
        }
        let mut started = false;
        for z in measurements {
            if started || start == Start::PredictFirst {
                let k = self.core.step();
                self.predict()?;
                links.push(FactorLink {
                    f: self.dynamics.matrix(k),
                    q_root: self.q_root.last().clone(),
                    prior_mean: self.core.mean().clone(),
                });
            }
            started = true;
            if let Some(z) = z {
                self.update(z)?;
            }
            steps.push(here(self, z.is_some()));
        }
        if steps.is_empty() {
            steps.push(here(self, false));
        }
        smooth_factors(&steps, &links, &mut self.scratch)
    }
}

/// What a square-root filter refuses for an as-given initial covariance.
pub(crate) const SQRT_AS_GIVEN: &str =
    "a square-root filter with an as-given initial covariance (it needs a factor)";

/// A square-root filter's factor and QR work array.
pub(crate) type FactorAndScratch<N> = (OMatrix<f64, N, N>, Vec<f64>);

/// A square-root filter's initial factor, from its checked core (Cholesky's, or for a
/// singular covariance the pivoted semi-definite factor made triangular), and a QR work array
/// of `scratch_len` entries.
pub(crate) fn initial_factor<N: Dim, M: Dim>(
    core: &KalmanCore<N, M>,
    scratch_len: usize,
) -> Result<FactorAndScratch<N>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let (root, _) = kalibra_linalg::semidefinite_factor(core.cov(), "initial covariance")
        .map_err(FilterError::Initial)?;
    let mut scratch = vec![0.0; scratch_len];
    let factor = lower_root(&mut scratch, &root);
    Ok((factor, scratch))
}

/// The square-root prediction `S- = tria([F S, sqrt(Q)])` for the mean `x_pred` already
/// computed, stored with the KF's record of the prior (`F P+ F^T + Q`) when it succeeds.
/// Shared by the square-root KF and the square-root UKF's linearised prediction.
#[allow(clippy::too_many_arguments)]
pub(crate) fn factor_predict<N: Dim, M: Dim>(
    core: &mut KalmanCore<N, M>,
    factor: &mut OMatrix<f64, N, N>,
    q_root: &mut NoiseRoot<N>,
    scratch: &mut Vec<f64>,
    x_pred: OVector<f64, N>,
    f: OMatrix<f64, N, N>,
    q: OMatrix<f64, N, N>,
) -> Result<(), FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let k = core.step();
    let n = factor.nrows();
    check_model_output("predicted mean f(x)", &x_pred, (n, 1), k)?;
    check_model_output("transition matrix F", &f, (n, n), k)?;
    check_model_output("process noise covariance Q", &q, (n, n), k)?;
    let lq = q_root
        .root(&q, "process noise covariance Q")
        .map_err(|e| FilterError::at(k, e))?;
    let predicted = lower_root_of_sum(scratch, &(&f * &*factor), lq);
    if !all_finite(&predicted) {
        check_finite(&f, "transition matrix F").map_err(|e| FilterError::at(k, e))?;
        return Err(FilterError::NonFinite {
            what: "predicted covariance factor",
            step: k + 1,
        });
    }
    core.predict::<false>(x_pred, f, q)?;
    *factor = predicted;
    Ok(())
}

/// The measurement update in array form: the QR factorisation of
/// `[[sqrt(R), H S-], [0, S-]]^T` gives `[[S_z, 0], [Kbar, S+]]`, with `S_z S_z^T = S`,
/// `K = Kbar S_z^-1` and `S+ S+^T = P+`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn array_update<'a, N: Dim, M: Dim, H: LinearMeasurement<N, M>>(
    core: &'a mut KalmanCore<N, M>,
    factor: &mut OMatrix<f64, N, N>,
    r_root: &mut NoiseRoot<M>,
    scratch: &mut Vec<f64>,
    measurement: &H,
    z: &OVector<f64, M>,
) -> Result<&'a StepRecord<N, M>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let k = core.step();
    let at = |e| FilterError::at(k, e);
    let m = measurement.meas_dim().value();
    core.check_measurement(m, z)?;
    let x = core.update_prior().mean.clone();
    let n = x.nrows();
    let zhat = measurement.measure(k, &x);
    check_model_output("predicted measurement h(x)", &zhat, (m, 1), k)?;
    let nu = measurement.residual(z, &zhat);
    check_model_output("measurement residual", &nu, (m, 1), k)?;
    let h = measurement.matrix(k);
    check_model_output("measurement matrix H", &h, (m, n), k)?;
    let r = measurement.noise_cov(k, &x);
    check_model_output("measurement noise covariance R", &r, (m, m), k)?;
    let lr = r_root
        .root(&r, "measurement noise covariance R")
        .map_err(at)?;
    let mut t = Array::zeroed(scratch, m + n, m + n);
    t.put_transposed(0, 0, lr);
    t.put_transposed(m, 0, &(&h * &*factor));
    t.put_transposed(m, m, &*factor);
    t.triangularise();
    let (nd, md) = (x.shape_generic().0, zhat.shape_generic().0);
    let sz: OMatrix<f64, M, M> = t.lower_block(0, 0, (md, md));
    let kbar: OMatrix<f64, N, M> = t.lower_block(m, 0, (nd, md));
    let posterior: OMatrix<f64, N, N> = t.lower_block(m, m, (nd, nd));
    let not_pd = || FilterError::NotPositiveDefinite {
        what: "innovation covariance S",
        step: k,
    };
    // K = Kbar S_z^-1, as the transpose of S_z^-T Kbar^T.
    let gain = sz
        .tr_solve_lower_triangular(&kbar.transpose())
        .ok_or_else(not_pd)?
        .transpose();
    let mut s = &sz * sz.transpose();
    symmetrize(&mut s);
    let s = Covariance::from_symmetric(s, "innovation covariance S").map_err(|e| {
        // NaN in H or R makes the factorisation fail too: name the real culprit.
        let culprit = check_finite(&h, "measurement matrix H")
            .and_then(|()| check_finite(&r, "measurement noise covariance R"));
        at(culprit.err().unwrap_or(e))
    })?;
    if !all_finite(&posterior) {
        return Err(at(LinalgError::NonFinite {
            what: "posterior covariance factor",
        }));
    }
    let mean = &x + &gain * &nu;
    let cov = &posterior * posterior.transpose();
    let record = core.commit_update(UpdateParts {
        zhat,
        innovation: nu,
        h,
        r,
        s,
        gain,
        mean,
        cov,
    })?;
    *factor = posterior;
    Ok(record)
}

impl<N: Dim, M: Dim, D: LinearDynamics<N>, H: LinearMeasurement<N, M>> Filter<N, M>
    for SqrtKf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    core_accessors!();

    fn predict(&mut self) -> Result<(), FilterError> {
        let k = self.core.step();
        let x_pred = self.dynamics.transition(k, self.core.mean());
        let (f, q) = (self.dynamics.matrix(k), self.dynamics.noise_cov(k));
        factor_predict(
            &mut self.core,
            &mut self.factor,
            &mut self.q_root,
            &mut self.scratch,
            x_pred,
            f,
            q,
        )
    }

    fn update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
        array_update(
            &mut self.core,
            &mut self.factor,
            &mut self.r_root,
            &mut self.scratch,
            &self.measurement,
            z,
        )
    }
}
