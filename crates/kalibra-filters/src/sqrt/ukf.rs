//! The square-root unscented Kalman filter (Van der Merwe and Wan, 2001).

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, LinalgError, OMatrix, OVector, all_finite,
    check_finite, symmetrize,
};
use std::sync::Arc;

use kalibra_models::{Dynamics, Measurement};

use crate::core::{KalmanCore, UpdateParts, check_model_output};
use crate::kalman::core_accessors;
use crate::sqrt::cholupdate::rank_one;
use crate::sqrt::kf::{SQRT_AS_GIVEN, factor_predict, initial_factor};
use crate::sqrt::noise_root::NoiseRoot;
use crate::sqrt::qr::Array;
use crate::ukf::points::{
    cross_covariance, measure, plain_mean, residual, space_deviations, transform,
};
use crate::ukf::{CandidateParts, Unscented, choose_kappa, criterion_value, unscented_builders};
use crate::{
    Filter, FilterError, FilterOptions, KappaCriterion, KappaGrid, SigmaSet, SigmaSpace,
    SigmaWeights, StepRecord, UkfPrediction,
};

/// The square-root UKF: the [`Ukf`](crate::Ukf)'s estimate, computed from a lower-triangular
/// Cholesky factor `S` of the covariance (Van der Merwe and Wan, 2001).
///
/// The sigma points are `x +- spread S_j` from the factor's columns (the [`Ukf`](crate::Ukf)'s
/// points: its Cholesky factor of `P` is this `S`). The predicted factor is the triangular
/// factor of the QR factorisation of `[sqrt(W) (X_i - x-), sqrt(Q)]^T` over the `2n` outer points,
/// then a rank-one update with the central point's deviation, a downdate when its covariance
/// weight is negative (the scaled set with small `alpha`, the symmetric set with negative
/// `kappa`). The measurement's factor `S_z` comes the same way from the sigma measurements and
/// `sqrt(R)`; the gain is `K = Pxz S_z^-T S_z^-1` by two triangular solves. The posterior factor
/// is not Van der Merwe and Wan's `S-` downdated by the `m` columns of `K S_z`, which fails where
/// the measurement is much better than the prior, but the QR factorisation of the sigma points'
/// errors `sqrt(W) (dx_i - K dz_i)` beside `K sqrt(R)` (equal for the optimal gain; see the
/// [module docs](crate::sqrt)).
///
/// The same sigma sets ([`SigmaSet`]), predictions ([`UkfPrediction`], the linearised one by the
/// square-root KF's QR step) and angle hooks ([`SqrtUkf::with_state_space`],
/// [`SqrtUkf::with_measurement_mean`]) as the [`Ukf`](crate::Ukf), and its [`StepRecord`], with
/// the covariances formed from the factors; where both work they agree (tested to 1e-10,
/// relative), and with an adaptive kappa ([`SqrtUkf::with_adaptive_kappa`]) they choose the
/// same kappa.
///
/// ```
/// use kalibra_filters::{Filter, SigmaSet, SqrtUkf, Ukf};
/// use kalibra_models::{Bearing, BearingReference, Kinematic, Stationary};
/// use kalibra_linalg::{Matrix4, U4, Vector1, Vector2, Vector4};
///
/// let cv = Kinematic::constant_velocity(2, 1.0)?.dynamics(U4)?;
/// let sensor = Bearing::new(U4, [0, 1], BearingReference::XAxis, 1e-4, Stationary(Vector2::zeros()))?;
/// let (x0, p0) = (Vector4::new(100.0, 10.0, -1.0, 0.0), Matrix4::identity() * 10.0);
/// let mut ukf = Ukf::new(&cv, &sensor, x0, p0, SigmaSet::recommended(4))?;
/// let mut sqrt = SqrtUkf::new(&cv, &sensor, x0, p0, SigmaSet::recommended(4))?;
/// ukf.predict()?;
/// sqrt.predict()?;
/// ukf.update(&Vector1::new(0.11))?;
/// sqrt.update(&Vector1::new(0.11))?;
/// assert!((ukf.mean() - sqrt.mean()).amax() < 1e-9);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct SqrtUkf<N: Dim, M: Dim, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    dynamics: D,
    measurement: H,
    core: KalmanCore<N, M>,
    /// Lower triangular, `factor factor^T` the current (prior or posterior) covariance.
    factor: OMatrix<f64, N, N>,
    sigma: Unscented<N, M>,
    q_root: NoiseRoot<N>,
    r_root: NoiseRoot<M>,
    /// The QR work array, sized at construction for the largest array, `(2n + n) x n`.
    scratch: Vec<f64>,
    adaptive: Option<(KappaCriterion, KappaGrid)>,
    last_kappa: Option<f64>,
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> SqrtUkf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// A filter at step 0 with initial mean `x0`, covariance `p0` and sigma set `set`,
    /// predicting with [`UkfPrediction::Unscented`].
    ///
    /// # Errors
    /// As [`Ukf::new`](crate::Ukf::new).
    pub fn new(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        set: SigmaSet,
    ) -> Result<Self, FilterError> {
        Self::with_options(dynamics, measurement, x0, p0, set, FilterOptions::default())
    }

    /// As [`SqrtUkf::new`] with [`FilterOptions`] (the first step and the initial check; the
    /// update form does not apply).
    ///
    /// # Errors
    /// As [`Ukf::with_options`](crate::Ukf::with_options); [`FilterError::Initial`] for a `p0`
    /// that passes [`InitialCheck::SymmetricOnly`](crate::InitialCheck::SymmetricOnly) but is
    /// indefinite (it has no factor).
    pub fn with_options(
        dynamics: D,
        measurement: H,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        set: SigmaSet,
        options: FilterOptions,
    ) -> Result<Self, FilterError> {
        let (n, m) = (dynamics.state_dim(), measurement.meas_dim());
        let (nv, mv) = (n.value(), m.value());
        let (core, sigma) =
            Unscented::start(&dynamics, &measurement, x0, p0, set, options, SQRT_AS_GIVEN)?;
        // The largest QR array: the prediction's 3n x n, the update's (2n + m) x m and
        // (2n + m) x n, or the linearised prediction's 2n x n.
        let len = (3 * nv * nv).max((2 * nv + mv) * mv.max(nv));
        let (factor, scratch) = initial_factor(&core, len)?;
        Ok(Self {
            dynamics,
            measurement,
            core,
            factor,
            sigma,
            q_root: NoiseRoot::new(n),
            r_root: NoiseRoot::new(m),
            scratch,
            adaptive: None,
            last_kappa: None,
        })
    }

    unscented_builders!();

    /// The same filter choosing kappa at every update as
    /// [`Ukf::with_adaptive_kappa`](crate::Ukf::with_adaptive_kappa) does: the square-root
    /// update at every value of `grid`, keeping the one minimising `criterion`, evaluated by
    /// the same definition as the [`Ukf`](crate::Ukf)'s (with the carried factor as the
    /// prior's Cholesky factor), so where both filters work they choose the same kappa. The
    /// prediction keeps the set's own kappa.
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

    /// The lower-triangular factor `S` of the current covariance (`P = S S^T`).
    pub fn factor(&self) -> &OMatrix<f64, N, N> {
        &self.factor
    }

    fn unscented_predict(&mut self) -> Result<(), FilterError> {
        let k = self.core.step();
        let n = self.dynamics.state_dim().value();
        let w = self.sigma.set.weights(n)?;
        let x = self.core.mean().clone();
        let points = &mut self.sigma.scratch_x;
        let x0 = transform(&self.dynamics, k, &x, &self.factor, &w, points)?;
        // The mean, then every point replaced by its deviation from it.
        let (mean, d0) = match &self.sigma.state_space {
            None => {
                let mean = plain_mean(&x0, points, &w);
                for xi in points.iter_mut() {
                    *xi -= &mean;
                }
                let d0 = &x0 - &mean;
                (mean, d0)
            }
            Some(space) => space_deviations(space.as_ref(), k, x0, points, &w)?,
        };
        let f = self.dynamics.jacobian(k, &x);
        check_model_output("transition Jacobian F", &f, (n, n), k)?;
        let q = self.dynamics.noise_cov(k);
        check_model_output("process noise covariance Q", &q, (n, n), k)?;
        let lq = self
            .q_root
            .root(&q, "process noise covariance Q")
            .map_err(|e| FilterError::at(k, e))?;
        let points = &self.sigma.scratch_x;
        let predicted = weighted_factor(&mut self.scratch, points, lq, &d0, &w).ok_or(
            FilterError::NotPositiveDefinite {
                what: "predicted covariance factor (central point's downdate)",
                step: k + 1,
            },
        )?;
        if !(all_finite(&predicted) && all_finite(&mean)) {
            return Err(FilterError::NonFinite {
                what: "predicted covariance factor",
                step: k + 1,
            });
        }
        // The record's prior and its split, as the Ukf records them.
        let mut cov = &d0 * d0.transpose() * w.cov_center;
        for d in points {
            cov += d * d.transpose() * w.other;
        }
        symmetrize(&mut cov);
        self.core.predict_unscented(mean, f, cov, q)?;
        self.factor = predicted;
        Ok(())
    }

    fn unscented_update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
        let k = self.core.step();
        let at = |e| FilterError::at(k, e);
        let m = self.measurement.meas_dim().value();
        self.core.check_measurement(m, z)?;
        let x = self.core.update_prior().mean.clone();
        let n = x.nrows();
        let l = &self.factor;
        let r = self.measurement.noise_cov(k, &x);
        check_model_output("measurement noise covariance R", &r, (m, m), k)?;
        check_finite(&r, "measurement noise covariance R").map_err(at)?;
        let lr = self
            .r_root
            .root(&r, "measurement noise covariance R")
            .map_err(at)?;
        let z0 = self.measurement.measure(k, &x);
        check_model_output("predicted measurement h(x)", &z0, (m, 1), k)?;
        let r_chol = self
            .adaptive
            .as_ref()
            .and_then(|_| Covariance::from_symmetric(r.clone(), "R").ok());
        let (measurement, set) = (&self.measurement, self.sigma.set);
        let (sigma, scratch) = (&mut self.sigma, &mut self.scratch);
        let at_weights = |w| {
            let prior = Prior { x: &x, l, z0: &z0 };
            candidate(measurement, sigma, scratch, k, prior, lr, z, w)
        };
        // The factor is the Cholesky factor of the prior covariance it stands for.
        let value = |criterion, c: &Candidate<N, M>| {
            let parts = CandidateParts {
                s: &c.s,
                nu: &c.nu,
                gain: &c.gain,
                mean: &c.mean,
            };
            criterion_value(
                criterion,
                measurement,
                k,
                z,
                parts,
                Some(l),
                r_chol.as_ref(),
            )
        };
        let (kappa, c) = choose_kappa(self.adaptive.as_ref(), set, n, k, at_weights, value)?;
        // The statistical linearisation H = Pxz^T P-^-1, through the factor; the model's
        // Jacobian where the factor is singular (as the Ukf).
        let h = l
            .solve_lower_triangular(&c.pxz)
            .and_then(|y| l.tr_solve_lower_triangular(&y))
            .map(|ht| ht.transpose())
            .unwrap_or_else(|| self.measurement.jacobian(k, &x));
        check_model_output("measurement Jacobian H", &h, (m, n), k)?;
        let cov = &c.posterior * c.posterior.transpose();
        let record = self.core.commit_update(UpdateParts {
            zhat: c.zhat,
            innovation: c.nu,
            h,
            r,
            s: c.s,
            gain: c.gain,
            mean: c.mean,
            cov,
        })?;
        self.factor = c.posterior;
        self.last_kappa = Some(kappa);
        Ok(record)
    }
}

/// The prior of an update: its mean, factor and central measurement `h(x-)`.
struct Prior<'a, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    x: &'a OVector<f64, N>,
    l: &'a OMatrix<f64, N, N>,
    z0: &'a OVector<f64, M>,
}

/// The update at one kappa, with its posterior factor.
struct Candidate<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    zhat: OVector<f64, M>,
    nu: OVector<f64, M>,
    s: Covariance<M>,
    pxz: OMatrix<f64, N, M>,
    gain: OMatrix<f64, N, M>,
    mean: OVector<f64, N>,
    posterior: OMatrix<f64, N, N>,
}

/// The square-root unscented update with weights `w`: the measurement's factor `S_z` and the
/// gain from the sigma measurements, the posterior factor from the sigma points' errors.
#[allow(clippy::too_many_arguments)]
fn candidate<N: Dim, M: Dim, H: Measurement<N, M>>(
    measurement: &H,
    sigma: &mut Unscented<N, M>,
    qr_scratch: &mut Vec<f64>,
    k: usize,
    prior: Prior<'_, N, M>,
    lr: &OMatrix<f64, M, M>,
    z: &OVector<f64, M>,
    w: SigmaWeights,
) -> Result<Candidate<N, M>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let Prior { x, l, z0 } = prior;
    let at = |e| FilterError::at(k, e);
    let (n, m) = (x.nrows(), z0.nrows());
    let mean_space = sigma.measurement_mean.as_deref();
    let scratch = &mut sigma.scratch_z;
    // The sigma measurements' deviations, then the cross covariance, in which the mean
    // cancels between each pair.
    let (mut zhat, e0) = measure(measurement, k, x, l, &w, z0, mean_space, scratch)?;
    let pxz = cross_covariance(l, scratch, z0.shape_generic().0, &w);
    if mean_space.is_none() {
        // Deviations from zhat: the residuals were taken from the central measurement.
        for d in scratch.iter_mut() {
            *d += &e0;
        }
        measurement.normalize(&mut zhat);
        check_model_output("normalized measurement", &zhat, (m, 1), k)?;
    }
    let not_pd = FilterError::NotPositiveDefinite {
        what: "innovation covariance Pz",
        step: k,
    };
    let sz = weighted_factor(qr_scratch, scratch, lr, &e0, &w).ok_or(not_pd.clone())?;
    let nu = residual(measurement, k, z, &zhat)?;
    let mut s = &sz * sz.transpose();
    symmetrize(&mut s);
    let s = Covariance::from_symmetric(s, "innovation covariance Pz").map_err(|e| {
        let e = if all_finite(&zhat) {
            e
        } else {
            LinalgError::NonFinite {
                what: "sigma-point measurements",
            }
        };
        at(e)
    })?;
    // K = Pxz S_z^-T S_z^-1, as the transpose of S_z^-T (S_z^-1 Pxz^T).
    let gain = sz
        .solve_lower_triangular(&pxz.transpose())
        .and_then(|y| sz.tr_solve_lower_triangular(&y))
        .ok_or(not_pd)?
        .transpose();
    let mut mean = x + &gain * &nu;
    if let Some(space) = &sigma.state_space {
        space.normalize(&mut mean);
        check_model_output("state space's normalized mean", &mean, (n, 1), k)?;
    }
    // S+ S+^T = sum_i W_i (dx_i - K dz_i)(dx_i - K dz_i)^T + (K sqrt(R))(K sqrt(R))^T, which
    // equals P- - K Pz K^T for the optimal gain: an orthogonal triangularisation, where
    // downdating S- by the columns of K S_z subtracts nearly equal numbers whenever the
    // measurement is much better than the prior (and fails on the test
    // `sqrt_ill_conditioned`'s first update).
    let errors = &mut sigma.scratch_x;
    for j in 0..n {
        let d = l.column(j) * w.spread;
        errors[j] = &d - &gain * &scratch[j];
        errors[n + j] = -d - &gain * &scratch[n + j];
    }
    let posterior = weighted_factor(qr_scratch, errors, &(&gain * lr), &(-(&gain * &e0)), &w)
        .ok_or(FilterError::NotPositiveDefinite {
            what: "posterior covariance factor (central point's downdate)",
            step: k,
        })?;
    Ok(Candidate {
        zhat,
        nu,
        s,
        pxz,
        gain,
        mean,
        posterior,
    })
}

/// The lower-triangular factor of `W_c0 d0 d0^T + W sum_i d_i d_i^T + L L^T` (the unscented
/// covariance of deviations `d_i` from the mean, plus a noise with root `L`, which need not be
/// square): the QR factorisation of `[sqrt(W) d_1 .. sqrt(W) d_2n, L]^T`, then a rank-one update with
/// `sqrt(|W_c0|) d0`, a downdate for a negative `W_c0`. `None` when that downdate fails.
fn weighted_factor<D: Dim, C: Dim>(
    scratch: &mut Vec<f64>,
    deviations: &[OVector<f64, D>],
    noise_root: &OMatrix<f64, D, C>,
    d0: &OVector<f64, D>,
    w: &SigmaWeights,
) -> Option<OMatrix<f64, D, D>>
where
    DefaultAllocator: Alloc<D> + nalgebra::allocator::Allocator<D, C>,
{
    let dim = noise_root.nrows();
    let count = deviations.len();
    let mut t = Array::zeroed(scratch, count + noise_root.ncols(), dim);
    let root_w = w.other.sqrt();
    for (i, d) in deviations.iter().enumerate() {
        t.put_transposed(i, 0, &(d * root_w));
    }
    t.put_transposed(count, 0, noise_root);
    t.triangularise();
    let dd = d0.shape_generic().0;
    let mut factor = t.lower_block(0, 0, (dd, dd));
    if w.cov_center != 0.0 {
        let mut x = d0 * w.cov_center.abs().sqrt();
        if !rank_one(&mut factor, &mut x, w.cov_center.signum()) {
            return None;
        }
    }
    Some(factor)
}

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Filter<N, M> for SqrtUkf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    core_accessors!();

    fn predict(&mut self) -> Result<(), FilterError> {
        match self.sigma.prediction {
            UkfPrediction::Unscented => self.unscented_predict(),
            UkfPrediction::Linearised => {
                let k = self.core.step();
                let x = self.core.mean();
                let x_pred = self.dynamics.transition(k, x);
                let (f, q) = (self.dynamics.jacobian(k, x), self.dynamics.noise_cov(k));
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
        }
    }

    fn update(&mut self, z: &OVector<f64, M>) -> Result<&StepRecord<N, M>, FilterError> {
        self.unscented_update(z)
    }
}
