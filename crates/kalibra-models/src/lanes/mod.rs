//! Models evaluated for [`BATCH`] Monte Carlo runs at once, in the lane layout of
//! [`kalibra_linalg::simd`] (re-exported here: [`BATCH`], [`Lanes`], [`load`], [`store`]) that
//! the batched filters of `kalibra_filters::batch` step: every scalar of a state, a measurement
//! or a matrix is a [`Lanes`] array with one entry per run.
//!
//! A batched filter asks its model for every lane's `f(x)`, `F`, `Q` ([`LaneDynamics`]) and
//! every lane's innovation `z (-) h(x)`, `H`, `R` ([`LaneMeasurement`]). [`PerLane`] answers for
//! any scalar model by calling it once per lane, exactly as the scalar filters call it; a
//! model implements the traits itself to evaluate its lanes together in SIMD (the methods are
//! generic over [`pulp::Simd`] and called inside the filter's dispatched kernel, so they
//! compile for its instruction set; implementations should be `#[inline(always)]`). The
//! models of this crate that do: [`LinearGaussian`](crate::LinearGaussian) and
//! [`LinearObservation`](crate::LinearObservation) (their matrices broadcast),
//! [`Bearing`](crate::Bearing) and [`RadarRates`](crate::RadarRates) (the arctangent of
//! [`math::atan2`]), [`AccelAxis`](crate::AccelAxis) (the sine and cosine of
//! [`math::sin_cos_lanes`]) and [`Ballistic`](crate::Ballistic) (the exponential of
//! [`math::exp_lanes`]).
//!
//! A lane-wise implementation must give each lane what the scalar calls give, to rounding:
//! the batched filters are checked against the scalar ones run by run.

pub mod math;

use kalibra_linalg::{Const, SMatrix, SVector};
use pulp::Simd;

use crate::{Dynamics, Measurement};

pub use kalibra_linalg::simd::{BATCH, Lanes, load, store};

/// Dynamics a batch evaluates for all its lanes at once: for every lane, the predicted mean
/// `f_k(x)`, the Jacobian `F_k` at `x` and the process noise `Q_k`.
pub trait LaneDynamics<const N: usize> {
    /// At step `k`: replaces each lane's mean in `x` by `f_k(x)`, and writes `F_k` evaluated
    /// at the old mean into `f` and `Q_k` into `q`, on the instruction set of `simd`.
    fn predict_lanes<S: Simd>(
        &self,
        simd: S,
        k: usize,
        x: &mut [Lanes; N],
        f: &mut [[Lanes; N]; N],
        q: &mut [[Lanes; N]; N],
    );

    /// At step `k`: replaces each lane's point in `x` by `f_k(x)` (the batched UKF's sigma
    /// points). By default through [`predict_lanes`](Self::predict_lanes), its `F` and `Q`
    /// discarded; a model overrides it to skip them.
    #[inline(always)]
    fn transition_lanes<S: Simd>(&self, simd: S, k: usize, x: &mut [Lanes; N]) {
        let mut f = [[[0.0; BATCH]; N]; N];
        let mut q = [[[0.0; BATCH]; N]; N];
        self.predict_lanes(simd, k, x, &mut f, &mut q);
    }
}

/// A measurement a batch evaluates for all its lanes at once: for every lane, the innovation
/// `nu = z (-) h_k(x)` (the model's residual, so angles wrap), the Jacobian `H_k` and the
/// noise `R_k`, all at the lane's predicted mean `x`.
pub trait LaneMeasurement<const N: usize, const M: usize> {
    /// At step `k`, for predicted means `x` and measurements `z`: writes the innovation into
    /// `nu`, `H_k(x)` into `h` and `R_k(x)` into `r`, on the instruction set of `simd`.
    #[allow(clippy::too_many_arguments)] // The lane arrays are the interface.
    fn innovate_lanes<S: Simd>(
        &self,
        simd: S,
        k: usize,
        x: &[Lanes; N],
        z: &[Lanes; M],
        nu: &mut [Lanes; M],
        h: &mut [[Lanes; N]; M],
        r: &mut [[Lanes; M]; M],
    );
}

/// A measurement a batched unscented filter evaluates at sigma points, for all lanes at once:
/// `h_k(x)` at any lane points, the model's residual `a (-) b` (angles wrap), the
/// normalisation of a predicted measurement, and `R_k(x)`.
///
/// The batched UKF calls them in the scalar UKF's order: `R_k` and `z0 = h_k(x-)` at the
/// prior mean, the residual `h_k(X_i) (-) z0` of every sigma point ([`sigma_residual_lanes`]),
/// the normalisation of `zhat = z0 + dbar`, the innovation `z (-) zhat`, and for the posterior
/// criteria of an adaptive kappa `z (-) h_k(x+)`.
///
/// [`sigma_residual_lanes`]: LaneSigmaMeasurement::sigma_residual_lanes
pub trait LaneSigmaMeasurement<const N: usize, const M: usize> {
    /// Writes each lane's `h_k(x)` into `z`, on the instruction set of `simd`.
    fn measure_lanes<S: Simd>(&self, simd: S, k: usize, x: &[Lanes; N], z: &mut [Lanes; M]);

    /// Writes each lane's residual `a (-) b` (the scalar model's `residual(a, b)`) into `out`.
    fn residual_lanes<S: Simd>(
        &self,
        simd: S,
        a: &[Lanes; M],
        b: &[Lanes; M],
        out: &mut [Lanes; M],
    );

    /// Brings each lane's `z` into its canonical range (the scalar model's `normalize`).
    fn normalize_lanes<S: Simd>(&self, simd: S, z: &mut [Lanes; M]);

    /// Writes each lane's `R_k(x)` into `r`.
    fn noise_lanes<S: Simd>(&self, simd: S, k: usize, x: &[Lanes; N], r: &mut [[Lanes; M]; M]);

    /// Writes each lane's `h_k(x) (-) z0` into `out`: a sigma point's measurement as a
    /// residual from the central one (so bearings are unwrapped around it). By default
    /// [`measure_lanes`](Self::measure_lanes) then [`residual_lanes`](Self::residual_lanes).
    #[inline(always)]
    fn sigma_residual_lanes<S: Simd>(
        &self,
        simd: S,
        k: usize,
        x: &[Lanes; N],
        z0: &[Lanes; M],
        out: &mut [Lanes; M],
    ) {
        let mut hx = [[0.0; BATCH]; M];
        self.measure_lanes(simd, k, x, &mut hx);
        self.residual_lanes(simd, &hx, z0, out);
    }
}

impl<const N: usize, const M: usize, T: LaneSigmaMeasurement<N, M>> LaneSigmaMeasurement<N, M>
    for &T
{
    #[inline(always)]
    fn measure_lanes<S: Simd>(&self, simd: S, k: usize, x: &[Lanes; N], z: &mut [Lanes; M]) {
        (**self).measure_lanes(simd, k, x, z);
    }

    #[inline(always)]
    fn residual_lanes<S: Simd>(
        &self,
        simd: S,
        a: &[Lanes; M],
        b: &[Lanes; M],
        out: &mut [Lanes; M],
    ) {
        (**self).residual_lanes(simd, a, b, out);
    }

    #[inline(always)]
    fn normalize_lanes<S: Simd>(&self, simd: S, z: &mut [Lanes; M]) {
        (**self).normalize_lanes(simd, z);
    }

    #[inline(always)]
    fn noise_lanes<S: Simd>(&self, simd: S, k: usize, x: &[Lanes; N], r: &mut [[Lanes; M]; M]) {
        (**self).noise_lanes(simd, k, x, r);
    }

    #[inline(always)]
    fn sigma_residual_lanes<S: Simd>(
        &self,
        simd: S,
        k: usize,
        x: &[Lanes; N],
        z0: &[Lanes; M],
        out: &mut [Lanes; M],
    ) {
        (**self).sigma_residual_lanes(simd, k, x, z0, out);
    }
}

impl<const N: usize, T: LaneDynamics<N>> LaneDynamics<N> for &T {
    #[inline(always)]
    fn predict_lanes<S: Simd>(
        &self,
        simd: S,
        k: usize,
        x: &mut [Lanes; N],
        f: &mut [[Lanes; N]; N],
        q: &mut [[Lanes; N]; N],
    ) {
        (**self).predict_lanes(simd, k, x, f, q);
    }

    #[inline(always)]
    fn transition_lanes<S: Simd>(&self, simd: S, k: usize, x: &mut [Lanes; N]) {
        (**self).transition_lanes(simd, k, x);
    }
}

impl<const N: usize, const M: usize, T: LaneMeasurement<N, M>> LaneMeasurement<N, M> for &T {
    #[inline(always)]
    fn innovate_lanes<S: Simd>(
        &self,
        simd: S,
        k: usize,
        x: &[Lanes; N],
        z: &[Lanes; M],
        nu: &mut [Lanes; M],
        h: &mut [[Lanes; N]; M],
        r: &mut [[Lanes; M]; M],
    ) {
        (**self).innovate_lanes(simd, k, x, z, nu, h, r);
    }
}

/// A scalar model evaluated lane by lane: the [`LaneDynamics`] of a [`Dynamics`], and the
/// [`LaneMeasurement`] and [`LaneSigmaMeasurement`] of a [`Measurement`], through exactly the
/// calls the scalar EKF and UKF make.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PerLane<T>(pub T);

/// Lane `l` of `x` as a vector.
pub fn lane<const N: usize>(x: &[Lanes; N], l: usize) -> SVector<f64, N> {
    SVector::from_fn(|i, _| x[i][l])
}

/// Writes the vector `v` into lane `l` of `out` (the inverse of [`lane`]).
pub fn set_lane_vector<const N: usize>(out: &mut [Lanes; N], l: usize, v: &SVector<f64, N>) {
    for (o, x) in out.iter_mut().zip(v.iter()) {
        o[l] = *x;
    }
}

/// Writes `m` into lane `l` of `out`.
pub fn set_lane<const R: usize, const C: usize>(
    out: &mut [[Lanes; C]; R],
    l: usize,
    m: &SMatrix<f64, R, C>,
) {
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            v[l] = m[(i, j)];
        }
    }
}

/// Writes `m` into every lane of `out` (a model's matrix shared by all runs).
pub fn broadcast<const R: usize, const C: usize>(
    out: &mut [[Lanes; C]; R],
    m: &SMatrix<f64, R, C>,
) {
    for (i, row) in out.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = [m[(i, j)]; BATCH];
        }
    }
}

impl<const N: usize, T: Dynamics<Const<N>>> LaneDynamics<N> for PerLane<T> {
    fn predict_lanes<S: Simd>(
        &self,
        _simd: S,
        k: usize,
        x: &mut [Lanes; N],
        f: &mut [[Lanes; N]; N],
        q: &mut [[Lanes; N]; N],
    ) {
        for l in 0..BATCH {
            let xl = lane(x, l);
            let pred = self.0.transition(k, &xl);
            set_lane(f, l, &self.0.jacobian(k, &xl));
            set_lane(q, l, &self.0.noise_cov(k));
            set_lane_vector(x, l, &pred);
        }
    }

    fn transition_lanes<S: Simd>(&self, _simd: S, k: usize, x: &mut [Lanes; N]) {
        for l in 0..BATCH {
            let pred = self.0.transition(k, &lane(x, l));
            set_lane_vector(x, l, &pred);
        }
    }
}

impl<const N: usize, const M: usize, T: Measurement<Const<N>, Const<M>>> LaneMeasurement<N, M>
    for PerLane<T>
{
    fn innovate_lanes<S: Simd>(
        &self,
        _simd: S,
        k: usize,
        x: &[Lanes; N],
        z: &[Lanes; M],
        nu: &mut [Lanes; M],
        h: &mut [[Lanes; N]; M],
        r: &mut [[Lanes; M]; M],
    ) {
        for l in 0..BATCH {
            let xl = lane(x, l);
            let zhat = self.0.measure(k, &xl);
            let residual = self.0.residual(&lane(z, l), &zhat);
            set_lane_vector(nu, l, &residual);
            set_lane(h, l, &self.0.jacobian(k, &xl));
            set_lane(r, l, &self.0.noise_cov(k, &xl));
        }
    }
}

impl<const N: usize, const M: usize, T: Measurement<Const<N>, Const<M>>> LaneSigmaMeasurement<N, M>
    for PerLane<T>
{
    fn measure_lanes<S: Simd>(&self, _simd: S, k: usize, x: &[Lanes; N], z: &mut [Lanes; M]) {
        for l in 0..BATCH {
            let zl = self.0.measure(k, &lane(x, l));
            set_lane_vector(z, l, &zl);
        }
    }

    fn residual_lanes<S: Simd>(
        &self,
        _simd: S,
        a: &[Lanes; M],
        b: &[Lanes; M],
        out: &mut [Lanes; M],
    ) {
        for l in 0..BATCH {
            let e = self.0.residual(&lane(a, l), &lane(b, l));
            set_lane_vector(out, l, &e);
        }
    }

    fn normalize_lanes<S: Simd>(&self, _simd: S, z: &mut [Lanes; M]) {
        for l in 0..BATCH {
            let mut zl = lane(z, l);
            self.0.normalize(&mut zl);
            set_lane_vector(z, l, &zl);
        }
    }

    fn noise_lanes<S: Simd>(&self, _simd: S, k: usize, x: &[Lanes; N], r: &mut [[Lanes; M]; M]) {
        for l in 0..BATCH {
            set_lane(r, l, &self.0.noise_cov(k, &lane(x, l)));
        }
    }

    // One scalar pass per lane: `measure` then `residual`, as the scalar UKF calls them,
    // without the round trip through lane arrays.
    fn sigma_residual_lanes<S: Simd>(
        &self,
        _simd: S,
        k: usize,
        x: &[Lanes; N],
        z0: &[Lanes; M],
        out: &mut [Lanes; M],
    ) {
        for l in 0..BATCH {
            let e = self
                .0
                .residual(&self.0.measure(k, &lane(x, l)), &lane(z0, l));
            set_lane_vector(out, l, &e);
        }
    }
}
