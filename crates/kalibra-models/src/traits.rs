//! The model traits: what a filter and a truth simulation ask of a model.

use kalibra_linalg::{Alloc, DefaultAllocator, Dim, OMatrix, OVector};
use rand::Rng;

use crate::{ModelError, noise::sample_with_factor};

/// State dynamics `x_{k+1} = f_k(x_k) + w_k`, `w_k ~ N(0, Q_k)`.
///
/// `k` is the index of the step being left: `transition(k, x)` maps the state at step `k` to
/// step `k + 1`. A model that needs time holds its own sampling period (`t = k T`) or a table
/// of times indexed by `k`; a known control input is part of `f_k` (see
/// [`WithInput`](crate::WithInput)).
///
/// Values are returned by value: with `Const` dimensions they live on the stack and cost
/// nothing; with `Dyn` dimensions the allocation is small beside the O(n^3) filter algebra.
pub trait Dynamics<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    /// The state dimension.
    fn state_dim(&self) -> N;

    /// `f_k(x)`: the state at step `k + 1` from the state `x` at step `k`, including any known
    /// input, without noise.
    fn transition(&self, k: usize, x: &OVector<f64, N>) -> OVector<f64, N>;

    /// The Jacobian `F_k = df_k/dx` at `x`.
    fn jacobian(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, N, N>;

    /// The process-noise covariance `Q_k` (positive semi-definite).
    fn noise_cov(&self, k: usize) -> OMatrix<f64, N, N>;

    /// Draws `w_k` for a truth simulation.
    ///
    /// The default draws `N(0, Q_k)` through a semi-definite factor computed on every call;
    /// models with a constant `Q` override it with a stored factor, and truth models with noise
    /// a filter does not model (non-Gaussian, rank-one, state-dependent) override it with their
    /// own law.
    ///
    /// # Errors
    /// [`ModelError::Linalg`] if `Q_k` is not positive semi-definite.
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        k: usize,
        rng: &mut R,
    ) -> Result<OVector<f64, N>, ModelError> {
        let q = self.noise_cov(k);
        let (l, _) = kalibra_linalg::semidefinite_factor(&q, "process noise covariance")?;
        Ok(sample_with_factor(&l, rng))
    }
}

/// Dynamics that are linear in the state: `f_k(x) = F_k x + u_k`, with `F_k` independent of `x`.
///
/// The Kalman filter asks for this trait; its `Jacobian` is `F_k` everywhere.
pub trait LinearDynamics<N: Dim>: Dynamics<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// The transition matrix `F_k`.
    fn matrix(&self, k: usize) -> OMatrix<f64, N, N>;
}

/// A measurement `z_k = h_k(x_k) + v_k`, `v_k ~ N(0, R_k)`, of dimension `M` on a state of
/// dimension `N`.
pub trait Measurement<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The measurement dimension.
    fn meas_dim(&self) -> M;

    /// `h_k(x)`, without noise. A moving platform enters here through `k`.
    fn measure(&self, k: usize, x: &OVector<f64, N>) -> OVector<f64, M>;

    /// The Jacobian `H_k = dh_k/dx` at `x`.
    fn jacobian(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, M, N>;

    /// The measurement-noise covariance `R_k` at the state `x` (state-dependent noise, such as
    /// converted-measurement noise that depends on the elevation, reads `x`; constant noise
    /// ignores it). Filters pass their prior estimate.
    fn noise_cov(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, M, M>;

    /// The residual `z - zhat`. Angles override this to wrap into (-pi, pi], so a bearing
    /// crossing +-pi gives a small innovation, not one of nearly 2 pi. Sigma-point filters also
    /// use it to unwrap sigma measurements around the central one.
    fn residual(&self, z: &OVector<f64, M>, zhat: &OVector<f64, M>) -> OVector<f64, M> {
        z - zhat
    }

    /// Puts a measurement into its canonical range (angles into (-pi, pi]); the truth
    /// simulation applies it after adding noise. The default does nothing.
    fn normalize(&self, _z: &mut OVector<f64, M>) {}

    /// Draws `v_k` for a truth simulation at the true state `x`. The default draws
    /// `N(0, R_k(x))` through a factor computed on every call; see
    /// [`Dynamics::sample_noise`].
    ///
    /// # Errors
    /// [`ModelError::Linalg`] if `R_k` is not positive semi-definite.
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        k: usize,
        x: &OVector<f64, N>,
        rng: &mut R,
    ) -> Result<OVector<f64, M>, ModelError> {
        let r = self.noise_cov(k, x);
        let (l, _) = kalibra_linalg::semidefinite_factor(&r, "measurement noise covariance")?;
        Ok(sample_with_factor(&l, rng))
    }
}

/// A measurement linear in the state: `h_k(x) = H_k x`.
pub trait LinearMeasurement<N: Dim, M: Dim>: Measurement<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// The measurement matrix `H_k`.
    fn matrix(&self, k: usize) -> OMatrix<f64, M, N>;
}

// Borrowed models are models, so a Monte Carlo study hands `&model` to thousands of filters
// without cloning.
impl<N: Dim, T: Dynamics<N>> Dynamics<N> for &T
where
    DefaultAllocator: Alloc<N>,
{
    fn state_dim(&self) -> N {
        (**self).state_dim()
    }
    fn transition(&self, k: usize, x: &OVector<f64, N>) -> OVector<f64, N> {
        (**self).transition(k, x)
    }
    fn jacobian(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, N, N> {
        (**self).jacobian(k, x)
    }
    fn noise_cov(&self, k: usize) -> OMatrix<f64, N, N> {
        (**self).noise_cov(k)
    }
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        k: usize,
        rng: &mut R,
    ) -> Result<OVector<f64, N>, ModelError> {
        (**self).sample_noise(k, rng)
    }
}

impl<N: Dim, T: LinearDynamics<N>> LinearDynamics<N> for &T
where
    DefaultAllocator: Alloc<N>,
{
    fn matrix(&self, k: usize) -> OMatrix<f64, N, N> {
        (**self).matrix(k)
    }
}

impl<N: Dim, M: Dim, T: Measurement<N, M>> Measurement<N, M> for &T
where
    DefaultAllocator: Alloc<N, M>,
{
    fn meas_dim(&self) -> M {
        (**self).meas_dim()
    }
    fn measure(&self, k: usize, x: &OVector<f64, N>) -> OVector<f64, M> {
        (**self).measure(k, x)
    }
    fn jacobian(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, M, N> {
        (**self).jacobian(k, x)
    }
    fn noise_cov(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, M, M> {
        (**self).noise_cov(k, x)
    }
    fn residual(&self, z: &OVector<f64, M>, zhat: &OVector<f64, M>) -> OVector<f64, M> {
        (**self).residual(z, zhat)
    }
    fn normalize(&self, z: &mut OVector<f64, M>) {
        (**self).normalize(z)
    }
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        k: usize,
        x: &OVector<f64, N>,
        rng: &mut R,
    ) -> Result<OVector<f64, M>, ModelError> {
        (**self).sample_noise(k, x, rng)
    }
}

impl<N: Dim, M: Dim, T: LinearMeasurement<N, M>> LinearMeasurement<N, M> for &T
where
    DefaultAllocator: Alloc<N, M>,
{
    fn matrix(&self, k: usize) -> OMatrix<f64, M, N> {
        (**self).matrix(k)
    }
}
