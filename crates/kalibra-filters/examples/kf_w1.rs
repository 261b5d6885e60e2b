//! Steps the scalar [`Kf`] on W1's model (the 4-state constant-velocity KF of `cargo xtask
//! bench w1`) with each update's NEES and NIS, for profilers: the filter's cost per step
//! without the truth simulation or the study's bookkeeping, for `valgrind --tool=callgrind`
//! (`examples/w1_scalar.rs` of kalibra-studies runs the whole scalar study).
//!
//! `cargo run --release -p kalibra-filters --example kf_w1 -- [runs] [steps]`
//!
//! The measurements are a cheap deterministic sequence around a zero truth: the filter's
//! instruction count does not depend on the values, only on the model's sizes.

// An example reports what it ran on standard output.
#![allow(clippy::print_stdout)]

use kalibra_filters::{Filter, Kf};
use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
use kalibra_models::{Kinematic, ProcessNoise};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let runs: usize = args.next().map_or(Ok(100), |a| a.parse())?;
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
    let mut total = 0.0;
    for _ in 0..runs {
        let mut kf = Kf::new(&f, &h, m0, p0)?;
        for k in 0..steps {
            if k > 0 {
                kf.predict()?;
            }
            let z = Vector2::new(next(), next());
            let rec = kf.update(&z)?;
            let e: Vector4<f64> = -rec.posterior().mean;
            total += rec.nees(&e)? + rec.nis();
        }
    }
    println!("{runs} runs x {steps} steps: sum of NEES + NIS {total:.6}");
    Ok(())
}
