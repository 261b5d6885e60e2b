//! Runs the batched W1 study once on one thread, for profilers (callgrind, perf):
//! `cargo run --release -p kalibra-studies --example w1_batched -- [avx512|avx2|scalar] [runs] [steps]`.
//! Prints the time average of the ANEES so that the work cannot be optimised away.

// An example reports what it ran on standard output.
#![allow(clippy::print_stdout)]

use kalibra_filters::batch::Isa;
use kalibra_studies::w1::{Config, run_batched};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let isa: Isa = args.next().unwrap_or_default().parse()?;
    let runs = args.next().map_or(Ok(1000), |a| a.parse())?;
    let steps = args.next().map_or(Ok(1000), |a| a.parse())?;
    let config = Config {
        runs,
        steps,
        seed: 2012,
        threads: 1,
        confidence: 0.95,
        simd: None,
    };
    let report = run_batched(&config, isa)?;
    println!("{isa}: ANEES {}", report.anees_time_average);
    Ok(())
}
