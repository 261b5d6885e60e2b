//! The scalar UKF's update: the unscented measurement statistics at one kappa ([`candidate`]),
//! and with an adaptive kappa the choice among the grid's candidates.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, LinalgError, OMatrix, OVector, SqrtMethod,
    add_cross_scatter, add_scatter, all_finite, check_finite, propagate, sigma_sqrt, symmetrize,
};
use kalibra_models::{Dynamics, Measurement};

use super::points::{cross_covariance, measure, residual};
use super::{KappaCriterion, KappaGrid, SigmaSet, SigmaSpace, SigmaWeights, Ukf};
use crate::core::{UpdateParts, check_model_output};
use crate::{Estimate, FilterError, StepRecord};

impl<N: Dim, M: Dim, D: Dynamics<N>, H: Measurement<N, M>> Ukf<N, M, D, H>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(super) fn unscented_update(
        &mut self,
        z: &OVector<f64, M>,
    ) -> Result<&StepRecord<N, M>, FilterError> {
        let k = self.core.step();
        self.core
            .check_measurement(self.measurement.meas_dim().value(), z)?;
        let prior: Estimate<N> = self.core.update_prior().clone();
        let n = prior.mean.nrows();
        let (l, method) = sigma_sqrt(&prior.cov, "prior covariance for sigma points")
            .map_err(|e| FilterError::at(k, e))?;
        let m = self.measurement.meas_dim().value();
        let r = self.measurement.noise_cov(k, &prior.mean);
        check_model_output("measurement noise covariance R", &r, (m, m), k)?;
        check_finite(&r, "measurement noise covariance R").map_err(|e| FilterError::at(k, e))?;
        let z0 = self.measurement.measure(k, &prior.mean);
        check_model_output("predicted measurement h(x)", &z0, (m, 1), k)?;
        let spaces = Spaces {
            state: self.sigma.state_space.as_deref(),
            measurement_mean: self.sigma.measurement_mean.as_deref(),
        };

        let r_chol = self
            .adaptive
            .as_ref()
            .and_then(|_| Covariance::from_symmetric(r.clone(), "R").ok());
        let measurement = &self.measurement;
        let scratch = &mut self.sigma.scratch_z;
        let at_weights = |w| candidate(measurement, scratch, k, &prior, &l, &z0, &r, z, w, spaces);
        let l_chol = (method == SqrtMethod::Cholesky).then_some(&l);
        let value = |criterion, c: &Candidate<N, M>| {
            let parts = CandidateParts {
                s: &c.s,
                nu: &c.nu,
                gain: &c.gain,
                mean: &c.mean,
            };
            criterion_value(criterion, measurement, k, z, parts, l_chol, r_chol.as_ref())
        };
        let best = choose_kappa(
            self.adaptive.as_ref(),
            self.sigma.set,
            n,
            k,
            at_weights,
            value,
        )?;
        let (kappa, c) = best;
        // The statistical linearisation H = Pxz^T P-^-1, through the Cholesky factor.
        let h = match method {
            SqrtMethod::Cholesky => l
                .solve_lower_triangular(&c.pxz)
                .and_then(|y| l.tr_solve_lower_triangular(&y))
                .map(|ht| ht.transpose()),
            _ => None,
        }
        .unwrap_or_else(|| self.measurement.jacobian(k, &prior.mean));
        check_model_output("measurement Jacobian H", &h, (m, n), k)?;
        self.last_kappa = Some(kappa);
        self.core.commit_update(UpdateParts {
            zhat: c.zhat,
            innovation: c.nu,
            h,
            r,
            s: c.s,
            gain: c.gain,
            mean: c.mean,
            cov: c.cov,
        })
    }
}

/// The update at one kappa.
#[derive(Clone, Debug)]
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
    cov: OMatrix<f64, N, N>,
}

/// The optional non-Euclidean spaces of an update.
struct Spaces<'a, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    state: Option<&'a dyn SigmaSpace<N>>,
    measurement_mean: Option<&'a dyn SigmaSpace<M>>,
}

impl<N: Dim, M: Dim> Clone for Spaces<'_, N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn clone(&self) -> Self {
        *self
    }
}

impl<N: Dim, M: Dim> Copy for Spaces<'_, N, M> where DefaultAllocator: Alloc<N, M> {}

/// The unscented measurement update with weights `w`, the prior's factor `l` and the central
/// measurement `z0` given (they do not depend on kappa).
#[allow(clippy::too_many_arguments)]
fn candidate<N: Dim, M: Dim, H: Measurement<N, M>>(
    measurement: &H,
    scratch: &mut [OVector<f64, M>],
    k: usize,
    prior: &Estimate<N>,
    l: &OMatrix<f64, N, N>,
    z0: &OVector<f64, M>,
    r: &OMatrix<f64, M, M>,
    z: &OVector<f64, M>,
    w: SigmaWeights,
    spaces: Spaces<'_, N, M>,
) -> Result<Candidate<N, M>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let n = prior.mean.nrows();
    let m = z0.nrows();
    let x = &prior.mean;
    // Fixed sizes write the sigma-point sums out, run-time sizes call the kernels (which may
    // hand them to faer): the same arithmetic below the faer threshold, but the kernel calls
    // change how the compiler inlines the fixed-size update (`cargo xtask bench w2`).
    let fixed = N::try_to_usize().is_some() && M::try_to_usize().is_some();
    let (zhat, e0) = measure(
        measurement,
        k,
        x,
        l,
        &w,
        z0,
        spaces.measurement_mean,
        scratch,
    )?;
    let mut pz = &e0 * e0.transpose() * w.cov_center;
    match spaces.measurement_mean {
        // The deviations from zhat are the residuals from the central measurement plus e0.
        None if fixed => {
            for d in scratch.iter() {
                let dd = d + &e0;
                pz += &dd * dd.transpose() * w.other;
            }
        }
        None => add_scatter(&mut pz, scratch, &(-&e0), w.other),
        Some(_) => {
            for e in scratch.iter() {
                pz += e * e.transpose() * w.other;
            }
        }
    }
    pz += r;
    symmetrize(&mut pz);
    let pxz = if fixed {
        cross_covariance(l, scratch, z0.shape_generic().0, &w)
    } else {
        let mut pxz =
            OMatrix::<f64, N, M>::zeros_generic(x.shape_generic().0, z0.shape_generic().0);
        add_cross_scatter(
            &mut pxz,
            l,
            &scratch[..n],
            &scratch[n..],
            w.spread * w.other,
        );
        pxz
    };
    let mut zhat = zhat;
    if spaces.measurement_mean.is_none() {
        measurement.normalize(&mut zhat);
        check_model_output("normalized measurement", &zhat, (m, 1), k)?;
    }
    let nu = residual(measurement, k, z, &zhat)?;
    let s = Covariance::from_symmetric(pz, "innovation covariance Pz").map_err(|e| {
        let e = if all_finite(&zhat) {
            e
        } else {
            LinalgError::NonFinite {
                what: "sigma-point measurements",
            }
        };
        FilterError::at(k, e)
    })?;
    // Sizes agree by construction: `pxz` has as many columns as `S` has rows.
    let gain = s.solve_right(&pxz).map_err(|e| FilterError::at(k, e))?;
    let mut mean = x + &gain * &nu;
    if let Some(space) = spaces.state {
        space.normalize(&mut mean);
        check_model_output("state space's normalized mean", &mean, (n, 1), k)?;
    }
    let cov = &prior.cov - propagate(&gain, s.matrix());
    Ok(Candidate {
        zhat,
        nu,
        s,
        pxz,
        gain,
        mean,
        cov,
    })
}

/// What the criteria read of one candidate update: the innovation covariance and the
/// innovation, the gain and the updated mean.
pub(crate) struct CandidateParts<'a, N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    pub(crate) s: &'a Covariance<M>,
    pub(crate) nu: &'a OVector<f64, M>,
    pub(crate) gain: &'a OMatrix<f64, N, M>,
    pub(crate) mean: &'a OVector<f64, N>,
}

/// The update at the set's own kappa, or with `adaptive` the grid's candidate whose
/// `value` is smallest ([`KappaCriterion::improves`]), with its kappa: `candidate` computes
/// the update at given weights. The scalar [`Ukf`] and the [`SqrtUkf`](crate::SqrtUkf) both
/// choose here, so they choose alike (`tests/sqrt_ukf.rs`).
///
/// # Errors
/// The candidate's error without `adaptive`; with it, the first candidate's error when no
/// kappa gave a finite criterion, or [`FilterError::NonFinite`] when every candidate
/// succeeded but none had a finite criterion.
pub(crate) fn choose_kappa<C>(
    adaptive: Option<&(KappaCriterion, KappaGrid)>,
    set: SigmaSet,
    n: usize,
    k: usize,
    mut candidate: impl FnMut(SigmaWeights) -> Result<C, FilterError>,
    value: impl Fn(KappaCriterion, &C) -> f64,
) -> Result<(f64, C), FilterError> {
    let Some((criterion, grid)) = adaptive else {
        return Ok((set.kappa(), candidate(set.weights(n)?)?));
    };
    let mut best: Option<(f64, f64, C)> = None;
    let mut first_error = None;
    for &kappa in grid.values() {
        let c = match candidate(set.with_kappa(kappa).weights(n)?) {
            Ok(c) => c,
            Err(e) => {
                first_error.get_or_insert(e);
                continue;
            }
        };
        let v = value(*criterion, &c);
        if KappaCriterion::improves(v, best.as_ref().map(|(b, _, _)| *b)) {
            best = Some((v, kappa, c));
        }
    }
    match best {
        Some((_, kappa, c)) => Ok((kappa, c)),
        None => Err(first_error.unwrap_or(FilterError::NonFinite {
            what: "adaptive kappa criterion (every grid value)",
            step: k,
        })),
    }
}

/// The value of `criterion` for one candidate (smaller is better); NaN when it cannot be
/// evaluated (no Cholesky factor `l` of `P-`, or a singular `R`, for the posterior criteria).
pub(crate) fn criterion_value<N: Dim, M: Dim, H: Measurement<N, M>>(
    criterion: KappaCriterion,
    measurement: &H,
    k: usize,
    z: &OVector<f64, M>,
    c: CandidateParts<'_, N, M>,
    l: Option<&OMatrix<f64, N, N>>,
    r: Option<&Covariance<M>>,
) -> f64
where
    DefaultAllocator: Alloc<N, M>,
{
    let nis = quad_or_non_finite(c.s, c.nu);
    criterion.value(c.s.log_det(), nis, || {
        // nu^T U nu = (K nu)^T P-^-1 (K nu) = |L^-1 K nu|^2: the prior's density at x+.
        let step = c.gain * c.nu;
        let prior_term = l
            .and_then(|l| l.solve_lower_triangular(&step))
            .map_or(f64::NAN, |y| y.norm_squared());
        // A model answering with the wrong length here makes the criterion NaN (this kappa
        // never wins), as a failed factorisation does; the update's own checks caught the
        // others.
        let zc = measurement.measure(k, c.mean);
        if zc.nrows() != z.nrows() {
            return (f64::NAN, f64::NAN);
        }
        let e = measurement.residual(z, &zc);
        if e.nrows() != z.nrows() {
            return (f64::NAN, f64::NAN);
        }
        let meas_term = r.map_or(f64::NAN, |r| quad_or_non_finite(r, &e));
        (prior_term, meas_term)
    })
}

/// `v^T S^-1 v` as a score term: `+inf` when it lies beyond f64's range, NaN for a non-finite
/// `v` (what the unchecked form gave before `quad_form` refused both).
fn quad_or_non_finite<M: Dim>(s: &Covariance<M>, v: &OVector<f64, M>) -> f64
where
    DefaultAllocator: Alloc<M>,
{
    s.quad_form(v).unwrap_or_else(|_| {
        if v.iter().all(|x| x.is_finite()) {
            f64::INFINITY
        } else {
            f64::NAN
        }
    })
}
