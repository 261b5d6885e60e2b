//! Tuning Q from measurements alone: sweep `Q = 10^p Q_nom`, compute the J1 (sensitivity) and
//! J2 (robustness) metrics of Saha, Goswami and Ghosh from each run's innovation covariances,
//! and take the crossover of the two curves as the compromise `Q_comp`.
//!
//! The truth is a 2-D constant-velocity target with white-acceleration intensity 0.5; the
//! nominal model has intensity 1. J1 and J2 need no truth; the example prints the position
//! RMSE beside them to show what the crossover chose. It is a compromise between sensitivity
//! and robustness, not the RMSE optimum: here it lands at a larger Q than the truth's (a
//! filter that follows manoeuvres it was not told about), at the cost of some RMSE.
//!
//! Run with `cargo run --example q_sweep`.

#![allow(clippy::print_stdout)]

use kalibra::prelude::*;

const STEPS: usize = 300;

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

    let exponents = grid(-4.0..=4.0, 0.25)?;
    println!("| p | nq | J1 | J2 | position RMSE |");
    println!("|---|---|---|---|---|");
    let mut points = Vec::new();
    let mut rmse_by_p = Vec::new();
    for &p in &exponents {
        let model = cv
            .noise(ProcessNoise::Discrete { q: 10f64.powf(p) })
            .dynamics(U4)?;
        let mut kf = Kf::new(&model, &sensor, x0, Matrix4::identity() * 100.0)?;
        let records = kf.run_collect(truth.measurements.iter().map(Some), Start::UpdateFirst)?;
        // J1/J2 average the step metrics over the horizon, from each update's A, B, R, C.
        let mut horizon = JHorizon::new();
        let mut squared = 0.0;
        for (record, x) in records.iter().zip(&truth.states) {
            horizon.push(&j_step(
                &record.compute_a(),
                &record.compute_b(),
                record.r(),
                &record.compute_c(),
            )?);
            let e = x - record.posterior().mean;
            squared += e[0] * e[0] + e[1] * e[1];
        }
        let j = horizon.summary(records.len())?;
        let rmse = (squared / records.len() as f64).sqrt();
        println!(
            "| {p:.2} | {:.3} | {:.3} | {:.3} | {rmse:.3} |",
            j.nq_log10_mean, j.j1, j.j2
        );
        rmse_by_p.push((p, rmse));
        points.push(kalibra::metrics::SweepPoint {
            p,
            nq: j.nq_log10_mean,
            j1: j.j1,
            j2: j.j2,
        });
    }
    let best = rmse_by_p.iter().fold(
        (f64::NAN, f64::INFINITY),
        |b, &(p, e)| if e < b.1 { (p, e) } else { b },
    );
    println!(
        "\nsmallest position RMSE {:.3} at p = {:.2}",
        best.1, best.0
    );
    match crossover(&points)? {
        Some(c) => println!(
            "crossover: p_c = {:.2} (Q_comp = {:.3} Q_nom), nq_c = {:.3}, J_c = {:.3}; \
             the truth's scale is 0.5 (p = -0.30)",
            c.p,
            10f64.powf(c.p),
            c.nq,
            c.j
        ),
        None => println!("J1 and J2 do not cross on this grid: widen it"),
    }
    Ok(())
}
