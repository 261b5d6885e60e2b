//! Linear-Gaussian models and the known-input combinator.

use kalibra_linalg::{
    Alloc, DefaultAllocator, Dim, OMatrix, OVector, PsdMatrix, check_dim, check_finite,
};
use rand::Rng;

use crate::noise::sample_with_factor;
use crate::{Dynamics, LinearDynamics, LinearMeasurement, Measurement, ModelError};

/// Time-invariant linear dynamics `x_{k+1} = F x_k + w_k`, `w_k ~ N(0, Q)`.
///
/// `Q` may be singular (a white-noise-acceleration `Q = q G G^T` has rank equal to the number of
/// axes); its semi-definite factor is computed once and used for every draw.
///
/// ```
/// use kalibra_models::{Dynamics, LinearGaussian};
/// use kalibra_linalg::{Matrix2, Vector2};
///
/// let model = LinearGaussian::new(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity() * 0.1)?;
/// assert_eq!(model.transition(0, &Vector2::new(1.0, 2.0)), Vector2::new(3.0, 2.0));
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Debug)]
pub struct LinearGaussian<N: Dim>
where
    DefaultAllocator: Alloc<N>,
{
    f: OMatrix<f64, N, N>,
    q: PsdMatrix<N>,
}

impl<N: Dim> LinearGaussian<N>
where
    DefaultAllocator: Alloc<N>,
{
    /// A model from its transition matrix `F` and noise covariance `Q`.
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] if `F` and `Q` differ in size or are not square,
    /// [`ModelError::Linalg`] if `F` is not finite or `Q` is not symmetric positive
    /// semi-definite.
    pub fn new(f: OMatrix<f64, N, N>, q: OMatrix<f64, N, N>) -> Result<Self, ModelError> {
        check_dim(f.nrows(), f.ncols(), "transition matrix F")?;
        check_dim(f.nrows(), q.nrows(), "process noise covariance Q")?;
        check_finite(&f, "transition matrix F")?;
        let q = PsdMatrix::named(q, "process noise covariance Q")?;
        Ok(Self { f, q })
    }

    /// The transition matrix `F`.
    pub fn f(&self) -> &OMatrix<f64, N, N> {
        &self.f
    }

    /// The process-noise covariance `Q` with its factor.
    pub fn q(&self) -> &PsdMatrix<N> {
        &self.q
    }

    /// The same dynamics with `Q` scaled by `factor` (a tuning sweep's `Q = 10^p Q_nom`).
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] unless `factor` is finite and non-negative.
    pub fn with_noise_scaled(&self, factor: f64) -> Result<Self, ModelError> {
        if !(factor.is_finite() && factor >= 0.0) {
            return Err(ModelError::InvalidParameter {
                name: "noise scale",
                value: factor,
            });
        }
        Self::new(self.f.clone(), self.q.matrix() * factor)
    }
}

impl<N: Dim> Dynamics<N> for LinearGaussian<N>
where
    DefaultAllocator: Alloc<N>,
{
    fn state_dim(&self) -> N {
        self.f.shape_generic().0
    }
    fn transition(&self, _k: usize, x: &OVector<f64, N>) -> OVector<f64, N> {
        &self.f * x
    }
    fn jacobian(&self, _k: usize, _x: &OVector<f64, N>) -> OMatrix<f64, N, N> {
        self.f.clone()
    }
    fn noise_cov(&self, _k: usize) -> OMatrix<f64, N, N> {
        self.q.matrix().clone()
    }
    // Always inlined, as `sample_with_factor` (which says why).
    #[inline(always)]
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        _k: usize,
        rng: &mut R,
    ) -> Result<OVector<f64, N>, ModelError> {
        Ok(sample_with_factor(self.q.factor(), rng))
    }
}

/// Lane-wise: `x = F x` across the lanes (products accumulated in column order with fused
/// multiply-adds where the instruction set has them), `F` and `Q` broadcast to every lane.
impl<const N: usize> crate::lanes::LaneDynamics<N> for LinearGaussian<kalibra_linalg::Const<N>> {
    #[inline(always)]
    fn predict_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        _k: usize,
        x: &mut [crate::lanes::Lanes; N],
        f: &mut [[crate::lanes::Lanes; N]; N],
        q: &mut [[crate::lanes::Lanes; N]; N],
    ) {
        use crate::lanes::{BATCH, broadcast, load, store};
        let fm = &self.f;
        for c in 0..BATCH / S::F64_LANES {
            let mut xc = [simd.splat_f64s(0.0); N];
            for (i, v) in xc.iter_mut().enumerate() {
                *v = load::<S>(&x[i], c);
            }
            for (i, xi) in x.iter_mut().enumerate() {
                let mut s = simd.mul_f64s(simd.splat_f64s(fm[(i, 0)]), xc[0]);
                for (j, v) in xc.iter().enumerate().skip(1) {
                    s = simd.mul_add_e_f64s(simd.splat_f64s(fm[(i, j)]), *v, s);
                }
                store::<S>(xi, c, s);
            }
        }
        broadcast(f, fm);
        broadcast(q, self.q.matrix());
    }
}

impl<N: Dim> LinearDynamics<N> for LinearGaussian<N>
where
    DefaultAllocator: Alloc<N>,
{
    fn matrix(&self, _k: usize) -> OMatrix<f64, N, N> {
        self.f.clone()
    }
}

/// Time-invariant linear measurement `z_k = H x_k + v_k`, `v_k ~ N(0, R)`.
#[derive(Clone, Debug)]
pub struct LinearObservation<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    h: OMatrix<f64, M, N>,
    r: PsdMatrix<M>,
}

impl<N: Dim, M: Dim> LinearObservation<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    /// A measurement from its matrix `H` (m x n) and noise covariance `R` (m x m).
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] if `R` does not match the rows of `H`,
    /// [`ModelError::Linalg`] if `H` is not finite or `R` is not symmetric positive
    /// semi-definite.
    pub fn new(h: OMatrix<f64, M, N>, r: OMatrix<f64, M, M>) -> Result<Self, ModelError> {
        check_dim(h.nrows(), r.nrows(), "measurement noise covariance R")?;
        check_finite(&h, "measurement matrix H")?;
        let r = PsdMatrix::named(r, "measurement noise covariance R")?;
        Ok(Self { h, r })
    }

    /// The measurement matrix `H`.
    pub fn h(&self) -> &OMatrix<f64, M, N> {
        &self.h
    }

    /// The noise covariance `R` with its factor.
    pub fn r(&self) -> &PsdMatrix<M> {
        &self.r
    }
}

impl<N: Dim, M: Dim> Measurement<N, M> for LinearObservation<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn meas_dim(&self) -> M {
        self.h.shape_generic().0
    }
    fn expected_state_dim(&self) -> Option<usize> {
        Some(self.h.ncols())
    }
    fn measure(&self, _k: usize, x: &OVector<f64, N>) -> OVector<f64, M> {
        &self.h * x
    }
    fn jacobian(&self, _k: usize, _x: &OVector<f64, N>) -> OMatrix<f64, M, N> {
        self.h.clone()
    }
    fn noise_cov(&self, _k: usize, _x: &OVector<f64, N>) -> OMatrix<f64, M, M> {
        self.r.matrix().clone()
    }
    // Always inlined, as `sample_with_factor` (which says why).
    #[inline(always)]
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        _k: usize,
        _x: &OVector<f64, N>,
        rng: &mut R,
    ) -> Result<OVector<f64, M>, ModelError> {
        Ok(sample_with_factor(self.r.factor(), rng))
    }
}

/// Lane-wise: `nu = z - H x` across the lanes (`H x` accumulated in column order with fused
/// multiply-adds where the instruction set has them), `H` and `R` broadcast to every lane.
impl<const N: usize, const M: usize> crate::lanes::LaneMeasurement<N, M>
    for LinearObservation<kalibra_linalg::Const<N>, kalibra_linalg::Const<M>>
{
    #[inline(always)]
    fn innovate_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        _k: usize,
        x: &[crate::lanes::Lanes; N],
        z: &[crate::lanes::Lanes; M],
        nu: &mut [crate::lanes::Lanes; M],
        h: &mut [[crate::lanes::Lanes; N]; M],
        r: &mut [[crate::lanes::Lanes; M]; M],
    ) {
        use crate::lanes::{BATCH, broadcast, load, store};
        let hm = &self.h;
        for c in 0..BATCH / S::F64_LANES {
            for (i, nu_i) in nu.iter_mut().enumerate() {
                let mut s = simd.mul_f64s(simd.splat_f64s(hm[(i, 0)]), load::<S>(&x[0], c));
                for (j, xj) in x.iter().enumerate().skip(1) {
                    s = simd.mul_add_e_f64s(simd.splat_f64s(hm[(i, j)]), load::<S>(xj, c), s);
                }
                store::<S>(nu_i, c, simd.sub_f64s(load::<S>(&z[i], c), s));
            }
        }
        broadcast(h, hm);
        broadcast(r, self.r.matrix());
    }
}

impl<N: Dim, M: Dim> LinearMeasurement<N, M> for LinearObservation<N, M>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn matrix(&self, _k: usize) -> OMatrix<f64, M, N> {
        self.h.clone()
    }
}

/// Dynamics with a known additive input: `f_k(x) = g_k(x) + u_k`, where `u_k` is already in
/// state coordinates (for gravity through an input matrix, `u_k = G [0, -g]^T`).
///
/// The input shifts the state but not the Jacobian or the noise, so a linear model stays
/// linear.
///
/// ```
/// use kalibra_models::{Dynamics, LinearGaussian, WithInput};
/// use kalibra_linalg::{Matrix2, Vector2};
///
/// let free = LinearGaussian::new(Matrix2::identity(), Matrix2::zeros())?;
/// let pushed = WithInput::new(free, |k: usize| Vector2::new(k as f64, 0.0));
/// assert_eq!(pushed.transition(3, &Vector2::new(1.0, 1.0)), Vector2::new(4.0, 1.0));
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Debug)]
pub struct WithInput<D, U> {
    inner: D,
    input: U,
}

impl<D, U> WithInput<D, U> {
    /// Adds the input `u_k = input(k)` to `inner`.
    pub fn new(inner: D, input: U) -> Self {
        Self { inner, input }
    }

    /// The dynamics without the input.
    pub fn inner(&self) -> &D {
        &self.inner
    }
}

impl<N: Dim, D: Dynamics<N>, U: Fn(usize) -> OVector<f64, N>> Dynamics<N> for WithInput<D, U>
where
    DefaultAllocator: Alloc<N>,
{
    fn state_dim(&self) -> N {
        self.inner.state_dim()
    }
    fn transition(&self, k: usize, x: &OVector<f64, N>) -> OVector<f64, N> {
        self.inner.transition(k, x) + (self.input)(k)
    }
    fn jacobian(&self, k: usize, x: &OVector<f64, N>) -> OMatrix<f64, N, N> {
        self.inner.jacobian(k, x)
    }
    fn noise_cov(&self, k: usize) -> OMatrix<f64, N, N> {
        self.inner.noise_cov(k)
    }
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        k: usize,
        rng: &mut R,
    ) -> Result<OVector<f64, N>, ModelError> {
        self.inner.sample_noise(k, rng)
    }
}

impl<N: Dim, D: LinearDynamics<N>, U: Fn(usize) -> OVector<f64, N>> LinearDynamics<N>
    for WithInput<D, U>
where
    DefaultAllocator: Alloc<N>,
{
    fn matrix(&self, k: usize) -> OMatrix<f64, N, N> {
        self.inner.matrix(k)
    }
}
