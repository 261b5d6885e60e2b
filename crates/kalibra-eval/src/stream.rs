//! The evaluation fed one cell at a time: [`Evaluator`], for logs too large to hold (a CSV
//! read row by row) and as the one implementation behind [`Evaluation::evaluate`].

use kalibra_linalg::{Covariance, DMatrix, DVector};
use kalibra_metrics::{
    Credibility, JHorizon, SquaredErrors, StepMean, j_step, nees, nis, normalized_innovation,
};

use crate::evaluate::{BandCache, FindingTally, reason};
use crate::log::check_times;
use crate::report::{Findings, Reason, Report, SCHEMA_VERSION, Summary, Verdict, VerdictKind};
use crate::{EvalError, Evaluation};

/// A square matrix in one cell: every entry row by row, or the diagonal alone.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MatrixCell<'a> {
    /// `dim * dim` values, row by row (numpy's C order).
    Full(&'a [f64]),
    /// The `dim` diagonal values of a matrix whose other entries are 0.
    Diagonal(&'a [f64]),
}

/// The model matrices at one cell, each row by row: `F` (`n x n`) and `Q` (`n x n`) of the
/// prediction into the step, `H` (`m x n`) and `R` (`m x m`) of its update (see
/// [`crate::FilterLog::with_model`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelCell<'a> {
    /// `F`, `n x n`.
    pub f: &'a [f64],
    /// `H`, `m x n`.
    pub h: &'a [f64],
    /// `Q`, `n x n`.
    pub q: &'a [f64],
    /// `R`, `m x m`.
    pub r: &'a [f64],
}

/// One run and step of a log, borrowed; `None` where the array was not logged at this cell.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Cell<'a> {
    /// The true state, `n` values (must be finite).
    pub truth: Option<&'a [f64]>,
    /// The filter's estimate, `n` values.
    pub estimate: Option<&'a [f64]>,
    /// The filter's (posterior) covariance, `n x n`.
    pub covariance: Option<MatrixCell<'a>>,
    /// The innovation, `m` values.
    pub innovation: Option<&'a [f64]>,
    /// The innovation covariance `S`, `m x m`.
    pub innovation_cov: Option<MatrixCell<'a>>,
    /// The model matrices, for `J1`/`J2` (must be finite).
    pub model: Option<ModelCell<'a>>,
}

/// Which arrays a log holds, with their dimensions, known before its cells arrive: a CSV
/// header, the arrays of a [`crate::FilterLog`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Contents {
    /// The truth's dimension `n`, if logged.
    pub truth: Option<usize>,
    /// The estimate's dimension `n`, if logged.
    pub estimate: Option<usize>,
    /// The covariance's dimension `n`, if logged.
    pub covariance: Option<usize>,
    /// The innovation's dimension `m`, if logged.
    pub innovation: Option<usize>,
    /// The innovation covariance's dimension `m`, if logged.
    pub innovation_cov: Option<usize>,
    /// `(n, m)` of the model matrices `F`, `H`, `Q`, `R`, if logged.
    pub model: Option<(usize, usize)>,
}

impl Contents {
    /// The state dimension `n`, from the first state array logged (or the model).
    pub fn state_dim(&self) -> Option<usize> {
        self.truth
            .or(self.estimate)
            .or(self.covariance)
            .or(self.model.map(|m| m.0))
    }

    /// The measurement dimension `m`, from the first innovation array logged (or the model).
    pub fn measurement_dim(&self) -> Option<usize> {
        self.innovation
            .or(self.innovation_cov)
            .or(self.model.map(|m| m.1))
    }

    /// Checks that the arrays agree on `n` and `m`, and that none is empty.
    fn check(&self) -> Result<(), EvalError> {
        let same =
            |array, what, expected: Option<usize>, found: Option<usize>| match (expected, found) {
                (_, Some(0)) => Err(EvalError::Empty {
                    what: "an array's dimension",
                }),
                (Some(expected), Some(found)) if expected != found => Err(EvalError::Mismatch {
                    array,
                    what,
                    expected,
                    found,
                }),
                _ => Ok(()),
            };
        let (n, m) = (self.state_dim(), self.measurement_dim());
        same("truth", "state dimension", n, self.truth)?;
        same("estimate", "state dimension", n, self.estimate)?;
        same("covariance", "state dimension", n, self.covariance)?;
        same("innovation", "measurement dimension", m, self.innovation)?;
        same(
            "innovation_cov",
            "measurement dimension",
            m,
            self.innovation_cov,
        )?;
        same("F", "state dimension", n, self.model.map(|x| x.0))?;
        same("H", "measurement dimension", m, self.model.map(|x| x.1))
    }
}

/// The state side: NEES, NCI, RMSE, the diagnostic run's errors and, with a model, what
/// `J1`/`J2` need of the previous step.
struct StateSide {
    n: usize,
    means: StepMean,
    cred: Credibility,
    squared: SquaredErrors,
    per_run: Vec<(f64, usize)>,
    findings: FindingTally,
    /// The diagnostic run's errors, by step (sorted when finishing).
    window_series: Vec<(usize, Vec<f64>)>,
}

/// The innovation side: NIS and the diagnostic run's normalised innovations.
struct InnovationSide {
    m: usize,
    means: StepMean,
    per_run: Vec<(f64, usize)>,
    findings: FindingTally,
    normalized: Vec<(usize, DVector<f64>)>,
}

/// `J1`/`J2` over consecutive steps of a run.
struct JSide {
    horizon: JHorizon,
    j1: StepMean,
    j2: StepMean,
    failed: usize,
    /// Per run, the last step fed and its covariance if it was valid.
    previous: Vec<Option<(usize, DMatrix<f64>)>>,
}

/// An evaluation fed one cell at a time ([`Evaluator::push`]), finished into the same
/// [`Report`] as [`Evaluation::evaluate`], which is built on it.
///
/// Cells may come in any order (run after run, step after step, or mixed); every cell of the
/// `R x K` rectangle must come exactly once, logged or not (an empty [`Cell`]), and the runs
/// and steps are learnt from the largest indices fed. Memory does not grow with the number
/// of cells beyond what the statistics need: per step the sums over runs, and per valid cell
/// the error and NEES that NCI needs (`n + 1` numbers; [`Credibility`]), one bit per cell to
/// catch repeats and gaps, and the diagnostic run's series.
///
/// Sums over runs are taken in the order the cells come, so two orders of the same cells
/// agree to rounding, and the order of [`Evaluation::evaluate`] (run after run) to the bit.
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
            state: state.map(|n| StateSide {
                n,
                means: StepMean::new(0),
                cred: Credibility::new(0, n),
                squared: SquaredErrors::new(0, n),
                per_run: Vec::new(),
                findings: FindingTally::default(),
                window_series: Vec::new(),
            }),
            innovation: innovation.map(|m| InnovationSide {
                m,
                means: StepMean::new(0),
                per_run: Vec::new(),
                findings: FindingTally::default(),
                normalized: Vec::new(),
            }),
            j: (state.is_some() && contents.model.is_some()).then(|| JSide {
                horizon: JHorizon::new(),
                j1: StepMean::new(0),
                j2: StepMean::new(0),
                failed: 0,
                previous: Vec::new(),
            }),
            runs: 0,
            steps: 0,
            seen: Vec::new(),
        })
    }
}

/// Checks a vector cell's length.
fn vector<'a>(
    array: &'static str,
    (run, step): (usize, usize),
    dim: usize,
    v: Option<&'a [f64]>,
) -> Result<Option<&'a [f64]>, EvalError> {
    match v {
        Some(v) if v.len() != dim => Err(EvalError::CellLength {
            array,
            run,
            step,
            expected: dim,
            found: v.len(),
        }),
        other => Ok(other),
    }
}

/// Checks a square matrix cell's length and builds the matrix.
fn square(
    array: &'static str,
    (run, step): (usize, usize),
    dim: usize,
    m: Option<MatrixCell<'_>>,
) -> Result<Option<DMatrix<f64>>, EvalError> {
    let (values, expected) = match m {
        None => return Ok(None),
        Some(MatrixCell::Full(v)) => (v, dim * dim),
        Some(MatrixCell::Diagonal(v)) => (v, dim),
    };
    if values.len() != expected {
        return Err(EvalError::CellLength {
            array,
            run,
            step,
            expected,
            found: values.len(),
        });
    }
    Ok(Some(match m {
        Some(MatrixCell::Diagonal(v)) => DMatrix::from_diagonal(&DVector::from_column_slice(v)),
        _ => DMatrix::from_row_slice(dim, dim, values),
    }))
}

/// A finite model matrix of `rows x cols` from its row-major cell.
fn model_matrix(
    array: &'static str,
    at: (usize, usize),
    (rows, cols): (usize, usize),
    values: &[f64],
) -> Result<DMatrix<f64>, EvalError> {
    if values.len() != rows * cols {
        return Err(EvalError::CellLength {
            array,
            run: at.0,
            step: at.1,
            expected: rows * cols,
            found: values.len(),
        });
    }
    if !values.iter().all(|v| v.is_finite()) {
        return Err(EvalError::NonFinite {
            array,
            run: at.0,
            step: at.1,
        });
    }
    Ok(DMatrix::from_row_slice(rows, cols, values))
}

impl Evaluator {
    /// Feeds the cell of `run` and `step`. Nothing is kept of a cell that fails.
    ///
    /// # Errors
    /// [`EvalError::DuplicateCell`] for a cell fed before; [`EvalError::CellLength`] for a
    /// value of the wrong length; [`EvalError::NonFinite`] for a non-finite truth or model
    /// matrix; [`EvalError::Metrics`] if a metric fails on data that passed the checks (not
    /// expected). A bad covariance or a non-finite estimate or innovation is a finding, not
    /// an error.
    pub fn push(&mut self, run: usize, step: usize, cell: &Cell<'_>) -> Result<(), EvalError> {
        let at = (run, step);
        // Every check before any state changes, so a failed cell leaves no trace.
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
        let model = match (cell.model, self.contents.model) {
            (Some(c), Some((n, m))) => Some([
                model_matrix("F", at, (n, n), c.f)?,
                model_matrix("H", at, (m, n), c.h)?,
                model_matrix("Q", at, (n, n), c.q)?,
                model_matrix("R", at, (m, m), c.r)?,
            ]),
            _ => None,
        };
        self.mark(run, step)?;
        let valid_cov = match (&mut self.state, truth, estimate) {
            (Some(side), Some(x), Some(xhat)) => side.push(&self.options, at, x, xhat, &cov)?,
            _ => false,
        };
        if let (Some(side), Some(nu), Some(s)) = (&mut self.innovation, nu, s) {
            side.push(&self.options, at, nu, s)?;
        }
        if let Some(j) = &mut self.j {
            j.push(at, valid_cov.then_some(cov).flatten(), model)?;
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
            self.steps = step + 1;
            if let Some(s) = &mut self.state {
                s.means.extend_steps(self.steps);
                s.cred.extend_steps(self.steps);
                s.squared.extend_steps(self.steps);
            }
            if let Some(s) = &mut self.innovation {
                s.means.extend_steps(self.steps);
            }
            if let Some(j) = &mut self.j {
                j.j1.extend_steps(self.steps);
                j.j2.extend_steps(self.steps);
            }
        }
        Ok(())
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
            side.per_run.resize(runs, (0.0, 0));
            options.state_report(
                side.n,
                (runs, steps),
                &side.means,
                &side.cred,
                &side.squared,
                &side.per_run,
                side.findings,
                side.window_series,
                &mut bands,
                &mut report,
            )?;
        }
        if let Some(mut side) = self.innovation {
            side.per_run.resize(runs, (0.0, 0));
            options.innovation_report(
                side.m,
                steps,
                &side.means,
                &side.per_run,
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

impl StateSide {
    /// One cell's state side; returns whether its covariance was valid (it entered NEES).
    fn push(
        &mut self,
        options: &Evaluation,
        (run, step): (usize, usize),
        x: &[f64],
        xhat: &[f64],
        cov: &Option<DMatrix<f64>>,
    ) -> Result<bool, EvalError> {
        if run >= self.per_run.len() {
            self.per_run.resize(run + 1, (0.0, 0));
        }
        if !xhat.iter().all(|v| v.is_finite()) {
            self.findings
                .add("estimate", run, step, Reason::NonFiniteVector);
            return Ok(false);
        }
        // RMSE and windows need no covariance: estimate minus truth (paper 002's sign).
        let error = DVector::from_iterator(self.n, xhat.iter().zip(x).map(|(a, b)| a - b));
        self.squared.push_slice(step, error.as_slice())?;
        if run == options.run {
            self.window_series.push((step, error.as_slice().to_vec()));
        }
        let Some(p) = cov else {
            return Ok(false);
        };
        let n = self.n as f64;
        match nees(&error, p) {
            Ok(value) => {
                self.means.push(step, value / n)?;
                self.cred.push_nees(step, error.as_slice(), value)?;
                self.per_run[run].0 += value / n;
                self.per_run[run].1 += 1;
                Ok(true)
            }
            Err(err) => {
                self.findings.add("covariance", run, step, reason(err)?);
                Ok(false)
            }
        }
    }
}

impl InnovationSide {
    fn push(
        &mut self,
        options: &Evaluation,
        (run, step): (usize, usize),
        nu: &[f64],
        s: DMatrix<f64>,
    ) -> Result<(), EvalError> {
        if run >= self.per_run.len() {
            self.per_run.resize(run + 1, (0.0, 0));
        }
        if !nu.iter().all(|v| v.is_finite()) {
            self.findings
                .add("innovation", run, step, Reason::NonFiniteVector);
            return Ok(());
        }
        let s = match Covariance::named(s, "innovation covariance S") {
            Ok(s) => s,
            Err(err) => {
                self.findings
                    .add("innovation_cov", run, step, reason(err.into())?);
                return Ok(());
            }
        };
        let nu = DVector::from_column_slice(nu);
        let value = nis(&nu, &s)?;
        let m = self.m as f64;
        self.means.push(step, value / m)?;
        self.per_run[run].0 += value / m;
        self.per_run[run].1 += 1;
        if run == options.run {
            self.normalized
                .push((step, normalized_innovation(&nu, &s)?));
        }
        Ok(())
    }
}

impl JSide {
    /// One cell: its covariance if valid, and its model matrices if logged.
    fn push(
        &mut self,
        (run, step): (usize, usize),
        cov: Option<DMatrix<f64>>,
        model: Option<[DMatrix<f64>; 4]>,
    ) -> Result<(), EvalError> {
        if run >= self.previous.len() {
            self.previous.resize(run + 1, None);
        }
        let previous = self.previous[run].take();
        if let (Some((k, p0)), Some(p1), Some([f, h, q, r])) = (&previous, &cov, &model)
            && *k + 1 == step
        {
            let ht = h.transpose();
            let hf = h * f;
            let a: DMatrix<f64> = &hf * p0 * hf.transpose();
            let b: DMatrix<f64> = h * q * &ht;
            let c: DMatrix<f64> = h * p1 * &ht;
            match j_step(&a, &b, r, &c) {
                Ok(js) => {
                    self.horizon.push(&js);
                    self.j1.push(step, js.j1)?;
                    self.j2.push(step, js.j2)?;
                }
                Err(_) => self.failed += 1,
            }
        }
        self.previous[run] = cov.map(|p| (step, p));
        Ok(())
    }

    fn report(self, steps: usize) -> Result<Option<crate::JReport>, EvalError> {
        if self.horizon.updates() == 0 {
            return Ok(None);
        }
        let summary = self.horizon.summary(self.horizon.updates())?;
        let series = |s: &StepMean| -> Vec<Option<f64>> {
            (0..steps)
                .map(|k| (s.count(k) > 0).then(|| s.mean(k)))
                .collect()
        };
        Ok(Some(crate::JReport {
            j1_per_step: series(&self.j1),
            j2_per_step: series(&self.j2),
            j1: summary.j1,
            j2: summary.j2,
            nq_mean_log10: summary.nq_mean_log10,
            nq_log10_mean: summary.nq_log10_mean,
            updates: summary.updates,
            indefinite_updates: summary.indefinite_updates,
            failed_updates: self.failed,
        }))
    }
}
