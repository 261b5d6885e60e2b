//! What one measurement update yields.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, OMatrix, OVector, U1, check_dim, check_finite,
    propagate, quad_form_symmetric, symmetrize,
};
use nalgebra::{Matrix, Storage, storage::IsContiguous};

use crate::as_given::{lu_ln_det, lu_solve};
use crate::{FilterError, InitialCheck};

/// A filter's Gaussian estimate: mean and covariance (the library's one mean-and-covariance
/// type, [`kalibra_linalg::Gaussian`]).
pub type Estimate<N> = kalibra_linalg::Gaussian<N>;

/// Everything a measurement update at step `k` computed, so that metrics (NEES, NIS, J1/J2,
/// NCI, surrogate bounds) need no recomputation and no access to the filter.
///
/// Notation (papers 000 and 003): the prior covariance splits as
/// `P-_k = F P+_{k-1} F^T + Q_{k-1}`; [`StepRecord::propagated`] is the first term and
/// [`StepRecord::process_noise`] the second, so `A_k = H_k (F P+ F^T) H_k^T` and
/// `B_k = H_k Q H_k^T` ([`StepRecord::compute_a`], [`StepRecord::compute_b`]) with
/// `S_k = A_k + B_k + R_k`. When several predictions run between updates, the split follows
/// them: the propagated part is the last posterior carried through every prediction, the noise
/// part everything added since. At an update with no prediction before it (a filter that
/// starts by updating), the prior is all "propagated" and `B_k = 0`.
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
    /// What was not checked, for a filter started with less than the default check; `None`
    /// (the default check) for the others, whose hot path never touches it. Boxed: a plain
    /// one-byte field for the check, or an inline `S`, changes the record's layout and
    /// lengthens the checked filters' step (`cargo xtask bench w1`); a pointer costs nothing.
    pub(crate) unchecked: Option<Box<Unchecked<M>>>,
}

/// The part of a record that only a filter started with less than the default check has.
#[derive(Clone, Debug)]
pub(crate) struct Unchecked<M: Dim>
where
    DefaultAllocator: Alloc<M>,
{
    /// The check the filter applied to its initial covariance.
    pub(crate) initial_check: InitialCheck,
    /// `S` as computed by a filter started with [`InitialCheck::AsGiven`], once it has updated
    /// (then the record's `s` is unused).
    pub(crate) s: Option<OMatrix<f64, M, M>>,
}

impl<M: Dim> Unchecked<M>
where
    DefaultAllocator: Alloc<M>,
{
    /// The record's part for a filter started with `check`: `None` for the default check.
    pub(crate) fn new(check: InitialCheck) -> Option<Box<Self>> {
        (check != InitialCheck::default()).then(|| {
            Box::new(Self {
                initial_check: check,
                s: None,
            })
        })
    }
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
    /// The innovation covariance `S_k` with its Cholesky factor; `None` in the records of a
    /// filter started with [`InitialCheck::AsGiven`], whose `S` need not be symmetric positive
    /// definite ([`StepRecord::s_matrix`] has it).
    pub fn s(&self) -> Option<&Covariance<M>> {
        match self.s_as_given() {
            None => Some(&self.s),
            Some(_) => None,
        }
    }
    /// The innovation covariance `S_k` as the update used it: the matrix of
    /// [`StepRecord::s`], or for [`InitialCheck::AsGiven`] the unsymmetrised `H P- H^T + R`.
    pub fn s_matrix(&self) -> &OMatrix<f64, M, M> {
        match self.s_as_given() {
            None => self.s.matrix(),
            Some(s) => s,
        }
    }
    /// How the filter checked its initial covariance, which says what this record's
    /// covariances were not checked for: [`InitialCheck::PositiveSemiDefinite`] (everything
    /// checked), [`InitialCheck::SymmetricOnly`] (the covariances may be indefinite), or
    /// [`InitialCheck::AsGiven`] (asymmetric and indefinite covariances carried as computed,
    /// `S` unfactored).
    pub fn initial_check(&self) -> InitialCheck {
        self.unchecked
            .as_ref()
            .map_or(InitialCheck::default(), |u| u.initial_check)
    }

    /// The unfactored `S` of an as-given record.
    fn s_as_given(&self) -> Option<&OMatrix<f64, M, M>> {
        self.unchecked.as_ref().and_then(|u| u.s.as_ref())
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
    /// assert!((s - rec.s_matrix()).amax() < 1e-12);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    ///
    /// In the records of a filter started with [`InitialCheck::AsGiven`], `A`, `B` and `C` are
    /// the products as computed, `(H X) H^T`, not symmetrised (the covariances are not
    /// symmetric there, and a study of that arithmetic needs it unaltered).
    pub fn compute_a(&self) -> OMatrix<f64, M, M> {
        self.projected(&self.propagated)
    }
    /// `B_k = H_k Q_{k-1} H_k^T` (paper 003, eq 10), computed from the stored `H_k` and process
    /// noise; directly, never as `S - A - R`, which would lose all precision for a tiny `Q`.
    pub fn compute_b(&self) -> OMatrix<f64, M, M> {
        self.projected(&self.process_noise)
    }
    /// `C_k = H_k P+_k H^T_k`, the posterior seen through `H_k` (for `tr(N_k)`), computed and
    /// symmetrised as [`StepRecord::compute_a`].
    pub fn compute_c(&self) -> OMatrix<f64, M, M> {
        self.projected(&self.posterior.cov)
    }
    /// The normalised estimation error squared `e^T (P+_k)^-1 e` of an error `e = x_k - x+_k`
    /// (either sign) against the posterior covariance.
    ///
    /// The same value as `kalibra_metrics::nees(e, &rec.posterior().cov)`, without its
    /// re-check that `P+_k` is finite and symmetric: the filter established both when it
    /// stored the posterior (every update symmetrises it and rejects non-finite values).
    ///
    /// In the records of a filter started with [`InitialCheck::AsGiven`] it is
    /// `e^T (P+_k)^-1 e` with the posterior as computed, by LU; it can then be negative.
    ///
    /// # Errors
    /// [`FilterError::NonFinite`] for a non-finite `e`, [`FilterError::DimensionMismatch`]
    /// for a wrong length (`Dyn`), [`FilterError::NotPositiveDefinite`] if `P+_k` is singular
    /// (possible from a semi-definite `P0` whose null space the process noise has not yet
    /// filled), [`FilterError::Singular`] for a singular `P+_k` of an as-given record.
    pub fn nees<S>(&self, error: &Matrix<f64, N, U1, S>) -> Result<f64, FilterError>
    where
        S: Storage<f64, N, U1> + IsContiguous,
    {
        if self.s_as_given().is_some() {
            return self.nees_as_given(error);
        }
        quad_form_symmetric(&self.posterior.cov, error, "posterior covariance P+")
            .map_err(|e| FilterError::at(self.k, e))
    }

    #[cold]
    #[inline(never)]
    fn nees_as_given<S>(&self, error: &Matrix<f64, N, U1, S>) -> Result<f64, FilterError>
    where
        S: Storage<f64, N, U1> + IsContiguous,
    {
        let at = |e| FilterError::at(self.k, e);
        check_dim(self.posterior.mean.nrows(), error.nrows(), "vector").map_err(at)?;
        check_finite(error, "vector").map_err(at)?;
        let e = error.clone_owned();
        let solved = lu_solve(&self.posterior.cov, &e).ok_or(FilterError::Singular {
            what: "posterior covariance P+",
            step: self.k,
        })?;
        Ok(e.dot(&solved))
    }

    /// The normalised innovation squared `nu^T S^-1 nu`, from the stored factor of `S`.
    ///
    /// In the records of a filter started with [`InitialCheck::AsGiven`] it is computed by LU
    /// with the `S` the update used; it can then be negative, and is NaN if `S` is singular.
    /// Otherwise it is finite, or `+inf` when the finite innovation's form lies beyond f64's
    /// range.
    pub fn nis(&self) -> f64 {
        match self.s_as_given() {
            // The record is built by the filter's update, which sizes the innovation and S from
            // the same measurement dimension and checks the innovation finite, so the one
            // error left is a form beyond f64's range.
            None => self.s.quad_form(&self.innovation).unwrap_or(f64::INFINITY),
            Some(s) => nis_as_given(s, &self.innovation),
        }
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
    ///
    /// In the records of a filter started with [`InitialCheck::AsGiven`], `ln det S` comes
    /// from an LU factorisation of the `S` the update used; the result is NaN unless that
    /// determinant is positive (no Gaussian density has such an `S`).
    pub fn log_likelihood(&self) -> f64 {
        let m = self.innovation.nrows() as f64;
        let log_det = match self.s_as_given() {
            None => self.s.log_det(),
            Some(s) => lu_ln_det(s),
        };
        -0.5 * (m * std::f64::consts::TAU.ln() + log_det + self.nis())
    }

    /// `H X H^T`, symmetrised unless the record is as given.
    fn projected(&self, x: &OMatrix<f64, N, N>) -> OMatrix<f64, M, M> {
        let mut out = propagate(&self.h, x);
        if self.s_as_given().is_none() {
            symmetrize(&mut out);
        }
        out
    }
}

/// `nu^T S^-1 nu` by LU, NaN for a singular `S`.
#[cold]
#[inline(never)]
fn nis_as_given<M: Dim>(s: &OMatrix<f64, M, M>, nu: &OVector<f64, M>) -> f64
where
    DefaultAllocator: Alloc<M>,
{
    lu_solve(s, nu).map_or(f64::NAN, |x| nu.dot(&x))
}
