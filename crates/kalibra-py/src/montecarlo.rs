//! `kalibra.monte_carlo`: a seeded Monte Carlo of a linear-Gaussian model through kalibra's
//! Kalman filter, evaluated, entirely in Rust.

use kalibra_eval::{Cell, Evaluation, MatrixCell, ModelCell};
use kalibra_filters::{Filter, Kf};
use kalibra_linalg::semidefinite_factor;
use kalibra_linalg::{
    Alloc, Const, DMatrix, DVector, DefaultAllocator, Dim, Dyn, OMatrix, OVector,
};
use kalibra_models::{LinearGaussian, LinearObservation, Simulator, sample_with_factor};
use kalibra_sim::{MonteCarlo, Shard, StudyId};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use rayon::prelude::*;

use crate::arrays::{new_array, read};
use crate::error;
use crate::eval::{Report, evaluation};
use crate::shards::{PyPartial, StudyConfig, VERSION, fold, study_contents};

/// One run's log, row-major per cell.
struct RunLog {
    truth: Vec<f64>,
    estimate: Vec<f64>,
    covariance: Vec<f64>,
    innovation: Vec<f64>,
    innovation_cov: Vec<f64>,
}

/// Appends `a` row by row (the log's layout; nalgebra stores columns).
fn push_rows<R: Dim, C: Dim>(out: &mut Vec<f64>, a: &OMatrix<f64, R, C>)
where
    DefaultAllocator: kalibra_linalg::nalgebra::allocator::Allocator<R, C>,
{
    for i in 0..a.nrows() {
        for j in 0..a.ncols() {
            out.push(a[(i, j)]);
        }
    }
}

/// A run's cells, borrowed from its log (`n`, `m`, `steps` its sizes), each with the model.
fn cells_of<'a>(
    run: usize,
    log: &'a RunLog,
    (n, m, steps): (usize, usize, usize),
    model: ModelCell<'a>,
) -> Vec<(usize, usize, Cell<'a>)> {
    (0..steps)
        .map(|k| {
            (
                run,
                k,
                Cell {
                    truth: Some(&log.truth[k * n..(k + 1) * n]),
                    estimate: Some(&log.estimate[k * n..(k + 1) * n]),
                    covariance: Some(MatrixCell::Full(
                        &log.covariance[k * n * n..(k + 1) * n * n],
                    )),
                    innovation: Some(&log.innovation[k * m..(k + 1) * m]),
                    innovation_cov: Some(MatrixCell::Full(
                        &log.innovation_cov[k * m * m..(k + 1) * m * m],
                    )),
                    model: Some(model),
                },
            )
        })
        .collect()
}

/// A study's models and size, as given (column-major `Dyn` matrices).
struct Setup {
    f: DMatrix<f64>,
    h: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DMatrix<f64>,
    fq: DMatrix<f64>,
    fr: DMatrix<f64>,
    x0: DVector<f64>,
    p0: DMatrix<f64>,
    l0: DMatrix<f64>,
    runs: usize,
    steps: usize,
    seed: u64,
    threads: usize,
    /// The blocks to evaluate: the whole study, or one shard's.
    shard: Shard,
}

/// What a study returns: the evaluators of its shard's blocks, in block order (unfolded, so
/// that a shard's blocks fold with the others' exactly as the one-process run folds them),
/// and its log as arrays when asked for.
type Outcome = (
    Vec<kalibra_eval::Evaluator>,
    Option<Vec<(String, Vec<usize>, Vec<f64>)>>,
);

/// The study at state dimension `N` and measurement dimension `M`: `Const` sizes for the
/// common small models (nalgebra's fixed-size code, no allocation per step), `Dyn` otherwise.
///
/// Each run draws from its own stream `MonteCarlo::rng(run)`. The runs are cut into the
/// Monte Carlo blocks; a block's runs are simulated, filtered and fed to the block's own
/// [`kalibra_eval::Evaluator`] in order, blocks run in parallel, and the evaluators are
/// returned in block order for the caller to merge in that order ([`fold`]). The report is
/// therefore the same for any thread count, and for any cut into shards; against `evaluate`
/// on the returned log (one evaluator, run after run) only the rounding of the per-step sums
/// differs. Only the blocks of `setup.shard` run.
fn study<N: Dim, M: Dim>(
    setup: &Setup,
    evaluation: &Evaluation,
    (nd, md): (N, M),
    return_log: bool,
) -> Result<Outcome, String>
where
    DefaultAllocator: Alloc<N, M>,
    // The models are shared by the threads that run the runs.
    OMatrix<f64, N, N>: Sync,
    OMatrix<f64, M, N>: Sync,
    OMatrix<f64, M, M>: Sync,
    OVector<f64, N>: Sync,
{
    let (n, m, steps) = (setup.x0.len(), setup.h.nrows(), setup.steps);
    let sq =
        |a: &DMatrix<f64>| OMatrix::<f64, N, N>::from_iterator_generic(nd, nd, a.iter().copied());
    let obs =
        |a: &DMatrix<f64>| OMatrix::<f64, M, N>::from_iterator_generic(md, nd, a.iter().copied());
    let meas =
        |a: &DMatrix<f64>| OMatrix::<f64, M, M>::from_iterator_generic(md, md, a.iter().copied());
    let x0 = OVector::<f64, N>::from_iterator_generic(nd, Const::<1>, setup.x0.iter().copied());
    let (p0, l0) = (sq(&setup.p0), sq(&setup.l0));
    let model = |what: &str, e: kalibra_models::ModelError| format!("{what}: {e}");
    let truth_dynamics =
        LinearGaussian::new(sq(&setup.f), sq(&setup.q)).map_err(|e| model("F, Q", e))?;
    let truth_sensor =
        LinearObservation::new(obs(&setup.h), meas(&setup.r)).map_err(|e| model("H, R", e))?;
    let dynamics =
        LinearGaussian::new(sq(&setup.f), sq(&setup.fq)).map_err(|e| model("filter_Q", e))?;
    let sensor =
        LinearObservation::new(obs(&setup.h), meas(&setup.fr)).map_err(|e| model("filter_R", e))?;
    Kf::new(&dynamics, &sensor, x0.clone(), p0.clone())
        .map_err(|e| format!("arguments x0, P0: {e}"))?;

    let mc = MonteCarlo::new(setup.runs, setup.seed);
    let one = |run: usize| -> Result<RunLog, String> {
        let mut rng = mc.rng(run);
        let fail = |e: &dyn std::fmt::Display| format!("run {run} failed: {e}");
        let start = &x0 + sample_with_factor(&l0, &mut rng);
        let mut truth =
            Simulator::new(&truth_dynamics, &truth_sensor, start, 0).map_err(|e| fail(&e))?;
        let mut kf = Kf::new(&dynamics, &sensor, x0.clone(), p0.clone()).map_err(|e| fail(&e))?;
        let mut log = RunLog {
            truth: Vec::with_capacity(steps * n),
            estimate: Vec::with_capacity(steps * n),
            covariance: Vec::with_capacity(steps * n * n),
            innovation: Vec::with_capacity(steps * m),
            innovation_cov: Vec::with_capacity(steps * m * m),
        };
        for k in 0..steps {
            let (x, z): (OVector<f64, N>, OVector<f64, M>) =
                truth.step(&mut rng).map_err(|e| fail(&e))?;
            if k > 0 {
                kf.predict().map_err(|e| fail(&e))?;
            }
            let rec = kf.update(&z).map_err(|e| fail(&e))?;
            log.innovation.extend(rec.innovation().iter());
            push_rows(&mut log.innovation_cov, rec.s_matrix());
            log.truth.extend(x.iter());
            log.estimate.extend(kf.mean().iter());
            push_rows(&mut log.covariance, kf.covariance());
        }
        Ok(log)
    };

    let rows = |a: &DMatrix<f64>| a.transpose().iter().copied().collect::<Vec<f64>>();
    let (f_rows, h_rows, q_rows, r_rows) = (
        rows(&setup.f),
        rows(&setup.h),
        rows(&setup.fq),
        rows(&setup.fr),
    );
    let model_cell = ModelCell {
        f: &f_rows,
        h: &h_rows,
        q: &q_rows,
        r: &r_rows,
    };
    let contents = study_contents(n, m);
    // The runs are cut into the Monte Carlo blocks (fixed by the number of runs); each block
    // is simulated, filtered and evaluated on its own evaluator, its runs in order, the blocks
    // in parallel, and the evaluators merge in block order: the report is the same for any
    // thread count, and the evaluation, not only the filtering, uses every core.
    let block = |b: usize| -> Result<(kalibra_eval::Evaluator, Vec<RunLog>), String> {
        let mut evaluator = evaluation.evaluator(contents).map_err(|e| e.to_string())?;
        let mut kept = Vec::new();
        for run in mc.block_runs(b) {
            let log = one(run)?;
            evaluator
                .push_batch(&cells_of(run, &log, (n, m, steps), model_cell))
                .map_err(|(_, e)| e.to_string())?;
            if return_log {
                kept.push(log);
            }
        }
        Ok((evaluator, kept))
    };
    // In block order, so the first error is the lowest failing run's.
    let blocks: Vec<_> = setup
        .shard
        .blocks(mc.blocks())
        .into_par_iter()
        .map(block)
        .collect();
    let mut evaluators = Vec::with_capacity(blocks.len());
    let mut kept = Vec::new();
    for b in blocks {
        let (e, logs) = b?;
        evaluators.push(e);
        kept.extend(logs);
    }
    if !return_log {
        return Ok((evaluators, None));
    }
    let runs = setup.runs;
    let gather = |field: fn(&RunLog) -> &Vec<f64>| -> Vec<f64> {
        kept.iter().flat_map(|l| field(l).iter().copied()).collect()
    };
    let arrays = vec![
        (
            "truth".to_string(),
            vec![runs, steps, n],
            gather(|l| &l.truth),
        ),
        (
            "estimate".to_string(),
            vec![runs, steps, n],
            gather(|l| &l.estimate),
        ),
        (
            "covariance".to_string(),
            vec![runs, steps, n, n],
            gather(|l| &l.covariance),
        ),
        (
            "innovation".to_string(),
            vec![runs, steps, m],
            gather(|l| &l.innovation),
        ),
        (
            "innovation_cov".to_string(),
            vec![runs, steps, m, m],
            gather(|l| &l.innovation_cov),
        ),
        ("F".to_string(), vec![n, n], f_rows),
        ("H".to_string(), vec![m, n], h_rows),
        ("Q".to_string(), vec![n, n], q_rows),
        ("R".to_string(), vec![m, m], r_rows),
    ];
    Ok((evaluators, Some(arrays)))
}

/// The study at fixed sizes for the common small models, at run-time sizes otherwise.
fn dispatch(setup: &Setup, evaluation: &Evaluation, return_log: bool) -> Result<Outcome, String> {
    macro_rules! fixed {
        ($(($n:literal, $m:literal)),*) => {
            match (setup.x0.len(), setup.h.nrows()) {
                $(($n, $m) => study(setup, evaluation, (Const::<$n>, Const::<$m>), return_log),)*
                (n, m) => study(setup, evaluation, (Dyn(n), Dyn(m)), return_log),
            }
        };
    }
    fixed!(
        (1, 1),
        (2, 1),
        (2, 2),
        (3, 1),
        (3, 2),
        (3, 3),
        (4, 1),
        (4, 2),
        (4, 3),
        (4, 4),
        (6, 2),
        (6, 3)
    )
}

fn square(obj: &Bound<'_, PyAny>, name: &str, dim: Option<usize>) -> PyResult<DMatrix<f64>> {
    let a = read(obj, name)?;
    match (a.shape.as_slice(), dim) {
        ([r, c], Some(d)) if *r == d && *c == d => Ok(DMatrix::from_row_slice(d, d, &a.data)),
        ([r, c], None) if r == c && *r > 0 => Ok(DMatrix::from_row_slice(*r, *c, &a.data)),
        (other, _) => Err(error(format!(
            "argument {name} has shape {other:?}; expected {}",
            dim.map_or("a square matrix".to_string(), |d| format!("({d}, {d})"))
        ))),
    }
}

/// A seeded Monte Carlo of the linear-Gaussian model `x_k = F x_{k-1} + w`, `z_k = H x_k + v`
/// through kalibra's Kalman filter, evaluated with `evaluate`'s statistics: entirely in Rust,
/// in parallel over blocks of runs (simulation, filter and evaluation), and bit-identical for
/// any thread count (run i draws from ChaCha8 stream i of `seed`). `evaluate` on the returned
/// log gives the same report to rounding (it sums the runs in one sequence, the study block by
/// block).
///
/// Each run draws its initial state from N(x0, P0) and simulates `steps` steps with noise
/// w ~ N(0, Q), v ~ N(0, R), measuring every step; the filter starts from (x0, P0) as the
/// prior at the first measurement, with its own `filter_Q` and `filter_R` (default: the true
/// Q and R, a consistent filter; smaller ones make it optimistic). The log (truth, estimate,
/// covariance, innovation, its covariance, and F, H and the filter's Q, R for J1/J2) is
/// evaluated with `evaluate`'s options.
///
/// Args:
///     F: (n, n), H: (m, n), Q: (n, n), R: (m, m), x0: (n,), P0: (n, n): the true model.
///     runs, steps: the size; seed: of the study; threads: 0 for one per core.
///     filter_Q, filter_R: the filter's noise, if not the true one.
///     confidence, window, groups, lags: as for `evaluate`.
///     return_log: also return the log as a dict of arrays (evaluate's argument names).
///     shard: (i, S) to run only shard i of S of the study (0 <= i < S): a contiguous range
///         of its blocks of runs, for another process or machine to run the others.
///         ``kalibra.merge`` of the partial results of all S shards is the report of the whole
///         study, to the bit, whatever S and the thread counts (with S above the study's
///         blocks, min(runs, 64), some shards are empty and still needed). Not with
///         return_log.
///
/// Returns:
///     Report, or (Report, dict[str, numpy.ndarray]) with return_log, or a picklable
///     ``kalibra.Partial`` with shard.
///
/// Example:
///     >>> import numpy as np, kalibra
///     >>> F = np.array([[1.0, 1.0], [0.0, 1.0]]); H = np.array([[1.0, 0.0]])
///     >>> Q = np.array([[0.25, 0.5], [0.5, 1.0]]); R = np.array([[4.0]])
///     >>> args = (F, H, Q, R, np.zeros(2), np.eye(2))
///     >>> kalibra.monte_carlo(*args, runs=200, steps=50, seed=1).verdict
///     'consistent'
///     >>> kalibra.monte_carlo(*args, runs=200, steps=50, seed=1, filter_R=R / 4).verdict
///     'optimistic'
///     >>> parts = [kalibra.monte_carlo(*args, runs=200, steps=50, seed=1, shard=(i, 2))
///     ...          for i in range(2)]
///     >>> kalibra.merge(parts).verdict
///     'consistent'
#[pyfunction]
#[pyo3(signature = (
    F, H, Q, R, x0, P0, *, runs=100, steps=100, seed=0, threads=0, filter_Q=None,
    filter_R=None, confidence=0.95, window=None, groups=None, lags=10, return_log=false,
    shard=None
))]
#[allow(non_snake_case, clippy::too_many_arguments)]
fn monte_carlo<'py>(
    py: Python<'py>,
    F: &Bound<'py, PyAny>,
    H: &Bound<'py, PyAny>,
    Q: &Bound<'py, PyAny>,
    R: &Bound<'py, PyAny>,
    x0: &Bound<'py, PyAny>,
    P0: &Bound<'py, PyAny>,
    runs: usize,
    steps: usize,
    seed: u64,
    threads: usize,
    filter_Q: Option<&Bound<'py, PyAny>>,
    filter_R: Option<&Bound<'py, PyAny>>,
    confidence: f64,
    window: Option<usize>,
    groups: Option<&Bound<'py, PyDict>>,
    lags: usize,
    return_log: bool,
    shard: Option<(i64, i64)>,
) -> PyResult<Bound<'py, PyAny>> {
    let whole = shard.is_none();
    let shard = match shard {
        None => Shard::WHOLE,
        // Signed, so that a negative index is named here rather than as an OverflowError.
        Some((i, count)) => usize::try_from(i)
            .ok()
            .zip(usize::try_from(count).ok())
            .and_then(|(i, count)| Shard::new(i, count).ok())
            .ok_or_else(|| {
                error(format!(
                    "argument shard: ({i}, {count}) is not a shard; expected (i, S) with \
                     0 <= i < S"
                ))
            })?,
    };
    if !whole && return_log {
        return Err(error(
            "arguments shard and return_log do not go together: a shard's log is only its \
             runs' (run the study whole for the log, or keep logs in the shards' own code)",
        ));
    }
    if runs == 0 || steps == 0 {
        return Err(error(format!(
            "arguments runs and steps must be at least 1 (got {runs} and {steps})"
        )));
    }
    // Checked before anything is simulated: the evaluator would refuse the first run beyond
    // its limit only after every run before it had run.
    if runs > kalibra_eval::MAX_RUNS || steps > kalibra_eval::MAX_STEPS {
        return Err(error(format!(
            "arguments runs and steps can be at most {} and {} (got {runs} and {steps})",
            kalibra_eval::MAX_RUNS,
            kalibra_eval::MAX_STEPS
        )));
    }
    let x0 = read(x0, "x0")?;
    let n = match x0.shape.as_slice() {
        [n] if *n > 0 => *n,
        other => {
            return Err(error(format!(
                "argument x0 has shape {other:?}; expected (n,) with n >= 1"
            )));
        }
    };
    let x0 = DVector::from_vec(x0.data);
    let f = square(F, "F", Some(n))?;
    let h_array = read(H, "H")?;
    let m = match h_array.shape.as_slice() {
        [m, c] if *c == n && *m > 0 => *m,
        other => {
            return Err(error(format!(
                "argument H has shape {other:?}; expected (m, {n}) (x0 has {n} components)"
            )));
        }
    };
    let h = DMatrix::from_row_slice(m, n, &h_array.data);
    let q = square(Q, "Q", Some(n))?;
    let r = square(R, "R", Some(m))?;
    let p0 = square(P0, "P0", Some(n))?;
    let fq = match filter_Q.filter(|o| !o.is_none()) {
        Some(o) => square(o, "filter_Q", Some(n))?,
        None => q.clone(),
    };
    let fr = match filter_R.filter(|o| !o.is_none()) {
        Some(o) => square(o, "filter_R", Some(m))?,
        None => r.clone(),
    };
    let evaluation = evaluation(confidence, window, groups, lags)?;
    // The study's identity: everything that decides its report but the seed and the runs
    // (the thread count never does), bit for bit.
    let config = (!whole)
        .then(|| -> PyResult<StudyConfig> {
            let rows = |a: &DMatrix<f64>| a.transpose().iter().copied().collect::<Vec<f64>>();
            Ok(StudyConfig {
                n,
                m,
                f: rows(&f),
                h: rows(&h),
                q: rows(&q),
                r: rows(&r),
                filter_q: rows(&fq),
                filter_r: rows(&fr),
                x0: x0.iter().copied().collect(),
                p0: rows(&p0),
                steps,
                confidence,
                window,
                groups: group_list(groups)?,
                lags,
            })
        })
        .transpose()?;
    let (l0, _) = semidefinite_factor(&p0, "initial covariance P0")
        .map_err(|e| error(format!("argument P0: {e}")))?;
    let setup = Setup {
        f,
        h,
        q,
        r,
        fq,
        fr,
        x0,
        p0,
        l0,
        runs,
        steps,
        seed,
        threads,
        shard,
    };
    let (evaluators, log) = py
        .detach(|| {
            let pool = (setup.threads > 0)
                .then(|| {
                    rayon::ThreadPoolBuilder::new()
                        .num_threads(setup.threads)
                        .build()
                        .map_err(|e| format!("build a pool of {} threads: {e}", setup.threads))
                })
                .transpose()?;
            match pool {
                Some(pool) => pool.install(|| dispatch(&setup, &evaluation, return_log)),
                None => dispatch(&setup, &evaluation, return_log),
            }
        })
        .map_err(error)?;
    if let Some(config) = config {
        let mc = MonteCarlo::new(runs, seed);
        let study = StudyId::new(&mc, config.hash().map_err(error)?, VERSION);
        return Ok(Bound::new(py, PyPartial::new(config, study, shard, evaluators))?.into_any());
    }
    let report = py
        .detach(|| {
            fold(
                evaluators
                    .into_iter()
                    .map(|e| Ok(("a block".to_string(), e))),
            )?
            .finish(None)
            .map_err(|e| e.to_string())
        })
        .map_err(error)?;
    let report = Bound::new(py, Report::new(report, "monte carlo"))?.into_any();
    match log {
        None => Ok(report),
        Some(arrays) => {
            let dict = PyDict::new(py);
            for (name, shape, data) in arrays {
                dict.set_item(name, new_array(py, &shape, data))?;
            }
            Ok(PyTuple::new(py, [report, dict.into_any()])?.into_any())
        }
    }
}

/// The groups as given (a dict's order), for the study's identity.
fn group_list(groups: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<(String, Vec<usize>)>> {
    let Some(groups) = groups else {
        return Ok(Vec::new());
    };
    // Read once already by `evaluation`, which named any bad key or value.
    groups
        .iter()
        .map(|(k, v)| Ok((k.extract()?, v.extract()?)))
        .collect()
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(monte_carlo, m)?)?;
    Ok(())
}
