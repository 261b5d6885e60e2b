//! `cargo xtask bench w4`: one Kalman filter at run-time sizes, faer's kernels against
//! nalgebra's, in one process; a numpy script doing the same step beside them.
//!
//! Per state dimension `n` in [`SIZES`], with `m = max(2, n / 4)`: a dense `F = 0.95 U` with `U`
//! orthogonal (the QR factor of a Gaussian matrix, so the spectral radius is 0.95), a dense
//! Gaussian `H / sqrt(n)`, random symmetric positive definite `Q`, `R` and `P0` (`A A^T / k +
//! c I`), and a truth simulated from them. One step is the KF's predict, its Joseph update
//! and the NEES of the posterior by Cholesky (`StepRecord::nees`), on `Dyn` sizes through the
//! public API. Each path runs [`WARM_UP`] steps, then blocks of [`STEPS`] steps are timed,
//! interleaved between the paths so machine noise hits all alike, until every path has at
//! least `--repeats` blocks and [`BUDGET`] seconds have passed; the best block counts.
//!
//! The paths are [`KernelPolicy`]s of the same filter code: `faer` hands every kernel to faer
//! (`KernelPolicy::faer_from(0)`), `nalgebra` none (`KernelPolicy::NALGEBRA`, the code before
//! faer came in), `library` is the default (faer from `FAER_MIN_DIM`). All run the same number
//! of steps, so their posteriors are compared at the end (relative Frobenius difference).
//!
//! GFLOP/s count the nominal work of the step written with general products (`8 1/3 n^3 +
//! 6 n^2 m + 6 n m^2 + m^3 / 3`, see [`nominal_flops`]) for every path, so they compare as
//! times do; faer's symmetric-output products do about a sixth less of it.
//!
//! numpy runs `xtask/bench/w4_numpy.py` (the same step: `F P F^T + Q`, the Joseph update with
//! `np.linalg.solve` for the gain, NEES by `np.linalg.solve`) in the virtual environment of
//! `bench eval` (`target/bench-eval/venv`, installed from PyPI if missing), with BLAS held to
//! one thread. Its figures are reported, not compared with goals. `--no-python` skips it.

use std::num::NonZeroUsize;
use std::path::Path as FsPath;
use std::process::Command;

use anyhow::{Context, Result, bail, ensure};
use kalibra_filters::{Filter, Kf, SigmaSet, Ukf};
use kalibra_linalg::{
    Covariance, DMatrix, DVector, Dyn, KernelPolicy, PARALLEL_MIN_DIM, innovation_covariance,
    joseph_update, product, propagate, quad_form_symmetric, with_kernel_policy,
};
use kalibra_models::{LinearGaussian, LinearObservation, Truth, simulate};
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

use super::{Args, Budget, Figures, timed};

/// State dimensions measured.
pub(crate) const SIZES: [usize; 8] = [8, 16, 32, 64, 128, 256, 512, 1024];

/// Steps per timed block.
pub(crate) const STEPS: usize = 20;

/// Steps each path runs before the first timed block.
pub(crate) const WARM_UP: usize = 5;

/// Least wall time spent timing one size, in seconds (all paths together).
const BUDGET: f64 = 1.0;

/// Length of the simulated truth; steps beyond it cycle through it again (the covariance
/// recursion, which carries the cost, does not depend on the measurements).
const TRUTH_STEPS: usize = 64;

/// Seed of the problem matrices and the truth (size `n` on ChaCha8 stream `n`).
const SEED: u64 = 2012;

/// The measurement dimension for state dimension `n`.
pub(crate) fn meas_dim(n: usize) -> usize {
    (n / 4).max(2)
}

/// Floating-point operations of one step written with general products: predict `4 n^3`;
/// `P H^T`, `H P H^T`, the gain solve, `K H` and `K R K^T` `6 n^2 m + 6 n m^2` together (two
/// products of each shape, the solve counted as `2 n m^2`); `(I - K H) P (I - K H)^T` `4 n^3`;
/// the Cholesky factors of `S` and `P` `(m^3 + n^3) / 3`.
pub(crate) fn nominal_flops(n: usize, m: usize) -> f64 {
    let (n, m) = (n as f64, m as f64);
    (8.0 + 1.0 / 3.0) * n.powi(3) + 6.0 * n * n * m + 6.0 * n * m * m + m.powi(3) / 3.0
}

/// The filter W4 times: a KF on `Dyn` sizes borrowing the problem's models.
type DynKf<'a> = Kf<Dyn, Dyn, &'a LinearGaussian<Dyn>, &'a LinearObservation<Dyn, Dyn>>;

/// A kernel call timed by `--kernels`.
type Kernel<'a> = (&'static str, Box<dyn FnMut() + 'a>);

/// One size's problem.
pub(crate) struct Problem {
    n: usize,
    dynamics: LinearGaussian<Dyn>,
    measurement: LinearObservation<Dyn, Dyn>,
    p0: DMatrix<f64>,
    truth: Truth<Dyn, Dyn>,
}

fn gaussian(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    DMatrix::from_fn(rows, cols, |_, _| StandardNormal.sample(rng))
}

/// `A A^T / k + c I` for a Gaussian `k x k` matrix `A`.
fn spd(k: usize, c: f64, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    let a = gaussian(k, k, rng);
    let mut s = product(&a, &a.transpose()) / k as f64;
    for i in 0..k {
        s[(i, i)] += c;
    }
    // Exactly symmetric, as a covariance read from a file would be.
    (&s + s.transpose()) * 0.5
}

impl Problem {
    /// The problem of state dimension `n`.
    pub(crate) fn new(n: usize) -> Result<Self> {
        let m = meas_dim(n);
        let mut rng = ChaCha8Rng::seed_from_u64(SEED);
        rng.set_stream(n as u64);
        let f = gaussian(n, n, &mut rng).qr().q() * 0.95;
        let h = gaussian(m, n, &mut rng) / (n as f64).sqrt();
        let q = spd(n, 0.1, &mut rng) * 0.1;
        let r = spd(m, 0.1, &mut rng);
        let p0 = spd(n, 1.0, &mut rng);
        let dynamics = LinearGaussian::new(f, q).context("W4 dynamics")?;
        let measurement = LinearObservation::new(h, r).context("W4 measurement")?;
        let x0 = DVector::from_fn(n, |_, _| StandardNormal.sample(&mut rng));
        let truth =
            simulate(&dynamics, &measurement, x0, TRUTH_STEPS, &mut rng).context("W4 truth")?;
        Ok(Self {
            n,
            dynamics,
            measurement,
            p0,
            truth,
        })
    }

    /// A filter started at zero with `P0`.
    fn filter(&self) -> Result<DynKf<'_>> {
        Ok(Kf::new(
            &self.dynamics,
            &self.measurement,
            DVector::zeros(self.n),
            self.p0.clone(),
        )?)
    }
}

/// Per-step times (seconds) of one size.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Row {
    pub(crate) n: usize,
    pub(crate) m: usize,
    pub(crate) faer: f64,
    pub(crate) nalgebra: f64,
    pub(crate) library: f64,
    /// With within-step parallelism: the thread count, the time per step, and whether the
    /// posterior is bit-identical to the one-thread library path's.
    pub(crate) parallel: Option<(usize, f64, bool)>,
    /// Relative Frobenius difference of the faer and nalgebra posteriors after the same steps.
    pub(crate) difference: f64,
    /// Steps every path ran.
    pub(crate) steps: usize,
}

/// Times the three paths on `problem`.
///
/// With `threads` above 1 and `n >= PARALLEL_MIN_DIM`, a fourth path runs the default policy
/// with faer on `threads` threads within each step ([`KernelPolicy::with_threads`]).
pub(crate) fn measure(
    problem: &Problem,
    min_blocks: usize,
    budget: f64,
    threads: usize,
) -> Result<Row> {
    let mut policies = vec![
        KernelPolicy::faer_from(0),
        KernelPolicy::NALGEBRA,
        KernelPolicy::DEFAULT,
    ];
    let parallel = NonZeroUsize::new(threads)
        .filter(|t| t.get() > 1 && problem.n >= PARALLEL_MIN_DIM)
        .map(|t| KernelPolicy::DEFAULT.with_threads(t));
    policies.extend(parallel);
    let mut paths: Vec<Lane<'_>> = Vec::new();
    for policy in policies {
        paths.push(Lane {
            policy,
            kf: problem.filter()?,
            k: 0,
            best: f64::INFINITY,
            blocks: 0,
            nees: 0.0,
        });
    }
    for path in &mut paths {
        path.run(problem, WARM_UP)?;
    }
    let clock = Budget::new(budget);
    while clock.more(paths[0].blocks, min_blocks) {
        for path in &mut paths {
            let t = path.run(problem, STEPS)?;
            path.best = path.best.min(t / STEPS as f64);
            path.blocks += 1;
        }
    }
    let p_faer = paths[0].kf.covariance();
    let p_nalgebra = paths[1].kf.covariance();
    let difference = (p_faer - p_nalgebra).norm() / p_nalgebra.norm();
    // The parallel path runs the same kernels as the library's on more threads: the same bits.
    let parallel = paths.get(3).map(|lane| {
        (
            lane.policy.threads().get(),
            lane.best,
            lane.kf.covariance() == paths[2].kf.covariance(),
        )
    });
    ensure!(
        paths.iter().all(|p| p.nees.is_finite()),
        "non-finite NEES at n = {}",
        problem.n
    );
    Ok(Row {
        n: problem.n,
        m: meas_dim(problem.n),
        faer: paths[0].best,
        nalgebra: paths[1].best,
        library: paths[2].best,
        parallel,
        difference,
        steps: paths[0].k,
    })
}

/// A filter on one kernel policy (borrowing the problem's models), how far it has run and its
/// best block so far.
struct Lane<'a> {
    policy: KernelPolicy,
    kf: DynKf<'a>,
    k: usize,
    best: f64,
    blocks: usize,
    nees: f64,
}

impl Lane<'_> {
    /// Runs `steps` steps on the path's policy; returns the wall time.
    fn run(&mut self, problem: &Problem, steps: usize) -> Result<f64> {
        let Self {
            policy,
            kf,
            k,
            nees,
            ..
        } = self;
        let (seconds, done) = timed(|| {
            with_kernel_policy(*policy, || -> Result<()> {
                for _ in 0..steps {
                    let i = *k % problem.truth.measurements.len();
                    kf.predict()?;
                    let rec = kf.update(&problem.truth.measurements[i])?;
                    let e = &problem.truth.states[i] - &rec.posterior().mean;
                    *nees += rec.nees(&e)?;
                    *k += 1;
                }
                Ok(())
            })
        });
        done?;
        Ok(seconds)
    }
}

/// Best times per call of `f` through faer and through nalgebra: batches of calls (doubled
/// until a batch takes a millisecond) timed alternately on the two policies, so that machine
/// noise hits both alike, until `budget` seconds have passed and each has at least three.
fn time_kernel(budget: f64, mut f: impl FnMut()) -> (f64, f64) {
    let policies = [KernelPolicy::faer_from(0), KernelPolicy::NALGEBRA];
    let mut best = [f64::INFINITY; 2];
    let mut calls = 1;
    for policy in policies {
        with_kernel_policy(policy, &mut f);
    }
    let clock = Budget::new(budget);
    let mut batches = 0;
    while clock.more(batches, 3) {
        let mut shortest = f64::INFINITY;
        for (policy, best) in policies.iter().zip(&mut best) {
            let (elapsed, ()) = with_kernel_policy(*policy, || {
                timed(|| {
                    for _ in 0..calls {
                        f();
                    }
                })
            });
            *best = best.min(elapsed / calls as f64);
            shortest = shortest.min(elapsed);
        }
        if shortest < 1e-3 {
            calls *= 2;
        } else {
            batches += 1;
        }
    }
    (best[0], best[1])
}

/// The kernels of a step one by one at dimension `n` (`m = max(2, n / 4)` where a
/// measurement enters): faer's time over nalgebra's, to place [`kalibra_linalg::FAER_MIN_DIM`].
fn kernel_ratios(n: usize, budget: f64) -> Result<Vec<(&'static str, f64)>> {
    let m = meas_dim(n);
    let mut rng = ChaCha8Rng::seed_from_u64(SEED);
    rng.set_stream(n as u64);
    let f = gaussian(n, n, &mut rng) / (n as f64).sqrt();
    let h = gaussian(m, n, &mut rng) / (n as f64).sqrt();
    let p = spd(n, 1.0, &mut rng);
    let r = spd(m, 0.1, &mut rng);
    let (pht, s) = innovation_covariance(&p, &h, &r);
    let s = Covariance::from_symmetric(s, "S")?;
    let k = s.solve_right(&pht)?;
    let e = DVector::from_fn(n, |_, _| StandardNormal.sample(&mut rng));
    let mut kernels: Vec<Kernel<'_>> = vec![
        (
            "F P F^T",
            Box::new(|| drop(std::hint::black_box(propagate(&f, &p)))),
        ),
        (
            "H P H^T + R",
            Box::new(|| drop(std::hint::black_box(innovation_covariance(&p, &h, &r)))),
        ),
        (
            "Cholesky of P",
            Box::new(|| {
                drop(std::hint::black_box(Covariance::from_symmetric(
                    p.clone(),
                    "P",
                )))
            }),
        ),
        (
            "P H^T S^-1",
            Box::new(|| drop(std::hint::black_box(s.solve_right(&pht)))),
        ),
        (
            "Joseph",
            Box::new(|| drop(std::hint::black_box(joseph_update(&p, &k, &h, &r)))),
        ),
        (
            "NEES e^T P^-1 e",
            Box::new(|| drop(std::hint::black_box(quad_form_symmetric(&p, &e, "P")))),
        ),
        (
            "F F",
            Box::new(|| drop(std::hint::black_box(product(&f, &f)))),
        ),
    ];
    let mut out = Vec::new();
    for (name, f) in &mut kernels {
        let (faer, nalgebra) = time_kernel(budget, &mut **f);
        out.push((*name, nalgebra / faer));
    }
    Ok(out)
}

/// Best time per step of a UKF (symmetric sigma set, `kappa = 0`) on `problem` under `policy`:
/// blocks of five steps after two warm-up steps, at least three blocks and `budget` seconds.
fn ukf_step(problem: &Problem, policy: KernelPolicy, budget: f64) -> Result<f64> {
    with_kernel_policy(policy, || {
        let mut ukf = Ukf::new(
            &problem.dynamics,
            &problem.measurement,
            DVector::zeros(problem.n),
            problem.p0.clone(),
            SigmaSet::Symmetric { kappa: 0.0 },
        )?;
        let zs = &problem.truth.measurements;
        let mut k = 0;
        let mut step = |ukf: &mut Ukf<_, _, _, _>| -> Result<()> {
            ukf.predict()?;
            ukf.update(&zs[k % zs.len()])?;
            k += 1;
            Ok(())
        };
        step(&mut ukf)?;
        step(&mut ukf)?;
        let (mut best, mut blocks, clock) = (f64::INFINITY, 0, Budget::new(budget));
        while clock.more(blocks, 3) {
            let (t, done) = timed(|| -> Result<()> {
                for _ in 0..5 {
                    step(&mut ukf)?;
                }
                Ok(())
            });
            done?;
            best = best.min(t / 5.0);
            blocks += 1;
        }
        Ok(best)
    })
}

/// numpy's time per step for each size, from `xtask/bench/w4_numpy.py`.
fn numpy_times(
    root: &FsPath,
    sizes: &[usize],
    min_blocks: usize,
) -> Result<(Vec<(usize, f64)>, String)> {
    let (python, versions) =
        super::eval::python_env(&root.join("target").join("bench-eval"), super::eval::PANDAS)?;
    let script = root.join("xtask").join("bench").join("w4_numpy.py");
    let sizes: Vec<String> = sizes.iter().map(usize::to_string).collect();
    let out = Command::new(&python)
        .arg(&script)
        .args(["--steps", &STEPS.to_string()])
        .args(["--warm-up", &WARM_UP.to_string()])
        .args(["--blocks", &min_blocks.to_string()])
        .args(["--budget", &BUDGET.to_string()])
        .args(["--sizes", &sizes.join(",")])
        // One thread, as the Rust paths: OpenBLAS (numpy's wheels), OpenMP and MKL builds.
        .env("OPENBLAS_NUM_THREADS", "1")
        .env("OMP_NUM_THREADS", "1")
        .env("MKL_NUM_THREADS", "1")
        .output()
        .with_context(|| format!("starting {}", python.display()))?;
    ensure!(
        out.status.success(),
        "{} failed: {}",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let mut times = Vec::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let v: serde_json::Value = serde_json::from_str(line)
            .with_context(|| format!("reading {}'s output line {line:?}", script.display()))?;
        let (Some(n), Some(t)) = (v["n"].as_u64(), v["seconds_per_step"].as_f64()) else {
            bail!("{} printed {line:?}", script.display());
        };
        times.push((n as usize, t));
    }
    Ok((times, versions))
}

/// Microseconds.
fn us(seconds: f64) -> f64 {
    seconds * 1e6
}

/// Runs W4, prints its figures and returns them.
pub(crate) fn run(args: &Args) -> Result<Figures> {
    let sizes = &args.sizes;
    ensure!(sizes.iter().all(|&n| n >= 1), "W4 sizes must be at least 1");
    let title = format!(
        "one KF step at run-time size (dense F, rho(F) = 0.95; m = max(2, n/4)): predict, \
         Joseph update, NEES by Cholesky; one thread; best block of {STEPS} steps after {WARM_UP} \
         warm-up steps, at least {} blocks and {BUDGET} s per size",
        args.repeats
    );
    println!("W4: {title}");
    let mut figures = Figures::new("w4", title);
    println!(
        "  faer = every kernel through faer; nalgebra = no kernel through faer (the code before \
         faer); library = the default (faer from n = {})",
        kalibra_linalg::FAER_MIN_DIM
    );
    println!(
        "  |dP|/|P|: relative Frobenius difference of the faer and nalgebra posteriors after the \
         steps every path ran"
    );
    println!(
        "  GFLOP/s: nominal flops of the step with general products (8.33 n^3 + 6 n^2 m + 6 n m^2 \
         + m^3/3) per second, the same count for every path"
    );
    let mut rows = Vec::new();
    println!(
        "  {:>5} {:>4} {:>12} {:>12} {:>8} {:>12} {:>9} {:>9} {:>10} {:>6}",
        "n",
        "m",
        "nalgebra us",
        "faer us",
        "speed-up",
        "library us",
        "GF/s nal",
        "GF/s faer",
        "|dP|/|P|",
        "steps"
    );
    for &n in sizes {
        let problem = Problem::new(n)?;
        let row = measure(&problem, args.repeats, BUDGET, args.threads)?;
        let flops = nominal_flops(row.n, row.m);
        println!(
            "  {:>5} {:>4} {:>12.1} {:>12.1} {:>7.2}x {:>12.1} {:>9.2} {:>9.2} {:>10.1e} {:>6}",
            row.n,
            row.m,
            us(row.nalgebra),
            us(row.faer),
            row.nalgebra / row.faer,
            us(row.library),
            flops / row.nalgebra / 1e9,
            flops / row.faer / 1e9,
            row.difference,
            row.steps,
        );
        let n = row.n;
        figures.push(format!("n = {n}: nalgebra step"), us(row.nalgebra), "us");
        figures.push(format!("n = {n}: faer step"), us(row.faer), "us");
        figures.push(
            format!("n = {n}: library step (default policy)"),
            us(row.library),
            "us",
        );
        figures.push(
            format!("n = {n}: faer speed-up over nalgebra"),
            row.nalgebra / row.faer,
            "x",
        );
        figures.push(format!("n = {n}: faer"), flops / row.faer / 1e9, "GFLOP/s");
        rows.push(row);
    }
    for row in &rows {
        if let Some((threads, t, same)) = row.parallel {
            println!(
                "  n = {}: library with faer on {threads} threads within the step: {:.1} us, \
                 {:.2}x the one-thread library path, results {}",
                row.n,
                us(t),
                row.library / t,
                if same { "bit-identical" } else { "DIFFERENT" }
            );
            ensure!(
                same,
                "within-step parallelism changed the results at n = {}",
                row.n
            );
            figures.push(
                format!("n = {}: library, {threads} threads within the step", row.n),
                us(t),
                "us",
            );
        }
    }
    let goal = |ok: bool| if ok { "met" } else { "NOT MET" };
    let speedups = |from: usize| {
        rows.iter()
            .filter(|r| r.n >= from)
            .map(|r| r.nalgebra / r.faer)
            .fold(f64::INFINITY, f64::min)
    };
    let s64 = speedups(64);
    let s128 = speedups(128);
    if rows.iter().any(|r| r.n >= 64) {
        println!(
            "  goal faer >= 1.4x nalgebra at n >= 64: least {s64:.2}x, {}",
            goal(s64 >= 1.4)
        );
    }
    if rows.iter().any(|r| r.n >= 128) {
        println!(
            "  goal faer >= 1.6x nalgebra at n >= 128: least {s128:.2}x, {}",
            goal(s128 >= 1.6)
        );
    }
    let small = rows
        .iter()
        .filter(|r| r.n <= 16)
        .map(|r| r.library / r.nalgebra)
        .fold(0.0f64, f64::max);
    if rows.iter().any(|r| r.n <= 16) {
        // Both run the same nalgebra code there; a few percent either way is timing noise.
        println!(
            "  goal library no slower than nalgebra at n <= 16: worst time ratio library / \
             nalgebra {small:.3} ({})",
            goal(small <= 1.05)
        );
    }
    if args.kernels {
        println!("  kernel by kernel: nalgebra's time / faer's (above 1: faer is faster)");
        let mut header = format!("  {:>5}", "n");
        for &n in sizes {
            let ratios = kernel_ratios(n, 0.05)?;
            if header.len() < 8 {
                for (name, _) in &ratios {
                    header.push_str(&format!(" {name:>16}"));
                }
                println!("{header}");
            }
            let mut line = format!("  {n:>5}");
            for (name, ratio) in &ratios {
                line.push_str(&format!(" {ratio:>16.2}"));
                figures.push(format!("n = {n}: {name}, nalgebra / faer"), *ratio, "x");
            }
            println!("{line}");
        }
    }
    if args.ukf {
        println!("  UKF (symmetric sigma set) on the same problems, n <= 256: time per step");
        println!(
            "  {:>5} {:>12} {:>12} {:>8}",
            "n", "nalgebra us", "faer us", "speed-up"
        );
        for &n in sizes.iter().filter(|&&n| n <= 256) {
            let problem = Problem::new(n)?;
            let faer = ukf_step(&problem, KernelPolicy::faer_from(0), BUDGET / 2.0)?;
            let nalgebra = ukf_step(&problem, KernelPolicy::NALGEBRA, BUDGET / 2.0)?;
            println!(
                "  {n:>5} {:>12.1} {:>12.1} {:>7.2}x",
                us(nalgebra),
                us(faer),
                nalgebra / faer
            );
            figures.push(format!("n = {n}: UKF, nalgebra step"), us(nalgebra), "us");
            figures.push(format!("n = {n}: UKF, faer step"), us(faer), "us");
        }
    }
    if args.no_python {
        return Ok(figures);
    }
    println!("  numpy (xtask/bench/w4_numpy.py, the same step, BLAS on one thread):");
    let (numpy, versions) = numpy_times(&crate::workspace_root(), sizes, args.repeats)?;
    println!("    {versions}");
    println!(
        "    {:>5} {:>12} {:>9} {:>14} {:>14}",
        "n", "numpy us", "GF/s", "numpy / faer", "numpy / library"
    );
    for (n, t) in numpy {
        let Some(row) = rows.iter().find(|r| r.n == n) else {
            bail!("numpy reported n = {n}, which was not measured");
        };
        println!(
            "    {:>5} {:>12.1} {:>9.2} {:>13.2}x {:>13.2}x",
            n,
            us(t),
            nominal_flops(row.n, row.m) / t / 1e9,
            t / row.faer,
            t / row.library,
        );
        figures.push(format!("n = {n}: numpy step"), us(t), "us");
    }
    Ok(figures)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_agree_on_a_small_problem() {
        let problem = Problem::new(40).unwrap();
        let row = measure(&problem, 1, 0.0, 1).unwrap();
        assert_eq!(row.steps, WARM_UP + STEPS);
        assert!(row.difference < 1e-12, "{}", row.difference);
        assert!(row.faer > 0.0 && row.nalgebra > 0.0 && row.library > 0.0);
    }

    #[test]
    fn flops_count_the_dominant_terms() {
        // n = 4, m = 1: 8.33 * 64 + 6 * 16 + 6 * 4 + 1/3.
        assert!((nominal_flops(4, 1) - (533.0 + 1.0 / 3.0 + 96.0 + 24.0 + 1.0 / 3.0)).abs() < 1e-9);
        assert_eq!(meas_dim(8), 2);
        assert_eq!(meas_dim(1024), 256);
    }
}
