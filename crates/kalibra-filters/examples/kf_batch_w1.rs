//! Steps W1's model (the 4-state constant-velocity KF of `cargo xtask bench w1`) through
//! [`KfBatch`] alone, for profilers: the kernel's cost per run-step without the truth
//! simulation or the study's bookkeeping (callgrind counts its instructions repeatably).
//!
//! `cargo run --release -p kalibra-filters --example kf_batch_w1 -- [avx512|avx2|scalar] [batches] [steps] [scheduled]`
//! (`scheduled`: the batches follow one [`KfSchedule`] of the covariances, as W1's study does)
//!
//! The measurements are a cheap deterministic sequence around a zero truth: the kernel's
//! instruction count does not depend on the values, only on the model's sizes.

// An example reports what it ran on standard output.
#![allow(clippy::print_stdout)]

use std::sync::Arc;

use kalibra_filters::batch::{BATCH, BatchModel, Isa, KfBatch, KfSchedule};
use nalgebra::{SMatrix, SVector};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let isa: Isa = args.next().unwrap_or_default().parse()?;
    let batches: usize = args.next().map_or(Ok(125), |a| a.parse())?;
    let steps: usize = args.next().map_or(Ok(1000), |a| a.parse())?;
    let scheduled = args.next().as_deref() == Some("scheduled");
    #[rustfmt::skip]
    let f = SMatrix::<f64, 4, 4>::new(
        1.0, 0.0, 1.0, 0.0,
        0.0, 1.0, 0.0, 1.0,
        0.0, 0.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
    );
    #[rustfmt::skip]
    let g = SMatrix::<f64, 4, 2>::new(
        0.5, 0.0,
        0.0, 0.5,
        1.0, 0.0,
        0.0, 1.0,
    );
    let h = SMatrix::<f64, 2, 4>::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
    let r = SMatrix::<f64, 2, 2>::identity() * 100.0;
    let model = BatchModel::new(f, g * g.transpose(), h, r)?;
    let m0 = SVector::<f64, 4>::new(0.0, 0.0, 10.0, -5.0);
    let p0 = SMatrix::<f64, 4, 4>::from_diagonal(&SVector::from([100.0, 100.0, 25.0, 25.0]));
    let truth = [[0.0; BATCH]; 4];
    // A 64-bit linear congruential sequence, mapped to [-10, 10).
    let mut state = 2012u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64 * 20.0 - 10.0
    };
    let schedule = Arc::new(KfSchedule::new(isa, model.clone(), p0, steps)?);
    let mut total = 0.0;
    for _ in 0..batches {
        let mut kf = if scheduled {
            KfBatch::scheduled(schedule.clone(), m0)?
        } else {
            KfBatch::new(isa, model.clone(), m0, p0)?
        };
        for k in 0..steps {
            let mut z = [[0.0; BATCH]; 2];
            for row in &mut z {
                for v in row.iter_mut() {
                    *v = next();
                }
            }
            let step = if k == 0 {
                kf.update(&z, &truth)
            } else {
                kf.predict_update(&z, &truth)
            };
            total += step.nees(0)? + step.nis(0)?;
        }
    }
    println!(
        "{isa}: mean NEES + NIS of lane 0 {}",
        total / (batches * steps) as f64
    );
    Ok(())
}
