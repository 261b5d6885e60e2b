//! An uncertainty bound for an EKF's error from one trajectory, by Spall and Wei's surrogate:
//! average the gain `K_k` and the Jacobian `J_k` along the run, form the AR(1) surrogate
//! `e'_{k+1} = (I - K* H) J* e'_k + eta`, and read 95% intervals off its limiting covariance.
//!
//! The model is a damped Duffing oscillator (a hardening spring, `x'' = -k x - c x^3 - d x'`)
//! stepped by semi-implicit Euler, position measured. One long run gives the surrogate; the same
//! run's errors after the burn-in show how often they fall inside the intervals (the
//! surrogate's are the limiting law of the error, the EKF's own covariance is its opinion).
//!
//! Run with `cargo run --example surrogate_bound`.

#![allow(clippy::print_stdout)]

use kalibra::prelude::*;

const DT: f64 = 0.1;
const STIFFNESS: f64 = 1.0;
const CUBIC: f64 = 0.5;
const DAMPING: f64 = 0.2;
const STEPS: usize = 5000;
const BURN_IN: usize = 500;

/// Damped Duffing oscillator, state `[position, velocity]`, white acceleration noise.
struct Duffing {
    q: Matrix2<f64>,
}

impl Dynamics<U2> for Duffing {
    fn state_dim(&self) -> U2 {
        U2
    }

    fn transition(&self, _k: usize, x: &Vector2<f64>) -> Vector2<f64> {
        // Semi-implicit Euler: the new velocity moves the position, which keeps the discrete
        // oscillator stable where explicit Euler would pump energy into it.
        let accel = -STIFFNESS * x[0] - CUBIC * x[0].powi(3) - DAMPING * x[1];
        let v = x[1] + DT * accel;
        Vector2::new(x[0] + DT * v, v)
    }

    fn jacobian(&self, _k: usize, x: &Vector2<f64>) -> Matrix2<f64> {
        let dv_dx = -DT * (STIFFNESS + 3.0 * CUBIC * x[0] * x[0]);
        let dv_dv = 1.0 - DT * DAMPING;
        Matrix2::new(1.0 + DT * dv_dx, DT * dv_dv, dv_dx, dv_dv)
    }

    fn noise_cov(&self, _k: usize) -> Matrix2<f64> {
        self.q
    }
}

fn main() -> Result<(), kalibra::Error> {
    let q = 0.05;
    let dynamics = Duffing {
        q: Matrix2::new(
            q * DT.powi(3) / 3.0,
            q * DT.powi(2) / 2.0,
            q * DT.powi(2) / 2.0,
            q * DT,
        ),
    };
    let h = OMatrix::<f64, U1, U2>::new(1.0, 0.0);
    let r = Matrix1::new(0.04);
    let sensor = LinearObservation::new(h, r)?;
    let x0 = Vector2::new(1.0, 0.0);
    let truth = simulate(
        &dynamics,
        &sensor,
        x0,
        STEPS,
        &mut MonteCarlo::new(1, 5).rng(0),
    )?;

    let mut ekf = Ekf::new(&dynamics, &sensor, x0, Matrix2::identity() * 0.1)?;
    let records = ekf.run_collect(truth.measurements.iter().map(Some), Start::UpdateFirst)?;

    // Ergodic averages of the gain and of the Jacobian at the estimate, after the burn-in.
    let mut averages = ErgodicAverage::new(U2, U1);
    for record in &records[BURN_IN..] {
        let jacobian = dynamics.jacobian(record.step(), &record.posterior().mean);
        averages.push(record.gain(), &jacobian)?;
    }
    let surrogate = Surrogate::from_averages(&averages, &h, &dynamics.q, &r)?;
    let widths = surrogate.half_widths(0.95)?;

    // How often the errors of this run (after the burn-in) fall inside each interval.
    let tail = &records[BURN_IN..];
    let mut inside_surrogate = [0usize; 2];
    let mut inside_own = [0usize; 2];
    for (record, x) in tail.iter().zip(&truth.states[BURN_IN..]) {
        let e = x - record.posterior().mean;
        for i in 0..2 {
            inside_surrogate[i] += usize::from(e[i].abs() <= widths[i]);
            let own = 1.959_963_984_540_054 * record.posterior().cov[(i, i)].sqrt();
            inside_own[i] += usize::from(e[i].abs() <= own);
        }
    }
    println!(
        "Duffing oscillator, one run of {STEPS} steps, burn-in {BURN_IN}; spectral radius of \
         (I - K* H) J*: {:.3}",
        surrogate.spectral_radius()
    );
    println!("| component | surrogate 95% half-width | errors inside | inside the EKF's own 95% |");
    println!("|---|---|---|---|");
    for (i, name) in ["position", "velocity"].iter().enumerate() {
        println!(
            "| {name} | {:.4} | {:.1}% | {:.1}% |",
            widths[i],
            100.0 * inside_surrogate[i] as f64 / tail.len() as f64,
            100.0 * inside_own[i] as f64 / tail.len() as f64
        );
    }
    Ok(())
}
