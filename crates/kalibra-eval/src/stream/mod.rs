//! The evaluation fed one cell at a time: [`Evaluator`], for logs too large to hold (a CSV
//! read row by row) and as the one implementation behind [`Evaluation::evaluate`].

use kalibra_linalg::DMatrix;
use kalibra_metrics::{JStep, MetricsError};
use rayon::prelude::*;

use crate::evaluate::{BandCache, reason};
use crate::log::check_times;
use crate::report::{Findings, Reason, Report, SCHEMA_VERSION, Summary, Verdict, VerdictKind};
use crate::{EvalError, Evaluation};

mod cell;
mod factor;
mod fixed;
mod j;
mod per_run;
mod sides;
mod state;
#[cfg(test)]
mod tests;

pub use cell::{Cell, Contents, MatrixCell, ModelCell};
use cell::{check_model, fill, square, vector};
use factor::Factor;
use j::{JSide, JWork};
use per_run::PerRun;
pub(crate) use per_run::RUN_SUM_STEPS;
use sides::{InnovationSide, StateSide};
pub use state::EvaluatorState;

/// An evaluation fed one cell at a time ([`Evaluator::push`]), finished into the same
/// [`Report`] as [`Evaluation::evaluate`], which is built on it.
///
/// Cells may come in any order (run after run, step after step, or mixed); every cell of the
/// `R x K` rectangle must come exactly once, logged or not (an empty [`Cell`]), and the runs
/// and steps are learnt from the largest indices fed. Memory does not grow with the number
/// of cells beyond what the statistics need: per step the sums over runs, and per valid cell
/// the error and NEES that NCI needs (`n + 1` numbers; [`Credibility`](kalibra_metrics::Credibility)), one bit per cell to
/// catch repeats and gaps, per run and block of 128 steps the sums of its normalised NEES and
/// NIS (for the t-test of the runs' time averages), and the diagnostic run's series.
///
/// Sums over runs are taken in the order the cells come, so two orders of the same cells
/// agree to rounding, and run after run to the bit with [`Evaluation::evaluate`] (which
/// evaluates blocks of 128 steps apart, each in strips of 32 steps run after run, and merges
/// them: each step still takes the runs in order, and a run's sum over its steps is added
/// block by block in either case).
/// `J1`/`J2` pair a step with the step before it in the same run, when they come one after
/// the other.
///
/// ```
/// use kalibra_eval::{Cell, Contents, Evaluation, MatrixCell};
/// let contents = Contents {
///     innovation: Some(1),
///     innovation_cov: Some(1),
///     ..Contents::default()
/// };
/// let mut evaluator = Evaluation::new().lags(1)?.evaluator(contents)?;
/// for (step, nu) in [0.5, -1.0, 1.5, -0.2].iter().enumerate() {
///     let cell = Cell {
///         innovation: Some(std::slice::from_ref(nu)),
///         innovation_cov: Some(MatrixCell::Full(&[1.0])),
///         ..Cell::default()
///     };
///     evaluator.push(0, step, &cell)?;
/// }
/// let report = evaluator.finish(None)?;
/// assert_eq!(report.anis_per_step[1], Some(1.0));
/// # Ok::<(), kalibra_eval::EvalError>(())
/// ```
pub struct Evaluator {
    options: Evaluation,
    contents: Contents,
    state: Option<StateSide>,
    innovation: Option<InnovationSide>,
    j: Option<JSide>,
    runs: usize,
    steps: usize,
    /// Per run, one bit per step fed.
    seen: Vec<Vec<u64>>,
}

impl Evaluation {
    /// An [`Evaluator`] for a log holding `contents`, to be fed cell by cell.
    ///
    /// # Errors
    /// [`EvalError::NothingToEvaluate`] if the log holds neither truth, estimate and
    /// covariance nor innovation and its covariance; [`EvalError::Mismatch`] or
    /// [`EvalError::Empty`] for dimensions that disagree or are zero;
    /// [`EvalError::GroupIndex`] for a group naming a component the state does not have.
    pub fn evaluator(&self, contents: Contents) -> Result<Evaluator, EvalError> {
        contents.check()?;
        let state = match (contents.truth, contents.estimate, contents.covariance) {
            (Some(n), Some(_), Some(_)) => Some(n),
            _ => None,
        };
        let innovation = match (contents.innovation, contents.innovation_cov) {
            (Some(m), Some(_)) => Some(m),
            _ => None,
        };
        if state.is_none() && innovation.is_none() {
            return Err(EvalError::NothingToEvaluate);
        }
        if let Some(n) = state {
            for g in &self.groups {
                if let Some(&index) = g.components.iter().find(|&&i| i >= n) {
                    return Err(EvalError::GroupIndex {
                        group: g.name.clone(),
                        index,
                        dim: n,
                    });
                }
            }
        }
        Ok(Evaluator {
            options: self.clone(),
            contents,
            state: state.map(StateSide::new),
            innovation: innovation.map(InnovationSide::new),
            j: (state.is_some() && contents.model.is_some()).then(JSide::new),
            runs: 0,
            steps: 0,
            seen: Vec::new(),
        })
    }
}

/// What the pure part of a cell gives, computed on any thread: its checked model matrices
/// and the outcomes of its two factorisations (each a value, or the reason of a finding).
struct Prepared {
    nees: Option<Result<f64, Reason>>,
    nis: Option<Result<f64, Reason>>,
    /// Whether the cell's model matrices were logged, are wanted and passed the checks.
    model: bool,
}

/// The pure part of a batch of cells, computed by [`Evaluator::prepare_batch`] (on any
/// thread) and fed with the cells by [`Evaluator::push_prepared`].
pub struct PreparedBatch {
    contents: Contents,
    /// Each cell's run and step.
    at: Vec<(usize, usize)>,
    prepared: Vec<Result<Prepared, EvalError>>,
}

/// The factorisation storage of one thread.
pub(crate) struct Scratch {
    p: Factor,
    s: Factor,
    /// The cell's error `xhat - x`.
    error: Vec<f64>,
}

/// The most runs an [`Evaluator`] takes (run indices `0 .. MAX_RUNS`): its per-run state is
/// about a hundred bytes a run, so the largest index fed sizes it, and a limit checked as each
/// cell comes keeps a mistaken index from allocating gigabytes. 2^24 runs (16.8 million) is
/// far beyond any Monte Carlo study that keeps NCI's per-run errors in memory.
pub const MAX_RUNS: usize = 1 << 24;

/// The most steps an [`Evaluator`] takes (step indices `0 .. MAX_STEPS`), for the same reason
/// as [`MAX_RUNS`]: per-step state is a few hundred bytes a step.
pub const MAX_STEPS: usize = 1 << 24;

/// Batches from this many cells on are prepared on several threads: below it the hand-over
/// costs more than it saves.
const PARALLEL_FROM: usize = 512;

impl Evaluator {
    /// Feeds the cell of `run` and `step`. Nothing is kept of a cell that fails.
    ///
    /// # Errors
    /// [`EvalError::IndexLimit`] for a run or step index at or beyond [`MAX_RUNS`] or
    /// [`MAX_STEPS`]; [`EvalError::DuplicateCell`] for a cell fed before; [`EvalError::CellLength`] for a
    /// value of the wrong length; [`EvalError::NonFinite`] for a non-finite truth or model
    /// matrix; [`EvalError::Metrics`] if a metric fails on data that passed the checks (not
    /// expected). A bad covariance or a non-finite estimate or innovation is a finding, not
    /// an error.
    pub fn push(&mut self, run: usize, step: usize, cell: &Cell<'_>) -> Result<(), EvalError> {
        let mut scratch = self.scratch();
        self.push_with(run, step, cell, &mut scratch)
    }

    /// [`Evaluator::push`] with the caller's factorisation storage, for a caller that feeds
    /// many cells on one thread ([`Evaluation::evaluate`]'s blocks of steps, which run in
    /// parallel with each other): no batch to build, nothing allocated per cell.
    pub(crate) fn push_with(
        &mut self,
        run: usize,
        step: usize,
        cell: &Cell<'_>,
        scratch: &mut Scratch,
    ) -> Result<(), EvalError> {
        let prepared = self.prepare((run, step), cell, scratch)?;
        self.accept((run, step), cell, prepared, None)
    }

    /// Feeds the cells of `cells`, each with its run and step, in order: the same as
    /// [`Evaluator::push`] on each, but the factorisations of a large batch run on every core
    /// (rayon), while the sums still take the cells in order, so the report does not depend on
    /// the number of threads.
    ///
    /// # Errors
    /// The first failing cell's index in `cells` and its error (as [`Evaluator::push`]); the
    /// cells before it were fed, it and those after it were not.
    pub fn push_batch(
        &mut self,
        cells: &[(usize, usize, Cell<'_>)],
    ) -> Result<(), (usize, EvalError)> {
        let this = &*self;
        let prepared = if cells.len() < PARALLEL_FROM {
            this.prepare_serial(cells)
        } else {
            cells
                .par_chunks(PARALLEL_FROM / 2)
                .map(|chunk| this.prepare_serial(chunk))
                .collect::<Vec<_>>()
                .into_iter()
                .flatten()
                .collect()
        };
        self.accept_all(cells, prepared)
    }

    /// The pure part of [`Evaluator::push_batch`] on `cells` (every check, and the
    /// factorisations), on the calling thread, changing nothing: an evaluator of the same
    /// [`Contents`] computes it on a reader's thread while this one adds the previous
    /// batch's sums, and [`Evaluator::push_prepared`] then feeds the cells with it. The two
    /// halves overlap where `push_batch` leaves every core but one idle while the sums are
    /// added (`cargo xtask bench eval`, NPZ).
    pub fn prepare_batch(&self, cells: &[(usize, usize, Cell<'_>)]) -> PreparedBatch {
        PreparedBatch {
            contents: self.contents,
            at: cells.iter().map(|(run, step, _)| (*run, *step)).collect(),
            prepared: self.prepare_serial(cells),
        }
    }

    /// [`Evaluator::push_batch`] of `cells` with their pure part computed before by
    /// [`Evaluator::prepare_batch`] on the same cells (by this evaluator or another of the
    /// same [`Contents`]): the same outcome and the same report as `push_batch` (the test
    /// `prepared_batches_give_the_same_report`). A `prepared` of other contents, or of other
    /// runs and steps, is set aside and the cells are prepared here.
    ///
    /// # Errors
    /// As [`Evaluator::push_batch`].
    pub fn push_prepared(
        &mut self,
        cells: &[(usize, usize, Cell<'_>)],
        prepared: PreparedBatch,
    ) -> Result<(), (usize, EvalError)> {
        let matches = prepared.contents == self.contents
            && prepared.at.len() == cells.len()
            && prepared
                .at
                .iter()
                .zip(cells)
                .all(|(at, (run, step, _))| *at == (*run, *step));
        if !matches {
            return self.push_batch(cells);
        }
        self.accept_all(cells, prepared.prepared)
    }

    /// [`Evaluator::prepare`] of each cell in turn, with one scratch.
    fn prepare_serial(
        &self,
        cells: &[(usize, usize, Cell<'_>)],
    ) -> Vec<Result<Prepared, EvalError>> {
        let mut scratch = self.scratch();
        cells
            .iter()
            .map(|(run, step, cell)| self.prepare((*run, *step), cell, &mut scratch))
            .collect()
    }

    /// The stateful part of [`Evaluator::push_batch`]: the `J1`/`J2` steps, then each cell's
    /// sums in order, up to the first failing cell.
    fn accept_all(
        &mut self,
        cells: &[(usize, usize, Cell<'_>)],
        prepared: Vec<Result<Prepared, EvalError>>,
    ) -> Result<(), (usize, EvalError)> {
        let mut computed = self.j_pass(cells, &prepared).into_iter();
        for (i, ((run, step, cell), p)) in cells.iter().zip(prepared).enumerate() {
            let p = p.map_err(|e| (i, e))?;
            let j = computed.next().flatten();
            self.accept((*run, *step), cell, p, j).map_err(|e| (i, e))?;
        }
        Ok(())
    }

    /// The `J1`/`J2` steps of a large batch, on every core: for each cell whose predecessor
    /// in the batch is the same run's previous step, both with a valid covariance, and whose
    /// model was logged, the step `accept` would compute, computed by the same code. Empty
    /// for a small batch or a log without a model; `None` where `accept` computes it itself
    /// (a run's first cell in the batch).
    fn j_pass(
        &self,
        cells: &[(usize, usize, Cell<'_>)],
        prepared: &[Result<Prepared, EvalError>],
    ) -> Vec<Option<Result<JStep, MetricsError>>> {
        if self.j.is_none() || cells.len() < PARALLEL_FROM {
            return Vec::new();
        }
        let n = self.contents.state_dim().unwrap_or(0);
        let m = self.contents.measurement_dim().unwrap_or(0);
        // The covariance entered NEES: what makes it `J`'s covariance in `accept`.
        let valid = |p: &Result<Prepared, EvalError>| {
            matches!(
                p,
                Ok(Prepared {
                    nees: Some(Ok(_)),
                    ..
                })
            )
        };
        let storage = || (JWork::new(), DMatrix::zeros(0, 0), DMatrix::zeros(0, 0));
        (0..cells.len())
            .into_par_iter()
            .with_min_len(PARALLEL_FROM / 2)
            .map_init(storage, |(work, p0, p1), i| {
                let before = cells.get(i.checked_sub(1)?)?;
                let (run, step, cell) = &cells[i];
                let model_logged = matches!(&prepared[i], Ok(p) if p.model);
                if before.0 != *run || before.1 + 1 != *step || !model_logged {
                    return None;
                }
                if !(valid(&prepared[i - 1]) && valid(&prepared[i])) {
                    return None;
                }
                let (Some(c0), Some(c1), Some(model)) =
                    (before.2.covariance, cell.covariance, cell.model)
                else {
                    return None;
                };
                fill(p0, n, c0);
                fill(p1, n, c1);
                Some(work.step(&model, (n, m), p0, p1))
            })
            .collect()
    }

    pub(crate) fn scratch(&self) -> Scratch {
        Scratch {
            p: Factor::new(self.contents.state_dim().unwrap_or(0)),
            s: Factor::new(self.contents.measurement_dim().unwrap_or(0)),
            error: Vec::with_capacity(self.contents.state_dim().unwrap_or(0)),
        }
    }

    /// The pure part of a cell: every check, and its factorisations. Changes nothing.
    fn prepare(
        &self,
        at: (usize, usize),
        cell: &Cell<'_>,
        scratch: &mut Scratch,
    ) -> Result<Prepared, EvalError> {
        let (run, step) = at;
        for (what, index, limit) in [("run", run, MAX_RUNS), ("step", step, MAX_STEPS)] {
            if index >= limit {
                return Err(EvalError::IndexLimit { what, index, limit });
            }
        }
        let (n, m) = (self.contents.state_dim(), self.contents.measurement_dim());
        let truth = vector("truth", at, n.unwrap_or(0), cell.truth)?;
        if truth.is_some_and(|x| !x.iter().all(|v| v.is_finite())) {
            return Err(EvalError::NonFinite {
                array: "truth",
                run,
                step,
            });
        }
        let estimate = vector("estimate", at, n.unwrap_or(0), cell.estimate)?;
        let cov = square("covariance", at, n.unwrap_or(0), cell.covariance)?;
        let nu = vector("innovation", at, m.unwrap_or(0), cell.innovation)?;
        let s = square("innovation_cov", at, m.unwrap_or(0), cell.innovation_cov)?;
        let model = match (cell.model, self.contents.model, &self.j) {
            (Some(c), Some((n, m)), Some(_)) => {
                check_model("F", at, (n, n), c.f)?;
                check_model("H", at, (m, n), c.h)?;
                check_model("Q", at, (n, n), c.q)?;
                check_model("R", at, (m, m), c.r)?;
                true
            }
            _ => false,
        };
        let mut nees = None;
        if let (Some(_), Some(x), Some(xhat), Some(p)) = (&self.state, truth, estimate, cov)
            && xhat.iter().all(|v| v.is_finite())
        {
            // RMSE and windows need no covariance: estimate minus truth (paper 002's sign).
            // Written in place, which is cheaper per cell than `clear` and `extend` through
            // the zipped iterators (`cargo xtask bench eval`).
            scratch.error.resize(xhat.len(), 0.0);
            for ((e, a), b) in scratch.error.iter_mut().zip(xhat).zip(x) {
                *e = a - b;
            }
            // Finite truth and estimate of opposite signs near the limit: the error has no
            // f64 value, which is the log's fault, not the filter's (`tests/extreme_floats.rs`).
            if !scratch.error.iter().all(|v| v.is_finite()) {
                return Err(EvalError::OutOfRange {
                    what: "estimation error estimate - truth",
                    run,
                    step,
                });
            }
            nees = Some(
                match scratch.p.nees_of(p, &scratch.error, "state covariance P") {
                    Ok(value) => Ok(value),
                    Err(err) => Err(reason(err.into())?),
                },
            );
        }
        let mut nis = None;
        if let (Some(_), Some(nu), Some(s)) = (&self.innovation, nu, s)
            && nu.iter().all(|v| v.is_finite())
        {
            nis = Some(match scratch.s.nis_of(s, nu, "innovation covariance S") {
                Ok(value) => Ok(value),
                Err(err) => Err(reason(err.into())?),
            });
        }
        Ok(Prepared { nees, nis, model })
    }

    /// The stateful part of a cell: marks it, and adds what `prepare` found to the sums.
    fn accept(
        &mut self,
        (run, step): (usize, usize),
        cell: &Cell<'_>,
        prepared: Prepared,
        computed: Option<Result<JStep, MetricsError>>,
    ) -> Result<(), EvalError> {
        self.mark(run, step)?;
        let at = (run, step);
        let valid_cov = match (&mut self.state, cell.truth, cell.estimate) {
            (Some(side), Some(x), Some(xhat)) => {
                side.accept(&self.options, at, x, xhat, prepared.nees)?
            }
            _ => false,
        };
        if let (Some(side), Some(nu), Some(s)) =
            (&mut self.innovation, cell.innovation, cell.innovation_cov)
        {
            side.accept(&self.options, at, nu, s, prepared.nis)?;
        }
        if let Some(j) = &mut self.j {
            let n = self.contents.state_dim().unwrap_or(0);
            let m = self.contents.measurement_dim().unwrap_or(0);
            let p = cell.covariance.filter(|_| valid_cov);
            let model = cell.model.filter(|_| prepared.model);
            j.push(at, (n, m), p, model, computed)?;
        }
        Ok(())
    }

    /// Adds the cells `other` was fed, as if they had come to this evaluator after its own:
    /// per-step sums add (`self`'s first, so the result depends on the order of merges, which
    /// the caller fixes), NCI's per-run errors and NEES append after this evaluator's, counts
    /// and findings add, and the runs and steps grow to cover both. The two must have been
    /// made by the same [`Evaluation`] for the same [`Contents`], and have been fed disjoint
    /// cells; a run split between them must not have a `J1`/`J2` pair across the split (feed
    /// whole runs to each, as a Monte Carlo study cut into blocks of runs does).
    ///
    /// A study that evaluates blocks of runs on separate evaluators and merges them in block
    /// order gets the same report whatever runs the blocks in parallel; it differs from feeding
    /// every cell to one evaluator only in the rounding of the sums.
    ///
    /// # Errors
    /// [`EvalError::MergeMismatch`] for evaluators of different options or contents;
    /// [`EvalError::DuplicateCell`] for a cell both were fed.
    pub fn merge(&mut self, mut other: Evaluator) -> Result<(), EvalError> {
        if self.options != other.options || self.contents != other.contents {
            return Err(EvalError::MergeMismatch);
        }
        // Duplicates first, so that nothing changes on error.
        for (run, bits) in other.seen.iter().enumerate() {
            if let Some(mine) = self.seen.get(run)
                && let Some(w) = mine.iter().zip(bits).position(|(a, b)| a & b != 0)
            {
                let step = w * 64 + (mine[w] & bits[w]).trailing_zeros() as usize;
                return Err(EvalError::DuplicateCell { run, step });
            }
        }
        // One horizon for both, so the per-step accumulators fit.
        self.grow_steps(other.steps);
        other.grow_steps(self.steps);
        if other.seen.len() > self.seen.len() {
            self.seen.resize_with(other.seen.len(), Vec::new);
        }
        for (mine, bits) in self.seen.iter_mut().zip(other.seen) {
            if bits.len() > mine.len() {
                mine.resize(bits.len(), 0);
            }
            for (a, b) in mine.iter_mut().zip(bits) {
                *a |= b;
            }
        }
        self.runs = self.runs.max(other.runs);
        if let (Some(a), Some(b)) = (&mut self.state, other.state) {
            a.merge(b);
        }
        if let (Some(a), Some(b)) = (&mut self.innovation, other.innovation) {
            a.merge(b);
        }
        if let (Some(a), Some(b)) = (&mut self.j, other.j) {
            a.merge(b);
        }
        Ok(())
    }

    /// The number of runs learnt so far: one more than the largest run fed.
    pub fn runs(&self) -> usize {
        self.runs
    }

    /// The number of steps learnt so far: one more than the largest step fed.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Records that `(run, step)` came, growing the horizon; an error if it came before.
    fn mark(&mut self, run: usize, step: usize) -> Result<(), EvalError> {
        if run >= self.seen.len() {
            self.seen.resize_with(run + 1, Vec::new);
        }
        let bits = &mut self.seen[run];
        let (word, bit) = (step / 64, 1u64 << (step % 64));
        if word >= bits.len() {
            bits.resize(word + 1, 0);
        }
        if bits[word] & bit != 0 {
            return Err(EvalError::DuplicateCell { run, step });
        }
        bits[word] |= bit;
        self.runs = self.runs.max(run + 1);
        if step >= self.steps {
            self.grow_steps(step + 1);
        }
        Ok(())
    }

    /// Extends the horizon to `steps.end` and reserves NCI's storage for `runs` runs at
    /// `steps`: for a caller that knows the cells it will feed ([`Evaluation::evaluate`]).
    pub(crate) fn reserve(&mut self, runs: usize, steps: std::ops::Range<usize>) {
        self.grow_steps(steps.end);
        if let Some(s) = &mut self.state {
            s.cred.reserve_runs(runs, steps);
        }
    }

    /// Extends the horizon, and every per-step accumulator, to `steps` steps.
    fn grow_steps(&mut self, steps: usize) {
        self.steps = self.steps.max(steps);
        let steps = self.steps;
        if let Some(s) = &mut self.state {
            s.means.extend_steps(steps);
            s.cred.extend_steps(steps);
            s.squared.extend_steps(steps);
        }
        if let Some(s) = &mut self.innovation {
            s.means.extend_steps(steps);
        }
        if let Some(j) = &mut self.j {
            j.j1.extend_steps(steps);
            j.j2.extend_steps(steps);
        }
    }

    /// The first cell of the rectangle never fed, as (run, step).
    fn first_missing(&self) -> Option<(usize, usize)> {
        (0..self.runs).find_map(|run| {
            let bits = &self.seen[run];
            (0..self.steps)
                .find(|&k| bits.get(k / 64).is_none_or(|w| w & (1u64 << (k % 64)) == 0))
                .map(|k| (run, k))
        })
    }

    /// The report of every cell fed, with the times of the steps if logged.
    ///
    /// # Errors
    /// [`EvalError::Empty`] if no cell came; [`EvalError::MissingCell`] for a cell of the
    /// rectangle that never came; [`EvalError::InvalidOption`] for a diagnostic run beyond the
    /// log; [`EvalError::Shape`], [`EvalError::NonFinite`] or
    /// [`EvalError::TimesNotIncreasing`] for bad times; [`EvalError::Metrics`] if a metric
    /// fails on data that passed the checks (not expected).
    pub fn finish(self, times: Option<Vec<f64>>) -> Result<Report, EvalError> {
        if self.runs == 0 {
            return Err(EvalError::Empty { what: "runs" });
        }
        if let Some((run, step)) = self.first_missing() {
            return Err(EvalError::MissingCell {
                run,
                step,
                steps: self.steps,
            });
        }
        if self.options.run >= self.runs {
            return Err(EvalError::InvalidOption {
                name: "diagnostic run",
                value: self.options.run as f64,
            });
        }
        if let Some(t) = &times {
            check_times(t, self.steps)?;
        }
        let (runs, steps) = (self.runs, self.steps);
        let mut report = Report {
            schema_version: SCHEMA_VERSION,
            runs,
            steps: (0..steps).collect(),
            times,
            state_dim: self.contents.state_dim(),
            measurement_dim: self.contents.measurement_dim(),
            confidence: self.options.confidence,
            anees_per_step: Vec::new(),
            anees_band: Vec::new(),
            nees_runs_per_step: Vec::new(),
            anis_per_step: Vec::new(),
            anis_band: Vec::new(),
            nis_runs_per_step: Vec::new(),
            nci_per_step: Vec::new(),
            rmse_per_step: Vec::new(),
            window: None,
            whiteness: None,
            j: None,
            findings: Findings::default(),
            summary: Summary {
                anees: None,
                anis: None,
                nci: None,
                anees_fraction_inside: None,
                anis_fraction_inside: None,
                whiteness_fraction_inside: None,
                anees_test: None,
                anis_test: None,
                verdict: Verdict {
                    kind: VerdictKind::Undetermined,
                    statistic: None,
                    evidence: String::new(),
                    test: String::new(),
                },
            },
        };
        let mut bands = BandCache::new(self.options.confidence);
        let options = &self.options;
        if let Some(mut side) = self.state {
            side.settle();
            let per_run = side.per_run.totals(runs);
            options.state_report(
                side.n,
                (runs, steps),
                &side.means,
                &side.cred,
                &side.squared,
                &per_run,
                side.findings,
                side.window_series,
                &mut bands,
                &mut report,
            )?;
        }
        if let Some(side) = self.innovation {
            let per_run = side.per_run.totals(runs);
            options.innovation_report(
                side.m,
                steps,
                &side.means,
                &per_run,
                side.findings,
                side.normalized,
                &mut bands,
                &mut report,
            )?;
        }
        if let Some(j) = self.j {
            report.j = j.report(steps)?;
        }
        report.summary.verdict =
            crate::evaluate::verdict(&report.summary, options.confidence, &report);
        Ok(report)
    }
}
