//! An angular target: the constant-acceleration angle / rate / acceleration model a filter
//! uses ([`AngularTarget`]), and a manoeuvring truth whose acceleration follows a
//! deterministic profile plus white input noise ([`ManoeuvringTarget`]).
//!
//! The model is the one of Minh, Luong, Bang and Toan, "Simulation and performance evaluation
//! of EKF in angular coordinate tracking of highly maneuvering targets" (eqs 3 and 4). The
//! truth's time step, duration, initial state, manoeuvre and input noise are all parameters.

use kalibra_linalg::{Matrix1, Matrix3, U1, U3, Vector1, Vector3};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::{Dynamics, LinearDynamics, LinearGaussian, LinearObservation, ModelError};

/// The constant-acceleration angle model: state `[theta, theta', theta'']`,
/// `x_{k+1} = F x_k + w_k` with `F = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]` and `w_k ~ N(0, Q)`,
/// `Q` a per-step covariance.
///
/// `f` is linear, so its Jacobian is `F` everywhere and an EKF on this model is the linear
/// Kalman filter.
///
/// ```
/// use kalibra_models::{AngularTarget, Dynamics};
/// use kalibra_linalg::Vector3;
///
/// let model = AngularTarget::diagonal(0.01, [0.005, 0.05, 0.2])?;
/// let x = model.transition(0, &Vector3::new(0.0, 1.0, 2.0));
/// assert!((x[0] - (0.01 + 0.5 * 2.0 * 1e-4)).abs() < 1e-15);
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Debug)]
pub struct AngularTarget {
    dt: f64,
    inner: LinearGaussian<U3>,
}

impl AngularTarget {
    /// The model with time step `dt` (s) and per-step process-noise covariance `q`.
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] unless `dt` is finite and positive;
    /// [`ModelError::Linalg`] if `q` is not symmetric positive semi-definite.
    pub fn new(dt: f64, q: Matrix3<f64>) -> Result<Self, ModelError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ModelError::InvalidParameter {
                name: "dt",
                value: dt,
            });
        }
        let f = Matrix3::new(1.0, dt, 0.5 * dt * dt, 0.0, 1.0, dt, 0.0, 0.0, 1.0);
        Ok(Self {
            dt,
            inner: LinearGaussian::new(f, q)?,
        })
    }

    /// The model with a diagonal `Q = diag(q)`.
    ///
    /// # Errors
    /// As [`AngularTarget::new`].
    pub fn diagonal(dt: f64, q: [f64; 3]) -> Result<Self, ModelError> {
        Self::new(dt, Matrix3::from_diagonal(&Vector3::from(q)))
    }

    /// The time step (s).
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The transition matrix `F`.
    pub fn f(&self) -> &Matrix3<f64> {
        self.inner.f()
    }

    /// The process-noise covariance `Q`.
    pub fn q(&self) -> &Matrix3<f64> {
        self.inner.q().matrix()
    }

    /// The angle-only measurement: `z = theta + v`, `v ~ N(0, r)`, `H = [1 0 0]`.
    ///
    /// The angle is not wrapped: the model's angle is unwrapped (in any unit, degrees
    /// included), so the residual is a plain difference.
    ///
    /// # Errors
    /// [`ModelError::Linalg`] unless `r` is finite and non-negative.
    pub fn angle_measurement(r: f64) -> Result<LinearObservation<U3, U1>, ModelError> {
        LinearObservation::new(
            kalibra_linalg::nalgebra::Matrix1x3::new(1.0, 0.0, 0.0),
            Matrix1::new(r),
        )
    }
}

impl Dynamics<U3> for AngularTarget {
    fn state_dim(&self) -> U3 {
        U3
    }
    fn transition(&self, k: usize, x: &Vector3<f64>) -> Vector3<f64> {
        self.inner.transition(k, x)
    }
    fn jacobian(&self, k: usize, x: &Vector3<f64>) -> Matrix3<f64> {
        self.inner.jacobian(k, x)
    }
    fn noise_cov(&self, k: usize) -> Matrix3<f64> {
        self.inner.noise_cov(k)
    }
    fn sample_noise<R: Rng + ?Sized>(
        &self,
        k: usize,
        rng: &mut R,
    ) -> Result<Vector3<f64>, ModelError> {
        self.inner.sample_noise(k, rng)
    }
}

impl LinearDynamics<U3> for AngularTarget {
    fn matrix(&self, k: usize) -> Matrix3<f64> {
        self.inner.matrix(k)
    }
}

/// One piece of a manoeuvre: an angular acceleration (in the angle's unit per s^2) active on
/// the half-open interval `[start, end)` of time (s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Manoeuvre {
    /// A constant acceleration.
    Step {
        /// Start time.
        start: f64,
        /// End time (excluded).
        end: f64,
        /// The acceleration.
        acceleration: f64,
    },
    /// `amplitude sin(2 pi frequency (t - start))`.
    Sine {
        /// Start time.
        start: f64,
        /// End time (excluded).
        end: f64,
        /// Peak acceleration.
        amplitude: f64,
        /// Frequency (Hz).
        frequency: f64,
    },
}

impl Manoeuvre {
    fn interval(&self) -> (f64, f64) {
        match *self {
            Manoeuvre::Step { start, end, .. } | Manoeuvre::Sine { start, end, .. } => (start, end),
        }
    }

    fn acceleration(&self, t: f64) -> f64 {
        let (start, end) = self.interval();
        if !(start <= t && t < end) {
            return 0.0;
        }
        match *self {
            Manoeuvre::Step { acceleration, .. } => acceleration,
            Manoeuvre::Sine {
                amplitude,
                frequency,
                start,
                ..
            } => amplitude * (2.0 * std::f64::consts::PI * frequency * (t - start)).sin(),
        }
    }

    fn scaled(self, factor: f64) -> Self {
        match self {
            Manoeuvre::Step {
                start,
                end,
                acceleration,
            } => Manoeuvre::Step {
                start,
                end,
                acceleration: acceleration * factor,
            },
            Manoeuvre::Sine {
                start,
                end,
                amplitude,
                frequency,
            } => Manoeuvre::Sine {
                start,
                end,
                amplitude: amplitude * factor,
                frequency,
            },
        }
    }
}

/// A deterministic acceleration profile: the sum of the [`Manoeuvre`]s active at a time.
#[derive(Clone, Debug, PartialEq)]
pub struct ManoeuvreProfile {
    parts: Vec<Manoeuvre>,
}

impl ManoeuvreProfile {
    /// A profile from its pieces (they may overlap; their accelerations add).
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] for a non-finite value, an interval with `end < start`
    /// or a negative frequency.
    pub fn new(parts: Vec<Manoeuvre>) -> Result<Self, ModelError> {
        for part in &parts {
            let (start, end) = part.interval();
            let (value, frequency) = match *part {
                Manoeuvre::Step { acceleration, .. } => (acceleration, 0.0),
                Manoeuvre::Sine {
                    amplitude,
                    frequency,
                    ..
                } => (amplitude, frequency),
            };
            for (name, v) in [
                ("manoeuvre start", start),
                ("manoeuvre end", end),
                ("manoeuvre acceleration", value),
                ("manoeuvre frequency", frequency),
            ] {
                if !v.is_finite() {
                    return Err(ModelError::InvalidParameter { name, value: v });
                }
            }
            if end < start {
                return Err(ModelError::InvalidParameter {
                    name: "manoeuvre end",
                    value: end,
                });
            }
            if frequency < 0.0 {
                return Err(ModelError::InvalidParameter {
                    name: "manoeuvre frequency",
                    value: frequency,
                });
            }
        }
        Ok(Self { parts })
    }

    /// No manoeuvre: zero acceleration throughout.
    pub fn none() -> Self {
        Self { parts: Vec::new() }
    }

    /// The pieces.
    pub fn parts(&self) -> &[Manoeuvre] {
        &self.parts
    }

    /// The acceleration at time `t`: plain arithmetic, infinite only when the active pieces'
    /// finite accelerations sum beyond f64 (pieces near `f64::MAX` that overlap). Its caller,
    /// [`ManoeuvringTarget::truth_from_noise`], checks every sample it builds and returns
    /// [`ModelError::NonFinite`] naming the step.
    pub fn acceleration(&self, t: f64) -> f64 {
        self.parts.iter().map(|p| p.acceleration(t)).sum()
    }

    /// Every acceleration multiplied by `factor` (timing unchanged): a manoeuvre-amplitude
    /// sweep.
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] unless `factor` is finite and every scaled
    /// acceleration is (a product beyond f64 is refused, naming the factor).
    pub fn scaled(&self, factor: f64) -> Result<Self, ModelError> {
        let parts: Vec<Manoeuvre> = self.parts.iter().map(|p| p.scaled(factor)).collect();
        let finite = parts.iter().all(|p| match *p {
            Manoeuvre::Step { acceleration, .. } => acceleration.is_finite(),
            Manoeuvre::Sine { amplitude, .. } => amplitude.is_finite(),
        });
        if !(factor.is_finite() && finite) {
            return Err(ModelError::InvalidParameter {
                name: "manoeuvre scale",
                value: factor,
            });
        }
        Ok(Self { parts })
    }
}

/// A manoeuvring angular target, as a truth for filters built on [`AngularTarget`].
///
/// Sample `k` is at `t_k = k dt`, `k = 0 ..= K` with `K = round(duration / dt)`. The
/// acceleration at sample `k` is `a_k = x0[2] + profile(t_k) + sigma_input n_k`, `n_k` standard
/// normal: the acceleration input noise is white jitter on the acceleration, not a
/// random walk. Angle and rate then move exactly under the constant acceleration `a_k` over
/// the step: `theta_{k+1} = theta_k + theta'_k dt + a_k dt^2 / 2`, `theta'_{k+1} = theta'_k + a_k dt`.
/// The truth is thus not the filter's model: the filter's `Q` is a tuning choice.
#[derive(Clone, Debug, PartialEq)]
pub struct ManoeuvringTarget {
    dt: f64,
    duration: f64,
    profile: ManoeuvreProfile,
    sigma_input: f64,
    x0: Vector3<f64>,
}

/// The parameters of a [`ManoeuvringTarget`], by name so that the three scalars (time step,
/// duration, input noise) cannot be swapped silently.
///
/// ```
/// use kalibra_linalg::Vector3;
/// use kalibra_models::{Manoeuvre, ManoeuvreProfile, ManoeuvringTarget, ManoeuvringTargetParams};
/// let turn = Manoeuvre::Step { start: 1.0, end: 2.0, acceleration: 3.0 };
/// let target = ManoeuvringTarget::new(ManoeuvringTargetParams {
///     dt: 0.01,
///     duration: 5.0,
///     profile: ManoeuvreProfile::new(vec![turn])?,
///     sigma_input: 0.5,
///     x0: Vector3::zeros(),
/// })?;
/// assert_eq!(target.steps(), 500);
/// # Ok::<(), kalibra_models::ModelError>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ManoeuvringTargetParams {
    /// The time step `dt` (s), finite and positive.
    pub dt: f64,
    /// The duration (s), finite and at least `dt`.
    pub duration: f64,
    /// The deterministic acceleration profile.
    pub profile: ManoeuvreProfile,
    /// The standard deviation of the white acceleration input noise, finite and non-negative.
    pub sigma_input: f64,
    /// The initial state `[theta_0, theta'_0, a_bias]`, finite.
    pub x0: Vector3<f64>,
}

impl ManoeuvringTarget {
    /// A target with every parameter given by name.
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] unless `dt` and `duration` are finite and positive
    /// with `duration >= dt`, and `sigma_input` is finite and non-negative;
    /// [`ModelError::NonFinite`] for a non-finite `x0`.
    pub fn new(params: ManoeuvringTargetParams) -> Result<Self, ModelError> {
        let ManoeuvringTargetParams {
            dt,
            duration,
            profile,
            sigma_input,
            x0,
        } = params;
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ModelError::InvalidParameter {
                name: "dt",
                value: dt,
            });
        }
        if !(duration.is_finite() && duration >= dt) {
            return Err(ModelError::InvalidParameter {
                name: "duration",
                value: duration,
            });
        }
        if !(sigma_input.is_finite() && sigma_input >= 0.0) {
            return Err(ModelError::InvalidParameter {
                name: "sigma_input",
                value: sigma_input,
            });
        }
        if !x0.iter().all(|v| v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "initial state x0",
                step: 0,
            });
        }
        Ok(Self {
            dt,
            duration,
            profile,
            sigma_input,
            x0,
        })
    }

    /// The same target with another manoeuvre profile.
    pub fn with_profile(mut self, profile: ManoeuvreProfile) -> Self {
        self.profile = profile;
        self
    }

    /// The time step (s).
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The duration (s).
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// The manoeuvre profile.
    pub fn profile(&self) -> &ManoeuvreProfile {
        &self.profile
    }

    /// Standard deviation of the acceleration input noise.
    pub fn sigma_input(&self) -> f64 {
        self.sigma_input
    }

    /// The initial state.
    pub fn x0(&self) -> &Vector3<f64> {
        &self.x0
    }

    /// The number of steps `K`; the truth has `K + 1` samples.
    pub fn steps(&self) -> usize {
        // A duration that is a multiple of dt up to rounding (20 / 0.01) gives that multiple.
        (self.duration / self.dt).round() as usize
    }

    /// The sample times `t_k = k dt`, `k = 0 ..= K`.
    pub fn times(&self) -> Vec<f64> {
        (0..=self.steps()).map(|k| k as f64 * self.dt).collect()
    }

    /// The truth `x_0 .. x_K` driven by the given standard-normal input noises `n_0 .. n_K`
    /// (for replaying an outside implementation's draws).
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] unless there are `K + 1` noises;
    /// [`ModelError::NonFinite`] for a non-finite noise, or a sample whose angle, rate or
    /// acceleration leaves f64 (finite parameters near its limits), naming the step.
    pub fn truth_from_noise(&self, noise: &[f64]) -> Result<Vec<Vector3<f64>>, ModelError> {
        let samples = self.steps() + 1;
        if noise.len() != samples {
            return Err(ModelError::DimensionMismatch {
                what: "acceleration input noise",
                expected: samples,
                found: noise.len(),
            });
        }
        if let Some(step) = noise.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "acceleration input noise",
                step,
            });
        }
        let dt = self.dt;
        let mut truth = Vec::with_capacity(samples);
        let (mut theta, mut rate) = (self.x0[0], self.x0[1]);
        for (k, n) in noise.iter().enumerate() {
            let a = self.x0[2] + self.profile.acceleration(k as f64 * dt) + self.sigma_input * n;
            let sample = Vector3::new(theta, rate, a);
            if !sample.iter().all(|v| v.is_finite()) {
                return Err(ModelError::NonFinite {
                    what: "truth (angle, rate or acceleration beyond f64)",
                    step: k,
                });
            }
            truth.push(sample);
            theta += rate * dt + 0.5 * a * dt * dt;
            rate += a * dt;
        }
        Ok(truth)
    }

    /// A truth drawn from `rng`: `K + 1` standard normals, in sample order.
    ///
    /// # Errors
    /// [`ModelError::NonFinite`] when a sample leaves f64, as
    /// [`ManoeuvringTarget::truth_from_noise`] (never for the papers' values).
    pub fn truth<R: Rng + ?Sized>(&self, rng: &mut R) -> Result<Vec<Vector3<f64>>, ModelError> {
        let noise: Vec<f64> = (0..=self.steps())
            .map(|_| StandardNormal.sample(rng))
            .collect();
        self.truth_from_noise(&noise)
    }

    /// Angle measurements `z_k = theta_k + sqrt(r) n_k` of samples `k = 1 ..= K` (the prior
    /// sits at `k = 0`) from the given standard-normal noises `n_1 .. n_K`.
    ///
    /// # Errors
    /// [`ModelError::DimensionMismatch`] unless `noise.len() == truth.len() - 1`;
    /// [`ModelError::InvalidParameter`] unless `r` is finite and non-negative;
    /// [`ModelError::NonFinite`] for a non-finite noise or truth, or a measurement beyond f64
    /// (`step` is its index in `noise`).
    pub fn measurements_from_noise(
        truth: &[Vector3<f64>],
        r: f64,
        noise: &[f64],
    ) -> Result<Vec<Vector1<f64>>, ModelError> {
        if !(r.is_finite() && r >= 0.0) {
            return Err(ModelError::InvalidParameter {
                name: "measurement variance r",
                value: r,
            });
        }
        let expected = truth.len().saturating_sub(1);
        if noise.len() != expected {
            return Err(ModelError::DimensionMismatch {
                what: "measurement noise",
                expected,
                found: noise.len(),
            });
        }
        if let Some(step) = noise.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "measurement noise",
                step,
            });
        }
        let sigma = r.sqrt();
        let z: Vec<Vector1<f64>> = truth[1..]
            .iter()
            .zip(noise)
            .map(|(x, n)| Vector1::new(x[0] + sigma * n))
            .collect();
        // A truth near f64::MAX plus its noise, or a non-finite truth, is refused by step.
        if let Some(step) = z.iter().position(|v| !v[0].is_finite()) {
            return Err(ModelError::NonFinite {
                what: "measurement (truth plus noise beyond f64)",
                step,
            });
        }
        Ok(z)
    }

    /// Angle measurements of samples `1 ..= K` drawn from `rng` (one standard normal each, in
    /// sample order).
    ///
    /// # Errors
    /// [`ModelError::InvalidParameter`] unless `r` is finite and non-negative.
    pub fn measurements<R: Rng + ?Sized>(
        truth: &[Vector3<f64>],
        r: f64,
        rng: &mut R,
    ) -> Result<Vec<Vector1<f64>>, ModelError> {
        let noise: Vec<f64> = (1..truth.len())
            .map(|_| StandardNormal.sample(rng))
            .collect();
        Self::measurements_from_noise(truth, r, &noise)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check_dynamics_jacobian;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn jacobian_is_f() {
        let model = AngularTarget::diagonal(0.01, [0.01, 0.1, 0.5]).unwrap();
        let x = Vector3::new(0.3, -2.0, 5.0);
        assert!(check_dynamics_jacobian(&model, 0, &x).scaled_error < 1e-8);
        assert_eq!(model.jacobian(3, &x), *model.f());
    }

    /// A step then a sine, with a piece that overlaps the sine.
    fn profile() -> ManoeuvreProfile {
        ManoeuvreProfile::new(vec![
            Manoeuvre::Step {
                start: 1.0,
                end: 2.0,
                acceleration: 4.0,
            },
            Manoeuvre::Sine {
                start: 2.0,
                end: 6.0,
                amplitude: 5.0,
                frequency: 0.25,
            },
            Manoeuvre::Step {
                start: 5.0,
                end: 6.0,
                acceleration: -1.0,
            },
        ])
        .unwrap()
    }

    /// A 10 s target sampled at 0.1 s with input noise.
    fn target() -> ManoeuvringTarget {
        ManoeuvringTarget::new(ManoeuvringTargetParams {
            dt: 0.1,
            duration: 10.0,
            profile: profile(),
            sigma_input: 0.5,
            x0: Vector3::zeros(),
        })
        .unwrap()
    }

    #[test]
    fn profile_is_half_open_adds_overlaps_and_scales() {
        let p = profile();
        assert_eq!(p.parts().len(), 3);
        assert_eq!(p.acceleration(0.999), 0.0);
        assert_eq!(p.acceleration(1.0), 4.0);
        assert_eq!(p.acceleration(2.0), 0.0); // the step has ended, the sine is at sin(0)
        assert!((p.acceleration(3.0) - 5.0).abs() < 1e-12); // a quarter period in
        assert!(
            (p.acceleration(5.5) - (5.0 * (1.75 * std::f64::consts::PI).sin() - 1.0)).abs() < 1e-12
        );
        assert_eq!(p.acceleration(6.0), 0.0);
        assert_eq!(ManoeuvreProfile::none().acceleration(3.0), 0.0);
        let s = p.scaled(2.0).unwrap();
        assert!((s.acceleration(3.0) - 10.0).abs() < 1e-12);
        assert_eq!(s.acceleration(1.5), 8.0);
        assert!(p.scaled(f64::NAN).is_err());
    }

    #[test]
    fn noise_free_truth_is_exact_constant_acceleration() {
        // Constant acceleration a from rest: theta(t) = a t^2 / 2 exactly at every sample.
        let profile = ManoeuvreProfile::new(vec![Manoeuvre::Step {
            start: 0.0,
            end: 100.0,
            acceleration: 2.0,
        }])
        .unwrap();
        let target = ManoeuvringTarget::new(ManoeuvringTargetParams {
            dt: 0.1,
            duration: 3.0,
            profile,
            sigma_input: 0.0,
            x0: Vector3::new(1.0, 0.5, 0.0),
        })
        .unwrap();
        assert_eq!(target.steps(), 30);
        let truth = target.truth_from_noise(&[0.0; 31]).unwrap();
        for (k, x) in truth.iter().enumerate() {
            let t = k as f64 * 0.1;
            assert!((x[0] - (1.0 + 0.5 * t + t * t)).abs() < 1e-12);
            assert!((x[1] - (0.5 + 2.0 * t)).abs() < 1e-12);
            assert_eq!(x[2], 2.0);
        }
    }

    #[test]
    fn draws_are_seeded_and_sized() {
        let target = target();
        assert_eq!(target.steps(), 100);
        let a = target.truth(&mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let b = target.truth(&mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.len(), 101);
        let z =
            ManoeuvringTarget::measurements(&a, 0.25, &mut ChaCha8Rng::seed_from_u64(2)).unwrap();
        assert_eq!(z.len(), 100);
    }

    #[test]
    fn bad_parameters_are_typed_errors() {
        let with = |dt, duration, sigma_input, x0| ManoeuvringTargetParams {
            dt,
            duration,
            profile: ManoeuvreProfile::none(),
            sigma_input,
            x0,
        };
        let x0 = Vector3::zeros();
        let invalid = |p: ManoeuvringTargetParams, name: &str| {
            matches!(
                ManoeuvringTarget::new(p),
                Err(ModelError::InvalidParameter { name: n, .. }) if n == name
            )
        };
        assert!(invalid(with(0.0, 1.0, 0.1, x0), "dt"));
        assert!(invalid(with(0.1, 0.01, 0.1, x0), "duration"));
        assert!(invalid(with(0.1, 1.0, -1.0, x0), "sigma_input"));
        assert!(matches!(
            ManoeuvringTarget::new(with(0.1, 1.0, 0.1, Vector3::new(f64::NAN, 0.0, 0.0))),
            Err(ModelError::NonFinite { .. })
        ));
        assert!(
            ManoeuvreProfile::new(vec![Manoeuvre::Step {
                start: 2.0,
                end: 1.0,
                acceleration: 1.0
            }])
            .is_err()
        );
        let target = target();
        assert!(target.truth_from_noise(&[0.0; 3]).is_err());
        let truth = target.truth_from_noise(&[0.0; 101]).unwrap();
        assert!(ManoeuvringTarget::measurements_from_noise(&truth, 0.25, &[0.0; 3]).is_err());
        assert!(ManoeuvringTarget::measurements_from_noise(&truth, -1.0, &[0.0; 100]).is_err());
        assert!(AngularTarget::diagonal(-0.1, [1.0; 3]).is_err());
        assert!(AngularTarget::diagonal(0.1, [1.0, -1.0, 1.0]).is_err());
    }
}
