//! The smoothers against FilterPy 2.0.0 and pykalman, from the fixtures that
//! `fixtures/smooth/make_fixtures.py` wrote (run once; its JSON output is committed, so the
//! tests need no Python): every smoothed mean, covariance and lag-one covariance to 1e-10.

// Each test prints the differences it measured (`-- --nocapture`), for the record.
#![allow(clippy::print_stderr)]

use kalibra_filters::smooth::{Smoothable, Smoothed};
use kalibra_filters::{AngleComponents, Kf, SigmaSet, Start, Ukf};
use kalibra_linalg::{DMatrix, DVector, Dyn, Matrix2, OMatrix, U1, U2, Vector1, Vector2};
use kalibra_models::{Dynamics, LinearGaussian, LinearObservation, Measurement, wrap_angle};
use serde_json::Value;

const TOLERANCE: f64 = 1e-10;

fn fixture(name: &str) -> Value {
    let path = format!(
        "{}/tests/fixtures/smooth/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn vector(v: &Value) -> DVector<f64> {
    DVector::from_iterator(
        v.as_array().unwrap().len(),
        v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()),
    )
}

fn matrix(v: &Value) -> DMatrix<f64> {
    let rows: Vec<DVector<f64>> = v.as_array().unwrap().iter().map(vector).collect();
    DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
}

fn fixed<const R: usize, const C: usize>(
    v: &Value,
) -> OMatrix<f64, kalibra_linalg::Const<R>, kalibra_linalg::Const<C>> {
    let m = matrix(v);
    nalgebra_fixed::<R, C>(&m)
}

fn fixed_vector<const R: usize>(v: &Value) -> OMatrix<f64, kalibra_linalg::Const<R>, U1> {
    let m = vector(v);
    nalgebra_fixed::<R, 1>(&DMatrix::from_column_slice(m.len(), 1, m.as_slice()))
}

fn nalgebra_fixed<const R: usize, const C: usize>(
    m: &DMatrix<f64>,
) -> OMatrix<f64, kalibra_linalg::Const<R>, kalibra_linalg::Const<C>> {
    kalibra_linalg::SMatrix::<f64, R, C>::from_fn(|i, j| m[(i, j)])
}

/// The measurements, `None` where the fixture has `null`.
fn measurements<const M: usize>(
    v: &Value,
) -> Vec<Option<OMatrix<f64, kalibra_linalg::Const<M>, U1>>> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|z| (!z.is_null()).then(|| fixed_vector::<M>(z)))
        .collect()
}

/// The largest absolute differences of the smoothed steps `from..` against the fixture's
/// `smoothed_mean` and `smoothed_cov` (their row 0 is step `from`); `angles` are compared
/// wrapped.
fn differences<N: kalibra_linalg::Dim>(
    smoothed: &Smoothed<N>,
    from: usize,
    fixture: &Value,
    angles: &[usize],
) -> (f64, f64)
where
    kalibra_linalg::DefaultAllocator: kalibra_linalg::Alloc<N>,
{
    let (means, covs) = (
        fixture["smoothed_mean"].as_array().unwrap(),
        fixture["smoothed_cov"].as_array().unwrap(),
    );
    assert_eq!(smoothed.steps().len(), from + means.len());
    let (mut mean, mut cov) = (0.0f64, 0.0f64);
    for (step, (m, p)) in smoothed.steps()[from..].iter().zip(means.iter().zip(covs)) {
        let m = vector(m);
        for i in 0..m.len() {
            let d = step.mean()[i] - m[i];
            let d = if angles.contains(&i) {
                wrap_angle(d)
            } else {
                d
            };
            mean = mean.max(d.abs());
        }
        let p = matrix(p);
        for i in 0..p.nrows() {
            for j in 0..p.ncols() {
                cov = cov.max((step.covariance()[(i, j)] - p[(i, j)]).abs());
            }
        }
    }
    (mean, cov)
}

#[test]
fn kf_matches_filterpy_rts_smoother() {
    let fx = fixture("kf_filterpy.json");
    let f = LinearGaussian::new(fixed::<4, 4>(&fx["f"]), fixed::<4, 4>(&fx["q"])).unwrap();
    let h = LinearObservation::new(fixed::<2, 4>(&fx["h"]), fixed::<2, 2>(&fx["r"])).unwrap();
    let z = measurements::<2>(&fx["z"]);
    let mut kf = Kf::new(
        &f,
        &h,
        fixed_vector::<4>(&fx["x0"]),
        fixed::<4, 4>(&fx["p0"]),
    )
    .unwrap();
    // FilterPy predicts first and smooths steps 1..n (its x0 is no step of its output).
    let smoothed = kf
        .smooth(z.iter().map(Option::as_ref), Start::PredictFirst)
        .unwrap();
    let (mean, cov) = differences(&smoothed, 1, &fx, &[]);
    eprintln!(
        "KF smoother against FilterPy rts_smoother: max |diff| mean {mean:.2e}, covariance {cov:.2e}"
    );
    assert!(
        mean < TOLERANCE && cov < TOLERANCE,
        "mean {mean:e}, covariance {cov:e}"
    );
}

#[test]
fn kf_matches_pykalman_smooth_and_pairwise_covariances() {
    // Dyn sizes: pykalman's model is 3 states, 1 measurement.
    let fx = fixture("kf_pykalman.json");
    let f = LinearGaussian::new(matrix(&fx["f"]), matrix(&fx["q"])).unwrap();
    let h = LinearObservation::new(matrix(&fx["h"]), matrix(&fx["r"])).unwrap();
    let z: Vec<Option<DVector<f64>>> = fx["z"]
        .as_array()
        .unwrap()
        .iter()
        .map(|z| (!z.is_null()).then(|| vector(z)))
        .collect();
    let mut kf: Kf<Dyn, Dyn, _, _> = Kf::new(&f, &h, vector(&fx["x0"]), matrix(&fx["p0"])).unwrap();
    // pykalman's initial state is the prior at the first observation: update first.
    let smoothed = kf
        .smooth(z.iter().map(Option::as_ref), Start::UpdateFirst)
        .unwrap();
    let (mean, cov) = differences(&smoothed, 0, &fx, &[]);
    let pairwise = fx["lag_one_cov"].as_array().unwrap();
    assert!(smoothed.steps()[0].lag_one().is_none());
    let mut lag_one = 0.0f64;
    for (step, expected) in smoothed.steps().iter().zip(pairwise).skip(1) {
        lag_one = lag_one.max((step.lag_one().unwrap() - matrix(expected)).amax());
    }
    eprintln!(
        "KF smoother against pykalman smooth: max |diff| mean {mean:.2e}, covariance {cov:.2e}, lag-one {lag_one:.2e}"
    );
    assert!(
        mean < TOLERANCE && cov < TOLERANCE && lag_one < TOLERANCE,
        "mean {mean:e}, covariance {cov:e}, lag-one {lag_one:e}"
    );
}

/// A heading turning at a constant rate: `theta' = wrap(theta + omega)`, `omega' = omega`.
#[derive(Debug)]
struct Turn {
    q: Matrix2<f64>,
}

impl Dynamics<U2> for Turn {
    fn state_dim(&self) -> U2 {
        U2
    }
    fn transition(&self, _k: usize, x: &Vector2<f64>) -> Vector2<f64> {
        Vector2::new(wrap_angle(x[0] + x[1]), x[1])
    }
    fn jacobian(&self, _k: usize, _x: &Vector2<f64>) -> Matrix2<f64> {
        Matrix2::new(1.0, 1.0, 0.0, 1.0)
    }
    fn noise_cov(&self, _k: usize) -> Matrix2<f64> {
        self.q
    }
}

/// The heading seen as a point on a circle.
#[derive(Debug)]
struct Circle {
    radius: f64,
    r: Matrix2<f64>,
}

impl Measurement<U2, U2> for Circle {
    fn meas_dim(&self) -> U2 {
        U2
    }
    fn measure(&self, _k: usize, x: &Vector2<f64>) -> Vector2<f64> {
        Vector2::new(x[0].cos(), x[0].sin()) * self.radius
    }
    fn jacobian(&self, _k: usize, x: &Vector2<f64>) -> OMatrix<f64, U2, U2> {
        Matrix2::new(-x[0].sin(), 0.0, x[0].cos(), 0.0) * self.radius
    }
    fn noise_cov(&self, _k: usize, _x: &Vector2<f64>) -> Matrix2<f64> {
        self.r
    }
}

#[test]
fn ukf_matches_filterpy_rts_smoother_across_pi() {
    let fx = fixture("ukf_angle.json");
    let num = |key: &str| fx[key].as_f64().unwrap();
    let dynamics = Turn {
        q: fixed::<2, 2>(&fx["q"]),
    };
    let sensor = Circle {
        radius: num("radius"),
        r: fixed::<2, 2>(&fx["r"]),
    };
    let set = SigmaSet::Scaled {
        alpha: num("alpha"),
        beta: num("beta"),
        kappa: num("kappa"),
    };
    let z = measurements::<2>(&fx["z"]);
    let mut ukf = Ukf::new(
        dynamics,
        sensor,
        fixed_vector::<2>(&fx["x0"]),
        fixed::<2, 2>(&fx["p0"]),
        set,
    )
    .unwrap()
    .with_state_space(AngleComponents::new([0]))
    .unwrap();
    let smoothed = ukf
        .smooth(z.iter().map(Option::as_ref), Start::PredictFirst)
        .unwrap();
    let (mean, cov) = differences(&smoothed, 1, &fx, &[0]);
    eprintln!(
        "UKF smoother against FilterPy (angle across pi): max |diff| mean {mean:.2e}, covariance {cov:.2e}"
    );
    assert!(
        mean < TOLERANCE && cov < TOLERANCE,
        "mean {mean:e}, covariance {cov:e}"
    );
    // The heading crosses +-pi, and the smoothed one stays in (-pi, pi].
    let headings: Vec<f64> = smoothed.steps().iter().map(|s| s.mean()[0]).collect();
    assert!(headings.windows(2).any(|w| (w[1] - w[0]).abs() > 5.0));
    assert!(headings.iter().all(|h| h.abs() <= std::f64::consts::PI));
}

/// Sarkka's pendulum: angle `a` and rate `w`, `a' = a + w dt`, `w' = w - g sin(a) dt`.
#[derive(Debug)]
struct Pendulum {
    dt: f64,
    gravity: f64,
    q: Matrix2<f64>,
}

impl Dynamics<U2> for Pendulum {
    fn state_dim(&self) -> U2 {
        U2
    }
    fn transition(&self, _k: usize, x: &Vector2<f64>) -> Vector2<f64> {
        Vector2::new(
            x[0] + x[1] * self.dt,
            x[1] - self.gravity * x[0].sin() * self.dt,
        )
    }
    fn jacobian(&self, _k: usize, x: &Vector2<f64>) -> Matrix2<f64> {
        Matrix2::new(1.0, self.dt, -self.gravity * x[0].cos() * self.dt, 1.0)
    }
    fn noise_cov(&self, _k: usize) -> Matrix2<f64> {
        self.q
    }
}

/// `sin(a)`.
#[derive(Debug)]
struct Sine {
    r: f64,
}

impl Measurement<U2, U1> for Sine {
    fn meas_dim(&self) -> U1 {
        U1
    }
    fn measure(&self, _k: usize, x: &Vector2<f64>) -> Vector1<f64> {
        Vector1::new(x[0].sin())
    }
    fn jacobian(&self, _k: usize, x: &Vector2<f64>) -> OMatrix<f64, U1, U2> {
        OMatrix::<f64, U1, U2>::new(x[0].cos(), 0.0)
    }
    fn noise_cov(&self, _k: usize, _x: &Vector2<f64>) -> Vector1<f64> {
        Vector1::new(self.r)
    }
}

#[test]
fn ukf_matches_filterpy_rts_smoother_on_the_pendulum() {
    let fx = fixture("ukf_pendulum.json");
    let num = |key: &str| fx[key].as_f64().unwrap();
    let dynamics = Pendulum {
        dt: num("dt"),
        gravity: num("gravity"),
        q: fixed::<2, 2>(&fx["q"]),
    };
    let sensor = Sine {
        r: fixed::<1, 1>(&fx["r"])[(0, 0)],
    };
    let set = SigmaSet::Symmetric {
        kappa: num("kappa"),
    };
    let z = measurements::<1>(&fx["z"]);
    let mut ukf = Ukf::new(
        dynamics,
        sensor,
        fixed_vector::<2>(&fx["x0"]),
        fixed::<2, 2>(&fx["p0"]),
        set,
    )
    .unwrap();
    let smoothed = ukf
        .smooth(z.iter().map(Option::as_ref), Start::PredictFirst)
        .unwrap();
    let (mean, cov) = differences(&smoothed, 1, &fx, &[]);
    eprintln!(
        "UKF smoother against FilterPy (pendulum): max |diff| mean {mean:.2e}, covariance {cov:.2e}"
    );
    assert!(
        mean < TOLERANCE && cov < TOLERANCE,
        "mean {mean:e}, covariance {cov:e}"
    );
}
