//! Spall and Wei's surrogate uncertainty bounds for the error of an EKF or a constant-gain
//! filter, from one trajectory ("Uncertainty bounds for state estimates with applications in
//! target tracking", AIAA Defense Forum 2023).
//!
//! # Notation
//! The filter error `e_k = x_k - x_hat_k` (Spall and Wei's sign) of a model
//! `x_k = f(x_{k-1}) + w_k`, `z_k = H x_k + v_k` obeys
//! `e_{k+1} = (I - K_{k+1} H) F_{k+1} e_k + (I - K_{k+1} H) w_{k+1} - K_{k+1} v_{k+1}`, an AR
//! process with random coefficients (`F_{k+1}` is a mean-value Jacobian, not computable). The
//! surrogate replaces the gain and the Jacobian by their ergodic averages along one trajectory,
//! `K*` (mean of `K_k`) and `J*` (mean of `J_k = df/dx` at the estimate), after a burn-in:
//! `e'_{k+1} = C e'_k + eta_{k+1}` with `C = (I - K* H) J*` and
//! `cov(eta) = (I - K* H) Q (I - K* H)^T + K* R K*^T`. With Gaussian noise its limiting
//! distribution is `N(0, P_bar)`, `P_bar = C P_bar C^T + cov(eta)` (a discrete Lyapunov
//! equation), whose quantiles are the surrogate's confidence intervals and ellipsoids.
//!
//! # Numerical choices
//! `P_bar` comes from [`discrete_lyapunov`] (Smith doubling) after the spectral radius of `C`
//! ([`spectral_radius`]) is checked to be below 1: an unobserved axis makes it 1 and the
//! surrogate unbounded, which is a typed error ([`BoundsError::Unstable`]), not a huge number.
//! Quantiles come from statrs.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Definiteness, Dim, OMatrix, OVector, check_covariance,
    check_dim, check_finite, discrete_lyapunov, product, propagate, spectral_radius, symmetrize,
};
use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};

/// The most steps [`Surrogate::covariance_after`] iterates before its recursion settles on a
/// fixed point or a two-cycle (after which any count is answered at once): 2^24.
pub const COVARIANCE_AFTER_MAX_ITERATIONS: usize = 1 << 24;

use crate::BoundsError;

/// Running sums of the filter gains `K_k` and Jacobians `J_k` along one trajectory, for their
/// ergodic averages `K*` and `J*`.
#[derive(Clone, Debug, PartialEq)]
pub struct ErgodicAverage<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    gain_sum: OMatrix<f64, N, M>,
    jacobian_sum: OMatrix<f64, N, N>,
    count: usize,
}

impl<N: Dim, M: Dim> ErgodicAverage<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// Empty sums for state dimension `n` and measurement dimension `m`.
    pub fn new(n: N, m: M) -> Self {
        Self {
            gain_sum: OMatrix::zeros_generic(n, m),
            jacobian_sum: OMatrix::zeros_generic(n, n),
            count: 0,
        }
    }

    /// The averages of sums accumulated elsewhere: `gain_sum` is the sum of `count` gains,
    /// `jacobian_sum` of as many Jacobians (for instance over the lanes of a batched filter,
    /// which adds its steps' entries in the order [`ErgodicAverage::push`] would).
    ///
    /// ```
    /// use kalibra_bounds::ErgodicAverage;
    /// use kalibra_linalg::nalgebra::SMatrix;
    /// use kalibra_linalg::{Matrix2, U1, U2};
    ///
    /// let (k, j) = (SMatrix::<f64, 2, 1>::new(0.5, 0.1), Matrix2::identity());
    /// let mut pushed = ErgodicAverage::new(U2, U1);
    /// pushed.push(&k, &j)?;
    /// pushed.push(&k, &j)?;
    /// let summed = ErgodicAverage::from_sums(k + k, j + j, 2)?;
    /// assert_eq!(summed, pushed);
    /// # Ok::<(), kalibra_bounds::BoundsError>(())
    /// ```
    ///
    /// # Errors
    /// [`BoundsError::Linalg`] if a sum is not finite (a step's gain or Jacobian was not, or
    /// the sum overflowed).
    pub fn from_sums(
        gain_sum: OMatrix<f64, N, M>,
        jacobian_sum: OMatrix<f64, N, N>,
        count: usize,
    ) -> Result<Self, BoundsError> {
        check_dim(gain_sum.nrows(), jacobian_sum.nrows(), "Jacobian")?;
        check_dim(jacobian_sum.nrows(), jacobian_sum.ncols(), "Jacobian")?;
        check_finite(&gain_sum, "gain sum")?;
        check_finite(&jacobian_sum, "Jacobian sum")?;
        Ok(Self {
            gain_sum,
            jacobian_sum,
            count,
        })
    }

    /// Adds one step's gain `K_k` and Jacobian `J_k`.
    ///
    /// # Errors
    /// [`BoundsError::Linalg`] for a non-finite or wrongly sized input (`Dyn`); the sums are
    /// unchanged then.
    pub fn push(
        &mut self,
        gain: &OMatrix<f64, N, M>,
        jacobian: &OMatrix<f64, N, N>,
    ) -> Result<(), BoundsError> {
        check_dim(self.gain_sum.nrows(), gain.nrows(), "gain rows")?;
        check_dim(self.gain_sum.ncols(), gain.ncols(), "gain columns")?;
        check_dim(self.jacobian_sum.nrows(), jacobian.nrows(), "Jacobian")?;
        check_dim(self.jacobian_sum.ncols(), jacobian.ncols(), "Jacobian")?;
        check_finite(gain, "gain")?;
        check_finite(jacobian, "Jacobian")?;
        self.gain_sum += gain;
        self.jacobian_sum += jacobian;
        self.count += 1;
        Ok(())
    }

    /// Steps added.
    pub fn count(&self) -> usize {
        self.count
    }

    /// `K*`, the mean gain.
    ///
    /// # Errors
    /// [`BoundsError::TooFewSamples`] if nothing was added.
    pub fn gain(&self) -> Result<OMatrix<f64, N, M>, BoundsError> {
        self.nonempty()?;
        Ok(&self.gain_sum / self.count as f64)
    }

    /// `J*`, the mean Jacobian.
    ///
    /// # Errors
    /// [`BoundsError::TooFewSamples`] if nothing was added.
    pub fn jacobian(&self) -> Result<OMatrix<f64, N, N>, BoundsError> {
        self.nonempty()?;
        Ok(&self.jacobian_sum / self.count as f64)
    }

    fn nonempty(&self) -> Result<(), BoundsError> {
        if self.count == 0 {
            return Err(BoundsError::TooFewSamples {
                what: "ergodic average",
                needed: 1,
                got: 0,
            });
        }
        Ok(())
    }
}

/// The surrogate AR process `e'_{k+1} = C e'_k + eta_{k+1}` and its limiting covariance.
#[derive(Clone, Debug, PartialEq)]
pub struct Surrogate<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    gain: OMatrix<f64, N, M>,
    jacobian: OMatrix<f64, N, N>,
    c: OMatrix<f64, N, N>,
    eta_cov: OMatrix<f64, N, N>,
    limit: OMatrix<f64, N, N>,
    spectral_radius: f64,
}

impl<N: Dim, M: Dim> Surrogate<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The surrogate of a filter with limiting gain `gain` (`K*`) and Jacobian `jacobian`
    /// (`J*`) on a model with measurement matrix `h` and noise covariances `q`, `r`.
    ///
    /// Every input is borrowed, as in [`Surrogate::from_averages`]; the surrogate keeps copies
    /// of `K*` and `J*` for [`Surrogate::gain`] and [`Surrogate::jacobian`].
    ///
    /// ```
    /// use kalibra_bounds::Surrogate;
    /// use kalibra_linalg::nalgebra::{Matrix1x2, Matrix2x1};
    /// use kalibra_linalg::{Matrix1, Matrix2};
    ///
    /// // A constant-velocity filter with a position measurement and a fixed gain.
    /// let j = Matrix2::new(1.0, 1.0, 0.0, 1.0);
    /// let h = Matrix1x2::new(1.0, 0.0);
    /// let k = Matrix2x1::new(0.5, 0.2);
    /// let q = Matrix2::new(0.25, 0.5, 0.5, 1.0) * 0.01;
    /// let r = Matrix1::new(1.0);
    /// let s = Surrogate::new(&k, &j, &h, &q, &r)?;
    /// assert!(s.spectral_radius() < 1.0);
    /// assert_eq!(s.gain(), &k);
    /// # Ok::<(), kalibra_bounds::BoundsError>(())
    /// ```
    ///
    /// # Errors
    /// [`BoundsError::Linalg`] for wrongly sized (`Dyn`) or non-finite input, and for a `q` or
    /// `r` that is not a covariance (asymmetric beyond
    /// [`SYMMETRY_TOLERANCE`](kalibra_linalg::SYMMETRY_TOLERANCE), indefinite or negative:
    /// [`check_covariance`], semi-definite); [`BoundsError::Unstable`] if the spectral radius
    /// of `C` is not below 1.
    pub fn new(
        gain: &OMatrix<f64, N, M>,
        jacobian: &OMatrix<f64, N, N>,
        h: &OMatrix<f64, M, N>,
        q: &OMatrix<f64, N, N>,
        r: &OMatrix<f64, M, M>,
    ) -> Result<Self, BoundsError> {
        let n = jacobian.nrows();
        check_dim(n, jacobian.ncols(), "Jacobian")?;
        check_dim(n, gain.nrows(), "gain rows")?;
        check_dim(gain.ncols(), h.nrows(), "measurement matrix rows")?;
        check_dim(n, h.ncols(), "measurement matrix columns")?;
        check_dim(n, q.nrows(), "process noise Q")?;
        check_dim(n, q.ncols(), "process noise Q columns")?;
        check_dim(h.nrows(), r.nrows(), "measurement noise R")?;
        check_dim(h.nrows(), r.ncols(), "measurement noise R columns")?;
        check_finite(jacobian, "Jacobian")?;
        check_finite(gain, "gain")?;
        check_finite(h, "measurement matrix H")?;
        check_covariance(q, "process noise Q", Definiteness::SemiDefinite)?;
        check_covariance(r, "measurement noise R", Definiteness::SemiDefinite)?;
        let mut i_kh = -(gain * h);
        for i in 0..n {
            i_kh[(i, i)] += 1.0;
        }
        let c = product(&i_kh, jacobian);
        let mut eta_cov = propagate(&i_kh, q) + propagate(gain, r);
        symmetrize(&mut eta_cov);
        let rho = spectral_radius(&c)?;
        if rho >= 1.0 {
            return Err(BoundsError::Unstable {
                spectral_radius: rho,
            });
        }
        let limit = discrete_lyapunov(&c, &eta_cov)?;
        Ok(Self {
            gain: gain.clone(),
            jacobian: jacobian.clone(),
            c,
            eta_cov,
            limit,
            spectral_radius: rho,
        })
    }

    /// The surrogate from ergodic averages along a trajectory.
    ///
    /// # Errors
    /// As [`Surrogate::new`], and [`BoundsError::TooFewSamples`] for empty averages.
    pub fn from_averages(
        averages: &ErgodicAverage<N, M>,
        h: &OMatrix<f64, M, N>,
        q: &OMatrix<f64, N, N>,
        r: &OMatrix<f64, M, M>,
    ) -> Result<Self, BoundsError> {
        Self::new(&averages.gain()?, &averages.jacobian()?, h, q, r)
    }

    /// `K*`.
    pub fn gain(&self) -> &OMatrix<f64, N, M> {
        &self.gain
    }

    /// `J*`.
    pub fn jacobian(&self) -> &OMatrix<f64, N, N> {
        &self.jacobian
    }

    /// `C = (I - K* H) J*`.
    pub fn c(&self) -> &OMatrix<f64, N, N> {
        &self.c
    }

    /// `cov(eta) = (I - K* H) Q (I - K* H)^T + K* R K*^T`.
    pub fn eta_cov(&self) -> &OMatrix<f64, N, N> {
        &self.eta_cov
    }

    /// The limiting covariance `P_bar = C P_bar C^T + cov(eta)`.
    pub fn limit_cov(&self) -> &OMatrix<f64, N, N> {
        &self.limit
    }

    /// The spectral radius of `C` (below 1).
    pub fn spectral_radius(&self) -> f64 {
        self.spectral_radius
    }

    /// `cov(e'_steps)` from `cov(e'_0) = initial` by the recursion
    /// `cov_{k+1} = C cov_k C^T + cov(eta)` (the paper's finite-horizon surrogate).
    ///
    /// # Errors
    /// [`BoundsError::Linalg`] for a wrongly sized `initial` or one that is not a covariance
    /// ([`check_covariance`], semi-definite); [`BoundsError::InvalidParameter`] for more than
    /// [`COVARIANCE_AFTER_MAX_ITERATIONS`] steps of a recursion that has not settled by then
    /// (`rho(C)` within about `1e-6` of 1).
    pub fn covariance_after(
        &self,
        steps: usize,
        initial: &OMatrix<f64, N, N>,
    ) -> Result<OMatrix<f64, N, N>, BoundsError> {
        check_dim(self.c.nrows(), initial.nrows(), "initial covariance")?;
        check_dim(self.c.nrows(), initial.ncols(), "initial covariance")?;
        check_covariance(initial, "initial covariance", Definiteness::SemiDefinite)?;
        // Since rho(C) < 1 the recursion settles, in floating point, on a fixed point or a
        // cycle of two values; from there every later step is known, so a count such as
        // `usize::MAX` returns at once with the bits the full loop would give
        // (`tests/extreme_sizes.rs`). A recursion that has not settled within
        // `COVARIANCE_AFTER_MAX_ITERATIONS` is an error rather than a loop of 2^64 steps.
        let mut cov = initial.clone();
        let mut previous: Option<OMatrix<f64, N, N>> = None;
        for done in 0..steps {
            let next = {
                let mut next = propagate(&self.c, &cov) + &self.eta_cov;
                symmetrize(&mut next);
                next
            };
            // `next` is step `done + 1`; steps left after it: `steps - done - 1`.
            let left = steps - done - 1;
            if next == cov {
                return Ok(next);
            }
            if previous.as_ref() == Some(&next) {
                // A cycle cov -> next -> cov: an even number of steps left ends on `next`.
                return Ok(if left.is_multiple_of(2) { next } else { cov });
            }
            if done >= COVARIANCE_AFTER_MAX_ITERATIONS {
                return Err(BoundsError::InvalidParameter {
                    what: "surrogate covariance recursion",
                    reason: "did not settle within COVARIANCE_AFTER_MAX_ITERATIONS steps",
                });
            }
            previous = Some(std::mem::replace(&mut cov, next));
        }
        Ok(cov)
    }

    /// Half-widths of the per-component two-sided intervals of the limiting `N(0, P_bar)` at
    /// `confidence` (0.95: `1.959964 sqrt(P_bar_ii)`).
    ///
    /// # Errors
    /// [`BoundsError::InvalidParameter`] unless `0 < confidence < 1`.
    pub fn half_widths(&self, confidence: f64) -> Result<OVector<f64, N>, BoundsError> {
        gaussian_half_widths(&self.limit, confidence)
    }

    /// The confidence ellipsoid `{e : e^T P_bar^-1 e <= chi2_n(confidence)}` of the limiting
    /// distribution.
    ///
    /// # Errors
    /// [`BoundsError::InvalidParameter`] unless `0 < confidence < 1`; [`BoundsError::Linalg`]
    /// if `P_bar` is singular (a noise-free direction).
    pub fn ellipsoid(&self, confidence: f64) -> Result<Ellipsoid<N>, BoundsError> {
        Ellipsoid::new(self.limit.clone(), confidence)
    }
}

fn check_confidence(confidence: f64) -> Result<(), BoundsError> {
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(BoundsError::InvalidParameter {
            what: "confidence region",
            reason: "confidence must lie in (0, 1)",
        });
    }
    Ok(())
}

/// Half-widths `z_{(1+c)/2} sqrt(P_ii)` of the per-component two-sided intervals of `N(0, P)`
/// at confidence `c`: the surrogate's intervals, or a filter's own `N(0, P_k)` intervals.
///
/// # Errors
/// [`BoundsError::InvalidParameter`] unless `0 < confidence < 1` with `(1 + confidence) / 2`
/// below 1 in f64; [`BoundsError::Linalg`] for a negative or non-finite variance.
///
/// statrs' normal quantile is called at `(1 + confidence) / 2` only, strictly inside (0, 1);
/// the ellipsoid's chi-square quantile ([`Ellipsoid::new`]) at `confidence` with the state
/// dimension as degrees of freedom, far below the 1e7 from which statrs' series slow.
pub fn gaussian_half_widths<N: Dim>(
    cov: &OMatrix<f64, N, N>,
    confidence: f64,
) -> Result<OVector<f64, N>, BoundsError>
where
    DefaultAllocator: Alloc<N>,
{
    check_confidence(confidence)?;
    let diag = cov.diagonal();
    if diag.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err(BoundsError::Linalg(
            kalibra_linalg::LinalgError::NotPositiveSemiDefinite {
                what: "covariance diagonal",
                index: diag
                    .iter()
                    .position(|v| !(v.is_finite() && *v >= 0.0))
                    .unwrap_or(0),
                pivot: f64::NAN,
            },
        ));
    }
    let p = 0.5 + 0.5 * confidence;
    // A confidence within 2^-53 of 1 rounds `p` to 1, whose quantile is infinite.
    if p >= 1.0 {
        return Err(BoundsError::InvalidParameter {
            what: "confidence interval",
            reason: "confidence so close to 1 that (1 + c) / 2 rounds to 1",
        });
    }
    let z = standard_normal_quantile(p);
    Ok(diag.map(|v| z * v.sqrt()))
}

/// The standard normal quantile.
fn standard_normal_quantile(p: f64) -> f64 {
    // Normal::new(0, 1) cannot fail.
    Normal::new(0.0, 1.0)
        .map(|n| n.inverse_cdf(p))
        .unwrap_or(f64::NAN)
}

/// A confidence ellipsoid `{e : e^T P^-1 e <= t}` of `N(0, P)`, `t = chi2_n(confidence)`.
#[derive(Clone, Debug)]
pub struct Ellipsoid<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    cov: Covariance<N>,
    threshold: f64,
}

impl<N: Dim> Ellipsoid<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The `confidence` ellipsoid of `N(0, cov)`.
    ///
    /// # Errors
    /// [`BoundsError::InvalidParameter`] unless `0 < confidence < 1`; [`BoundsError::Linalg`]
    /// unless `cov` is symmetric positive definite.
    pub fn new(cov: OMatrix<f64, N, N>, confidence: f64) -> Result<Self, BoundsError> {
        check_confidence(confidence)?;
        let cov = Covariance::named(cov, "ellipsoid covariance")?;
        let dof = cov.dim() as f64;
        let threshold = ChiSquared::new(dof)
            .map(|c| c.inverse_cdf(confidence))
            .map_err(|_| BoundsError::InvalidParameter {
                what: "confidence ellipsoid",
                reason: "dimension must be positive",
            })?;
        Ok(Self { cov, threshold })
    }

    /// The threshold `t` of the quadratic form.
    pub fn threshold(&self) -> f64 {
        self.threshold
    }

    /// The covariance.
    pub fn covariance(&self) -> &OMatrix<f64, N, N> {
        self.cov.matrix()
    }

    /// Whether `e` lies inside: `e^T P^-1 e <= t`. A finite `e` whose form lies beyond f64's
    /// range is outside.
    ///
    /// # Errors
    /// [`BoundsError::Linalg`] for a wrongly sized (`Dyn`) or non-finite `e` (a NaN point is
    /// neither inside nor outside; before, it came back as `Ok(false)`).
    pub fn contains(&self, e: &OVector<f64, N>) -> Result<bool, BoundsError> {
        check_dim(self.cov.dim(), e.nrows(), "point")?;
        check_finite(e, "point")?;
        match self.cov.quad_form(e) {
            Ok(q) => Ok(q <= self.threshold),
            // The point is finite, so the form overflowed: far outside.
            Err(kalibra_linalg::LinalgError::NonFinite { .. }) => Ok(false),
            Err(other) => Err(other.into()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kalibra_linalg::nalgebra::{DMatrix, Matrix1x2, Matrix2x1};
    use kalibra_linalg::{Matrix1, Matrix2, Vector2};

    fn direct_lyapunov(c: &Matrix2<f64>, q: &Matrix2<f64>) -> Matrix2<f64> {
        // vec(P) = (I - C kron C)^-1 vec(Q), solved with LU: an independent route.
        let kron = c.kronecker(c);
        let lhs =
            DMatrix::<f64>::identity(4, 4) - DMatrix::from_column_slice(4, 4, kron.as_slice());
        let rhs = kalibra_linalg::DVector::from_column_slice(q.as_slice());
        let vec = lhs.lu().solve(&rhs).unwrap();
        Matrix2::from_column_slice(vec.as_slice())
    }

    #[test]
    fn limit_matches_a_direct_lyapunov_solve() {
        let dt = 0.5;
        let f = Matrix2::new(1.0, dt, 0.0, 0.95);
        let h = Matrix1x2::new(1.0, 0.0);
        let q = Matrix2::new(0.02, 0.03, 0.03, 0.1);
        let r = Matrix1::new(0.5);
        let k = Matrix2x1::new(0.4, 0.2);
        let s = Surrogate::new(&k, &f, &h, &q, &r).unwrap();
        let direct = direct_lyapunov(s.c(), s.eta_cov());
        assert!((s.limit_cov() - direct).amax() <= 1e-12 * direct.amax());
        // The recursion converges to the same limit.
        let rec = s.covariance_after(2000, &Matrix2::identity()).unwrap();
        assert!((rec - direct).amax() <= 1e-12 * direct.amax());
        assert!(s.spectral_radius() < 1.0);
        // 95% half-widths are 1.959964 standard deviations.
        let hw = s.half_widths(0.95).unwrap();
        assert!((hw[0] - 1.959_963_984_540_054 * direct[(0, 0)].sqrt()).abs() < 1e-12);
    }

    /// The docs promised an error for asymmetric noise that never came, and
    /// indefinite or negative `Q` and `R` gave a surrogate as `Ok`.
    #[test]
    fn noise_that_is_not_a_covariance_is_refused() {
        use kalibra_linalg::LinalgError;
        let f = Matrix2::new(1.0, 0.5, 0.0, 0.95);
        let h = Matrix1x2::new(1.0, 0.0);
        let k = Matrix2x1::new(0.4, 0.2);
        let q = Matrix2::new(0.02, 0.03, 0.03, 0.1);
        let r = Matrix1::new(0.5);
        assert!(Surrogate::new(&k, &f, &h, &q, &r).is_ok());
        let asymmetric = Matrix2::new(0.02, 0.03, 0.0, 0.1);
        assert!(matches!(
            Surrogate::new(&k, &f, &h, &asymmetric, &r),
            Err(BoundsError::Linalg(LinalgError::NotSymmetric { .. }))
        ));
        for bad in [Matrix2::new(1.0, 2.0, 2.0, 1.0), -q] {
            assert!(matches!(
                Surrogate::new(&k, &f, &h, &bad, &r),
                Err(BoundsError::Linalg(
                    LinalgError::NotPositiveSemiDefinite { .. }
                ))
            ));
        }
        assert!(matches!(
            Surrogate::new(&k, &f, &h, &q, &Matrix1::new(-0.5)),
            Err(BoundsError::Linalg(
                LinalgError::NotPositiveSemiDefinite { .. }
            ))
        ));
        let s = Surrogate::new(&k, &f, &h, &q, &r).unwrap();
        assert!(
            s.covariance_after(3, &Matrix2::new(1.0, 2.0, 2.0, 1.0))
                .is_err()
        );
        // Dyn sizes that disagree: a mismatch, not a panic inside nalgebra.
        let dq = DMatrix::<f64>::identity(2, 3);
        let d = |m: &Matrix2<f64>| DMatrix::from_column_slice(2, 2, m.as_slice());
        assert!(matches!(
            Surrogate::new(
                &DMatrix::from_column_slice(2, 1, k.as_slice()),
                &d(&f),
                &DMatrix::from_column_slice(1, 2, h.as_slice()),
                &dq,
                &DMatrix::from_column_slice(1, 1, r.as_slice()),
            ),
            Err(BoundsError::Linalg(LinalgError::DimensionMismatch {
                expected: 2,
                found: 3,
                ..
            }))
        ));
    }

    #[test]
    fn an_unobserved_unit_root_is_unstable() {
        let f = Matrix2::new(1.0, 0.0, 0.0, 0.5);
        let h = Matrix1x2::new(0.0, 1.0);
        let k = Matrix2x1::new(0.0, 0.3);
        let r = Matrix1::new(1.0);
        assert!(matches!(
            Surrogate::new(&k, &f, &h, &Matrix2::identity(), &r),
            Err(BoundsError::Unstable { .. })
        ));
    }

    #[test]
    fn ellipsoid_and_averages() {
        let e = Ellipsoid::new(Matrix2::identity(), 0.95).unwrap();
        // chi2_2(0.95) = -2 ln 0.05.
        // statrs inverts the chi-square cdf numerically, to about 1e-9 relative.
        let exact = -2.0 * 0.05f64.ln();
        assert!(
            (e.threshold() - exact).abs() < 1e-8 * exact,
            "{} vs {exact}",
            e.threshold()
        );
        assert!(e.contains(&Vector2::new(1.0, 1.0)).unwrap());
        assert!(!e.contains(&Vector2::new(2.0, 2.0)).unwrap());
        // A NaN point was Ok(false); a huge finite one is outside.
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(matches!(
                e.contains(&Vector2::new(bad, 0.0)),
                Err(BoundsError::Linalg(
                    kalibra_linalg::LinalgError::NonFinite { .. }
                ))
            ));
        }
        assert!(!e.contains(&Vector2::new(1e200, 1e200)).unwrap());
        assert!(e.contains(&Vector2::new(1e-310, 0.0)).unwrap());
        assert!(Ellipsoid::new(Matrix2::identity(), 1.0).is_err());

        let mut avg = ErgodicAverage::new(kalibra_linalg::U2, kalibra_linalg::U1);
        assert!(avg.gain().is_err());
        avg.push(&Matrix2x1::new(1.0, 2.0), &Matrix2::identity())
            .unwrap();
        avg.push(&Matrix2x1::new(3.0, 4.0), &(Matrix2::identity() * 3.0))
            .unwrap();
        assert!(
            avg.push(&Matrix2x1::new(f64::NAN, 0.0), &Matrix2::identity())
                .is_err()
        );
        assert_eq!(avg.count(), 2);
        assert_eq!(avg.gain().unwrap(), Matrix2x1::new(2.0, 3.0));
        assert_eq!(avg.jacobian().unwrap(), Matrix2::identity() * 2.0);
    }
}
