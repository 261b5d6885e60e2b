//! What one measurement update yields.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, OMatrix, OVector, U1, propagate, quad_form_symmetric,
    symmetrize,
};
use nalgebra::{Matrix, Storage, storage::IsContiguous};

use crate::FilterError;

/// A Gaussian estimate: mean and covariance.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The mean `x`.
    pub mean: OVector<f64, N>,
    /// The covariance `P`.
    pub cov: OMatrix<f64, N, N>,
}

/// Everything a measurement update at step `k` computed, so that metrics (NEES, NIS, J1/J2,
/// NCI, surrogate bounds) need no recomputation and no access to the filter.
///
/// Notation (papers 000 and 003): the prior covariance splits as
/// `P-_k = F P+_{k-1} F^T + Q_{k-1}`; [`StepRecord::propagated`] is the first term and
/// [`StepRecord::process_noise`] the second, so `A_k = H_k (F P+ F^T) H_k^T` and
/// `B_k = H_k Q H_k^T` ([`StepRecord::compute_a`], [`StepRecord::compute_b`]) with
/// `S_k = A_k + B_k + R_k`. When several predictions run between updates, the split follows
/// them: the propagated part is the last posterior carried through every prediction, the noise
/// part everything added since. At an update with no prediction before it (a filter that starts by updating), the
/// prior is all "propagated" and `B_k = 0`.
///
/// # Borrowed and computed
/// Accessors named after a stored quantity borrow it: [`StepRecord::prior`],
/// [`StepRecord::s`], [`StepRecord::gain`], [`StepRecord::h`], [`StepRecord::r`] and the rest.
/// Matrices the record does not store are computed on demand, returned by value, and named
/// `compute_*` so that the cost shows at the call site: [`StepRecord::compute_a`],
/// [`StepRecord::compute_b`], [`StepRecord::compute_c`]. Scalars derived from the stored
/// factors ([`StepRecord::nis`], [`StepRecord::nees`], [`StepRecord::log_likelihood`]) are
/// values too. Storing `A`, `B` and `C` instead would cost every update three projections that
/// most runs never read.
#[derive(Clone, Debug)]
pub struct StepRecord<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) k: usize,
    pub(crate) prior: Estimate<N>,
    pub(crate) posterior: Estimate<N>,
    pub(crate) predicted_measurement: OVector<f64, M>,
    pub(crate) innovation: OVector<f64, M>,
    pub(crate) s: Covariance<M>,
    pub(crate) gain: OMatrix<f64, N, M>,
    pub(crate) h: OMatrix<f64, M, N>,
    pub(crate) r: OMatrix<f64, M, M>,
    pub(crate) f: OMatrix<f64, N, N>,
    pub(crate) propagated: OMatrix<f64, N, N>,
    pub(crate) process_noise: OMatrix<f64, N, N>,
}

impl<N: Dim, M: Dim> StepRecord<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The step index `k` of the update.
    pub fn step(&self) -> usize {
        self.k
    }
    /// The prior `x-_k, P-_k`.
    pub fn prior(&self) -> &Estimate<N> {
        &self.prior
    }
    /// The posterior `x+_k, P+_k`.
    pub fn posterior(&self) -> &Estimate<N> {
        &self.posterior
    }
    /// The predicted measurement `h_k(x-_k)`.
    pub fn predicted_measurement(&self) -> &OVector<f64, M> {
        &self.predicted_measurement
    }
    /// The innovation `nu_k = z_k - h_k(x-_k)` (through the measurement's residual, so wrapped
    /// for angles).
    pub fn innovation(&self) -> &OVector<f64, M> {
        &self.innovation
    }
    /// The innovation covariance `S_k` with its Cholesky factor.
    pub fn s(&self) -> &Covariance<M> {
        &self.s
    }
    /// The gain `K_k`.
    pub fn gain(&self) -> &OMatrix<f64, N, M> {
        &self.gain
    }
    /// The measurement Jacobian `H_k` used (at the prior mean).
    pub fn h(&self) -> &OMatrix<f64, M, N> {
        &self.h
    }
    /// The measurement-noise covariance `R_k` used.
    pub fn r(&self) -> &OMatrix<f64, M, M> {
        &self.r
    }
    /// The transition Jacobian `F_{k-1}` of the last prediction into this step (at the previous
    /// posterior mean); the identity if no prediction preceded the update.
    pub fn f(&self) -> &OMatrix<f64, N, N> {
        &self.f
    }
    /// `F P+_{k-1} F^T`: the part of the prior covariance carried from the last posterior.
    pub fn propagated(&self) -> &OMatrix<f64, N, N> {
        &self.propagated
    }
    /// `Q_{k-1}`: the part of the prior covariance added as process noise since the last update.
    pub fn process_noise(&self) -> &OMatrix<f64, N, N> {
        &self.process_noise
    }
    /// `A_k = H_k F P+_{k-1} F^T H_k^T` (paper 003, eq 10), computed from the stored `H_k` and
    /// propagated part.
    ///
    /// Symmetrised: with measurement rows of very different scales (paper 003's radar: 1 to
    /// 1e-9) rounding leaves relative asymmetries near 1e-8, which the J metrics reject.
    ///
    /// ```
    /// use kalibra_filters::{Filter, Kf};
    /// use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
    /// use kalibra_models::Kinematic;
    ///
    /// let cv = Kinematic::constant_velocity(2, 1.0)?;
    /// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity())?);
    /// let mut kf = Kf::new(&f, &h, Vector4::zeros(), Matrix4::identity())?;
    /// kf.predict()?;
    /// let rec = kf.update(&Vector2::new(1.0, 0.5))?;
    /// // S = A + B + R: the prior's two parts seen through H, plus the measurement noise.
    /// let s = rec.compute_a() + rec.compute_b() + rec.r();
    /// assert!((s - rec.s().matrix()).amax() < 1e-12);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn compute_a(&self) -> OMatrix<f64, M, M> {
        projected(&self.h, &self.propagated)
    }
    /// `B_k = H_k Q_{k-1} H_k^T` (paper 003, eq 10), computed from the stored `H_k` and process
    /// noise; directly, never as `S - A - R`, which would lose all precision for a tiny `Q`.
    pub fn compute_b(&self) -> OMatrix<f64, M, M> {
        projected(&self.h, &self.process_noise)
    }
    /// `C_k = H_k P+_k H^T_k`, the posterior seen through `H_k` (for `tr(N_k)`), computed and
    /// symmetrised as [`StepRecord::compute_a`].
    pub fn compute_c(&self) -> OMatrix<f64, M, M> {
        projected(&self.h, &self.posterior.cov)
    }
    /// Renamed [`StepRecord::compute_a`] (the name now says that it computes a new matrix).
    #[deprecated(since = "0.1.0", note = "renamed to `compute_a`")]
    pub fn a(&self) -> OMatrix<f64, M, M> {
        self.compute_a()
    }
    /// Renamed [`StepRecord::compute_b`].
    #[deprecated(since = "0.1.0", note = "renamed to `compute_b`")]
    pub fn b(&self) -> OMatrix<f64, M, M> {
        self.compute_b()
    }
    /// Renamed [`StepRecord::compute_c`].
    #[deprecated(since = "0.1.0", note = "renamed to `compute_c`")]
    pub fn c(&self) -> OMatrix<f64, M, M> {
        self.compute_c()
    }
    /// The normalised estimation error squared `e^T (P+_k)^-1 e` of an error `e = x_k - x+_k`
    /// (either sign) against the posterior covariance.
    ///
    /// The same value as `kalibra_metrics::nees(e, &rec.posterior().cov)`, without its
    /// re-check that `P+_k` is finite and symmetric: the filter established both when it
    /// stored the posterior (every update symmetrises it and rejects non-finite values).
    ///
    /// # Errors
    /// [`FilterError::NonFinite`] for a non-finite `e`, [`FilterError::DimensionMismatch`]
    /// for a wrong length (`Dyn`), [`FilterError::NotPositiveDefinite`] if `P+_k` is singular
    /// (possible from a semi-definite `P0` whose null space the process noise has not yet
    /// filled).
    pub fn nees<S>(&self, error: &Matrix<f64, N, U1, S>) -> Result<f64, FilterError>
    where
        S: Storage<f64, N, U1> + IsContiguous,
    {
        quad_form_symmetric(&self.posterior.cov, error, "posterior covariance P+")
            .map_err(|e| FilterError::at(self.k, e))
    }

    /// The normalised innovation squared `nu^T S^-1 nu`, from the stored factor of `S`.
    pub fn nis(&self) -> f64 {
        self.s
            .quad_form(&self.innovation)
            .expect("innovation and S share the dimension M")
    }

    /// The Gaussian log-likelihood of the update's measurement under the filter's prediction,
    /// `ln N(nu; 0, S) = -1/2 (m ln 2 pi + ln det S + nu^T S^-1 nu)`, with `ln det S` and the
    /// quadratic form from the stored Cholesky factor of `S` (no refactorisation, no inverse).
    ///
    /// Summed over the updates of a run it is the prediction-error decomposition of the
    /// measurements' log-likelihood, the objective of maximum-likelihood tuning (and the
    /// UKF-ML criterion of paper 001, eq 23, up to sign, scale and the constant).
    ///
    /// ```
    /// use kalibra_filters::{Filter, Kf};
    /// use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
    /// use kalibra_models::Kinematic;
    ///
    /// let cv = Kinematic::constant_velocity(2, 1.0)?;
    /// let (f, h) = (cv.dynamics(U4)?, cv.position_measurement(U4, U2, Matrix2::identity())?);
    /// let mut kf = Kf::new(&f, &h, Vector4::zeros(), Matrix4::identity())?;
    /// let rec = kf.update(&Vector2::zeros())?;
    /// // nu = 0 and S = 2 I: ln N(0; 0, 2 I) = -ln(2 pi) - ln 2.
    /// let expected = -(2.0 * std::f64::consts::PI).ln() - 2f64.ln();
    /// assert!((rec.log_likelihood() - expected).abs() < 1e-14);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn log_likelihood(&self) -> f64 {
        let m = self.innovation.nrows() as f64;
        -0.5 * (m * std::f64::consts::TAU.ln() + self.s.log_det() + self.nis())
    }
}

/// `H X H^T`, symmetrised.
fn projected<N: Dim, M: Dim>(h: &OMatrix<f64, M, N>, x: &OMatrix<f64, N, N>) -> OMatrix<f64, M, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    let mut out = propagate(h, x);
    symmetrize(&mut out);
    out
}
