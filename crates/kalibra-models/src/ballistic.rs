//! Two-dimensional ballistic re-entry with air drag (Farina, Ristic and Benvenuti 2002), its
//! drag-free linear counterpart, and two radar measurement models for it.
//!
//! # Notation
//! State `x = [x1, x1dot, x2, x2dot]`: down-range, its rate, altitude, its rate (m, m/s); the
//! radar sits at the origin. With sampling period `T`,
//!
//! `x_{k+1} = F1 x_k + G fkk(x_k) + G u + w_k`, `w_k ~ N(0, Q)`,
//!
//! `F1 = blockdiag([[1, T], [0, 1]] x 2)`, `G = [[T^2/2, 0], [T, 0], [0, T^2/2], [0, T]]`,
//! `u = [0, -g]` (gravity as a known input), and the drag acceleration
//! `fkk(x) = -rho(x2) g v [x1dot, x2dot] / (2 beta)`, `v = |[x1dot, x2dot]|`, with the
//! piecewise exponential air density `rho(h) = C1 exp(-C2 h)`. The map is discrete: one Euler
//! step of the continuous model per sample, as Farina et al. write it, with their `G`.
//!
//! # Numerical choices
//! The density switches at 9144 m (30 000 ft): below it `(C1, C2) = (1.227, 1.093e-4)`, at or
//! above it `(1.754, 1.490e-4)` (the boundary belongs to the upper piece).
//! The analytic Jacobian is the one-sided derivative on the current piece; it is undefined at
//! the switch and at zero speed (`v = 0`), where this module returns the limit without the
//! `x dot x dot^T / v` term.

use kalibra_linalg::{
    Matrix2, Matrix3, Matrix4, PsdMatrix, SMatrix, U2, U3, U4, Vector2, Vector3, Vector4,
};
use rand::Rng;

use crate::{
    Dynamics, LinearDynamics, LinearMeasurement, Measurement, ModelError, sample_with_factor,
    wrap_angle,
};

/// Piecewise exponential air density `rho(h) = C1 exp(-C2 h)` (kg/m^3), switching at
/// `threshold` metres of altitude.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AirDensity {
    /// Altitude (m) at which the coefficients switch; `h >= threshold` uses `above`.
    pub threshold: f64,
    /// `(C1, C2)` below the threshold.
    pub below: (f64, f64),
    /// `(C1, C2)` at or above the threshold.
    pub above: (f64, f64),
}

impl AirDensity {
    /// The density of Farina, Ristic and Benvenuti (2002): `(1.227, 1.093e-4)` below 9144 m,
    /// `(1.754, 1.490e-4)` at or above.
    pub fn farina() -> Self {
        Self {
            threshold: 9144.0,
            below: (1.227, 1.093e-4),
            above: (1.754, 1.490e-4),
        }
    }

    fn coefficients(&self, h: f64) -> (f64, f64) {
        if h >= self.threshold {
            self.above
        } else {
            self.below
        }
    }

    /// `rho(h)`.
    ///
    /// Plain arithmetic for speed on the filters' hot path: infinite or NaN only for states
    /// far outside the physical range (speeds near 1e150 m/s, altitudes below -6e6 m). The
    /// filters that evaluate it through [`Dynamics`] check every output and return
    /// `FilterError::NonFinite` naming the step (`tests/extreme_floats.rs` `models_paper`).
    pub fn at(&self, h: f64) -> f64 {
        let (c1, c2) = self.coefficients(h);
        c1 * (-c2 * h).exp()
    }

    /// `d rho / d h` on the piece containing `h`.
    ///
    /// Plain arithmetic for speed on the filters' hot path: infinite or NaN only for states
    /// far outside the physical range (speeds near 1e150 m/s, altitudes below -6e6 m). The
    /// filters that evaluate it through [`Dynamics`] check every output and return
    /// `FilterError::NonFinite` naming the step (`tests/extreme_floats.rs` `models_paper`).
    pub fn derivative(&self, h: f64) -> f64 {
        let (c1, c2) = self.coefficients(h);
        -c2 * c1 * (-c2 * h).exp()
    }
}

/// `F1`, the constant-velocity part of the transition: finite for every finite `t` (its
/// entries are 0, 1 and `t`).
pub fn ballistic_f1(t: f64) -> Matrix4<f64> {
    Matrix4::new(
        1.0, t, 0.0, 0.0, //
        0.0, 1.0, 0.0, 0.0, //
        0.0, 0.0, 1.0, t, //
        0.0, 0.0, 0.0, 1.0,
    )
}

/// `G`, which maps an acceleration `[a1, a2]` into the state over one period: infinite for
/// `t` above 1.9e154 (`t^2 / 2`), which [`Ballistic::new`] refuses as a period.
pub fn ballistic_g(t: f64) -> SMatrix<f64, 4, 2> {
    SMatrix::<f64, 4, 2>::new(0.5 * t * t, 0.0, t, 0.0, 0.0, 0.5 * t * t, 0.0, t)
}

/// Shared parameters of the drag and drag-free models.
#[derive(Clone, Debug)]
struct Params {
    t: f64,
    g: f64,
    q: PsdMatrix<U4>,
    f1: Matrix4<f64>,
    gm: SMatrix<f64, 4, 2>,
    /// `G u`, the gravity input in state coordinates.
    input: Vector4<f64>,
}

impl Params {
    fn new(t: f64, g: f64, q: Matrix4<f64>) -> Result<Self, ModelError> {
        positive("sampling period T", t)?;
        if !g.is_finite() {
            return Err(ModelError::InvalidParameter {
                name: "gravity g",
                value: g,
            });
        }
        let q = PsdMatrix::named(q, "process noise covariance Q")?;
        let gm = ballistic_g(t);
        // `T^2 / 2` beyond f64 (T above 1.9e154 s), or `g T^2 / 2`: refused here, so that the
        // model's constant parts are finite.
        if !gm.iter().all(|v| v.is_finite()) {
            return Err(ModelError::InvalidParameter {
                name: "sampling period T",
                value: t,
            });
        }
        let input = gm * Vector2::new(0.0, -g);
        if !input.iter().all(|v| v.is_finite()) {
            return Err(ModelError::InvalidParameter {
                name: "gravity g",
                value: g,
            });
        }
        Ok(Self {
            t,
            g,
            q,
            f1: ballistic_f1(t),
            gm,
            input,
        })
    }
}

impl Params {
    /// A draw of `w ~ N(0, Q)` through the kept factor (shared by both models).
    fn sample_noise<R: Rng + ?Sized>(&self, rng: &mut R) -> Vector4<f64> {
        sample_with_factor(self.q.factor(), rng)
    }

    fn with_noise(&self, q: Matrix4<f64>) -> Result<Self, ModelError> {
        Ok(Self {
            q: PsdMatrix::named(q, "process noise covariance Q")?,
            ..self.clone()
        })
    }
}

fn positive(name: &'static str, value: f64) -> Result<(), ModelError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ModelError::InvalidParameter { name, value })
    }
}

/// The scalar parameters of [`Ballistic`], by name so that no two can be swapped silently.
///
/// ```
/// use kalibra_models::{Ballistic, BallisticParams};
/// use kalibra_linalg::Matrix4;
/// let params = BallisticParams { period: 2.0, beta: 40_000.0, gravity: 9.81 };
/// let model = Ballistic::new(params, Matrix4::identity())?;
/// assert_eq!(model.params(), params);
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BallisticParams {
    /// The sampling period `T` (s), positive.
    pub period: f64,
    /// The ballistic coefficient `beta` (kg m^-1 s^-2), positive.
    pub beta: f64,
    /// The gravitational acceleration `g` (m/s^2), finite.
    pub gravity: f64,
}

/// The ballistic re-entry dynamics with drag and gravity.
///
/// ```
/// use kalibra_models::{Ballistic, BallisticParams, Dynamics, check_dynamics_jacobian};
/// use kalibra_linalg::{Matrix4, Vector4};
/// let params = BallisticParams { period: 2.0, beta: 40_000.0, gravity: 9.81 };
/// let model = Ballistic::new(params, Matrix4::identity())?;
/// let x0 = Vector4::new(232e3, -2255.2, 88e3, -397.7);
/// let x1 = model.transition(0, &x0);
/// assert!(x1[2] < x0[2]); // falling
/// assert!(check_dynamics_jacobian(&model, 0, &x0).scaled_error < 1e-6);
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Debug)]
pub struct Ballistic {
    params: Params,
    beta: f64,
    density: AirDensity,
}

impl Ballistic {
    /// The model with period, ballistic coefficient and gravity from `params` and the
    /// process-noise covariance `q` (the truth's `Qt`, or a filter's tuning `Q`); the density
    /// of [`AirDensity::farina`].
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] for a non-positive `period` or `beta` or a non-finite
    /// `gravity`, a `period` (gravity) whose `G` (`G u`) leaves f64, or a `beta` so small that
    /// `gravity / (2 beta)` does;
    /// [`ModelError::Linalg`] if `q` is not symmetric positive semi-definite.
    pub fn new(params: BallisticParams, q: Matrix4<f64>) -> Result<Self, ModelError> {
        let BallisticParams {
            period,
            beta,
            gravity,
        } = params;
        positive("ballistic coefficient beta", beta)?;
        let params = Params::new(period, gravity, q)?;
        // The drag's constant `g / (2 beta)`: a subnormal beta would make every drag infinite.
        if !(gravity / (2.0 * beta)).is_finite() {
            return Err(ModelError::InvalidParameter {
                name: "ballistic coefficient beta",
                value: beta,
            });
        }
        Ok(Self {
            params,
            beta,
            density: AirDensity::farina(),
        })
    }

    /// The period, ballistic coefficient and gravity the model was built with.
    pub fn params(&self) -> BallisticParams {
        BallisticParams {
            period: self.params.t,
            beta: self.beta,
            gravity: self.params.g,
        }
    }

    /// The same model with another air density.
    pub fn with_density(mut self, density: AirDensity) -> Self {
        self.density = density;
        self
    }

    /// The same model with another process-noise covariance (a tuning sweep scales `Q`).
    ///
    /// # Errors
    /// [`ModelError::Linalg`] if `q` is not symmetric positive semi-definite.
    pub fn with_noise(&self, q: Matrix4<f64>) -> Result<Self, ModelError> {
        Ok(Self {
            params: self.params.with_noise(q)?,
            ..self.clone()
        })
    }

    /// The drag-free (linear) model with the same period, gravity and noise: `F1 x + G u`.
    pub fn drag_free(&self) -> BallisticDragFree {
        BallisticDragFree {
            params: self.params.clone(),
        }
    }

    /// The sampling period `T`.
    pub fn period(&self) -> f64 {
        self.params.t
    }

    /// The air density model.
    pub fn density(&self) -> &AirDensity {
        &self.density
    }

    /// The drag acceleration `fkk(x)` (m/s^2).
    ///
    /// Plain arithmetic for speed on the filters' hot path: infinite or NaN only for states
    /// far outside the physical range (speeds near 1e150 m/s, altitudes below -6e6 m). The
    /// filters that evaluate it through [`Dynamics`] check every output and return
    /// `FilterError::NonFinite` naming the step (`tests/extreme_floats.rs` `models_paper`).
    pub fn drag(&self, x: &Vector4<f64>) -> Vector2<f64> {
        let vel = Vector2::new(x[1], x[3]);
        let v = vel.norm();
        vel * (-self.density.at(x[2]) * self.params.g * v / (2.0 * self.beta))
    }

    /// `d fkk / d x` (2 x 4).
    ///
    /// Plain arithmetic for speed on the filters' hot path: infinite or NaN only for states
    /// far outside the physical range (speeds near 1e150 m/s, altitudes below -6e6 m). The
    /// filters that evaluate it through [`Dynamics`] check every output and return
    /// `FilterError::NonFinite` naming the step (`tests/extreme_floats.rs` `models_paper`).
    pub fn drag_jacobian(&self, x: &Vector4<f64>) -> SMatrix<f64, 2, 4> {
        let (v1, v2) = (x[1], x[3]);
        let v = (v1 * v1 + v2 * v2).sqrt();
        let c = -self.params.g / (2.0 * self.beta);
        let rho = self.density.at(x[2]);
        let drho = self.density.derivative(x[2]);
        // d(v vel_i)/d vel_j = v delta_ij + vel_i vel_j / v; at v = 0 the second term's limit
        // is direction-dependent, and dropping it gives the derivative along the axes.
        let outer = if v > 0.0 { 1.0 / v } else { 0.0 };
        let dv = Matrix2::new(
            v + v1 * v1 * outer,
            v1 * v2 * outer,
            v1 * v2 * outer,
            v + v2 * v2 * outer,
        ) * (c * rho);
        let dh = Vector2::new(v1, v2) * (c * v * drho);
        SMatrix::<f64, 2, 4>::new(
            0.0,
            dv[(0, 0)],
            dh[0],
            dv[(0, 1)], //
            0.0,
            dv[(1, 0)],
            dh[1],
            dv[(1, 1)],
        )
    }
}

impl Dynamics<U4> for Ballistic {
    fn state_dim(&self) -> U4 {
        U4
    }
    fn transition(&self, _k: usize, x: &Vector4<f64>) -> Vector4<f64> {
        self.params.f1 * x + self.params.gm * self.drag(x) + self.params.input
    }
    fn jacobian(&self, _k: usize, x: &Vector4<f64>) -> Matrix4<f64> {
        self.params.f1 + self.params.gm * self.drag_jacobian(x)
    }
    fn noise_cov(&self, _k: usize) -> Matrix4<f64> {
        *self.params.q.matrix()
    }
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        _k: usize,
        rng: &mut R,
    ) -> Result<Vector4<f64>, ModelError> {
        Ok(self.params.sample_noise(rng))
    }
}

/// Lane-wise: `f(x) = F1 x + G fkk(x) + G u` and `F = F1 + G dfkk/dx` for every lane, in the
/// scalar model's order of operations, with one [`exp_lanes`](crate::lanes::math::exp_lanes)
/// per step for the density and its derivative (within 1 ulp of glibc's `exp`), and `Q`
/// broadcast.
impl crate::lanes::LaneDynamics<4> for Ballistic {
    #[inline(always)]
    fn predict_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        k: usize,
        x: &mut [crate::lanes::Lanes; 4],
        f: &mut [[crate::lanes::Lanes; 4]; 4],
        q: &mut [[crate::lanes::Lanes; 4]; 4],
    ) {
        use crate::lanes::{BATCH, Lanes, broadcast, load, math, store};
        let chunks = BATCH / S::F64_LANES;
        let sp = |v: f64| simd.splat_f64s(v);
        let d = &self.density;
        // The piece of the density each lane's altitude is on, and the exponent -C2 h.
        let mut c1: Lanes = [0.0; BATCH];
        let mut c2: Lanes = [0.0; BATCH];
        let mut arg: Lanes = [0.0; BATCH];
        for c in 0..chunks {
            let h = load::<S>(&x[2], c);
            let above = simd.greater_than_or_equal_f64s(h, sp(d.threshold));
            let c1v = simd.select_f64s(above, sp(d.above.0), sp(d.below.0));
            let c2v = simd.select_f64s(above, sp(d.above.1), sp(d.below.1));
            store::<S>(&mut c1, c, c1v);
            store::<S>(&mut c2, c, c2v);
            store::<S>(&mut arg, c, simd.mul_f64s(simd.neg_f64s(c2v), h));
        }
        let e = math::exp_lanes(simd, &arg);
        let p = &self.params;
        let (f1, gm) = (&p.f1, &p.gm);
        let (g, beta) = (p.g, self.beta);
        let (mul, add) = (|a, b| simd.mul_f64s(a, b), |a, b| simd.add_f64s(a, b));
        for c in 0..chunks {
            let xc: [S::f64s; 4] = std::array::from_fn(|i| load::<S>(&x[i], c));
            let (v1, v2) = (xc[1], xc[3]);
            let (c1v, c2v, ev) = (load::<S>(&c1, c), load::<S>(&c2, c), load::<S>(&e, c));
            let rho = mul(c1v, ev);
            let drho = mul(mul(simd.neg_f64s(c2v), c1v), ev);
            let v = simd.sqrt_f64s(add(mul(v1, v1), mul(v2, v2)));
            // fkk = vel (-rho g v / (2 beta)).
            let s = simd.div_f64s(mul(mul(simd.neg_f64s(rho), sp(g)), v), sp(2.0 * beta));
            let drag = [mul(v1, s), mul(v2, s)];
            // d fkk / dx (2 x 4), as `Ballistic::drag_jacobian` forms it.
            let cr = mul(sp(-g / (2.0 * beta)), rho);
            let outer = simd.select_f64s(
                simd.greater_than_f64s(v, sp(0.0)),
                simd.div_f64s(sp(1.0), v),
                sp(0.0),
            );
            let dvh = mul(mul(sp(-g / (2.0 * beta)), v), drho);
            let cross = mul(mul(mul(v1, v2), outer), cr);
            let zero = sp(0.0);
            let dj = [
                [
                    zero,
                    mul(add(v, mul(mul(v1, v1), outer)), cr),
                    mul(v1, dvh),
                    cross,
                ],
                [
                    zero,
                    cross,
                    mul(v2, dvh),
                    mul(add(v, mul(mul(v2, v2), outer)), cr),
                ],
            ];
            for i in 0..4 {
                // F1 x, column by column as nalgebra's product adds them.
                let mut fx = mul(sp(f1[(i, 0)]), xc[0]);
                for (j, xj) in xc.iter().enumerate().skip(1) {
                    fx = add(fx, mul(sp(f1[(i, j)]), *xj));
                }
                let gd = add(mul(sp(gm[(i, 0)]), drag[0]), mul(sp(gm[(i, 1)]), drag[1]));
                store::<S>(&mut x[i], c, add(add(fx, gd), sp(p.input[i])));
                for (j, fij) in f[i].iter_mut().enumerate() {
                    let gdj = add(mul(sp(gm[(i, 0)]), dj[0][j]), mul(sp(gm[(i, 1)]), dj[1][j]));
                    store::<S>(fij, c, add(sp(f1[(i, j)]), gdj));
                }
            }
        }
        broadcast(q, &self.noise_cov(k));
    }
}

/// The ballistic model without drag: `x_{k+1} = F1 x_k + G u + w_k`, the linear model a
/// Kalman filter can run on when it ignores drag.
#[derive(Clone, Debug)]
pub struct BallisticDragFree {
    params: Params,
}

impl BallisticDragFree {
    /// The same model with another process-noise covariance.
    ///
    /// # Errors
    /// [`ModelError::Linalg`] if `q` is not symmetric positive semi-definite.
    pub fn with_noise(&self, q: Matrix4<f64>) -> Result<Self, ModelError> {
        Ok(Self {
            params: self.params.with_noise(q)?,
        })
    }
}

impl Dynamics<U4> for BallisticDragFree {
    fn state_dim(&self) -> U4 {
        U4
    }
    fn transition(&self, _k: usize, x: &Vector4<f64>) -> Vector4<f64> {
        self.params.f1 * x + self.params.input
    }
    fn jacobian(&self, _k: usize, _x: &Vector4<f64>) -> Matrix4<f64> {
        self.params.f1
    }
    fn noise_cov(&self, _k: usize) -> Matrix4<f64> {
        *self.params.q.matrix()
    }
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        _k: usize,
        rng: &mut R,
    ) -> Result<Vector4<f64>, ModelError> {
        Ok(self.params.sample_noise(rng))
    }
}

impl LinearDynamics<U4> for BallisticDragFree {
    fn matrix(&self, _k: usize) -> Matrix4<f64> {
        self.params.f1
    }
}

/// Radar range and elevation converted to Cartesian position:
/// `z = [x1, x2] + v`, `v ~ N(0, RA(r, eps))` with
/// `RA = [[sr^2 c^2 + r^2 se^2 s^2, (sr^2 - r^2 se^2) s c], [., sr^2 s^2 + r^2 se^2 c^2]]`,
/// `c = cos eps`, `s = sin eps`, at the true range `r` and elevation `eps`. `sr` and `se` are
/// the standard deviations of range (m) and elevation (rad).
///
/// A filter that evaluates [`Measurement::noise_cov`] passes its prior estimate, so this type
/// also serves a filter that models the converted noise; a filter with a constant `R` uses
/// [`crate::LinearObservation`] instead.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConvertedPosition {
    sigma_range: f64,
    sigma_elevation: f64,
}

/// The noise of [`ConvertedPosition`], by name: the two standard deviations are in different
/// units (m, rad) and must not be swapped silently.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConvertedPositionParams {
    /// The range standard deviation `sr` (m), positive.
    pub sigma_range: f64,
    /// The elevation standard deviation `se` (rad), positive.
    pub sigma_elevation: f64,
}

impl ConvertedPosition {
    /// The model with the range and elevation standard deviations of `params`.
    ///
    /// ```
    /// use kalibra_models::{ConvertedPosition, ConvertedPositionParams};
    /// let radar = ConvertedPosition::new(ConvertedPositionParams {
    ///     sigma_range: 100.0,
    ///     sigma_elevation: 0.017 / 57.3,
    /// })?;
    /// // Along the line of sight (elevation 0) the variance is the range variance.
    /// assert!((radar.covariance(50e3, 0.0)[(0, 0)] - 1e4).abs() < 1e-9);
    /// # Ok::<(), kalibra_models::ModelError>(())
    /// ```
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] unless both are positive and finite.
    pub fn new(params: ConvertedPositionParams) -> Result<Self, ModelError> {
        let ConvertedPositionParams {
            sigma_range,
            sigma_elevation,
        } = params;
        positive("range standard deviation", sigma_range)?;
        positive("elevation standard deviation", sigma_elevation)?;
        Ok(Self {
            sigma_range,
            sigma_elevation,
        })
    }

    /// `H = [[1, 0, 0, 0], [0, 0, 1, 0]]`.
    pub fn h() -> SMatrix<f64, 2, 4> {
        SMatrix::<f64, 2, 4>::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    }

    /// `RA` at range `r` and elevation `eps`.
    ///
    /// Plain arithmetic: infinite for ranges whose `(r se)^2` leaves f64 (`r` above about
    /// `1e154 / se`). A filter evaluates it through [`Measurement::noise_cov`] at its prior
    /// and returns `FilterError::NonFinite` naming the step for a non-finite `R`
    /// (`tests/extreme_floats.rs` `models_paper`).
    pub fn covariance(&self, r: f64, eps: f64) -> Matrix2<f64> {
        let (s, c) = eps.sin_cos();
        let sr2 = self.sigma_range * self.sigma_range;
        let re2 = r * r * self.sigma_elevation * self.sigma_elevation;
        Matrix2::new(
            sr2 * c * c + re2 * s * s,
            (sr2 - re2) * s * c,
            (sr2 - re2) * s * c,
            sr2 * s * s + re2 * c * c,
        )
    }
}

impl Measurement<U4, U2> for ConvertedPosition {
    fn meas_dim(&self) -> U2 {
        U2
    }
    fn measure(&self, _k: usize, x: &Vector4<f64>) -> Vector2<f64> {
        Vector2::new(x[0], x[2])
    }
    fn jacobian(&self, _k: usize, _x: &Vector4<f64>) -> SMatrix<f64, 2, 4> {
        Self::h()
    }
    fn noise_cov(&self, _k: usize, x: &Vector4<f64>) -> Matrix2<f64> {
        let r = x[0].hypot(x[2]);
        self.covariance(r, x[2].atan2(x[0]))
    }
}

impl LinearMeasurement<U4, U2> for ConvertedPosition {
    fn matrix(&self, _k: usize) -> SMatrix<f64, 2, 4> {
        Self::h()
    }
}

/// Radar range rate, elevation and sightline rate, with the radar at the
/// origin: `h(x) = [(x1 x1dot + x2 x2dot) / r, atan2(x2, x1), (x1 x2dot - x2 x1dot) / r^2]`,
/// `r = |[x1, x2]|`. The elevation residual is wrapped into (-pi, pi].
///
/// `atan2(x2, x1)` equals the elevation `tan^-1(x2 / x1)` for a target down-range (`x1 > 0`)
/// and stays continuous when `x1` changes sign.
///
/// ```
/// use kalibra_models::{RadarRates, check_measurement_jacobian};
/// use kalibra_linalg::{Matrix3, Vector4};
/// let radar = RadarRates::new(Matrix3::from_diagonal(&[225.0, 3e-6, 3e-8].into()))?;
/// let x = Vector4::new(232e3, -2255.2, 88e3, -397.7);
/// assert!(check_measurement_jacobian(&radar, 0, &x).scaled_error < 1e-6);
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Debug)]
pub struct RadarRates {
    r: PsdMatrix<U3>,
}

impl RadarRates {
    /// The index of the elevation in the measurement vector.
    pub const ELEVATION: usize = 1;

    /// A radar with measurement-noise covariance `r` (3 x 3).
    ///
    /// # Errors
    /// [`ModelError::Linalg`] if `r` is not symmetric positive semi-definite.
    pub fn new(r: Matrix3<f64>) -> Result<Self, ModelError> {
        Ok(Self {
            r: PsdMatrix::named(r, "measurement noise covariance R")?,
        })
    }
}

impl Measurement<U4, U3> for RadarRates {
    fn meas_dim(&self) -> U3 {
        U3
    }
    fn measure(&self, _k: usize, x: &Vector4<f64>) -> Vector3<f64> {
        let (x1, v1, x2, v2) = (x[0], x[1], x[2], x[3]);
        let r2 = x1 * x1 + x2 * x2;
        Vector3::new(
            (x1 * v1 + x2 * v2) / r2.sqrt(),
            x2.atan2(x1),
            (x1 * v2 - x2 * v1) / r2,
        )
    }
    /// Non-finite at the radar (`r = 0`); filters report that as an error.
    fn jacobian(&self, _k: usize, x: &Vector4<f64>) -> SMatrix<f64, 3, 4> {
        let (x1, v1, x2, v2) = (x[0], x[1], x[2], x[3]);
        let r2 = x1 * x1 + x2 * x2;
        let r = r2.sqrt();
        let r3 = r2 * r;
        let dot = x1 * v1 + x2 * v2;
        let cross = x1 * v2 - x2 * v1;
        let r4 = r2 * r2;
        SMatrix::<f64, 3, 4>::new(
            v1 / r - dot * x1 / r3,
            x1 / r,
            v2 / r - dot * x2 / r3,
            x2 / r,
            //
            -x2 / r2,
            0.0,
            x1 / r2,
            0.0,
            //
            v2 / r2 - 2.0 * x1 * cross / r4,
            -x2 / r2,
            -v1 / r2 - 2.0 * x2 * cross / r4,
            x1 / r2,
        )
    }
    fn noise_cov(&self, _k: usize, _x: &Vector4<f64>) -> Matrix3<f64> {
        *self.r.matrix()
    }
    fn residual(&self, z: &Vector3<f64>, zhat: &Vector3<f64>) -> Vector3<f64> {
        let mut d = z - zhat;
        d[Self::ELEVATION] = wrap_angle(d[Self::ELEVATION]);
        d
    }
    fn normalize(&self, z: &mut Vector3<f64>) {
        z[Self::ELEVATION] = wrap_angle(z[Self::ELEVATION]);
    }
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        _k: usize,
        _x: &Vector4<f64>,
        rng: &mut R,
    ) -> Result<Vector3<f64>, ModelError> {
        Ok(sample_with_factor(self.r.factor(), rng))
    }
}

/// Lane-wise: every lane's `h(x)`, `H` and innovation across the lanes in the scalar model's
/// order of operations, the elevation by [`lanes::math::atan2`] (within 3 ulp of glibc's) and
/// its residual wrapped as [`wrap_angle`] wraps it, to the bit; `R` broadcast.
///
/// [`lanes::math::atan2`]: crate::lanes::math::atan2
impl crate::lanes::LaneMeasurement<4, 3> for RadarRates {
    #[inline(always)]
    fn innovate_lanes<S: pulp::Simd>(
        &self,
        simd: S,
        _k: usize,
        x: &[crate::lanes::Lanes; 4],
        z: &[crate::lanes::Lanes; 3],
        nu: &mut [crate::lanes::Lanes; 3],
        h: &mut [[crate::lanes::Lanes; 4]; 3],
        r: &mut [[crate::lanes::Lanes; 3]; 3],
    ) {
        use crate::lanes::{BATCH, broadcast, load, math, store};
        for c in 0..BATCH / S::F64_LANES {
            let (x1, v1, x2, v2) = (
                load::<S>(&x[0], c),
                load::<S>(&x[1], c),
                load::<S>(&x[2], c),
                load::<S>(&x[3], c),
            );
            let (add, sub, mul, div) = (
                |a, b| simd.add_f64s(a, b),
                |a, b| simd.sub_f64s(a, b),
                |a, b| simd.mul_f64s(a, b),
                |a, b| simd.div_f64s(a, b),
            );
            let r2 = add(mul(x1, x1), mul(x2, x2));
            let r = simd.sqrt_f64s(r2);
            let dot = add(mul(x1, v1), mul(x2, v2));
            let cross = sub(mul(x1, v2), mul(x2, v1));
            let zhat = [div(dot, r), math::atan2(simd, x2, x1), div(cross, r2)];
            for (i, zh) in zhat.into_iter().enumerate() {
                store::<S>(&mut nu[i], c, sub(load::<S>(&z[i], c), zh));
            }
            let r3 = mul(r2, r);
            let r4 = mul(r2, r2);
            let two = simd.splat_f64s(2.0);
            let zero = simd.splat_f64s(0.0);
            let rows = [
                [
                    sub(div(v1, r), div(mul(dot, x1), r3)),
                    div(x1, r),
                    sub(div(v2, r), div(mul(dot, x2), r3)),
                    div(x2, r),
                ],
                [div(simd.neg_f64s(x2), r2), zero, div(x1, r2), zero],
                [
                    sub(div(v2, r2), div(mul(mul(two, x1), cross), r4)),
                    div(simd.neg_f64s(x2), r2),
                    sub(
                        div(simd.neg_f64s(v1), r2),
                        div(mul(mul(two, x2), cross), r4),
                    ),
                    div(x1, r2),
                ],
            ];
            for (hi, row) in h.iter_mut().zip(rows) {
                for (hij, v) in hi.iter_mut().zip(row) {
                    store::<S>(hij, c, v);
                }
            }
        }
        crate::lanes::math::wrap_angle_lanes(simd, &mut nu[Self::ELEVATION]);
        broadcast(r, self.r.matrix());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{check_dynamics_jacobian, check_measurement_jacobian};

    const PARAMS: BallisticParams = BallisticParams {
        period: 2.0,
        beta: 40_000.0,
        gravity: 9.81,
    };
    const RADAR: ConvertedPositionParams = ConvertedPositionParams {
        sigma_range: 100.0,
        sigma_elevation: 0.017 / 57.3,
    };

    fn x0() -> Vector4<f64> {
        let a = 190f64.to_radians();
        Vector4::new(232e3, 2290.0 * a.cos(), 88e3, 2290.0 * a.sin())
    }

    fn model() -> Ballistic {
        Ballistic::new(PARAMS, Matrix4::identity()).unwrap()
    }

    #[test]
    fn drag_jacobian_matches_finite_differences_on_both_density_pieces() {
        let m = model();
        for x in [
            x0(),
            Vector4::new(20e3, -900.0, 5e3, -1500.0),
            Vector4::new(1e3, 10.0, 12e3, -3.0),
        ] {
            let c = check_dynamics_jacobian(&m, 0, &x);
            assert!(c.scaled_error < 1e-6, "{x:?}: {c:?}");
        }
    }

    #[test]
    fn drag_free_is_linear_with_gravity() {
        let m = model().drag_free();
        let x = x0();
        let next = m.transition(0, &x);
        assert_eq!(
            next,
            ballistic_f1(2.0) * x + ballistic_g(2.0) * Vector2::new(0.0, -9.81)
        );
        assert_eq!(m.matrix(0), ballistic_f1(2.0));
        assert!(check_dynamics_jacobian(&m, 0, &x).scaled_error < 1e-9);
    }

    #[test]
    fn drag_opposes_velocity_and_grows_with_density() {
        let m = model();
        let x_high = x0();
        let mut x_low = x_high;
        x_low[2] = 5e3;
        let d_high = m.drag(&x_high);
        let d_low = m.drag(&x_low);
        assert!(d_high.dot(&Vector2::new(x_high[1], x_high[3])) < 0.0);
        assert!(d_low.norm() > 10.0 * d_high.norm());
        // Density switches at 9144 m to the other coefficient pair.
        let rho = AirDensity::farina();
        assert_eq!(rho.at(9144.0), 1.754 * (-1.490e-4f64 * 9144.0).exp());
        assert_eq!(rho.at(9143.9), 1.227 * (-1.093e-4f64 * 9143.9).exp());
    }

    #[test]
    fn radar_jacobian_matches_finite_differences_and_wraps_elevation() {
        let radar =
            RadarRates::new(Matrix3::from_diagonal(&Vector3::new(225.0, 3e-6, 3e-8))).unwrap();
        for x in [
            x0(),
            Vector4::new(-3e3, 100.0, 2e3, -50.0),
            Vector4::new(5e3, 0.0, -1e3, 7.0),
        ] {
            let c = check_measurement_jacobian(&radar, 0, &x);
            assert!(c.scaled_error < 1e-6, "{x:?}: {c:?}");
        }
        let z = Vector3::new(0.0, 3.1, 0.0);
        let zhat = Vector3::new(0.0, -3.1, 0.0);
        let d = radar.residual(&z, &zhat);
        assert!((d[1] - (6.2 - 2.0 * std::f64::consts::PI)).abs() < 1e-12);
    }

    #[test]
    fn converted_noise_is_range_noise_along_the_line_of_sight() {
        let m = ConvertedPosition::new(RADAR).unwrap();
        let eps = 0.3f64;
        let ra = m.covariance(50e3, eps);
        // Along the line of sight the variance is sr^2, across it (r se)^2.
        let along = Vector2::new(eps.cos(), eps.sin());
        let across = Vector2::new(-eps.sin(), eps.cos());
        assert!(((along.transpose() * ra * along)[0] - 1e4).abs() < 1e-8);
        let cross = (50e3f64 * 0.017 / 57.3).powi(2);
        assert!(((across.transpose() * ra * across)[0] - cross).abs() < 1e-8);
        assert!((along.transpose() * ra * across)[0].abs() < 1e-8);
        assert!(check_measurement_jacobian(&m, 0, &x0()).scaled_error < 1e-9);
    }

    #[test]
    fn named_parameters_reach_their_places() {
        // Each named parameter lands where its name says: the period in F1 and G, gravity in
        // the input, beta in the drag. A swap of two of them would change all three checks.
        let m = model();
        assert_eq!(m.params(), PARAMS);
        assert_eq!(m.period(), 2.0);
        let x = x0();
        let d = m.drag(&x);
        let v = Vector2::new(x[1], x[3]);
        let expect = v * (-AirDensity::farina().at(x[2]) * 9.81 * v.norm() / (2.0 * 40_000.0));
        assert_eq!(d, expect);
        let free = m.drag_free();
        assert_eq!(
            free.transition(0, &Vector4::zeros()),
            ballistic_g(2.0) * Vector2::new(0.0, -9.81)
        );
    }

    #[test]
    fn with_noise_replaces_q_only() {
        let m = model();
        let q = Matrix4::identity() * 3.0;
        let (a, b) = (
            m.with_noise(q).unwrap(),
            m.drag_free().with_noise(q).unwrap(),
        );
        assert_eq!(a.noise_cov(0), q);
        assert_eq!(b.noise_cov(0), q);
        assert_eq!(a.transition(0, &x0()), m.transition(0, &x0()));
        assert!(m.with_noise(-q).is_err());
    }

    #[test]
    fn invalid_parameters_are_typed_errors() {
        let with = |period, beta, gravity| BallisticParams {
            period,
            beta,
            gravity,
        };
        let i = Matrix4::identity();
        let invalid = |r: Result<Ballistic, ModelError>, name: &str| matches!(r, Err(ModelError::InvalidParameter { name: n, .. }) if n == name);
        assert!(invalid(
            Ballistic::new(with(0.0, 1.0, 9.81), i),
            "sampling period T"
        ));
        assert!(invalid(
            Ballistic::new(with(2.0, -1.0, 9.81), i),
            "ballistic coefficient beta"
        ));
        assert!(invalid(
            Ballistic::new(with(2.0, 1.0, f64::NAN), i),
            "gravity g"
        ));
        assert!(matches!(
            Ballistic::new(with(2.0, 1.0, 9.81), -i),
            Err(ModelError::Linalg(_))
        ));
        assert!(
            ConvertedPosition::new(ConvertedPositionParams {
                sigma_range: 0.0,
                sigma_elevation: 1.0,
            })
            .is_err()
        );
        assert!(
            RadarRates::new(Matrix3::new(1.0, 2.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)).is_err()
        );
    }
}
