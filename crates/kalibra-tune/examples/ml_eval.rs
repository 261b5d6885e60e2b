//! The log-likelihood evaluations of maximum likelihood, for profiling on their own: the
//! model of `cargo xtask bench tune` (4 states, 2 measurements, noise through `G`, diagonal
//! `Qw` and `R`) on a simulated log of `STEPS` steps, evaluated `EVALS` times at the truth,
//! either by [`kalibra_tune::log_likelihood`] (`lib`) or through the generic `Kf` on run-time
//! sizes (`kf`, what the evaluation cost before the allocation-free loop).
//!
//! Usage: `ml_eval lib|kf STEPS EVALS`; the figures are `cargo xtask bench tune`'s.

// An example reports what it ran on standard output.
#![allow(clippy::print_stdout)]

use kalibra_filters::{Filter, Kf};
use kalibra_models::{LinearGaussian, LinearObservation};
use kalibra_tune::{
    CovarianceForm, DMatrix, DVector, NoiseProblem, Parametrisation, Run, Start, log_likelihood,
};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: ml_eval lib|kf STEPS EVALS";
    let (path, steps, evals) = match args.as_slice() {
        [_, p, s, e] => (p.clone(), s.parse::<usize>()?, e.parse::<usize>()?),
        _ => return Err(usage.into()),
    };
    #[rustfmt::skip]
    let f = DMatrix::from_row_slice(4, 4, &[
        1.0, 0.0, 1.0, 0.0,
        0.0, 1.0, 0.0, 1.0,
        0.0, 0.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
    ]);
    let g = DMatrix::from_row_slice(4, 2, &[0.5, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 1.0]);
    let h = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
    let (qw, r): ([f64; 2], [f64; 2]) = ([0.2, 0.05], [1.0, 2.0]);
    let mut rng = ChaCha8Rng::seed_from_u64(2031);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let mut x = DVector::from_vec(vec![0.0, 0.0, 1.0, 0.5]);
    let run: Run = (0..steps)
        .map(|_| {
            let w = DVector::from_fn(2, |i, _| qw[i].sqrt() * normal());
            x = &f * &x + &g * w;
            let z = &h * &x;
            Some(DVector::from_fn(2, |i, _| z[i] + r[i].sqrt() * normal()))
        })
        .collect();
    let noise = Parametrisation::new(
        Some(g),
        CovarianceForm::diagonal(DMatrix::identity(2, 2)),
        CovarianceForm::diagonal(DMatrix::identity(2, 2)),
    )?;
    let p0 = DMatrix::from_diagonal(&DVector::from_vec(vec![10.0, 10.0, 1.0, 1.0]));
    let problem = NoiseProblem::new(
        f,
        h,
        DVector::zeros(4),
        p0,
        Start::UpdateFirst,
        noise,
        vec![run],
    )?;
    let theta = problem.noise().theta_of(
        &DMatrix::from_diagonal(&DVector::from_row_slice(&qw)),
        &DMatrix::from_diagonal(&DVector::from_row_slice(&r)),
    )?;
    let matrices = problem.noise().matrices(theta.as_slice())?;
    let mut total = 0.0;
    for _ in 0..evals {
        total += match path.as_str() {
            "lib" => log_likelihood(&problem, theta.as_slice())?,
            "kf" => {
                let dynamics = LinearGaussian::new(problem.f().clone(), matrices.q.clone())?;
                let sensor = LinearObservation::new(problem.h().clone(), matrices.r.clone())?;
                let mut ll = 0.0;
                let mut kf = Kf::new(
                    &dynamics,
                    &sensor,
                    problem.x0().clone(),
                    problem.p0().clone(),
                )?;
                kf.run(
                    problem.runs()[0].iter().map(Option::as_ref),
                    problem.start(),
                    |rec| ll += rec.log_likelihood(),
                )?;
                ll
            }
            _ => return Err(usage.into()),
        };
    }
    println!("{total}");
    Ok(())
}
