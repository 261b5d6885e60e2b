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
///
/// # Why `noise_cov(k)` takes no state, while [`Measurement::noise_cov`] takes one
/// The two differ on purpose. Process noise here is additive and independent of the state,
/// `Q_k` a function of the step only, because the code that asks for it has no state to give:
/// the steady-state gain and the surrogate bound solve Riccati and Lyapunov equations in `Q`
/// alone, the additive-noise UKF adds `Q_k` after the unscented transform, and the split
/// `P-_k = F P+ F^T + Q_{k-1}` that J1/J2 read from a step record assumes that `Q` does not
/// move with the estimate. A state-dependent `Q(x)` would need the augmented UKF and a choice
/// of `x` in each of those places, so it is not offered.
///
/// Measurement noise, in contrast, does depend on the state in models users meet: a bearing
/// with translational noise has `R_eff = R_theta + g(x)^T diag(var_x, var_y) g(x)`, and a
/// converted radar measurement has a covariance that turns with the elevation. Filters pass
/// their prior estimate as `x`; constant noise ignores it.
///
/// ```
/// use kalibra_linalg::{U2, Vector2};
/// use kalibra_models::{
///     Bearing, BearingReference, Coordinate, Dynamics, Kinematic, Measurement, Stationary,
/// };
///
/// // Process noise: one Q per step, the same whatever the state.
/// let cv = Kinematic::constant_velocity(1, 1.0)?.dynamics(U2)?;
/// assert_eq!(cv.noise_cov(0), cv.noise_cov(7));
///
/// // Measurement noise: a bearing's effective variance falls as the target moves away.
/// let sensor = Bearing::from_coordinates(
///     U2,
///     [Coordinate::State(0), Coordinate::Constant(0.0)],
///     BearingReference::XAxis,
///     1e-4,
///     Stationary(Vector2::new(0.0, -20.0)),
/// )?
/// .with_translational_noise(1.0, 1.0)?;
/// let near = sensor.noise_cov(0, &Vector2::new(20.0, 0.0))[(0, 0)];
/// let far = sensor.noise_cov(0, &Vector2::new(200.0, 0.0))[(0, 0)];
/// assert!(near > far);
/// // R_theta + 1 / r^2 with r^2 = 20^2 + 20^2.
/// assert!((near - (1e-4 + 1.0 / 800.0)).abs() < 1e-15);
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
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

    /// The process-noise covariance `Q_k` (positive semi-definite), independent of the state:
    /// see the trait docs for why it takes no `x` while [`Measurement::noise_cov`] does.
    fn noise_cov(&self, k: usize) -> OMatrix<f64, N, N>;

    /// Draws `w_k` for a truth simulation.
    ///
    /// The default draws `N(0, Q_k)` through a semi-definite factor computed on every call;
    /// models with a constant `Q` override it with a stored factor, and truth models with noise
    /// a filter does not model (non-Gaussian, rank-one, a law of the step) override it with
    /// their own law. Like [`Dynamics::noise_cov`] it sees no state: noise that depends on the
    /// state belongs in `transition`.
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

    /// The state dimension the model is built for, when it knows it. Filters compare it with
    /// their dynamics' state dimension at construction, so that `Dyn` models built for
    /// different states (an `H` with another number of columns, a bearing whose coordinates
    /// lie outside the filter's state) are a `DimensionMismatch` naming both sizes there,
    /// instead of a panic inside nalgebra at the first step. The default, `None`, claims
    /// nothing (with `Const` sizes the types already agree); every model of this crate that
    /// takes a run-time state size returns it.
    fn expected_state_dim(&self) -> Option<usize> {
        None
    }

    /// `h_k(x)`, without noise. A moving platform enters here through `k`.
    fn measure(&self, k: usize, x: &OVector<f64, N>) -> OVector<f64, M>;

    /// The Jacobian `H_k = dh_k/dx` at `x`.
    fn jacobian(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, M, N>;

    /// The measurement-noise covariance `R_k` at the state `x` (state-dependent noise, such as
    /// converted-measurement noise that depends on the elevation, reads `x`; constant noise
    /// ignores it). Filters pass their prior estimate. Unlike [`Dynamics::noise_cov`] it takes
    /// the state: see the [`Dynamics`] docs for why the two differ.
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
    // Always inlined, so that a borrowed linear model's draw inlines as its own does
    // (`sample_with_factor`).
    #[inline(always)]
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
    fn expected_state_dim(&self) -> Option<usize> {
        (**self).expected_state_dim()
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
    // Always inlined, so that a borrowed linear model's draw inlines as its own does
    // (`sample_with_factor`).
    #[inline(always)]
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
