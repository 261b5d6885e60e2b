//! Your own nonlinear model through the EKF and the UKF, judged by a Monte Carlo consistency
//! check: the ANEES per step against its chi-square band.
//!
//! The model is a pendulum (angle `theta`, rate `omega`) stepped by explicit Euler, observed
//! through the horizontal position of its bob, `L sin(theta)`. Both traits are implemented
//! here, outside kalibra: a filter needs nothing else.
//!
//! Run with `cargo run --example custom_model`.

#![allow(clippy::print_stdout)]

use kalibra::linalg::PsdMatrix;
use kalibra::models::sample_with_factor;
use kalibra::prelude::*;

/// Pendulum length (m), gravity (m/s^2) and time step (s).
const LENGTH: f64 = 2.0;
const GRAVITY: f64 = 9.81;
const DT: f64 = 0.05;

/// `theta' = theta + dt omega`, `omega' = omega - dt (g / L) sin(theta)`, with white
/// acceleration noise entering the rate.
struct Pendulum {
    q: Matrix2<f64>,
}

impl Dynamics<U2> for Pendulum {
    fn state_dim(&self) -> U2 {
        U2
    }

    fn transition(&self, _k: usize, x: &Vector2<f64>) -> Vector2<f64> {
        Vector2::new(x[0] + DT * x[1], x[1] - DT * GRAVITY / LENGTH * x[0].sin())
    }

    fn jacobian(&self, _k: usize, x: &Vector2<f64>) -> Matrix2<f64> {
        Matrix2::new(1.0, DT, -DT * GRAVITY / LENGTH * x[0].cos(), 1.0)
    }

    fn noise_cov(&self, _k: usize) -> Matrix2<f64> {
        self.q
    }
}

/// The bob's horizontal position, `L sin(theta)`, with variance `r`.
struct BobPosition {
    r: f64,
}

impl Measurement<U2, U1> for BobPosition {
    fn meas_dim(&self) -> U1 {
        U1
    }

    fn measure(&self, _k: usize, x: &Vector2<f64>) -> Vector1<f64> {
        Vector1::new(LENGTH * x[0].sin())
    }

    fn jacobian(&self, _k: usize, x: &Vector2<f64>) -> OMatrix<f64, U1, U2> {
        OMatrix::<f64, U1, U2>::new(LENGTH * x[0].cos(), 0.0)
    }

    fn noise_cov(&self, _k: usize, _x: &Vector2<f64>) -> Matrix1<f64> {
        Matrix1::new(self.r)
    }
}

const RUNS: usize = 500;
const STEPS: usize = 200;

fn main() -> Result<(), kalibra::Error> {
    // Noise enters the rate only; the angle follows through the dynamics.
    let q = 0.01 * DT;
    let dynamics = Pendulum {
        q: Matrix2::new(q * DT * DT / 3.0, q * DT / 2.0, q * DT / 2.0, q),
    };
    let sensor = BobPosition { r: 0.05 * 0.05 };
    let prior_mean = Vector2::new(0.8, 0.0);
    let prior_cov = Matrix2::from_diagonal(&Vector2::new(0.1 * 0.1, 0.2 * 0.2));
    let prior_factor = PsdMatrix::new(prior_cov)?.factor().clone_owned();

    let mc = MonteCarlo::new(RUNS, 2024);
    // Mean NEES per step for the EKF and the UKF, over the runs.
    let (ekf_nees, ukf_nees) = mc.accumulate(
        || (StepMean::new(STEPS), StepMean::new(STEPS)),
        |_run, rng, (ekf_acc, ukf_acc)| {
            // The truth starts from a draw of the filters' prior, so a consistent filter's
            // NEES has mean n = 2.
            let x0 = prior_mean + sample_with_factor(&prior_factor, rng);
            let truth = simulate(&dynamics, &sensor, x0, STEPS, rng)?;
            let measurements = || truth.measurements.iter().map(Some);

            let mut ekf = Ekf::new(&dynamics, &sensor, prior_mean, prior_cov)?;
            let mut ukf = Ukf::new(
                &dynamics,
                &sensor,
                prior_mean,
                prior_cov,
                SigmaSet::recommended(2),
            )?;
            for (acc, records) in [
                (
                    &mut *ekf_acc,
                    ekf.run_collect(measurements(), Start::UpdateFirst)?,
                ),
                (
                    &mut *ukf_acc,
                    ukf.run_collect(measurements(), Start::UpdateFirst)?,
                ),
            ] {
                for (k, (record, x)) in records.iter().zip(&truth.states).enumerate() {
                    acc.push(k, record.nees(&(x - record.posterior().mean))?)?;
                }
            }
            Ok::<(), kalibra::Error>(())
        },
    )?;

    // ANEES = mean NEES / n; the two-sided 95% band for an average over RUNS runs.
    let band = ChiSquareBand::for_normalized_mean(2.0, RUNS, 0.95)?;
    println!(
        "pendulum, {RUNS} runs x {STEPS} steps; 95% band for the ANEES per step: [{:.3}, {:.3}]",
        band.lower, band.upper
    );
    println!("| filter | time-averaged ANEES | steps inside the band |");
    println!("|---|---|---|");
    for (name, nees) in [("EKF", &ekf_nees), ("UKF", &ukf_nees)] {
        // Every run pushed every step, so every step has a mean (`None` marks an empty step).
        let anees: Vec<f64> = nees.means().iter().flatten().map(|m| m / 2.0).collect();
        let inside = anees.iter().filter(|a| band.contains(**a)).count();
        println!(
            "| {name} | {:.3} | {:.1}% |",
            time_average(&anees)?,
            100.0 * inside as f64 / STEPS as f64
        );
    }
    println!(
        "A consistent filter's time average is near 1 with about 95% of steps inside the band; \
         above the band the filter is optimistic (its covariance too small)."
    );
    Ok(())
}
