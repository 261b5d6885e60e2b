//! The shifted Rayleigh filter (Clark, Vinter and Yaqoob 2007), paper 001 Alg. 2, for bearings
//! only.

use kalibra_linalg::{
    Alloc, Covariance, DefaultAllocator, Dim, OMatrix, OVector, U1, U2, Vector2, check_finite,
    propagate,
};
use kalibra_models::{Bearing, BearingReference, LinearDynamics, Measurement, Platform};

/// What the shifted Rayleigh filter needs of a bearing sensor beyond [`Measurement`]: the
/// geometry `m = L x - p_k` and the noise levels. Implemented for [`Bearing`] and for
/// references to any implementor, so a Monte Carlo study hands `&bearing` to every filter.
pub trait BearingSensor<N: Dim>: Measurement<N, U1>
where
    DefaultAllocator: Alloc<N, U1> + Alloc<N, U2>,
{
    /// The matrix `L` selecting the target position from the state.
    fn selection(&self) -> OMatrix<f64, U2, N>;
    /// The offset `p_k` with `L x - p_k` the target's position relative to the sensor.
    fn shift(&self, k: usize) -> Vector2<f64>;
    /// From which axis bearings are measured.
    fn reference(&self) -> BearingReference;
    /// The bearing noise variance `R_theta`.
    fn variance(&self) -> f64;
    /// The translational noise variances along x and y.
    fn translational_variance(&self) -> (f64, f64);
}

impl<N: Dim, P: Platform<2>> BearingSensor<N> for Bearing<N, P>
where
    DefaultAllocator: Alloc<N, U1> + Alloc<N, U2>,
{
    fn selection(&self) -> OMatrix<f64, U2, N> {
        Bearing::selection(self)
    }
    fn shift(&self, k: usize) -> Vector2<f64> {
        Bearing::shift(self, k)
    }
    fn reference(&self) -> BearingReference {
        Bearing::reference(self)
    }
    fn variance(&self) -> f64 {
        Bearing::variance(self)
    }
    fn translational_variance(&self) -> (f64, f64) {
        Bearing::translational_variance(self)
    }
}

impl<N: Dim, T: BearingSensor<N>> BearingSensor<N> for &T
where
    DefaultAllocator: Alloc<N, U1> + Alloc<N, U2>,
{
    fn selection(&self) -> OMatrix<f64, U2, N> {
        (**self).selection()
    }
    fn shift(&self, k: usize) -> Vector2<f64> {
        (**self).shift(k)
    }
    fn reference(&self) -> BearingReference {
        (**self).reference()
    }
    fn variance(&self) -> f64 {
        (**self).variance()
    }
    fn translational_variance(&self) -> (f64, f64) {
        (**self).translational_variance()
    }
}

use crate::core::{KalmanCore, UpdateParts};
use crate::kalman::core_accessors;
use crate::{Filter, FilterError, FilterOptions, StepRecord, shifted_rayleigh_moments};

/// The shifted Rayleigh filter: an exact moment-matching update for a bearing measurement
/// under a Gaussian prior, with the linear Gaussian prediction of the Kalman filter.
///
/// Notation (paper 001, Alg. 2): `L` selects the target position from the state and `p_k` is
/// the platform's offset, so the target sits at `m = L x - p_k` from the sensor
/// ([`BearingSensor`]); `b_k` is the measured bearing as a unit
/// vector, `(cos z, sin z)` for bearings from the x axis and `(sin z, cos z)` for nautical
/// ones. With the prior `x-, P-`:
///
/// * `V = L P- L^T + R_theta (|L x- - p_k|^2 + tr(L P- L^T)) I_2 + Sigma_t` (eq 30 with the
///   range term read as the squared predicted range from the platform, and the translational
///   noise covariance `Sigma_t` of problem I added);
/// * `K = P- L^T V^-1` (eq 29 lost the inverse);
/// * `y = (b^T V^-1 b)^-1/2 b^T V^-1 m`, `gamma = (b^T V^-1 b)^-1/2 rho_2(y)`,
///   `delta = (b^T V^-1 b)^-1 (2 + y rho_2(y) - rho_2(y)^2)` (eqs 31-33 with `V^-1`, not `V`,
///   and the platform subtracted);
/// * `x+ = x- + K (gamma b - m)`, i.e. `(I - K L) x- + K p_k + gamma K b`, and
///   `P+ = (I - K L) P- + delta K b b^T K^T` (eqs 27-28).
///
/// `rho_2` and the bracket of eq 33 are the mean and variance of a shifted Rayleigh variable
/// ([`shifted_rayleigh_moments`]), evaluated stably for large negative arguments.
///
/// The step record holds the exact prior and posterior. Its measurement-side fields are the
/// EKF's view at the same prior, since the SRF has none of its own: the bearing `h(x-)`, the
/// wrapped innovation, the Jacobian `H`, `R_k` (the effective bearing variance with
/// translational noise), `S = H P- H^T + R` and the gain `P- H^T S^-1`; NIS and J1/J2 on an SRF
/// record are therefore the linearised ones.
#[derive(Clone, Debug)]
pub struct Srf<N: Dim, D, B>
where
    DefaultAllocator: Alloc<N, U1> + Alloc<N, U2>,
{
    dynamics: D,
    bearing: B,
    core: KalmanCore<N, U1>,
}

impl<N: Dim, D: LinearDynamics<N>, B: BearingSensor<N>> Srf<N, D, B>
where
    DefaultAllocator: Alloc<N, U1> + Alloc<N, U2>,
{
    /// A shifted Rayleigh filter at step 0 with initial mean `x0` and covariance `p0`.
    ///
    /// # Errors
    /// [`FilterError::Initial`] for a bad initial estimate (as [`crate::Kf::new`]);
    /// [`FilterError::DimensionMismatch`] for a bearing sensor built for another state
    /// dimension than the dynamics, whose coordinates may lie outside the filter's state (as
    /// [`crate::Kf::new`]).
    pub fn new(
        dynamics: D,
        bearing: B,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
    ) -> Result<Self, FilterError> {
        Self::with_options(dynamics, bearing, x0, p0, FilterOptions::default())
    }

    /// As [`Srf::new`] with [`FilterOptions`] (the first step and the initial check; the
    /// update form is always eq 28's).
    ///
    /// # Errors
    /// As [`Srf::new`]; [`FilterError::Unsupported`] for
    /// [`InitialCheck::AsGiven`](crate::InitialCheck::AsGiven).
    pub fn with_options(
        dynamics: D,
        bearing: B,
        x0: OVector<f64, N>,
        p0: OMatrix<f64, N, N>,
        options: FilterOptions,
    ) -> Result<Self, FilterError> {
        let core = crate::kalman::checked_core(
            &dynamics,
            &bearing,
            x0,
            p0,
            options,
            Some("the SRF with an as-given initial covariance"),
        )?;
        Ok(Self {
            dynamics,
            bearing,
            core,
        })
    }

    /// The dynamics model.
    pub fn dynamics(&self) -> &D {
        &self.dynamics
    }

    /// The bearing model.
    pub fn bearing(&self) -> &B {
        &self.bearing
    }
}

impl<N: Dim, D: LinearDynamics<N>, B: BearingSensor<N>> Filter<N, U1> for Srf<N, D, B>
where
    DefaultAllocator: Alloc<N, U1> + Alloc<N, U2>,
{
    core_accessors!(U1);

    fn predict(&mut self) -> Result<(), FilterError> {
        crate::kalman::linear_predict::<false, _, _, _>(&mut self.core, &self.dynamics)
    }

    fn update(&mut self, z: &OVector<f64, U1>) -> Result<&StepRecord<N, U1>, FilterError> {
        let k = self.core.step();
        self.core.check_measurement(1, z)?;
        let prior = self.core.update_prior().clone();
        let at = |e| FilterError::at(k, e);
        let bearing = &self.bearing;

        // The EKF's view for the record.
        let zhat = bearing.measure(k, &prior.mean);
        let innovation = bearing.residual(z, &zhat);
        let h = bearing.jacobian(k, &prior.mean);
        let l = bearing.selection();
        // A Dyn sensor answering with the wrong number of columns is an error at this step
        // (the filter unchanged), not a panic inside the products below.
        let n = prior.mean.nrows();
        crate::core::check_model_output("bearing Jacobian H", &h, (1, n), k)?;
        crate::core::check_model_output("position selection L", &l, (2, n), k)?;
        let r = bearing.noise_cov(k, &prior.mean);
        let s = propagate(&h, &prior.cov) + r;
        let s = Covariance::from_symmetric(s, "linearised innovation covariance S").map_err(at)?;
        let ekf_gain = s.cholesky().solve(&(&h * &prior.cov)).transpose();

        // Alg. 2.
        let m: Vector2<f64> = &l * &prior.mean - bearing.shift(k);
        let lpl = propagate(&l, &prior.cov);
        let (tx, ty) = bearing.translational_variance();
        let range2 = m.norm_squared() + lpl.trace();
        let mut v = lpl;
        v[(0, 0)] += bearing.variance() * range2 + tx;
        v[(1, 1)] += bearing.variance() * range2 + ty;
        let v = Covariance::from_symmetric(v, "shifted Rayleigh V").map_err(at)?;
        let b = match bearing.reference() {
            BearingReference::XAxis => Vector2::new(z[0].cos(), z[0].sin()),
            BearingReference::North => Vector2::new(z[0].sin(), z[0].cos()),
        };
        let vinv_b = v.cholesky().solve(&b);
        let bvb = b.dot(&vinv_b);
        let y = vinv_b.dot(&m) / bvb.sqrt();
        let moments = shifted_rayleigh_moments(y);
        let gamma = moments.mean / bvb.sqrt();
        let delta = moments.variance / bvb;
        // K = P- L^T V^-1, as the transpose of V^-1 (L P-).
        let gain: OMatrix<f64, N, U2> = v.cholesky().solve(&(&l * &prior.cov)).transpose();
        let mean = &prior.mean + &gain * (b * gamma - m);
        let kb = &gain * b;
        let cov = &prior.cov - &gain * &l * &prior.cov + &kb * kb.transpose() * delta;
        if !(gamma.is_finite() && delta.is_finite()) {
            check_finite(&prior.mean, "prior mean").map_err(at)?;
            return Err(FilterError::NonFinite {
                what: "shifted Rayleigh statistics",
                step: k,
            });
        }
        self.core.commit_update(UpdateParts {
            zhat,
            innovation,
            h,
            r,
            s,
            gain: ekf_gain,
            mean,
            cov,
        })
    }
}
