//! Tuning Q from measurements alone, in one call: `Tuning::tune` sweeps `Q = 10^p Q_nom`,
//! computes the J1 (sensitivity) and J2 (robustness) metrics of Saha, Goswami and Ghosh from
//! each point's innovation covariances, and takes the crossover of the two curves as the
//! compromise `Q_comp`.
//!
//! The truth is a 2-D constant-velocity target with white-acceleration intensity 0.5; the
//! nominal model has intensity 1. J1 and J2 need no truth; the truth handed to the problem only
//! adds the position RMSE beside them, to show what the crossover chose. It is a compromise
//! between sensitivity and robustness, not the RMSE optimum: here it lands at a larger Q than
//! the truth's (a filter that follows manoeuvres it was not told about), at the cost of some
//! RMSE. `kalibra tune` and Python's `kalibra.sweep_q` run the same call.
//!
//! Run with `cargo run --example q_sweep`.

#![allow(clippy::print_stdout)]

use kalibra::prelude::*;

const STEPS: usize = 300;

/// A fixed-size matrix as the run-time-sized one a `TuneProblem` takes.
fn dynamic<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> DMatrix<f64> {
    DMatrix::from_column_slice(R, C, m.as_slice())
}

fn main() -> Result<(), kalibra::Error> {
    let cv = Kinematic::constant_velocity(2, 1.0)?;
    let r = Matrix2::identity() * 25.0;
    let truth_model = cv.noise(ProcessNoise::Discrete { q: 0.5 });
    let sensor = cv.position_measurement(U4, U2, r)?;
    let x0 = Vector4::new(0.0, 0.0, 5.0, 2.0);
    let truth = simulate(
        truth_model.dynamics(U4)?,
        &sensor,
        x0,
        STEPS,
        &mut MonteCarlo::new(1, 11).rng(0),
    )?;

    // The nominal model: intensity 1, so that `10^p Q_nom` is the model of intensity 10^p.
    let nominal = cv.noise(ProcessNoise::Discrete { q: 1.0 });
    let column = |v: &[f64]| Some(DVector::from_column_slice(v));
    let problem = TuneProblem::new(
        dynamic(&nominal.transition_matrix(U4)?),
        dynamic(sensor.h()),
        dynamic(&nominal.noise_matrix(U4)?),
        dynamic(&r),
        DVector::from_column_slice(x0.as_slice()),
        DMatrix::identity(4, 4) * 100.0,
        truth
            .measurements
            .iter()
            .map(|z| column(z.as_slice()))
            .collect(),
    )?
    .with_start(Start::UpdateFirst)
    .with_truth(truth.states.iter().map(|x| column(x.as_slice())).collect())?;

    let report = Tuning::new()
        .exponents(-4.0, 4.0, 0.25)?
        .position(vec![0, 1])
        .tune(&problem)?;

    println!("| p | nq | J1 | J2 | position RMSE |");
    println!("|---|---|---|---|---|");
    for point in &report.points {
        let nq = point.nq_log10_mean.unwrap_or(f64::NAN);
        let rmse = point
            .rmse
            .as_ref()
            .and_then(|r| r.position)
            .unwrap_or(f64::NAN);
        println!(
            "| {:.2} | {nq:.3} | {:.3} | {:.3} | {rmse:.3} |",
            point.p, point.j1, point.j2
        );
    }
    if let Some(best) = report.rmse_minimum
        && let (Some(p), Some(rmse)) = (best.p_position, best.position)
    {
        println!("\nsmallest position RMSE {rmse:.3} at p = {p:.2}");
    }
    match report.crossover {
        Some(c) => println!(
            "crossover: p_c = {:.2} (Q_comp = {:.3} Q_nom), nq_c = {:.3}, J_c = {:.3}; \
             the truth's scale is 0.5 (p = -0.30)",
            c.p,
            10f64.powf(c.p),
            c.nq_log10_mean.unwrap_or(f64::NAN),
            c.j
        ),
        None => println!("J1 and J2 do not cross on this grid: widen it"),
    }
    Ok(())
}
