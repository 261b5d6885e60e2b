//! An [`Evaluator`]'s accumulated state as data ([`EvaluatorState`]): what a Monte Carlo
//! shard ships to the machine that merges, so that the merge folds the very evaluators the
//! one-process study folds, and the report is the same to the bit.

use kalibra_linalg::DVector;
use kalibra_metrics::{Credibility, JHorizon, SquaredErrors, StepMean};
use serde::{Deserialize, Serialize};

use super::{Evaluator, MAX_RUNS, MAX_STEPS};
use crate::evaluate::FindingTally;
use crate::{Contents, EvalError, Evaluation};

/// The sums, counts, findings and diagnostic series of an [`Evaluator`], without its options
/// and contents (the caller keeps those: they are the same for every block of a study) and
/// without what only a run in progress needs (the last covariance of each run, which pairs it
/// with its next step for `J1`/`J2`, and scratch storage).
///
/// Made by [`Evaluator::into_state`] and turned back into an evaluator by
/// [`Evaluation::resume`]; [`Evaluator::merge`] and [`Evaluator::finish`] of the resumed
/// evaluator give what they give on the original, to the bit. Serialised (serde) it is a
/// record of
/// - `runs`, `steps`: the horizon learnt; `first_run`: the first run fed (the runs before it
///   hold nothing, and are not written: a block of a Monte Carlo study starts at its first
///   run);
/// - `seen`: per run from `first_run`, the bit set of the steps fed (64 steps a word);
/// - `state`, `innovation`, `j`: each side's dimension (`n`, `m`) and accumulators, in their own serde forms
///   ([`StepMean`], [`Credibility`], [`SquaredErrors`], [`JHorizon`]), the per-run sums from
///   `first_run`, the findings, and the diagnostic run's series;
///
/// and in binary formats every array of numbers is one byte string of little-endian 8-byte
/// values ([`kalibra_metrics::packed`]), so NaN and infinities keep their bits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvaluatorState {
    runs: usize,
    steps: usize,
    first_run: usize,
    seen: Vec<Words>,
    state: Option<StateData>,
    innovation: Option<InnovationData>,
    j: Option<JData>,
}

/// One run's bit set of steps fed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
struct Words(#[serde(with = "kalibra_metrics::packed")] Vec<u64>);

/// Per-run sums and counts from the state's `first_run`, per block of
/// [`RUN_SUM_STEPS`](super::RUN_SUM_STEPS) steps (the evaluator keeps them so, for the bits of
/// one pass): run `first_run + i` holds `blocks[i]` blocks, whose sums and counts follow one
/// another in `sum` and `count`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct PerRun {
    #[serde(with = "kalibra_metrics::packed")]
    blocks: Vec<u64>,
    #[serde(with = "kalibra_metrics::packed")]
    sum: Vec<f64>,
    #[serde(with = "kalibra_metrics::packed")]
    count: Vec<u64>,
}

/// A diagnostic series: (step, values) in the order fed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Series {
    #[serde(with = "kalibra_metrics::packed")]
    steps: Vec<u64>,
    #[serde(with = "kalibra_metrics::packed")]
    values: Vec<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct StateData {
    /// The state dimension `n`.
    n: usize,
    means: StepMean,
    cred: Credibility,
    squared: SquaredErrors,
    per_run: PerRun,
    findings: FindingTallyData,
    window_series: Series,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct InnovationData {
    /// The measurement dimension `m`.
    m: usize,
    means: StepMean,
    per_run: PerRun,
    findings: FindingTallyData,
    normalized: Series,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct JData {
    horizon: JHorizon,
    j1: StepMean,
    j2: StepMean,
    failed: usize,
}

/// [`FindingTally`] with the comparisons a state needs (the tally itself has none).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FindingTallyData {
    count: crate::FindingCount,
    steps: std::collections::BTreeSet<usize>,
}

impl From<FindingTally> for FindingTallyData {
    fn from(t: FindingTally) -> Self {
        Self {
            count: t.count,
            steps: t.steps,
        }
    }
}

/// The refusal of a state that does not fit.
fn bad(message: impl Into<String>) -> EvalError {
    EvalError::State(message.into())
}

impl PerRun {
    /// The sums of runs `first..`; the runs before `first` were never fed, so they hold none.
    fn from_runs(per_run: &super::PerRun, first: usize) -> Self {
        let tail = per_run.blocks.get(first..).unwrap_or(&[]);
        Self {
            blocks: tail.iter().map(|b| b.len() as u64).collect(),
            sum: tail.iter().flatten().map(|p| p.0).collect(),
            count: tail.iter().flatten().map(|p| p.1 as u64).collect(),
        }
    }

    /// The evaluator's per-run sums again, empty before `first`; refused unless every count
    /// fits its block and every run its steps.
    fn into_runs(
        self,
        first: usize,
        (runs, steps): (usize, usize),
    ) -> Result<super::PerRun, EvalError> {
        let block = super::RUN_SUM_STEPS;
        let total: Option<u64> = self.blocks.iter().try_fold(0u64, |a, b| a.checked_add(*b));
        if self.sum.len() != self.count.len()
            || total != Some(self.sum.len() as u64)
            || first
                .checked_add(self.blocks.len())
                .is_none_or(|end| end > runs)
        {
            return Err(bad(format!(
                "{} per-run sums, {} counts and {} runs of blocks from run {first} of {runs}",
                self.sum.len(),
                self.count.len(),
                self.blocks.len()
            )));
        }
        let mut out = vec![Vec::new(); first];
        let mut pairs = self.sum.into_iter().zip(self.count);
        for n in self.blocks {
            if n > steps.div_ceil(block) as u64 {
                return Err(bad(format!("a run holds {n} blocks of {steps} steps")));
            }
            let mut run = Vec::with_capacity(n as usize);
            for (s, c) in pairs.by_ref().take(n as usize) {
                let c = usize::try_from(c)
                    .ok()
                    .filter(|&c| c <= block.min(steps))
                    .ok_or_else(|| bad(format!("a block of steps counts {c} cells")))?;
                run.push((s, c));
            }
            out.push(run);
        }
        Ok(super::PerRun { blocks: out })
    }
}

impl Series {
    fn from_pairs<'a>(pairs: impl Iterator<Item = (usize, &'a [f64])>) -> Self {
        let mut s = Self {
            steps: Vec::new(),
            values: Vec::new(),
        };
        for (k, v) in pairs {
            s.steps.push(k as u64);
            s.values.extend_from_slice(v);
        }
        s
    }

    /// The pairs again, each of `dim` values at a step below `steps`.
    fn into_pairs(self, dim: usize, steps: usize) -> Result<Vec<(usize, Vec<f64>)>, EvalError> {
        if self.values.len() != self.steps.len() * dim {
            return Err(bad(format!(
                "a diagnostic series of {} steps holds {} values, not {dim} a step",
                self.steps.len(),
                self.values.len()
            )));
        }
        self.steps
            .iter()
            .zip(self.values.chunks_exact(dim.max(1)))
            .map(|(&k, v)| match usize::try_from(k) {
                Ok(k) if k < steps => Ok((k, v.to_vec())),
                _ => Err(bad(format!("a diagnostic series at step {k} of {steps}"))),
            })
            .collect()
    }
}

impl FindingTallyData {
    fn into_tally(self, (runs, steps): (usize, usize)) -> Result<FindingTally, EvalError> {
        let beyond = self.steps.last().is_some_and(|&k| k >= steps)
            || self
                .count
                .first
                .as_ref()
                .is_some_and(|f| f.run >= runs || f.step >= steps);
        if beyond || self.steps.len() > self.count.cells {
            return Err(bad("findings beyond the runs and steps"));
        }
        let c = &self.count;
        let kinds = [
            c.non_finite,
            c.not_symmetric,
            c.not_positive_definite,
            c.non_finite_vector,
        ];
        if kinds.iter().any(|&k| k > c.cells) {
            return Err(bad(
                "a kind of finding counted more often than the findings",
            ));
        }
        cells("findings", c.cells, (runs, steps))?;
        Ok(FindingTally {
            count: self.count,
            steps: self.steps,
        })
    }
}

/// Checks that no count passes what `runs x steps` cells can give (per step: `runs`), so
/// that the merge of a state read from outside cannot overflow a count.
fn counts(
    what: &str,
    per_step: impl Fn(usize) -> u64,
    (runs, steps): (usize, usize),
) -> Result<(), EvalError> {
    match (0..steps).find(|&k| per_step(k) > runs as u64) {
        Some(k) => Err(bad(format!(
            "{what} count {} runs at step {k} of a state of {runs} runs",
            per_step(k)
        ))),
        None => Ok(()),
    }
}

/// Checks a count over all cells against `runs x steps`.
fn cells(what: &str, count: usize, (runs, steps): (usize, usize)) -> Result<(), EvalError> {
    if count as u128 > runs as u128 * steps as u128 {
        return Err(bad(format!(
            "{count} {what} in a state of {runs} runs x {steps} steps"
        )));
    }
    Ok(())
}

/// Checks that a per-step accumulator covers the horizon (and, for those with one, the
/// dimension).
fn horizon(what: &str, found: (usize, usize), expected: (usize, usize)) -> Result<(), EvalError> {
    if found == expected {
        Ok(())
    } else {
        Err(bad(format!(
            "{what} covers {} steps of dimension {}, the state {} of dimension {}",
            found.0, found.1, expected.0, expected.1
        )))
    }
}

impl Evaluator {
    /// The evaluator's accumulated state, for another process to [`Evaluation::resume`] and
    /// merge (a shard of a Monte Carlo study ships one per block). Runs should be whole: a
    /// run continued after resuming starts its `J1`/`J2` pairs afresh.
    pub fn into_state(self) -> EvaluatorState {
        let first_run = self
            .seen
            .iter()
            .position(|bits| !bits.is_empty())
            .unwrap_or(self.seen.len());
        EvaluatorState {
            runs: self.runs,
            steps: self.steps,
            first_run,
            seen: self
                .seen
                .get(first_run..)
                .unwrap_or(&[])
                .iter()
                .map(|bits| Words(bits.clone()))
                .collect(),
            state: self.state.map(|mut s| {
                s.settle();
                StateData {
                    n: s.n,
                    per_run: PerRun::from_runs(&s.per_run, first_run),
                    window_series: Series::from_pairs(
                        s.window_series.iter().map(|(k, v)| (*k, v.as_slice())),
                    ),
                    means: s.means,
                    cred: s.cred,
                    squared: s.squared,
                    findings: s.findings.into(),
                }
            }),
            innovation: self.innovation.map(|s| InnovationData {
                m: s.m,
                per_run: PerRun::from_runs(&s.per_run, first_run),
                normalized: Series::from_pairs(
                    s.normalized.iter().map(|(k, v)| (*k, v.as_slice())),
                ),
                means: s.means,
                findings: s.findings.into(),
            }),
            j: self.j.map(|j| JData {
                horizon: j.horizon,
                j1: j.j1,
                j2: j.j2,
                failed: j.failed,
            }),
        }
    }
}

impl Evaluation {
    /// The evaluator of this evaluation and `contents` holding `state` (from
    /// [`Evaluator::into_state`] of an evaluator made with the same options and contents):
    /// merging and finishing it give what they gave on the original, to the bit.
    ///
    /// ```
    /// use kalibra_eval::{Cell, Contents, Evaluation, MatrixCell};
    /// let contents = Contents { innovation: Some(1), innovation_cov: Some(1), ..Contents::default() };
    /// let evaluation = Evaluation::new().lags(1)?;
    /// let mut evaluator = evaluation.evaluator(contents)?;
    /// for (step, nu) in [0.5, -1.0, 1.5].iter().enumerate() {
    ///     let cell = Cell {
    ///         innovation: Some(std::slice::from_ref(nu)),
    ///         innovation_cov: Some(MatrixCell::Full(&[1.0])),
    ///         ..Cell::default()
    ///     };
    ///     evaluator.push(0, step, &cell)?;
    /// }
    /// let state = evaluator.into_state(); // what another process receives (serde)
    /// let report = evaluation.resume(contents, state)?.finish(None)?;
    /// assert_eq!(report.anis_per_step[1], Some(1.0));
    /// # Ok::<(), kalibra_eval::EvalError>(())
    /// ```
    ///
    /// # Errors
    /// As [`Evaluation::evaluator`] for the contents; [`EvalError::State`] for a state whose
    /// sides, dimensions, horizon or indices do not fit them (a state read from outside is
    /// checked so that merging and finishing it cannot fail on its shape).
    pub fn resume(
        &self,
        contents: Contents,
        state: EvaluatorState,
    ) -> Result<Evaluator, EvalError> {
        let mut ev = self.evaluator(contents)?;
        let (runs, steps, first) = (state.runs, state.steps, state.first_run);
        if runs > MAX_RUNS || steps > MAX_STEPS {
            return Err(bad(format!(
                "{runs} runs and {steps} steps pass the limits {MAX_RUNS} and {MAX_STEPS}"
            )));
        }
        if first > runs || state.seen.len() != runs - first {
            return Err(bad(format!(
                "{} runs' steps seen from run {first}, where the state has {runs} runs",
                state.seen.len()
            )));
        }
        let words = steps.div_ceil(64);
        // Every step fed is below the horizon: a bit beyond it would be a cell `finish`
        // never looks for.
        let beyond = |bits: &Words| {
            bits.0.len() > words
                || (steps % 64 != 0
                    && bits
                        .0
                        .get(steps / 64)
                        .is_some_and(|w| w >> (steps % 64) != 0))
        };
        if state.seen.iter().any(beyond) {
            return Err(bad(format!("a step seen beyond the {steps} steps")));
        }
        let sides = (
            state.state.is_some(),
            state.innovation.is_some(),
            state.j.is_some(),
        );
        if sides != (ev.state.is_some(), ev.innovation.is_some(), ev.j.is_some()) {
            return Err(bad(
                "its state, innovation and J sides are not those of the contents",
            ));
        }
        if let (Some(side), Some(data)) = (&mut ev.state, state.state) {
            let n = side.n;
            horizon("the state side", (steps, data.n), (steps, n))?;
            horizon("the NEES means", (data.means.steps(), n), (steps, n))?;
            horizon(
                "NCI's errors",
                (data.cred.steps(), data.cred.dim()),
                (steps, n),
            )?;
            horizon(
                "the squared errors",
                (data.squared.steps(), data.squared.dim()),
                (steps, n),
            )?;
            counts("the NEES means", |k| data.means.count(k), (runs, steps))?;
            counts(
                "the squared errors",
                |k| data.squared.count(k),
                (runs, steps),
            )?;
            side.means = data.means;
            side.cred = data.cred;
            side.squared = data.squared;
            side.per_run = data.per_run.into_runs(first, (runs, steps))?;
            side.findings = data.findings.into_tally((runs, steps))?;
            side.window_series = data.window_series.into_pairs(n, steps)?;
        }
        if let (Some(side), Some(data)) = (&mut ev.innovation, state.innovation) {
            let m = side.m;
            horizon("the innovation side", (steps, data.m), (steps, m))?;
            horizon("the NIS means", (data.means.steps(), m), (steps, m))?;
            counts("the NIS means", |k| data.means.count(k), (runs, steps))?;
            side.means = data.means;
            side.per_run = data.per_run.into_runs(first, (runs, steps))?;
            side.findings = data.findings.into_tally((runs, steps))?;
            side.normalized = data
                .normalized
                .into_pairs(m, steps)?
                .into_iter()
                .map(|(k, v)| (k, DVector::from_vec(v)))
                .collect();
        }
        if let (Some(side), Some(data)) = (&mut ev.j, state.j) {
            horizon("J1", (data.j1.steps(), 0), (steps, 0))?;
            horizon("J2", (data.j2.steps(), 0), (steps, 0))?;
            counts("J1", |k| data.j1.count(k), (runs, steps))?;
            counts("J2", |k| data.j2.count(k), (runs, steps))?;
            cells("J updates", data.horizon.updates(), (runs, steps))?;
            cells("failed J steps", data.failed, (runs, steps))?;
            side.horizon = data.horizon;
            side.j1 = data.j1;
            side.j2 = data.j2;
            side.failed = data.failed;
        }
        ev.runs = runs;
        ev.steps = steps;
        ev.seen = std::iter::repeat_with(Vec::new)
            .take(first)
            .chain(state.seen.into_iter().map(|w| w.0))
            .collect();
        Ok(ev)
    }
}
