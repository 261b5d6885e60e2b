//! A 3-D target with nonlinear acceleration: `f(x) = A x + u(x)` on the state
//! `[p_x, v_x, a_x, p_y, v_y, a_y, p_z, v_z, a_z]`, and its per-axis blocks.
//!
//! The model is the one of Spall and Wei, "Uncertainty bounds for state estimates with
//! applications in target tracking" (AIAA Defense Forum 2023), with every coefficient a
//! parameter ([`Target3dParams`]).
//!
//! Every block of `A`, `u`, `Q` (and of the measurement models offered here) acts on one axis
//! only, so the 9-state model is three independent 3-state models ([`AccelAxis`]) side by
//! side; a filter on the 9-state model equals three filters on the axes when its initial
//! covariance is block-diagonal too (tested). Studies use the axes for speed.

use kalibra_linalg::nalgebra::{Matrix1x3, Matrix2x3, SMatrix, SVector};
use kalibra_linalg::{Matrix1, Matrix2, Matrix3, U3, U9, Vector3};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::{Dynamics, LinearObservation, ModelError};

/// 9 x 9 matrices (inside this module; public signatures spell `SMatrix<f64, 9, 9>`, since
/// a private alias there would name a type users cannot see).
type Matrix9 = SMatrix<f64, 9, 9>;
/// 9-vectors.
type Vector9 = SMatrix<f64, 9, 1>;

/// The parameters of a [`Target3d`] (and of each [`AccelAxis`]), by name.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target3dParams {
    /// Sampling interval `dt` (s).
    pub dt: f64,
    /// Process-noise scale `sigma_w`: each axis's noise is `sigma_w b n`,
    /// `b = [dt^2/2, dt, 1]`, `n ~ N(0, 1)`.
    pub sigma_w: f64,
    /// The `(2, 2)` entry of each block of `A` (velocity row): 1 in a constant-acceleration
    /// block; 0 makes velocity forget itself every step.
    pub velocity_diagonal: f64,
    /// The linear coefficient `c_a` of the acceleration in `u`: with `A`'s 1 the acceleration
    /// map is `a' = (1 + c_a) a + amp g(a)` (-0.5 gives `0.5 a + amp g(a)`, -1 gives
    /// `amp g(a)` alone).
    pub accel_coefficient: f64,
    /// Amplitude `amp` of the sine (x, z) or cosine (y) term `g` in `u`.
    pub accel_amplitude: f64,
    /// Linear damping `d` of position and velocity in `u`, per axis (x, y, z); 0 for none,
    /// negative to pull position and velocity toward zero.
    pub damping: [f64; 3],
}

impl Default for Target3dParams {
    /// A constant-acceleration block per axis (velocity diagonal 1, no damping) with unit noise
    /// scale at `dt = 0.1`, whose acceleration follows `a' = 0.5 a + 0.5 g(a)`: a contraction,
    /// so the acceleration stays bounded while position and velocity integrate it.
    fn default() -> Self {
        Self {
            dt: 0.1,
            sigma_w: 1.0,
            velocity_diagonal: 1.0,
            accel_coefficient: -0.5,
            accel_amplitude: 0.5,
            damping: [0.0; 3],
        }
    }
}

impl Target3dParams {
    fn check(&self) -> Result<(), ModelError> {
        let named = [
            ("dt", self.dt),
            ("sigma_w", self.sigma_w),
            ("velocity_diagonal", self.velocity_diagonal),
            ("accel_coefficient", self.accel_coefficient),
            ("accel_amplitude", self.accel_amplitude),
            ("damping x", self.damping[0]),
            ("damping y", self.damping[1]),
            ("damping z", self.damping[2]),
        ];
        for (name, value) in named {
            if !value.is_finite() {
                return Err(ModelError::InvalidParameter { name, value });
            }
        }
        if self.dt <= 0.0 {
            return Err(ModelError::InvalidParameter {
                name: "dt",
                value: self.dt,
            });
        }
        if self.sigma_w < 0.0 {
            return Err(ModelError::InvalidParameter {
                name: "sigma_w",
                value: self.sigma_w,
            });
        }
        Ok(())
    }
}

/// One axis of a [`Target3d`]: state `[p, v, a]`,
/// `p' = (1 + d) p + dt v + dt^2/2 a`, `v' = (c_v + d) v + dt a`,
/// `a' = (1 + c_a) a + amp g(a)` with `g = sin` on the x and z axes and `cos` on y, plus the
/// rank-one noise `sigma_w b n`, `b = [dt^2/2, dt, 1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccelAxis {
    params: Target3dParams,
    axis: usize,
}

impl AccelAxis {
    /// Axis `axis` (0 = x, 1 = y, 2 = z) of the target with `params`.
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] for an axis above 2, a non-finite parameter, `dt <= 0`
    /// or `sigma_w < 0`.
    pub fn new(params: Target3dParams, axis: usize) -> Result<Self, ModelError> {
        params.check()?;
        if axis > 2 {
            return Err(ModelError::InvalidParameter {
                name: "axis",
                value: axis as f64,
            });
        }
        Ok(Self { params, axis })
    }

    /// The noise direction `b = [dt^2/2, dt, 1]`.
    pub fn noise_direction(&self) -> Vector3<f64> {
        let dt = self.params.dt;
        Vector3::new(0.5 * dt * dt, dt, 1.0)
    }

    /// `g(a)` and `g'(a)`: sine on x and z, cosine on y.
    fn g(&self, a: f64) -> (f64, f64) {
        if self.axis == 1 {
            (a.cos(), -a.sin())
        } else {
            (a.sin(), a.cos())
        }
    }

    /// Position measurement of this axis, `z = p + v`, `v ~ N(0, r)`.
    ///
    /// # Errors
    /// [`ModelError::Linalg`] unless `r` is finite and non-negative.
    pub fn position_measurement(
        r: f64,
    ) -> Result<LinearObservation<U3, kalibra_linalg::U1>, ModelError> {
        LinearObservation::new(Matrix1x3::new(1.0, 0.0, 0.0), Matrix1::new(r))
    }

    /// Position and velocity of this axis, `R = r I2`.
    ///
    /// # Errors
    /// [`ModelError::Linalg`] unless `r` is finite and non-negative.
    pub fn position_velocity_measurement(
        r: f64,
    ) -> Result<LinearObservation<U3, kalibra_linalg::U2>, ModelError> {
        LinearObservation::new(
            Matrix2x3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
            Matrix2::identity() * r,
        )
    }
}

impl AccelAxis {
    /// `F` given the slope `g'(a)` of the acceleration term: the only entry that depends on
    /// the state.
    fn jacobian_at_slope(&self, dg: f64) -> Matrix3<f64> {
        let p = &self.params;
        let (dt, d) = (p.dt, p.damping[self.axis]);
        Matrix3::new(
            1.0 + d,
            dt,
            0.5 * dt * dt,
            0.0,
            p.velocity_diagonal + d,
            dt,
            0.0,
            0.0,
            1.0 + p.accel_coefficient + p.accel_amplitude * dg,
        )
    }

    /// `g(a)` and `g'(a)` of every lane of `a` (sine on x and z, cosine on y), from one
    /// [`sin_cos_lanes`](crate::lanes::math::sin_cos_lanes) (within 2 ulp of glibc's).
    #[inline(always)]
    fn g_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        a: &crate::lanes::Lanes,
    ) -> (crate::lanes::Lanes, crate::lanes::Lanes) {
        let (sin, cos) = crate::lanes::math::sin_cos_lanes(simd, a);
        if self.axis == 1 {
            (cos, sin.map(|v| -v))
        } else {
            (sin, cos)
        }
    }

    /// Replaces every lane of `x` by `f(x)` given `g(a)` of its lanes, in the scalar
    /// [`Dynamics::transition`]'s order of operations.
    #[inline(always)]
    fn advance_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        x: &mut [crate::lanes::Lanes; 3],
        g: &crate::lanes::Lanes,
    ) {
        use crate::lanes::{BATCH, load, store};
        let p = &self.params;
        let (dt, d) = (p.dt, p.damping[self.axis]);
        let sp = |v: f64| simd.splat_f64s(v);
        let (a_p, a_v, a_a) = (sp(1.0 + d), sp(dt), sp(0.5 * dt * dt));
        let b_v = sp(p.velocity_diagonal + d);
        let (c_a, amp) = (sp(1.0 + p.accel_coefficient), sp(p.accel_amplitude));
        for c in 0..BATCH / S::F64_LANES {
            let (xp, xv, xa) = (
                load::<S>(&x[0], c),
                load::<S>(&x[1], c),
                load::<S>(&x[2], c),
            );
            let (mul, add) = (|a, b| simd.mul_f64s(a, b), |a, b| simd.add_f64s(a, b));
            let np = add(add(mul(a_p, xp), mul(a_v, xv)), mul(a_a, xa));
            let nv = add(mul(b_v, xv), mul(a_v, xa));
            let na = add(mul(c_a, xa), mul(amp, load::<S>(g, c)));
            store::<S>(&mut x[0], c, np);
            store::<S>(&mut x[1], c, nv);
            store::<S>(&mut x[2], c, na);
        }
    }

    /// Writes `F` at every lane of `x` into `f` given `g'(a)` of its lanes: the constant
    /// entries broadcast, `F[2][2] = (1 + c_a) + amp g'(a)`.
    #[inline(always)]
    fn jacobian_into_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        dg: &crate::lanes::Lanes,
        f: &mut [[crate::lanes::Lanes; 3]; 3],
    ) {
        use crate::lanes::{BATCH, broadcast, load, store};
        let p = &self.params;
        // The constant entries; F[2][2] is overwritten below.
        broadcast(f, &self.jacobian_at_slope(0.0));
        let (c_a, amp) = (
            simd.splat_f64s(1.0 + p.accel_coefficient),
            simd.splat_f64s(p.accel_amplitude),
        );
        for c in 0..BATCH / S::F64_LANES {
            let v = simd.add_f64s(c_a, simd.mul_f64s(amp, load::<S>(dg, c)));
            store::<S>(&mut f[2][2], c, v);
        }
    }

    /// Lane-wise [`Dynamics::jacobian`]: `F` at every lane of `x` into `f`, on the
    /// instruction set of `simd`.
    #[inline(always)]
    pub fn jacobian_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        x: &[crate::lanes::Lanes; 3],
        f: &mut [[crate::lanes::Lanes; 3]; 3],
    ) {
        let (_, dg) = self.g_lanes(simd, &x[2]);
        self.jacobian_into_lanes(simd, &dg, f);
    }
}

/// Lane-wise: `f(x)` and `F` at `x` across the lanes in the scalar model's order of
/// operations, with one [`sin_cos_lanes`](crate::lanes::math::sin_cos_lanes) per step for both
/// `g(a)` and `g'(a)` (within 2 ulp of glibc's), and the constant `Q` broadcast.
impl crate::lanes::LaneDynamics<3> for AccelAxis {
    #[inline(always)]
    fn predict_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        k: usize,
        x: &mut [crate::lanes::Lanes; 3],
        f: &mut [[crate::lanes::Lanes; 3]; 3],
        q: &mut [[crate::lanes::Lanes; 3]; 3],
    ) {
        let (g, dg) = self.g_lanes(simd, &x[2]);
        // F at the old a, before the mean moves.
        self.jacobian_into_lanes(simd, &dg, f);
        crate::lanes::broadcast(q, &self.noise_cov(k));
        self.advance_lanes(simd, x, &g);
    }

    /// `f(x)` alone (the prediction's mean, to the bit): for simulating truths together, and
    /// for the batched UKF's sigma points.
    #[inline(always)]
    fn transition_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        _k: usize,
        x: &mut [crate::lanes::Lanes; 3],
    ) {
        let (g, _) = self.g_lanes(simd, &x[2]);
        self.advance_lanes(simd, x, &g);
    }
}

impl Dynamics<U3> for AccelAxis {
    fn state_dim(&self) -> U3 {
        U3
    }
    fn transition(&self, _k: usize, x: &Vector3<f64>) -> Vector3<f64> {
        let p = &self.params;
        let (dt, d) = (p.dt, p.damping[self.axis]);
        let (g, _) = self.g(x[2]);
        Vector3::new(
            (1.0 + d) * x[0] + dt * x[1] + 0.5 * dt * dt * x[2],
            (p.velocity_diagonal + d) * x[1] + dt * x[2],
            (1.0 + p.accel_coefficient) * x[2] + p.accel_amplitude * g,
        )
    }
    fn jacobian(&self, _k: usize, x: &Vector3<f64>) -> Matrix3<f64> {
        self.jacobian_at_slope(self.g(x[2]).1)
    }
    fn noise_cov(&self, _k: usize) -> Matrix3<f64> {
        let b = self.noise_direction() * self.params.sigma_w;
        b * b.transpose()
    }
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        _k: usize,
        rng: &mut R,
    ) -> Result<Vector3<f64>, ModelError> {
        // Exact sampling of the rank-one Q: one normal along b.
        let n: f64 = StandardNormal.sample(rng);
        Ok(self.noise_direction() * (self.params.sigma_w * n))
    }
}

/// The 9-state target, `f(x) = A x + u(x)`: three [`AccelAxis`] blocks in the state order
/// `[p_x, v_x, a_x, p_y, v_y, a_y, p_z, v_z, a_z]`.
///
/// ```
/// use kalibra_models::{check_dynamics_jacobian, Target3d, Target3dParams};
/// use kalibra_linalg::nalgebra::SVector;
///
/// let target = Target3d::new(Target3dParams::default())?;
/// let x = SVector::<f64, 9>::from_fn(|i, _| 0.3 * i as f64 - 1.0);
/// assert!(check_dynamics_jacobian(&target, 0, &x).scaled_error < 1e-8);
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target3d {
    axes: [AccelAxis; 3],
}

impl Target3d {
    /// The target with `params`.
    ///
    /// # Errors
    /// As [`AccelAxis::new`].
    pub fn new(params: Target3dParams) -> Result<Self, ModelError> {
        Ok(Self {
            axes: [
                AccelAxis::new(params, 0)?,
                AccelAxis::new(params, 1)?,
                AccelAxis::new(params, 2)?,
            ],
        })
    }

    /// The per-axis models (x, y, z).
    pub fn axes(&self) -> &[AccelAxis; 3] {
        &self.axes
    }

    /// Positions observed, `R = r I3`.
    ///
    /// # Errors
    /// [`ModelError::Linalg`] unless `r` is finite and non-negative.
    pub fn position_measurement(
        r: f64,
    ) -> Result<LinearObservation<U9, kalibra_linalg::U3>, ModelError> {
        let mut h = SMatrix::<f64, 3, 9>::zeros();
        for axis in 0..3 {
            h[(axis, 3 * axis)] = 1.0;
        }
        LinearObservation::new(h, Matrix3::identity() * r)
    }

    /// Positions and velocities observed, `R = r I6`, measurement order
    /// `[p_x, v_x, p_y, v_y, p_z, v_z]` (per axis, as the axis models).
    ///
    /// # Errors
    /// [`ModelError::Linalg`] unless `r` is finite and non-negative.
    pub fn position_velocity_measurement(
        r: f64,
    ) -> Result<LinearObservation<U9, kalibra_linalg::U6>, ModelError> {
        let mut h = SMatrix::<f64, 6, 9>::zeros();
        for axis in 0..3 {
            h[(2 * axis, 3 * axis)] = 1.0;
            h[(2 * axis + 1, 3 * axis + 1)] = 1.0;
        }
        LinearObservation::new(h, SMatrix::<f64, 6, 6>::identity() * r)
    }
}

fn block(x: &Vector9, axis: usize) -> Vector3<f64> {
    Vector3::new(x[3 * axis], x[3 * axis + 1], x[3 * axis + 2])
}

impl Dynamics<U9> for Target3d {
    fn state_dim(&self) -> U9 {
        U9
    }
    fn transition(&self, k: usize, x: &SVector<f64, 9>) -> SVector<f64, 9> {
        let mut out = Vector9::zeros();
        for (axis, model) in self.axes.iter().enumerate() {
            out.fixed_rows_mut::<3>(3 * axis)
                .copy_from(&model.transition(k, &block(x, axis)));
        }
        out
    }
    fn jacobian(&self, k: usize, x: &SVector<f64, 9>) -> SMatrix<f64, 9, 9> {
        let mut out = Matrix9::zeros();
        for (axis, model) in self.axes.iter().enumerate() {
            out.fixed_view_mut::<3, 3>(3 * axis, 3 * axis)
                .copy_from(&model.jacobian(k, &block(x, axis)));
        }
        out
    }
    fn noise_cov(&self, k: usize) -> SMatrix<f64, 9, 9> {
        let mut out = Matrix9::zeros();
        for (axis, model) in self.axes.iter().enumerate() {
            out.fixed_view_mut::<3, 3>(3 * axis, 3 * axis)
                .copy_from(&model.noise_cov(k));
        }
        out
    }
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        k: usize,
        rng: &mut R,
    ) -> Result<SVector<f64, 9>, ModelError> {
        let mut out = Vector9::zeros();
        for (axis, model) in self.axes.iter().enumerate() {
            out.fixed_rows_mut::<3>(3 * axis)
                .copy_from(&model.sample_noise(k, rng)?);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check_dynamics_jacobian;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn jacobians_match_finite_differences() {
        let mut params = Target3dParams::default();
        for coefficient in [-0.5, -1.0] {
            params.accel_coefficient = coefficient;
            let target = Target3d::new(params).unwrap();
            let x = Vector9::from_fn(|i, _| 0.7 * i as f64 - 2.0);
            assert!(check_dynamics_jacobian(&target, 0, &x).scaled_error < 1e-8);
            for axis in target.axes() {
                assert!(check_dynamics_jacobian(axis, 0, &block(&x, 1)).scaled_error < 1e-8);
            }
        }
    }

    #[test]
    fn coefficients_land_where_the_model_says() {
        let p = Target3dParams {
            dt: 0.2,
            sigma_w: 3.0,
            velocity_diagonal: 0.5,
            accel_coefficient: -0.25,
            accel_amplitude: 2.0,
            damping: [-0.1, -0.2, -0.3],
        };
        let x = AccelAxis::new(p, 0).unwrap();
        let j = x.jacobian(0, &Vector3::zeros());
        // Position 1 + d_x; velocity c_v + d_x; acceleration 1 + c_a + amp cos(0).
        assert!((j[(0, 0)] - 0.9).abs() < 1e-15);
        assert!((j[(0, 1)] - 0.2).abs() < 1e-15);
        assert!((j[(0, 2)] - 0.02).abs() < 1e-15);
        assert!((j[(1, 1)] - 0.4).abs() < 1e-15);
        assert!((j[(1, 2)] - 0.2).abs() < 1e-15);
        assert!((j[(2, 2)] - 2.75).abs() < 1e-15);
        // y uses cos: a' = 0.75 a + 2 cos a, so a = 0 maps to 2; z has its own damping.
        let y = AccelAxis::new(p, 1).unwrap();
        assert!((y.transition(0, &Vector3::zeros())[2] - 2.0).abs() < 1e-15);
        let z = AccelAxis::new(p, 2).unwrap();
        assert!((z.jacobian(0, &Vector3::zeros())[(0, 0)] - 0.7).abs() < 1e-15);
        let q = x.noise_cov(0);
        let b = Vector3::new(0.02, 0.2, 1.0);
        assert!((q - b * b.transpose() * 9.0).amax() < 1e-15);
    }

    #[test]
    fn noise_is_sampled_along_b_exactly() {
        let x = AccelAxis::new(Target3dParams::default(), 2).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let w = x.sample_noise(0, &mut rng).unwrap();
        let b = x.noise_direction();
        // w is a multiple of b: rank one.
        assert!((w - b * (w[2] / b[2])).amax() < 1e-15);
    }

    #[test]
    fn bad_parameters_are_errors() {
        let mut p = Target3dParams::default();
        assert!(AccelAxis::new(p, 3).is_err());
        p.dt = 0.0;
        assert!(Target3d::new(p).is_err());
        p = Target3dParams {
            sigma_w: f64::NAN,
            ..Target3dParams::default()
        };
        assert!(Target3d::new(p).is_err());
    }
}
