//! The cost of a square-root KF step against the Joseph-form `Kf`'s, on W1's model (4 states,
//! 2 position measurements, `R = 100 I`): times both filters over the same measurements and
//! prints the time per step (one prediction and one update) and the ratio.
//!
//! `cargo run --release -p kalibra-filters --example sqrt_cost -- [both|kf|sqrt] [steps] [repeats]`
//!
//! `kf` or `sqrt` runs one filter only, for `valgrind --tool=callgrind` (instructions per step
//! are the difference of two step counts divided by the difference of steps, so start-up
//! cancels). The measurements are a cheap deterministic sequence: the cost does not depend on
//! the values.

// An example reports what it measured on standard output.
#![allow(clippy::print_stdout)]

use std::hint::black_box;
use std::time::Instant;

use kalibra_filters::{Filter, Kf, SqrtKf};
use kalibra_linalg::{Matrix2, Matrix4, U2, U4, Vector2, Vector4};
use kalibra_models::{Kinematic, LinearGaussian, LinearObservation};

/// `steps` measurements from a 64-bit linear congruential sequence, in `[-10, 10)`.
fn measurements(steps: usize) -> Vec<Vector2<f64>> {
    let mut state = 2012u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 * 20.0 - 10.0
    };
    (0..steps).map(|_| Vector2::new(next(), next())).collect()
}

/// Steps `filter` through `z` (predict, update) and returns a sum of the means, so that the
/// work cannot be optimised away.
fn run<F: Filter<U4, U2>>(
    mut filter: F,
    z: &[Vector2<f64>],
) -> Result<f64, Box<dyn std::error::Error>> {
    let mut total = 0.0;
    for zk in z {
        filter.predict()?;
        total += filter.update(black_box(zk))?.posterior().mean[0];
    }
    Ok(total)
}

/// The best of `repeats` timings of `run` over `z`, in nanoseconds per step.
fn time_per_step(
    repeats: usize,
    z: &[Vector2<f64>],
    mut run_once: impl FnMut(&[Vector2<f64>]) -> Result<f64, Box<dyn std::error::Error>>,
) -> Result<f64, Box<dyn std::error::Error>> {
    let mut best = f64::INFINITY;
    for _ in 0..repeats {
        let start = Instant::now();
        black_box(run_once(z)?);
        best = best.min(start.elapsed().as_secs_f64() * 1e9 / z.len() as f64);
    }
    Ok(best)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let which = args.next().unwrap_or_else(|| "both".into());
    let steps: usize = args.next().map_or(Ok(100_000), |a| a.parse())?;
    let repeats: usize = args.next().map_or(Ok(9), |a| a.parse())?;
    let cv = Kinematic::constant_velocity(2, 1.0)?;
    let f: LinearGaussian<U4> = cv.dynamics(U4)?;
    let h: LinearObservation<U4, U2> =
        cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)?;
    let x0 = Vector4::new(0.0, 0.0, 10.0, -5.0);
    let p0 = Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 25.0, 25.0));
    let z = measurements(steps);
    let kf = |z: &[Vector2<f64>]| run(Kf::new(&f, &h, x0, p0)?, z);
    let sqrt = |z: &[Vector2<f64>]| run(SqrtKf::new(&f, &h, x0, p0)?, z);
    match which.as_str() {
        "kf" => println!("kf: sum of means {}", kf(&z)?),
        "sqrt" => println!("sqrt: sum of means {}", sqrt(&z)?),
        _ => {
            let t_kf = time_per_step(repeats, &z, kf)?;
            let t_sqrt = time_per_step(repeats, &z, sqrt)?;
            println!("steps {steps}, best of {repeats}");
            println!("Kf      {t_kf:8.1} ns/step");
            println!("SqrtKf  {t_sqrt:8.1} ns/step");
            println!("ratio   {:8.2}", t_sqrt / t_kf);
        }
    }
    Ok(())
}
