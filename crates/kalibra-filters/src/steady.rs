//! The steady state of the Kalman filter of a time-invariant linear(ised) model: the limit of
//! the discrete Riccati recursion and its gain.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Definiteness, Dim, OMatrix, check_covariance, check_dim,
    check_finite, joseph_update, product, propagate, symmetrize,
};

use crate::FilterError;

/// Most Riccati iterations [`steady_state`] runs before giving up.
pub const RICCATI_MAX_ITERATIONS: usize = 1_000_000;

/// Relative change of the prior covariance (Frobenius norm) below which the Riccati
/// recursion counts as converged. A few hundred units of rounding: the recursion converges
/// linearly and then flutters at rounding level.
pub const RICCATI_TOLERANCE: f64 = 1e-13;

/// The steady state of a Kalman filter: gain, prior and posterior covariance.
#[derive(Clone, Debug, PartialEq)]
pub struct SteadyState<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The steady-state gain `K = P- H^T S^-1`.
    pub gain: OMatrix<f64, N, M>,
    /// The prior covariance `P-`, the fixed point of `P- = F P+ F^T + Q`.
    pub prior: OMatrix<f64, N, N>,
    /// The posterior covariance `P+ = (I - K H) P- (I - K H)^T + K R K^T`.
    pub posterior: OMatrix<f64, N, N>,
    /// Iterations the recursion took.
    pub iterations: usize,
}

/// The steady state of the Kalman filter for `x_{k+1} = F x_k + w_k`, `z_k = H x_k + v_k`
/// (`w ~ N(0, Q)`, `v ~ N(0, R)`), by iterating the discrete Riccati recursion from `P- = Q`
/// (a posterior of zero) until the prior covariance changes by less than
/// [`RICCATI_TOLERANCE`] relative.
///
/// Plain iteration rather than a doubling or Schur method: it needs only the filter's own
/// algebra (Joseph update, gain by a Cholesky solve), works for any `Dim`, and its cost is
/// negligible beside the Monte Carlo studies that use it. For a singular `Q` the limit is the
/// one reached from `P0 = 0`.
///
/// # Errors
/// [`FilterError::DimensionMismatch`] for inconsistent sizes (`Dyn`), [`FilterError::NonFinite`]
/// for non-finite input, [`FilterError::NotPositiveDefinite`] at step 0 for a `Q` or `R` that
/// is not symmetric positive semi-definite
/// ([`check_covariance`](kalibra_linalg::check_covariance)) and at a later step if `S` is
/// singular,
/// [`FilterError::NotConvergent`] if the recursion has not converged after
/// [`RICCATI_MAX_ITERATIONS`] (the model is not detectable).
///
/// ```
/// use kalibra_filters::steady_state;
/// use kalibra_linalg::Matrix1;
/// // Random walk observed directly: P-^2 - q P- - q r = 0.
/// let (q, r) = (1.0, 4.0);
/// let ss = steady_state(&Matrix1::new(1.0), &Matrix1::new(1.0), &Matrix1::new(q), &Matrix1::new(r))?;
/// let p = 0.5 * (q + (q * q + 4.0 * q * r).sqrt());
/// assert!((ss.prior[(0, 0)] - p).abs() < 1e-10);
/// assert!((ss.gain[(0, 0)] - p / (p + r)).abs() < 1e-12);
/// # Ok::<(), kalibra_filters::FilterError>(())
/// ```
pub fn steady_state<N: Dim, M: Dim>(
    f: &OMatrix<f64, N, N>,
    h: &OMatrix<f64, M, N>,
    q: &OMatrix<f64, N, N>,
    r: &OMatrix<f64, M, M>,
) -> Result<SteadyState<N, M>, FilterError>
where
    DefaultAllocator: Alloc<N, M>,
{
    let at = |e| FilterError::at(0, e);
    check_dim(f.nrows(), f.ncols(), "transition matrix F").map_err(at)?;
    check_dim(f.nrows(), q.nrows(), "process noise Q").map_err(at)?;
    check_dim(f.nrows(), q.ncols(), "process noise Q columns").map_err(at)?;
    check_dim(f.nrows(), h.ncols(), "measurement matrix H").map_err(at)?;
    check_dim(h.nrows(), r.nrows(), "measurement noise R").map_err(at)?;
    check_dim(h.nrows(), r.ncols(), "measurement noise R columns").map_err(at)?;
    check_finite(f, "transition matrix F").map_err(at)?;
    check_finite(h, "measurement matrix H").map_err(at)?;
    check_covariance(q, "process noise Q", Definiteness::SemiDefinite).map_err(at)?;
    check_covariance(r, "measurement noise R", Definiteness::SemiDefinite).map_err(at)?;
    let mut prior = q.clone();
    symmetrize(&mut prior);
    for iteration in 1..=RICCATI_MAX_ITERATIONS {
        let s = Covariance::named(propagate(h, &prior) + r, "innovation covariance S")
            .map_err(|e| FilterError::at(iteration, e))?;
        let gain = s
            .solve(&product(h, &prior))
            .map_err(|e| FilterError::at(iteration, e))?
            .transpose();
        let posterior = joseph_update(&prior, &gain, h, r);
        let mut next = propagate(f, &posterior) + q;
        symmetrize(&mut next);
        let change = (&next - &prior).norm();
        let scale = next.norm();
        if !(change.is_finite() && scale.is_finite()) {
            return Err(FilterError::NonFinite {
                what: "Riccati iterate",
                step: iteration,
            });
        }
        if change <= RICCATI_TOLERANCE * scale {
            return Ok(SteadyState {
                gain,
                prior,
                posterior,
                iterations: iteration,
            });
        }
        prior = next;
    }
    Err(FilterError::NotConvergent {
        what: "Riccati recursion",
        iterations: RICCATI_MAX_ITERATIONS,
    })
}
