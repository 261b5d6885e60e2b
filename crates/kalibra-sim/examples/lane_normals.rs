//! Times [`ChaCha8Lanes`]' draws on one thread, the measurement behind `lanes.rs`' choice of
//! lane-wise draws on AVX-512 only (`ChaCha8Lanes::for_batch`): 6 million
//! standard normals (W1's: 1000 runs x 1000 steps, in groups of 8 runs, a call of 2 rows and
//! one of 4 per step) lane-wise on every instruction set the CPU has and through the runs' own
//! generators ([`Isa::Scalar`]), then 6 million `u64` the same ways, alternating the modes and
//! keeping the best of the repeats:
//! `cargo run --release -p kalibra-sim --example lane_normals -- [repeats] [avx512,avx2,scalar]
//! [normals|u64]` (both kinds without the last argument).

// An example reports what it measured on standard output.
#![allow(clippy::print_stdout)]

use std::time::Instant;

use kalibra_linalg::simd::{BATCH, Isa};
use kalibra_sim::{ChaCha8Lanes, MonteCarlo};
use rand_chacha::rand_core::Rng;

const RUNS: usize = 1000;
const STEPS: usize = 1000;

/// Seconds for W1's normals drawn in mode `isa`, and their sum (kept so nothing is skipped).
fn normals(mc: &MonteCarlo, isa: Isa) -> (f64, f64) {
    let t = Instant::now();
    let mut sum = 0.0;
    for group in (0..RUNS).step_by(BATCH) {
        let rngs: Vec<_> = (group..(group + BATCH).min(RUNS))
            .map(|run| mc.rng(run))
            .collect();
        let mut lanes = ChaCha8Lanes::new(isa, &rngs).expect("available");
        let (mut nv, mut nw) = ([[0.0; BATCH]; 2], [[0.0; BATCH]; 4]);
        for _ in 0..STEPS {
            lanes.standard_normals(&mut nv);
            lanes.standard_normals(&mut nw);
            sum += nv[1][3] + nw[3][5];
        }
    }
    (t.elapsed().as_secs_f64(), sum)
}

/// Seconds for as many `u64` as [`normals`] draws normals, lane by lane in each step.
fn words(mc: &MonteCarlo, isa: Isa) -> (f64, f64) {
    let t = Instant::now();
    let mut sum = 0u64;
    for group in (0..RUNS).step_by(BATCH) {
        let rngs: Vec<_> = (group..(group + BATCH).min(RUNS))
            .map(|run| mc.rng(run))
            .collect();
        let mut lanes = ChaCha8Lanes::new(isa, &rngs).expect("available");
        for _ in 0..STEPS {
            for lane in 0..lanes.len() {
                let mut rng = lanes.lane(lane).expect("a lane");
                for _ in 0..6 {
                    sum = sum.wrapping_add(rng.next_u64());
                }
            }
        }
    }
    (t.elapsed().as_secs_f64(), sum as f64)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let repeats: usize = args.next().map_or(Ok(9), |a| a.parse())?;
    let isas: Vec<Isa> = match args.next() {
        Some(list) => list.split(',').map(str::parse).collect::<Result<_, _>>()?,
        None => Isa::available(),
    };
    let only = args.next();
    let mc = MonteCarlo::new(RUNS, 2012);
    for (what, f) in [
        ("normals", normals as fn(&MonteCarlo, Isa) -> (f64, f64)),
        ("u64", words),
    ] {
        if only.as_ref().is_some_and(|o| o != what) {
            continue;
        }
        let mut best = vec![f64::INFINITY; isas.len()];
        let mut sums = vec![0.0; isas.len()];
        for _ in 0..repeats {
            for (i, isa) in isas.iter().enumerate() {
                let (t, sum) = f(&mc, *isa);
                best[i] = best[i].min(t);
                sums[i] = sum;
            }
        }
        for (i, isa) in isas.iter().enumerate() {
            let mode = if *isa == Isa::Scalar {
                "runs' own generators"
            } else {
                "lane-wise"
            };
            println!(
                "6 M {what:<7} {isa:<6} ({mode}): {:6.2} ms best of {repeats} (sum {})",
                best[i] * 1e3,
                sums[i]
            );
        }
    }
    Ok(())
}
