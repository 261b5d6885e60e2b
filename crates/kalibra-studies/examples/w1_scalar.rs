//! Runs W1's scalar study, [`w1::run_scalar`] (the library side of `cargo xtask bench w1`: the
//! truth simulation, the scalar `Kf`, NEES/NIS and the per-step sums), for profilers:
//! callgrind counts its instructions per run-step repeatably. kalibra-filters'
//! `examples/kf_w1.rs` steps the filter alone on the same model.
//!
//! `cargo run --release -p kalibra-studies --example w1_scalar -- [runs] [steps]`

// An example reports what it ran on standard output.
#![allow(clippy::print_stdout)]

use kalibra_studies::w1;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let runs: usize = args.next().map_or(Ok(100), |a| a.parse())?;
    let steps: usize = args.next().map_or(Ok(1000), |a| a.parse())?;
    let report = w1::run_scalar(&w1::Config {
        runs,
        steps,
        seed: 2012,
        threads: 1,
        confidence: 0.95,
        simd: None,
    })?;
    println!(
        "{runs} runs x {steps} steps: ANEES time average {:.6}, ANIS {:.6}",
        report.anees_time_average, report.anis_time_average
    );
    Ok(())
}
