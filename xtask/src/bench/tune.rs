//! `bench tune`: choosing `Q` and `R` from measurements, kalibra against statsmodels and
//! pykalman on the same data from the same starting point.
//!
//! The system: a 2-D constant-velocity target (4 states, `dt = 1`), the two positions measured
//! (2 measurements), [`STEPS`] steps simulated from ChaCha8 seed [`SEED`] (the first state drawn
//! from `N(x0, P0)`, the prior at the first measurement: `Start::UpdateFirst`, statsmodels'
//! `initialization="known"` and pykalman's convention) and written to
//! `target/bench-tune/measurements.f64`, which every side reads.
//!
//! * **Maximum likelihood**, 4 free parameters: the process noise enters through `G` (4 x 2, an
//!   acceleration per axis) with `Qw` diagonal (2 variances), `R` diagonal (2 variances), all
//!   started from 1. kalibra's [`MaximumLikelihood::estimate`] (BFGS to its gradient tolerance
//!   on `-ln L / N`, three starts, the observed information, identifiability and bounds)
//!   against statsmodels 0.15's `MLEModel.fit()` (`xtask/bench/tune_statsmodels.py`: L-BFGS-B
//!   to the same tolerance on the same function, standard errors from the observed
//!   information). kalibra's candidate evaluations of a finite-difference gradient run side by
//!   side on threads (rayon's pool); the estimate is timed on one thread and on
//!   `--threads`. The estimates must agree to the optimisers' tolerance (see
//!   [`ML_AGREEMENT`]).
//! * **One log-likelihood evaluation** at the truth: kalibra's (the allocation-free loop with
//!   its steady state) against the same sum through the generic `Kf` on run-time sizes, which
//!   is what the evaluation cost before the loop; the two must agree to `1e-12` relative.
//! * **EM**, a full `Q` (no `G`) and a full `R`, started from identities: a full `Q` and a full
//!   `R` with two measurements ask for 13 parameters where innovations identify at most
//!   `n m + m (m + 1) / 2 = 11`, which kalibra refuses, so EM's log adds a third measurement,
//!   the first velocity (variance [`R3_TRUE`], from the same simulation, written to
//!   `target/bench-tune/measurements3.f64`); kalibra's
//!   [`Em`] for exactly [`EM_ITERATIONS`] iterations against pykalman 0.11.2's
//!   `KalmanFilter.em` for as many (`xtask/bench/tune_pykalman.py`), per iteration; `Q`, `R`
//!   and the log-likelihood must agree to `1e-9` relative.
//!
//! Python runs in a virtual environment under `target/bench-tune` (created, and statsmodels and
//! pykalman installed from PyPI, the first time); `--no-python` skips both references. The
//! goals, printed with pass or fail: ML at least 10x statsmodels' `fit()`, EM at least 20x
//! pykalman per iteration.

use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result, ensure};
use kalibra_filters::{Filter, Kf};
use kalibra_models::{LinearGaussian, LinearObservation};
use kalibra_tune::{
    CovarianceForm, DMatrix, DVector, Em, MaximumLikelihood, NoiseProblem, Parametrisation, Run,
    Start, log_likelihood,
};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use serde_json::{Value, json};

use super::{Args, Best, Figures};

/// Steps of the log.
pub(crate) const STEPS: usize = 10_000;
/// ChaCha8 seed of the simulated log.
pub(crate) const SEED: u64 = 2031;
/// EM iterations timed on both sides.
pub(crate) const EM_ITERATIONS: usize = 5;
/// The gradient tolerance of both optimisers on `-ln L / N` (kalibra's default).
pub(crate) const GRADIENT_TOLERANCE: f64 = 1e-8;
/// The largest relative difference of an ML estimate to statsmodels' that counts as equal:
/// both stop with the gradient of `-ln L / N` below `1e-8`, which leaves a parameter about
/// `sqrt(2 N g^2 / lambda) / theta` from the maximum (below `1e-5` here); ten times that.
pub(crate) const ML_AGREEMENT: f64 = 1e-4;
/// The agreement of EM's `Q`, `R` and log-likelihood with pykalman's.
pub(crate) const EM_AGREEMENT: f64 = 1e-9;

/// The true variances of the simulation: `Qw = diag(0.2, 0.05)`, `R = diag(1, 2)`.
const QW_TRUE: [f64; 2] = [0.2, 0.05];
const R_TRUE: [f64; 2] = [1.0, 2.0];
/// The variance of EM's third measurement, the first velocity.
pub(crate) const R3_TRUE: f64 = 0.5;

struct Model {
    f: DMatrix<f64>,
    g: DMatrix<f64>,
    h: DMatrix<f64>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
}

fn model() -> Model {
    #[rustfmt::skip]
    let f = DMatrix::from_row_slice(4, 4, &[
        1.0, 0.0, 1.0, 0.0,
        0.0, 1.0, 0.0, 1.0,
        0.0, 0.0, 1.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
    ]);
    #[rustfmt::skip]
    let g = DMatrix::from_row_slice(4, 2, &[
        0.5, 0.0,
        0.0, 0.5,
        1.0, 0.0,
        0.0, 1.0,
    ]);
    let h = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
    Model {
        f,
        g,
        h,
        x0: DVector::from_vec(vec![0.0, 0.0, 1.0, 0.5]),
        p0: DMatrix::from_diagonal(&DVector::from_vec(vec![10.0, 10.0, 1.0, 1.0])),
    }
}

/// The log: the first state from `N(x0, P0)`, then `STEPS` steps of the model; the third
/// channel (the first velocity) is EM's.
fn simulate(model: &Model) -> Vec<[f64; 3]> {
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let mut x: DVector<f64> =
        DVector::from_fn(4, |i, _| model.x0[i] + model.p0[(i, i)].sqrt() * normal());
    (0..STEPS)
        .map(|k| {
            if k > 0 {
                let w = DVector::from_fn(2, |i, _| QW_TRUE[i].sqrt() * normal());
                x = &model.f * &x + &model.g * w;
            }
            let z = &model.h * &x;
            [
                z[0] + R_TRUE[0].sqrt() * normal(),
                z[1] + R_TRUE[1].sqrt() * normal(),
                x[2] + R3_TRUE.sqrt() * normal(),
            ]
        })
        .collect()
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

fn read_f64(path: &Path) -> Result<Vec<f64>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect())
}

fn problem(model: &Model, h: &DMatrix<f64>, run: Run, g: bool) -> Result<NoiseProblem> {
    let noise = if g {
        Parametrisation::new(
            Some(model.g.clone()),
            CovarianceForm::diagonal(DMatrix::identity(2, 2)),
            CovarianceForm::diagonal(DMatrix::identity(2, 2)),
        )?
    } else {
        Parametrisation::new(
            None,
            CovarianceForm::full(DMatrix::identity(4, 4)),
            CovarianceForm::full(DMatrix::identity(h.nrows(), h.nrows())),
        )?
    };
    Ok(NoiseProblem::new(
        model.f.clone(),
        h.clone(),
        model.x0.clone(),
        model.p0.clone(),
        Start::UpdateFirst,
        noise,
        vec![run],
    )?)
}

/// The log-likelihood through the generic `Kf` on run-time sizes: the sum of its records'
/// log-densities, as kalibra evaluated it before the allocation-free loop.
fn through_kf(problem: &NoiseProblem, q: &DMatrix<f64>, r: &DMatrix<f64>) -> Result<f64> {
    let dynamics = LinearGaussian::new(problem.f().clone(), q.clone())?;
    let sensor = LinearObservation::new(problem.h().clone(), r.clone())?;
    let mut total = 0.0;
    for zs in problem.runs() {
        let mut kf = Kf::new(
            &dynamics,
            &sensor,
            problem.x0().clone(),
            problem.p0().clone(),
        )?;
        kf.run(zs.iter().map(Option::as_ref), problem.start(), |rec| {
            total += rec.log_likelihood();
        })?;
    }
    Ok(total)
}

/// The largest `|a - b|` over the largest `|b|`.
fn relative(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax()
}

fn matrix(v: &Value) -> Result<DMatrix<f64>> {
    let rows: Vec<Vec<f64>> = serde_json::from_value(v.clone())?;
    ensure!(!rows.is_empty(), "an empty matrix");
    Ok(DMatrix::from_fn(rows.len(), rows[0].len(), |i, j| {
        rows[i][j]
    }))
}

/// Runs the tuning bench, prints its figures and returns them.
pub(crate) fn run(args: &Args) -> Result<Figures> {
    let title = format!(
        "Noise estimation: 2-D constant velocity (n = 4), {STEPS} steps; ML (m = 2, 4 free \
         parameters) against statsmodels' fit(), EM (m = 3, full Q and R) per iteration \
         against pykalman (best of {})",
        args.repeats
    );
    println!("tune: {title}");
    let mut figures = Figures::new("tune", title);
    let root = crate::workspace_root();
    let dir = root.join("target").join("bench-tune");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let model = model();
    // The log, written once and read back by every side.
    let z_path = dir.join("measurements.f64");
    let z3_path = dir.join("measurements3.f64");
    let log = simulate(&model);
    let bytes = |channels: usize| -> Vec<u8> {
        log.iter()
            .flat_map(|z| z[..channels].iter().flat_map(|v| v.to_le_bytes()))
            .collect()
    };
    std::fs::write(&z_path, bytes(2))?;
    std::fs::write(&z3_path, bytes(3))?;
    let read_run = |path: &Path, m: usize| -> Result<Run> {
        let values = read_f64(path)?;
        ensure!(
            values.len() == m * STEPS,
            "the log has {} values",
            values.len()
        );
        Ok(values
            .chunks_exact(m)
            .map(|z| Some(DVector::from_column_slice(z)))
            .collect())
    };
    let run = read_run(&z_path, 2)?;
    let run3 = read_run(&z3_path, 3)?;
    let mut h3 = DMatrix::zeros(3, 4);
    h3.view_mut((0, 0), (2, 4)).copy_from(&model.h);
    h3[(2, 2)] = 1.0;
    let model_path = dir.join("model.json");
    std::fs::write(
        &model_path,
        serde_json::to_vec(&json!({
            "F": rows(&model.f), "G": rows(&model.g), "H": rows(&model.h),
            "x0": model.x0.as_slice(), "P0": rows(&model.p0),
            "qw_start": rows(&DMatrix::identity(2, 2)), "r_start": rows(&DMatrix::identity(2, 2)),
            "q_start": rows(&DMatrix::identity(4, 4)),
        }))?,
    )?;
    let em_model_path = dir.join("model3.json");
    std::fs::write(
        &em_model_path,
        serde_json::to_vec(&json!({
            "F": rows(&model.f), "H": rows(&h3),
            "x0": model.x0.as_slice(), "P0": rows(&model.p0),
            "q_start": rows(&DMatrix::identity(4, 4)), "r_start": rows(&DMatrix::identity(3, 3)),
        }))?,
    )?;

    // One evaluation at the truth: the loop against the filter.
    let ml_problem = problem(&model, &model.h, run, true)?;
    let truth = ml_problem.noise().theta_of(
        &DMatrix::from_diagonal(&DVector::from_row_slice(&QW_TRUE)),
        &DMatrix::from_diagonal(&DVector::from_row_slice(&R_TRUE)),
    )?;
    let matrices = ml_problem.noise().matrices(truth.as_slice())?;
    let (mut loop_best, mut kf_best) = (Best::default(), Best::default());
    let (mut ours, mut theirs) = (0.0, 0.0);
    for _ in 0..args.repeats.max(5) {
        ours = loop_best.time(|| log_likelihood(&ml_problem, truth.as_slice()))?;
        theirs = kf_best.time(|| through_kf(&ml_problem, &matrices.q, &matrices.r))?;
    }
    let eval_diff = (ours - theirs).abs() / theirs.abs();
    println!(
        "  log-likelihood evaluation: kalibra {:.3} ms, through Kf {:.3} ms ({:.1}x); \
         agreement {eval_diff:.1e} relative",
        loop_best.seconds() * 1e3,
        kf_best.seconds() * 1e3,
        kf_best.seconds() / loop_best.seconds()
    );
    figures.push(
        "log-likelihood evaluation, kalibra",
        loop_best.seconds() * 1e3,
        "ms",
    );
    figures.push(
        "log-likelihood evaluation through Kf",
        kf_best.seconds() * 1e3,
        "ms",
    );
    figures.push("|kalibra - Kf| / |Kf| (log-likelihood)", eval_diff, "rel");

    // Maximum likelihood, on one thread and on `--threads`.
    let ml = MaximumLikelihood::new().gradient_tolerance(GRADIENT_TOLERANCE)?;
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let many = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.max(1))
        .build()?;
    let (mut ml1_best, mut mln_best) = (Best::default(), Best::default());
    let mut estimate = None;
    for _ in 0..args.repeats {
        ml1_best.time(|| one.install(|| ml.estimate(&ml_problem)))?;
        estimate = Some(mln_best.time(|| many.install(|| ml.estimate(&ml_problem)))?);
    }
    let estimate = estimate.context("no repeat ran")?;
    let ml_seconds = mln_best.seconds();
    println!(
        "  kalibra ML: {:.1} ms on {} threads, {:.1} ms on 1 thread ({} evaluations, {} \
         iterations, converged {}, ln L {:.6})",
        ml_seconds * 1e3,
        args.threads,
        ml1_best.seconds() * 1e3,
        estimate.evaluations,
        estimate.iterations,
        estimate.converged,
        estimate.log_likelihood
    );
    for p in &estimate.parameters {
        println!(
            "    {:<8} {:.6} (se {:.2e})",
            p.parameter.name,
            p.value,
            p.stderr.unwrap_or(f64::NAN)
        );
    }
    figures.push(
        format!("kalibra ML, {} threads", args.threads),
        ml_seconds * 1e3,
        "ms",
    );
    figures.push("kalibra ML, 1 thread", ml1_best.seconds() * 1e3, "ms");
    figures.push(
        "kalibra ML, log-likelihood evaluations",
        estimate.evaluations as f64,
        "count",
    );

    // EM, exactly EM_ITERATIONS iterations.
    let em_problem = problem(&model, &h3, run3, false)?;
    let em = Em::new().exact_iterations(EM_ITERATIONS);
    let mut em_best = Best::default();
    let mut em_fit = None;
    for _ in 0..args.repeats {
        em_fit = Some(em_best.time(|| em.estimate(&em_problem))?);
    }
    let em_fit = em_fit.context("no repeat ran")?;
    let em_iter = em_best.seconds() / EM_ITERATIONS as f64;
    println!(
        "  kalibra EM: {:.2} ms per iteration ({EM_ITERATIONS} iterations, ln L {:.6})",
        em_iter * 1e3,
        em_fit.final_log_likelihood()
    );
    figures.push("kalibra EM, per iteration", em_iter * 1e3, "ms");

    let mut goals = Vec::new();
    if args.no_python {
        println!("  statsmodels and pykalman: skipped (--no-python)");
    } else {
        let (python, versions) = super::eval::python_env(
            &dir,
            &[
                ("numpy", "numpy"),
                ("scipy", "scipy"),
                ("statsmodels", "statsmodels==0.15.0"),
                ("pykalman", "pykalman==0.11.2"),
            ],
        )?;
        println!("  Python: {versions}");
        // statsmodels.
        let out = dir.join("statsmodels.json");
        let status = Command::new(&python)
            .arg(root.join("xtask").join("bench").join("tune_statsmodels.py"))
            .arg(&model_path)
            .arg(&z_path)
            .arg(STEPS.to_string())
            .arg(args.repeats.to_string())
            .arg(GRADIENT_TOLERANCE.to_string())
            .arg(&out)
            .status()
            .context("starting statsmodels' script")?;
        ensure!(status.success(), "statsmodels' script failed ({status})");
        let sm: Value = serde_json::from_slice(&std::fs::read(&out)?)?;
        let sm_seconds = sm["seconds"].as_f64().context("no seconds")?;
        let sm_params: Vec<f64> = serde_json::from_value(sm["params"].clone())?;
        let sm_ll = sm["loglike"].as_f64().context("no loglike")?;
        let param_diff = estimate
            .parameters
            .iter()
            .zip(&sm_params)
            .map(|(p, s)| (p.value - s).abs() / s.abs())
            .fold(0.0, f64::max);
        let ll_diff = (estimate.log_likelihood - sm_ll).abs() / sm_ll.abs();
        let speedup = sm_seconds / ml_seconds;
        println!(
            "  statsmodels fit(): {:.1} ms ({} iterations, {} evaluations, converged {}, ln L \
             {sm_ll:.6})",
            sm_seconds * 1e3,
            sm["iterations"],
            sm["evaluations"],
            sm["converged"]
        );
        println!(
            "  agreement: estimates {param_diff:.1e} relative (<= {ML_AGREEMENT:.0e}), ln L \
             {ll_diff:.1e} relative"
        );
        figures.push("statsmodels 0.15 fit()", sm_seconds * 1e3, "ms");
        figures.push("kalibra ML / statsmodels (speed)", speedup, "x");
        figures.push(
            "max |kalibra - statsmodels| / |statsmodels| (ML estimate)",
            param_diff,
            "rel",
        );
        goals.push((
            format!(
                "ML at least 10x statsmodels' fit(): {speedup:.1}x, estimates equal to \
                 {param_diff:.1e}"
            ),
            speedup >= 10.0 && param_diff <= ML_AGREEMENT && sm["converged"] == true,
        ));
        // pykalman.
        let out = dir.join("pykalman.json");
        let status = Command::new(&python)
            .arg(root.join("xtask").join("bench").join("tune_pykalman.py"))
            .arg(&em_model_path)
            .arg(&z3_path)
            .arg(STEPS.to_string())
            .arg(EM_ITERATIONS.to_string())
            .arg(args.repeats.to_string())
            .arg(&out)
            .status()
            .context("starting pykalman's script")?;
        ensure!(status.success(), "pykalman's script failed ({status})");
        let pk: Value = serde_json::from_slice(&std::fs::read(&out)?)?;
        let pk_iter = pk["seconds"].as_f64().context("no seconds")? / EM_ITERATIONS as f64;
        let (dq, dr) = (
            relative(&em_fit.matrices.q, &matrix(&pk["Q"])?),
            relative(&em_fit.matrices.r, &matrix(&pk["R"])?),
        );
        let pk_ll = pk["loglike"].as_f64().context("no loglike")?;
        let dll = (em_fit.final_log_likelihood() - pk_ll).abs() / pk_ll.abs();
        let em_diff = dq.max(dr).max(dll);
        let em_speedup = pk_iter / em_iter;
        println!(
            "  pykalman em(): {:.1} ms per iteration ({EM_ITERATIONS} iterations, ln L \
             {pk_ll:.6})",
            pk_iter * 1e3
        );
        println!(
            "  agreement after {EM_ITERATIONS} iterations: Q {dq:.1e}, R {dr:.1e}, ln L \
             {dll:.1e} relative (<= {EM_AGREEMENT:.0e})"
        );
        figures.push("pykalman 0.11.2 em(), per iteration", pk_iter * 1e3, "ms");
        figures.push(
            "kalibra EM / pykalman per iteration (speed)",
            em_speedup,
            "x",
        );
        figures.push("max |kalibra - pykalman| (EM Q, R, ln L)", em_diff, "rel");
        goals.push((
            format!(
                "EM at least 20x pykalman per iteration: {em_speedup:.1}x, equal to {em_diff:.1e}"
            ),
            em_speedup >= 20.0 && em_diff <= EM_AGREEMENT,
        ));
    }
    goals.push((
        format!("log-likelihood equal to the Kf's to 1e-12: {eval_diff:.1e}"),
        eval_diff <= 1e-12,
    ));
    for (goal, pass) in &goals {
        println!("  goal: {goal}: {}", if *pass { "PASS" } else { "FAIL" });
    }
    Ok(figures)
}
