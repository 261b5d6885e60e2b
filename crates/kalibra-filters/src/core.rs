//! The numerical core shared by the Kalman-type filters: predict and update as algebra on
//! `F, Q, H, R` and the residual, separate from model evaluation (so that a batched kernel can
//! later reuse the same model calls and the same step record).

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, LinalgError, OMatrix, OVector, check_dim, check_finite,
    joseph_update, propagate, standard_update, symmetrize,
};

use crate::{Estimate, FilterError, StepRecord};

/// Which covariance update a filter applies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum UpdateForm {
    /// `(I - K H) P (I - K H)^T + K R K^T`: symmetric positive semi-definite for any gain.
    #[default]
    Joseph,
    /// `(I - K H) P`: cheaper, correct only at the optimal gain, as printed in some papers.
    Standard,
}

/// How strictly the initial covariance is checked.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub enum InitialCheck {
    /// Finite, symmetric and positive semi-definite.
    #[default]
    PositiveSemiDefinite,
    /// Finite and symmetric only: for reproducing a paper that starts from a printed,
    /// indefinite `P0` (paper 000). Metrics on such runs must report the indefiniteness.
    SymmetricOnly,
}

/// Options shared by the Kalman-type filters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FilterOptions {
    /// Step index of the initial estimate.
    pub first_step: usize,
    /// Covariance update form.
    pub update: UpdateForm,
    /// Check applied to the initial covariance.
    pub initial_check: InitialCheck,
}

/// Mean, covariance and the prior split of a Kalman-type filter, with the last step record.
#[derive(Clone, Debug)]
pub(crate) struct KalmanCore<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    x: OVector<f64, N>,
    p: OMatrix<f64, N, N>,
    k: usize,
    update: UpdateForm,
    /// Whether a prediction ran since the last update (or the start).
    predicted: bool,
    f: OMatrix<f64, N, N>,
    propagated: OMatrix<f64, N, N>,
    process_noise: OMatrix<f64, N, N>,
    record: Option<StepRecord<N, M>>,
}

impl<N: Dim, M: Dim> KalmanCore<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) fn new(n: N, x0: OVector<f64, N>, mut p0: OMatrix<f64, N, N>, options: FilterOptions) -> Result<Self, FilterError> {
        let init = |e: LinalgError| FilterError::Initial(e);
        check_dim(n.value(), x0.nrows(), "initial mean").map_err(init)?;
        check_dim(n.value(), p0.nrows(), "initial covariance").map_err(init)?;
        check_dim(n.value(), p0.ncols(), "initial covariance").map_err(init)?;
        check_finite(&x0, "initial mean").map_err(init)?;
        // `PsdMatrix` checks finiteness and symmetry; for the symmetric-only reading only those.
        match options.initial_check {
            InitialCheck::PositiveSemiDefinite => {
                p0 = kalibra_linalg::PsdMatrix::named(p0, "initial covariance").map_err(init)?.matrix().clone();
            }
            InitialCheck::SymmetricOnly => {
                check_finite(&p0, "initial covariance").map_err(init)?;
                let asym = (&p0 - p0.transpose()).amax();
                let scale = p0.diagonal().amax().max(f64::MIN_POSITIVE);
                if asym > kalibra_linalg::SYMMETRY_TOLERANCE * scale {
                    return Err(init(LinalgError::NotSymmetric { what: "initial covariance", asymmetry: asym / scale }));
                }
                symmetrize(&mut p0);
            }
        }
        let identity = OMatrix::<f64, N, N>::identity_generic(n, n);
        let zeros = OMatrix::<f64, N, N>::zeros_generic(n, n);
        Ok(Self {
            x: x0,
            propagated: p0.clone(),
            p: p0,
            k: options.first_step,
            update: options.update,
            predicted: false,
            f: identity,
            process_noise: zeros,
            record: None,
        })
    }

    pub(crate) fn mean(&self) -> &OVector<f64, N> {
        &self.x
    }
    pub(crate) fn cov(&self) -> &OMatrix<f64, N, N> {
        &self.p
    }
    pub(crate) fn step(&self) -> usize {
        self.k
    }
    pub(crate) fn record(&self) -> Option<&StepRecord<N, M>> {
        self.record.as_ref()
    }

    /// Predicts from step `k` to `k + 1` given the predicted mean, the transition Jacobian and
    /// the process noise, all evaluated by the caller.
    pub(crate) fn predict(&mut self, x_pred: OVector<f64, N>, f: OMatrix<f64, N, N>, q: OMatrix<f64, N, N>) -> Result<(), FilterError> {
        let next = self.k + 1;
        check_finite(&f, "transition Jacobian F").map_err(|e| FilterError::at(self.k, e))?;
        check_finite(&q, "process noise covariance Q").map_err(|e| FilterError::at(self.k, e))?;
        check_finite(&x_pred, "predicted mean").map_err(|e| FilterError::at(next, e))?;
        let (propagated, noise) = if self.predicted {
            // A second prediction without an update: carry both parts.
            (propagate(&f, &self.propagated), propagate(&f, &self.process_noise) + &q)
        } else {
            (propagate(&f, &self.p), q)
        };
        let mut p = &propagated + &noise;
        symmetrize(&mut p);
        check_finite(&p, "predicted covariance").map_err(|e| FilterError::at(next, e))?;
        self.x = x_pred;
        self.p = p;
        self.f = f;
        self.propagated = propagated;
        self.process_noise = noise;
        self.predicted = true;
        self.k = next;
        Ok(())
    }

    /// Updates at the current step with the predicted measurement, the innovation (residual),
    /// the measurement Jacobian and the noise, all evaluated by the caller.
    pub(crate) fn update(
        &mut self,
        zhat: OVector<f64, M>,
        innovation: OVector<f64, M>,
        h: OMatrix<f64, M, N>,
        r: OMatrix<f64, M, M>,
    ) -> Result<&StepRecord<N, M>, FilterError> {
        let k = self.k;
        let at = |e| FilterError::at(k, e);
        check_finite(&h, "measurement Jacobian H").map_err(at)?;
        check_finite(&r, "measurement noise covariance R").map_err(at)?;
        check_finite(&innovation, "innovation").map_err(at)?;
        let pht = &self.p * h.transpose();
        let mut s = &h * &pht + &r;
        symmetrize(&mut s);
        let s = Covariance::from_symmetric(s, "innovation covariance S").map_err(at)?;
        // K = P H^T S^-1, as the transpose of S^-1 (H P): a solve with the factor of S.
        let gain = s.cholesky().solve(&pht.transpose()).transpose();
        let x_post = &self.x + &gain * &innovation;
        let p_post = match self.update {
            UpdateForm::Joseph => joseph_update(&self.p, &gain, &h, &r),
            UpdateForm::Standard => standard_update(&self.p, &gain, &h),
        };
        check_finite(&x_post, "posterior mean").map_err(at)?;
        check_finite(&p_post, "posterior covariance").map_err(at)?;
        let n = self.x.shape_generic().0;
        let prior = Estimate { mean: std::mem::replace(&mut self.x, x_post.clone()), cov: std::mem::replace(&mut self.p, p_post.clone()) };
        let record = StepRecord {
            k,
            prior,
            posterior: Estimate { mean: x_post, cov: p_post },
            predicted_measurement: zhat,
            innovation,
            s,
            gain,
            h,
            r,
            f: std::mem::replace(&mut self.f, OMatrix::identity_generic(n, n)),
            propagated: std::mem::replace(&mut self.propagated, self.p.clone()),
            process_noise: std::mem::replace(&mut self.process_noise, OMatrix::zeros_generic(n, n)),
        };
        self.predicted = false;
        Ok(self.record.insert(record))
    }

    /// Checks the length and finiteness of a measurement handed in from outside.
    pub(crate) fn check_measurement(&self, m: usize, z: &OVector<f64, M>) -> Result<(), FilterError> {
        check_dim(m, z.nrows(), "measurement").map_err(|e| FilterError::at(self.k, e))?;
        check_finite(z, "measurement").map_err(|e| FilterError::at(self.k, e))
    }
}
