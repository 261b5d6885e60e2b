//! Smooths runs of W1's model (the 4-state constant-velocity KF of `cargo xtask bench smooth`)
//! with the library's [`Kf`] smoother or with the hand-written nalgebra loop of that bench, for
//! profilers: the smoother's cost per run without the bench's bookkeeping (the figures
//! are `cargo xtask bench smooth`'s).
//!
//! `cargo run --release -p kalibra-filters --example smooth_w1 -- [kalibra|hand] [runs] [steps]`
//!
//! Run it with `MALLOC_MMAP_THRESHOLD_=1000000000 MALLOC_TRIM_THRESHOLD_=1000000000`: otherwise
//! glibc maps the hand loop's zeroed vector afresh for every run, and its page faults (a tenth
//! of its time under `perf record -e cpu-clock`) are a cost the bench, whose earlier
//! allocations have raised glibc's thresholds, does not see.
//!
//! The measurements are a cheap deterministic sequence around a zero truth: the instruction
//! count does not depend on the values, only on the model's sizes.

// An example reports what it ran on standard output.
#![allow(clippy::print_stdout)]

use kalibra_filters::smooth::Smoothable;
use kalibra_filters::{Kf, Start};
use kalibra_linalg::{Matrix2, Matrix4, SMatrix, U2, U4, Vector2, Vector4};
use kalibra_models::{
    Dynamics, Kinematic, LinearDynamics, LinearMeasurement, Measurement, ProcessNoise,
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mode = args.next().unwrap_or_else(|| "kalibra".to_owned());
    let runs: usize = args.next().map_or(Ok(10), |a| a.parse())?;
    let steps: usize = args.next().map_or(Ok(1000), |a| a.parse())?;
    // W1's models and prior (kalibra-studies' `w1::models` and `w1::prior`).
    let cv = Kinematic::constant_velocity(2, 1.0)?.noise(ProcessNoise::Discrete { q: 1.0 });
    let f = cv.dynamics(U4)?;
    let h = cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)?;
    let m0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let p0 = Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0));
    // A 64-bit linear congruential sequence, mapped to [-10, 10).
    let mut state = 2012u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 * 20.0 - 10.0
    };
    let zs: Vec<Vector2<f64>> = (0..steps).map(|_| Vector2::new(next(), next())).collect();
    let model = Hand {
        f: f.matrix(0),
        q: f.noise_cov(0),
        h: h.matrix(0),
        r: h.noise_cov(0, &m0),
    };
    let mut total = 0.0;
    for _ in 0..runs {
        total += match mode.as_str() {
            "hand" => hand_smooth(&model, m0, p0, &zs)[0],
            _ => {
                let mut kf = Kf::new(&f, &h, m0, p0)?;
                let smoothed = kf.smooth(zs.iter().map(Some), Start::PredictFirst)?;
                smoothed.steps()[0].mean()[0]
            }
        };
    }
    println!("{mode}: {runs} runs x {steps} steps: sum of the first smoothed x {total:.6}");
    Ok(())
}

/// W1's matrices for the hand-written loop.
struct Hand {
    f: Matrix4<f64>,
    q: Matrix4<f64>,
    h: SMatrix<f64, 2, 4>,
    r: Matrix2<f64>,
}

fn sym4(m: &mut Matrix4<f64>) {
    *m = (*m + m.transpose()) * 0.5;
}

/// `xtask/src/bench/smooth.rs`'s hand-written smoother: the forward Joseph-form KF storing the
/// filtered and predicted estimates, then the RTS backward pass with a Cholesky solve and the
/// lag-one covariance. Returns the first smoothed mean.
fn hand_smooth(
    model: &Hand,
    m0: Vector4<f64>,
    p0: Matrix4<f64>,
    zs: &[Vector2<f64>],
) -> Vector4<f64> {
    let Hand { f, q, h, r } = *model;
    let k = zs.len();
    let mut xs = Vec::with_capacity(k + 1);
    let mut ps = Vec::with_capacity(k + 1);
    let mut priors: Vec<(Vector4<f64>, Matrix4<f64>)> = Vec::with_capacity(k);
    let (mut x, mut p) = (m0, p0);
    xs.push(x);
    ps.push(p);
    for z in zs {
        x = f * x;
        p = f * p * f.transpose() + q;
        sym4(&mut p);
        priors.push((x, p));
        let pht = p * h.transpose();
        let mut s = h * pht + r;
        s = (s + s.transpose()) * 0.5;
        let Some(chol) = s.cholesky() else {
            return Vector4::from_element(f64::NAN);
        };
        let gain = chol.solve(&pht.transpose()).transpose();
        x += gain * (z - h * x);
        let ikh = Matrix4::identity() - gain * h;
        p = ikh * p * ikh.transpose() + gain * r * gain.transpose();
        sym4(&mut p);
        xs.push(x);
        ps.push(p);
    }
    let mut lag_one = vec![Matrix4::zeros(); k + 1];
    for i in (0..k).rev() {
        let (xp, pp) = &priors[i];
        let cross = ps[i] * f.transpose();
        let Some(chol) = pp.cholesky() else {
            return Vector4::from_element(f64::NAN);
        };
        let gain = chol.solve(&cross.transpose()).transpose();
        let next = xs[i + 1];
        xs[i] += gain * (next - xp);
        let mut cov = ps[i] + gain * (ps[i + 1] - pp) * gain.transpose();
        sym4(&mut cov);
        lag_one[i + 1] = ps[i + 1] * gain.transpose();
        ps[i] = cov;
    }
    std::hint::black_box(&lag_one);
    std::hint::black_box(&ps);
    xs[0]
}
