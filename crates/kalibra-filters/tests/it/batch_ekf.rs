//! The batched EKF ([`EkfBatch`]) lane by lane against the scalar [`Ekf`], on every
//! instruction set this CPU has, forced in turn: a nonlinear transition (paper 004's
//! sine/cosine axis) with a nonlinear, wrapping bearing measurement, and per-lane errors.

use std::f64::consts::PI;

use kalibra_filters::batch::{BATCH, EkfBatch, Isa, Lanes, PerLane};
use kalibra_filters::{Ekf, Filter, FilterError};
use kalibra_linalg::{Matrix1, Matrix3, SMatrix, U1, U3, Vector1, Vector3};
use kalibra_models::{AccelAxis, Measurement, Target3dParams};

use crate::lane_data;

/// The bearing of the point `(x0 + 3, x1 + 1)` seen from the origin, with its residual
/// wrapped into (-pi, pi] as angle models do: the lanes cross the +-pi cut.
#[derive(Clone, Copy, Debug)]
struct Bearing;

impl Measurement<U3, U1> for Bearing {
    fn meas_dim(&self) -> U1 {
        U1
    }
    fn measure(&self, _k: usize, x: &Vector3<f64>) -> Vector1<f64> {
        Vector1::new((x[1] + 1.0).atan2(x[0] + 3.0))
    }
    fn jacobian(&self, _k: usize, x: &Vector3<f64>) -> SMatrix<f64, 1, 3> {
        let (a, b) = (x[0] + 3.0, x[1] + 1.0);
        let r2 = a * a + b * b;
        SMatrix::<f64, 1, 3>::new(-b / r2, a / r2, 0.0)
    }
    fn noise_cov(&self, _k: usize, _x: &Vector3<f64>) -> Matrix1<f64> {
        Matrix1::new(0.01)
    }
    fn residual(&self, z: &Vector1<f64>, zhat: &Vector1<f64>) -> Vector1<f64> {
        let d = (z[0] - zhat[0]).rem_euclid(2.0 * PI);
        Vector1::new(if d > PI { d - 2.0 * PI } else { d })
    }
}

fn axis() -> AccelAxis {
    AccelAxis::new(Target3dParams::default(), 1).unwrap()
}

/// Lane `lane`'s measurement and truth at step `k` (`lane_data`).
fn data(k: usize, lane: usize) -> (Vector1<f64>, Vector3<f64>) {
    let x = lane_data::truth(k, lane);
    (
        lane_data::measured(k, lane, Bearing.measure(k, &x), 0.05),
        x,
    )
}

fn lanes_at(k: usize) -> ([Lanes; 1], [Lanes; 3]) {
    let mut z = [[0.0; BATCH]; 1];
    let mut x = [[0.0; BATCH]; 3];
    for lane in 0..BATCH {
        let (zl, xl) = data(k, lane);
        z[0][lane] = zl[0];
        for i in 0..3 {
            x[i][lane] = xl[i];
        }
    }
    (z, x)
}

fn rel(a: f64, b: f64, scale: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(scale)
}

fn batch(isa: Isa) -> EkfBatch<3, 1, PerLane<AccelAxis>, PerLane<Bearing>> {
    let (m0, p0) = lane_data::prior(0);
    let mut b = EkfBatch::new(isa, PerLane(axis()), PerLane(Bearing), m0, p0).unwrap();
    for lane in 0..BATCH {
        let (m, p) = lane_data::prior(lane);
        b.set_lane(lane, m, p).unwrap();
    }
    b
}

#[test]
fn every_lane_agrees_with_the_scalar_ekf_on_every_instruction_set() {
    let dynamics = axis();
    for isa in Isa::available() {
        let mut batch = batch(isa);
        assert_eq!(batch.isa(), isa);
        let mut scalar: Vec<_> = (0..BATCH)
            .map(|lane| {
                let (m, p) = lane_data::prior(lane);
                Ekf::new(dynamics, Bearing, m, p).unwrap()
            })
            .collect();
        let mut worst = 0.0f64;
        let mut wrapped = 0;
        // Step 0 is an update alone, as the scalar filter's first measurement at its
        // initial step.
        for k in 0..=300 {
            let (z, x) = lanes_at(k);
            let step = if k == 0 {
                batch.update(&z, &x)
            } else {
                batch.predict_update(&z, &x)
            }
            .clone();
            assert!(step.all_ok(), "{isa}, step {k}");
            assert_eq!(step.step(), k);
            for (lane, ekf) in scalar.iter_mut().enumerate() {
                if k > 0 {
                    ekf.predict().unwrap();
                }
                let (zl, xl) = data(k, lane);
                let rec = ekf.update(&zl).unwrap();
                if (zl[0] - rec.predicted_measurement()[0]).abs() > PI {
                    wrapped += 1;
                }
                let e = xl - rec.posterior().mean;
                // NIS and NEES relative to their expected values (M = 1, N = 3) where they are
                // smaller: a tiny NIS comes from an innovation z - h(x) that cancels, and
                // inherits that cancellation's relative error (2.9e-12 seen at NIS ~ 1e-3,
                // an absolute 3e-15), which says nothing about the filter.
                worst = worst
                    .max(rel(step.nis(lane).unwrap(), rec.nis(), 1.0))
                    .max(rel(step.nees(lane).unwrap(), rec.nees(&e).unwrap(), 3.0));
                let (mean, cov, gain) = (batch.mean(lane), batch.cov(lane), batch.gain(lane));
                let p = &rec.posterior().cov;
                for i in 0..3 {
                    worst = worst.max(rel(mean[i], rec.posterior().mean[i], mean.norm()));
                    worst = worst.max(rel(step.error(lane)[i], e[i], e.norm()));
                    worst = worst.max(rel(gain[(i, 0)], rec.gain()[(i, 0)], gain.norm()));
                    for j in 0..3 {
                        worst = worst.max(rel(cov[(i, j)], p[(i, j)], p.norm()));
                    }
                }
            }
        }
        assert!(wrapped > 0, "the data must cross the +-pi cut");
        assert!(
            worst <= 1e-12,
            "{isa}: largest relative difference {worst:e}"
        );
    }
}

#[test]
fn the_vector_paths_agree_to_the_bit() {
    // AVX-512 steps the batch as one vector, AVX2 as two: the same fused arithmetic per lane.
    let isas: Vec<Isa> = Isa::available()
        .into_iter()
        .filter(|i| matches!(i, Isa::Avx512 | Isa::Avx2))
        .collect();
    let mut runs = isas.iter().map(|&isa| batch(isa)).collect::<Vec<_>>();
    for k in 1..=100 {
        let (z, x) = lanes_at(k);
        let steps: Vec<_> = runs
            .iter_mut()
            .map(|b| b.predict_update(&z, &x).clone())
            .collect();
        for (s, b) in steps.iter().zip(&runs).skip(1) {
            assert_eq!(s, &steps[0]);
            assert_eq!(b.means(), runs[0].means());
        }
    }
}

#[test]
fn a_nan_measurement_fails_only_its_lane_and_keeps_its_prediction() {
    let dynamics = axis();
    for isa in Isa::available() {
        let mut clean = batch(isa);
        let mut dirty = batch(isa);
        let (m, p) = lane_data::prior(3);
        let mut ekf3 = Ekf::new(dynamics, Bearing, m, p).unwrap();
        for k in 1..=12 {
            let (z, x) = lanes_at(k);
            let mut z_bad = z;
            if k == 5 {
                z_bad[0][3] = f64::NAN;
            }
            let a = clean.predict_update(&z, &x).clone();
            let b = dirty.predict_update(&z_bad, &x).clone();
            ekf3.predict().unwrap();
            let scalar = ekf3.update(&Vector1::new(z_bad[0][3])).map(|rec| rec.nis());
            for lane in 0..BATCH {
                if lane == 3 && k == 5 {
                    let expected = FilterError::NonFinite {
                        what: "measurement",
                        step: 5,
                    };
                    assert_eq!(scalar, Err(expected.clone()));
                    assert_eq!(b.nis(lane), Err(expected.clone()), "{isa}");
                    assert_eq!(b.nees(lane), Err(expected), "{isa}");
                    let d = dirty.mean(3) - ekf3.mean();
                    assert!(d.amax() <= 1e-12 * ekf3.mean().amax(), "{isa}: {d}");
                } else if !(lane == 3 && k > 5) {
                    assert_eq!(b.nis(lane), a.nis(lane), "{isa}, lane {lane}, step {k}");
                    assert_eq!(dirty.cov(lane), clean.cov(lane));
                }
            }
        }
    }
}

/// A transition whose lane 6 (initial position 1e200) overflows to infinity: its run fails
/// alone, as the scalar filter's does.
#[derive(Clone, Copy, Debug)]
struct Squaring;

impl kalibra_models::Dynamics<U3> for Squaring {
    fn state_dim(&self) -> U3 {
        U3
    }
    fn transition(&self, _k: usize, x: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(x[0] * x[0].abs().min(1e300), x[1], x[2])
    }
    fn jacobian(&self, _k: usize, _x: &Vector3<f64>) -> Matrix3<f64> {
        Matrix3::identity()
    }
    fn noise_cov(&self, _k: usize) -> Matrix3<f64> {
        Matrix3::identity() * 0.01
    }
}

#[test]
fn a_model_that_overflows_in_one_lane_fails_that_lane_only() {
    for isa in Isa::available() {
        let (m0, p0) = lane_data::prior(0);
        let mut b = EkfBatch::new(isa, PerLane(Squaring), PerLane(Bearing), m0, p0).unwrap();
        b.set_lane(6, Vector3::new(1e200, 0.0, 0.0), p0).unwrap();
        let (z, x) = lanes_at(1);
        let step = b.predict_update(&z, &x);
        for lane in 0..BATCH {
            assert_eq!(step.nis(lane).is_err(), lane == 6, "{isa}, lane {lane}");
        }
        assert!(matches!(
            step.nis(6),
            Err(FilterError::NonFinite { step: 1, .. })
        ));
    }
}

#[test]
fn bad_initial_estimates_are_errors_and_leave_the_lane_unchanged() {
    let (m0, p0) = lane_data::prior(0);
    let mut nan = m0;
    nan[1] = f64::NAN;
    assert!(matches!(
        EkfBatch::new(Isa::Scalar, PerLane(axis()), PerLane(Bearing), nan, p0),
        Err(FilterError::Initial(_))
    ));
    let mut b = EkfBatch::new(Isa::Scalar, PerLane(axis()), PerLane(Bearing), m0, p0).unwrap();
    assert!(b.set_lane(2, m0, -p0).is_err());
    assert!(b.set_lane(2, nan, p0).is_err());
    assert_eq!(b.cov(2), p0);
    assert_eq!(b.mean(2), m0);
}

/// Paper 003's re-entry EKF (ballistic dynamics, radar range rate / elevation / sightline
/// rate): the batch's J1/J2 step terms against `kalibra_metrics::j_step` on the scalar
/// records, over process-noise levels from tiny to large.
#[test]
fn the_j_terms_agree_with_j_step_on_the_reentry_radar() {
    use kalibra_linalg::{Matrix4, Vector4};
    use kalibra_models::{Ballistic, BallisticParams, Dynamics, RadarRates};
    let params = BallisticParams {
        period: 2.0,
        beta: 40_000.0,
        gravity: 9.81,
    };
    let q_nom = Matrix4::new(
        20.80, 0.06, -0.96, -0.40, 0.06, 0.06, -0.12, 0.01, -0.96, -0.12, 6.00, 0.13, -0.40, 0.01,
        0.13, 0.04,
    ) * 1e2;
    let p0 = Matrix4::new(
        99.39, -0.56, 22.38, -1.73, -0.56, 0.23, -0.01, 0.04, 22.38, -0.01, 9.15, -0.58, -1.73,
        0.04, -0.58, 0.09,
    ) * 1e3;
    let x0 = Vector4::new(2.336e5, -0.022e5, 0.889e5, -0.004e5);
    let radar = RadarRates::new(Matrix3::from_diagonal(&Vector3::new(
        225.0,
        (0.1f64 / 57.3).powi(2),
        (0.01f64 / 57.3).powi(2),
    )))
    .unwrap();
    let angle = 190f64.to_radians();
    let truth0 = Vector4::new(232e3, 2290.0 * angle.cos(), 88e3, 2290.0 * angle.sin());
    for p in [-8.0, 0.0, 5.0] {
        let dynamics = Ballistic::new(params, q_nom * 10f64.powf(p)).unwrap();
        for isa in Isa::available() {
            let mut batch =
                EkfBatch::new(isa, PerLane(&dynamics), PerLane(&radar), x0, p0).unwrap();
            let mut scalar: Vec<_> = (0..BATCH)
                .map(|_| Ekf::new(&dynamics, &radar, x0, p0).unwrap())
                .collect();
            // Lane l's truth starts 100 l metres higher; its measurements are noise-free.
            let mut truth: Vec<Vector4<f64>> = (0..BATCH)
                .map(|l| truth0 + Vector4::new(0.0, 0.0, 100.0 * l as f64, 0.0))
                .collect();
            let mut worst = 0.0f64;
            for k in 1..=40 {
                let mut z = [[0.0; BATCH]; 3];
                let mut x = [[0.0; BATCH]; 4];
                for (l, t) in truth.iter_mut().enumerate() {
                    *t = dynamics.transition(k - 1, t);
                    let zl = radar.measure(k, t);
                    for i in 0..3 {
                        z[i][l] = zl[i];
                    }
                    for i in 0..4 {
                        x[i][l] = t[i];
                    }
                }
                let (step, terms) = batch.predict_update_j(&z, &x);
                assert!(step.all_ok(), "{isa}, p {p}, step {k}");
                for (l, ekf) in scalar.iter_mut().enumerate() {
                    ekf.predict().unwrap();
                    let zl = Vector3::new(z[0][l], z[1][l], z[2][l]);
                    let rec = ekf.update(&zl).unwrap();
                    let j = kalibra_metrics::j_step(
                        &rec.compute_a(),
                        &rec.compute_b(),
                        rec.r(),
                        &rec.compute_c(),
                    )
                    .unwrap();
                    assert!(j.a_plus_b_definite);
                    // The J's lie in [0, 3]: relative to 1 where they are smaller.
                    worst = worst
                        .max(rel(terms.j1(l), j.j1, 1.0))
                        .max(rel(terms.j2(l), j.j2, 1.0))
                        .max(rel(terms.tr_n(l), j.tr_n, 1.0))
                        .max(rel(terms.tr_b(l), j.tr_b, 0.0));
                    let b = rec.compute_b();
                    worst = worst.max((terms.b(l) - b).amax() / b.amax());
                    assert_eq!(terms.r(l), *rec.r());
                }
            }
            assert!(worst <= 1e-12, "{isa}, p {p}: {worst:e}");
        }
    }
}

/// The lane-wise models of kalibra-models (`LinearGaussian`'s broadcast `F x`, `Bearing`'s SIMD
/// arctangent) in the batch, against the scalar `Ekf` on the same models: paper 001's problem
/// III layout (a target seen from a platform on the unit circle), bearings across +-pi.
#[test]
fn lane_wise_models_agree_with_the_scalar_ekf_on_every_instruction_set() {
    use kalibra_linalg::{Matrix2, U2, Vector2};
    use kalibra_models::{Bearing, BearingReference, LinearGaussian, Tabulated};
    let dynamics = LinearGaussian::new(
        Matrix2::new(0.9, 0.0, 0.0, 1.0),
        Matrix2::new(0.1, 0.01, 0.01, 0.1),
    )
    .unwrap();
    let steps = 60;
    let platform = Tabulated::new(
        (0..steps)
            .map(|k| Vector2::new((k as f64).cos(), (k as f64).sin()))
            .collect(),
    )
    .unwrap();
    let sensor = Bearing::new(U2, [0, 1], BearingReference::XAxis, 0.025, platform).unwrap();
    // Lane l's target: on the far side of the platform for odd lanes (bearings near +-pi).
    let target = |k: usize, l: usize| {
        let t = k as f64;
        let side = if l % 2 == 1 { -1.0 } else { 1.0 };
        Vector2::new(side * (20.0 - 0.1 * t), 0.5 * (0.3 * t + l as f64).sin())
    };
    for isa in Isa::available() {
        let (m0, p0) = (Vector2::new(20.0, 0.0), Matrix2::identity());
        let mut batch = EkfBatch::new(isa, &dynamics, &sensor, m0, p0).unwrap();
        let mut scalar: Vec<_> = (0..BATCH)
            .map(|l| {
                let m = Vector2::new(if l % 2 == 1 { -20.0 } else { 20.0 }, 0.0);
                batch.set_lane(l, m, p0).unwrap();
                Ekf::new(&dynamics, &sensor, m, p0).unwrap()
            })
            .collect();
        let mut worst = 0.0f64;
        for k in 0..steps {
            let mut z = [[0.0; BATCH]; 1];
            let mut x = [[0.0; BATCH]; 2];
            for l in 0..BATCH {
                let t = target(k, l);
                z[0][l] = kalibra_models::wrap_angle(
                    sensor.measure(k, &t)[0] + 0.05 * (1.3 * k as f64 + l as f64).sin(),
                );
                x[0][l] = t[0];
                x[1][l] = t[1];
            }
            let step = if k == 0 {
                batch.update(&z, &x)
            } else {
                batch.predict_update(&z, &x)
            }
            .clone();
            assert!(step.all_ok(), "{isa}, step {k}");
            for (l, ekf) in scalar.iter_mut().enumerate() {
                if k > 0 {
                    ekf.predict().unwrap();
                }
                let rec = ekf.update(&Vector1::new(z[0][l])).unwrap();
                let e = Vector2::new(x[0][l], x[1][l]) - rec.posterior().mean;
                worst = worst
                    .max(rel(step.nis(l).unwrap(), rec.nis(), 1.0))
                    .max(rel(step.nees(l).unwrap(), rec.nees(&e).unwrap(), 2.0));
                let (mean, cov) = (batch.mean(l), batch.cov(l));
                let p = &rec.posterior().cov;
                for i in 0..2 {
                    worst = worst.max(rel(mean[i], rec.posterior().mean[i], mean.norm()));
                    for j in 0..2 {
                        worst = worst.max(rel(cov[(i, j)], p[(i, j)], p.norm()));
                    }
                }
            }
        }
        assert!(
            worst <= 1e-12,
            "{isa}: largest relative difference {worst:e}"
        );
    }
}
