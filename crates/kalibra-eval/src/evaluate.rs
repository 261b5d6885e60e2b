//! The evaluation: options, and the computation of a [`Report`] from a [`FilterLog`].

use std::collections::{BTreeMap, BTreeSet};

use kalibra_linalg::{DVector, LinalgError};
use kalibra_metrics::{
    ChiSquareBand, Credibility, MetricsError, SquaredErrors, StepMean, paired_t_test,
    sliding_window, whiteness,
};
use rayon::prelude::*;

use crate::report::{
    Band, ComponentWindow, ConsistencyTest, Finding, FindingCount, LagReport, Reason, Report,
    RmseSeries, Summary, TestMethod, Verdict, VerdictKind, WhitenessReport, WindowReport,
};
use crate::stream::RUN_SUM_STEPS;
use crate::{EvalError, FilterLog};

/// A cell's error with its (run, step).
type CellError = ((usize, usize), EvalError);

/// Cells handed to [`crate::Evaluator::push_batch`] at a time by [`Evaluation::evaluate`].
const BATCH_CELLS: usize = 4096;

/// Steps per strip of [`feed_in_strips`].
const STRIP_STEPS: usize = 32;

/// Feeds the cells of `runs` runs at the steps `block` to `evaluator` in strips of
/// `strip_steps` steps ([`STRIP_STEPS`]; the whole block is one pass run after run): each
/// strip run after run, the strips in step order. Each step still
/// takes the runs in run order and each run its steps in step order, so every sum is the one
/// a pass run after run gives, to the bit (the test
/// `blocks_of_steps_give_one_pass_to_the_bit_for_any_thread_count`). Why strips: NCI keeps
/// each step's errors in a vector of its own ([`kalibra_metrics::Credibility`]), so a run's
/// pass over a whole block stored to places far apart, cell after cell, while a strip of 32
/// steps stores to few places and still reads 32 cells of each array in a row
/// (`cargo xtask bench eval` times it); the evaluator now buffers NCI's cells in a
/// [`kalibra_metrics::CredibilityRows`] either way.
///
/// # Errors
/// The first failing cell in the order fed (not necessarily the first run after run).
fn feed_in_strips(
    evaluator: &mut crate::Evaluator,
    scratch: &mut crate::stream::Scratch,
    log: &FilterLog<'_>,
    runs: usize,
    block: &std::ops::Range<usize>,
    strip_steps: usize,
) -> Result<(), CellError> {
    for start in block.clone().step_by(strip_steps) {
        let strip = start..(start + strip_steps).min(block.end);
        for run in 0..runs {
            for step in strip.clone() {
                evaluator
                    .push_with(run, step, &log.cell(run, step), scratch)
                    .map_err(|e| ((run, step), e))?;
            }
        }
    }
    Ok(())
}

/// A named group of state components (position = `[0, 1]`), whose RMSE is reported beside the
/// components'.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Group {
    /// The group's name.
    pub name: String,
    /// Its components.
    pub components: Vec<usize>,
}

/// The options of an evaluation, and the evaluation itself ([`Evaluation::evaluate`]).
///
/// Defaults: confidence 0.95, window `max(2, K / 10)` samples, no groups, 10 whiteness lags
/// (fewer if the log is short), diagnostics (window, whiteness) on run 0.
///
/// ```
/// use kalibra_eval::{Evaluation, FilterLog, Matrices, Vectors, VerdictKind};
/// let log = FilterLog::new(1, 4)?
///     .with_innovation(Vectors::dense(1, vec![0.5, -1.0, 1.5, -0.2]))?
///     .with_innovation_cov(Matrices::constant(1, 1, vec![1.0]))?;
/// let report = Evaluation::new().lags(1)?.evaluate(&log)?;
/// assert_eq!(report.anis_per_step[1], Some(1.0));
/// assert_eq!(report.summary.verdict.kind, VerdictKind::Consistent);
/// # Ok::<(), kalibra_eval::EvalError>(())
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluation {
    pub(crate) confidence: f64,
    window: Option<usize>,
    pub(crate) groups: Vec<Group>,
    lags: usize,
    pub(crate) run: usize,
}

impl Default for Evaluation {
    fn default() -> Self {
        Self::new()
    }
}

impl Evaluation {
    /// The default options.
    pub fn new() -> Self {
        Self {
            confidence: 0.95,
            window: None,
            groups: Vec::new(),
            lags: 10,
            run: 0,
        }
    }

    /// The confidence of every band and test.
    ///
    /// # Errors
    /// [`EvalError::InvalidOption`] outside (0, 1).
    pub fn confidence(mut self, confidence: f64) -> Result<Self, EvalError> {
        if !(confidence > 0.0 && confidence < 1.0) {
            return Err(EvalError::InvalidOption {
                name: "confidence",
                value: confidence,
            });
        }
        self.confidence = confidence;
        Ok(self)
    }

    /// The sliding window `W` in samples.
    ///
    /// # Errors
    /// [`EvalError::InvalidOption`] below 2 (the window's std divides by `W - 1`).
    pub fn window(mut self, window: usize) -> Result<Self, EvalError> {
        if window < 2 {
            return Err(EvalError::InvalidOption {
                name: "window",
                value: window as f64,
            });
        }
        self.window = Some(window);
        Ok(self)
    }

    /// Adds a group of components whose joint RMSE is reported.
    ///
    /// # Errors
    /// [`EvalError::InvalidOption`] for an empty group (indices are checked against the log
    /// by [`Evaluation::evaluate`]).
    pub fn group(
        mut self,
        name: impl Into<String>,
        components: Vec<usize>,
    ) -> Result<Self, EvalError> {
        if components.is_empty() {
            return Err(EvalError::InvalidOption {
                name: "group size",
                value: 0.0,
            });
        }
        self.groups.push(Group {
            name: name.into(),
            components,
        });
        Ok(self)
    }

    /// The largest whiteness lag `L`.
    ///
    /// # Errors
    /// [`EvalError::InvalidOption`] for 0.
    pub fn lags(mut self, lags: usize) -> Result<Self, EvalError> {
        if lags == 0 {
            return Err(EvalError::InvalidOption {
                name: "lags",
                value: 0.0,
            });
        }
        self.lags = lags;
        Ok(self)
    }

    /// The run whose sliding windows and whiteness are reported (default 0; checked by
    /// [`Evaluation::evaluate`]).
    pub fn diagnostic_run(mut self, run: usize) -> Self {
        self.run = run;
        self
    }

    /// Evaluates `log` (definitions in the crate documentation): feeds its cells to
    /// [`crate::Evaluator`]s, the one implementation of the evaluation.
    ///
    /// The steps are cut into blocks of 128 steps, evaluated in parallel
    /// (rayon), each by its own evaluator fed in strips of 32 steps, each strip run after
    /// run, and the evaluators are merged in block order ([`crate::Evaluator::merge`]). Every
    /// per-step sum then adds the runs in run order, every run its steps in step order, and
    /// every per-run sum is kept per block of steps, so the report is the same to the bit as
    /// one evaluator fed run after run (as `kalibra eval` streams an NPZ or CSV log), whatever
    /// the number of threads. A log with model matrices is one block:
    /// `J1`/`J2` pair each step with the step before it in the same evaluator.
    ///
    /// # Errors
    /// [`EvalError::NothingToEvaluate`] if the log holds neither truth, estimate and
    /// covariance nor innovation and its covariance; [`EvalError::GroupIndex`] for a group
    /// naming a component the state does not have; [`EvalError::InvalidOption`] for a
    /// diagnostic run beyond the log; [`EvalError::Metrics`] if a metric fails on data that
    /// passed the checks (not expected). A failing cell's error is that of the first failing
    /// cell run after run, as one pass would meet it.
    pub fn evaluate(&self, log: &FilterLog<'_>) -> Result<Report, EvalError> {
        let (runs, steps) = (log.runs(), log.steps());
        let block = if log.model.is_some() {
            steps
        } else {
            RUN_SUM_STEPS
        };
        let blocks: Vec<std::ops::Range<usize>> = (0..steps)
            .step_by(block)
            .map(|start| start..(start + block).min(steps))
            .collect();
        let single = blocks.len() == 1;
        let parts: Vec<Result<crate::Evaluator, CellError>> = blocks
            .into_par_iter()
            .map(|range| {
                let mut evaluator = self.evaluator(log.contents()).map_err(|e| ((0, 0), e))?;
                evaluator.reserve(runs, range.clone());
                if !single {
                    // The blocks run in parallel with each other: each feeds its cells on its
                    // own thread, one at a time.
                    let mut scratch = evaluator.scratch();
                    let fed = feed_in_strips(
                        &mut evaluator,
                        &mut scratch,
                        log,
                        runs,
                        &range,
                        STRIP_STEPS,
                    );
                    if fed.is_err() {
                        // The strips meet the cells in another order than one pass: the
                        // error to report is that of the first failing cell run after run.
                        let mut evaluator =
                            self.evaluator(log.contents()).map_err(|e| ((0, 0), e))?;
                        let mut scratch = evaluator.scratch();
                        let whole = range.len();
                        feed_in_strips(&mut evaluator, &mut scratch, log, runs, &range, whole)?;
                    }
                    fed?;
                    return Ok(evaluator);
                }
                // A single block: its batches prepare their cells on every core instead
                // (`push_batch`).
                let mut batch = Vec::with_capacity(BATCH_CELLS);
                let feed =
                    |evaluator: &mut crate::Evaluator,
                     batch: &mut Vec<(usize, usize, crate::Cell<'_>)>| {
                        let fed = evaluator
                            .push_batch(batch)
                            .map_err(|(i, e)| ((batch[i].0, batch[i].1), e));
                        batch.clear();
                        fed
                    };
                let cells = (0..runs).flat_map(|run| range.clone().map(move |step| (run, step)));
                for (run, step) in cells {
                    batch.push((run, step, log.cell(run, step)));
                    if batch.len() == BATCH_CELLS {
                        feed(&mut evaluator, &mut batch)?;
                    }
                }
                feed(&mut evaluator, &mut batch)?;
                Ok(evaluator)
            })
            .collect();
        // The first failing cell run after run: each block stopped at its own first.
        let first = parts
            .iter()
            .filter_map(|p| p.as_ref().err())
            .min_by_key(|(at, _)| *at);
        if let Some((_, e)) = first {
            return Err(e.clone());
        }
        let mut parts = parts.into_iter().flatten();
        let mut evaluator = parts.next().ok_or(EvalError::Empty { what: "steps" })?;
        for part in parts {
            evaluator.merge(part)?;
        }
        evaluator.finish(log.times.clone())
    }

    /// The state side of the report: NEES, NCI, RMSE and windows, from the accumulators.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn state_report(
        &self,
        n: usize,
        (runs, steps): (usize, usize),
        means: &StepMean,
        cred: &Credibility,
        squared: &SquaredErrors,
        per_run: &[(f64, usize)],
        findings: FindingTally,
        mut window_series: Vec<(usize, Vec<f64>)>,
        bands: &mut BandCache,
        report: &mut Report,
    ) -> Result<(), EvalError> {
        report.findings.state = findings.finish();
        let anees = self.mean_report("anees", n, means, per_run, bands)?;
        report.summary.anees = anees.test.as_ref().map(|t| t.value);
        (
            report.summary.anees_fraction_inside,
            report.summary.anees_test,
        ) = (anees.fraction_inside, anees.test);
        (
            report.anees_per_step,
            report.anees_band,
            report.nees_runs_per_step,
        ) = (anees.per_step, anees.band, anees.runs_per_step);
        if runs >= 2 {
            // Each step's summary stands alone (an eigen-decomposition and a median over the
            // runs): computed on every core, collected in step order.
            report.nci_per_step = (0..steps)
                .into_par_iter()
                .map(|k| {
                    if cred.runs(k) < 2 {
                        return Ok(None);
                    }
                    let nci = cred.step_nci(k)?;
                    Ok(nci.is_finite().then_some(nci))
                })
                .collect::<Result<_, MetricsError>>()?;
            let nci: Vec<f64> = report.nci_per_step.iter().flatten().copied().collect();
            report.summary.nci =
                (!nci.is_empty()).then(|| nci.iter().sum::<f64>() / nci.len() as f64);
        }
        let mut series: Vec<(String, Vec<usize>)> =
            (0..n).map(|i| (format!("x{i}"), vec![i])).collect();
        series.extend(
            self.groups
                .iter()
                .map(|g| (g.name.clone(), g.components.clone())),
        );
        report.rmse_per_step = series
            .into_iter()
            .map(|(name, components)| {
                let values: Vec<Option<f64>> = (0..steps)
                    .map(|k| {
                        match squared.rmse_group(k, &components) {
                            Ok(r) => Ok(r.is_finite().then_some(r)),
                            // No error logged at this step.
                            Err(MetricsError::Empty { .. }) => Ok(None),
                            Err(e) => Err(e),
                        }
                    })
                    .collect::<Result<_, MetricsError>>()?;
                let present: Vec<usize> = (0..steps).filter(|&k| values[k].is_some()).collect();
                let over_time = match present.as_slice() {
                    [] => None,
                    _ => {
                        let ms: f64 = present
                            .iter()
                            .map(|&k| values[k].unwrap_or(0.0).powi(2))
                            .sum();
                        Some((ms / present.len() as f64).sqrt())
                    }
                };
                Ok(RmseSeries {
                    name,
                    components,
                    values,
                    over_time,
                })
            })
            .collect::<Result<_, EvalError>>()?;
        // Cells may have come in any order; the windows run along the steps.
        window_series.sort_by_key(|(k, _)| *k);
        let window = self.window.unwrap_or((steps / 10).max(2));
        if window_series.len() >= window {
            let components = (0..n)
                .map(|i| {
                    let e: Vec<f64> = window_series.iter().map(|(_, v)| v[i]).collect();
                    let w = sliding_window(&e, window)?;
                    Ok(ComponentWindow {
                        component: i,
                        rmse: w.rmse,
                        bias: w.bias,
                        std: w.std,
                    })
                })
                .collect::<Result<_, MetricsError>>()?;
            report.window = Some(WindowReport {
                run: self.run,
                window,
                start_steps: window_series[..=window_series.len() - window]
                    .iter()
                    .map(|(k, _)| *k)
                    .collect(),
                components,
            });
        }
        Ok(())
    }

    /// The innovation side of the report: NIS and whiteness, from the accumulators.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn innovation_report(
        &self,
        m: usize,
        steps: usize,
        means: &StepMean,
        per_run: &[(f64, usize)],
        findings: FindingTally,
        diagnostic: Vec<(usize, DVector<f64>)>,
        bands: &mut BandCache,
        report: &mut Report,
    ) -> Result<(), EvalError> {
        let mut normalized: Vec<Option<DVector<f64>>> = vec![None; steps];
        for (step, w) in diagnostic {
            normalized[step] = Some(w);
        }
        report.findings.innovation = findings.finish();
        let anis = self.mean_report("anis", m, means, per_run, bands)?;
        report.summary.anis = anis.test.as_ref().map(|t| t.value);
        (
            report.summary.anis_fraction_inside,
            report.summary.anis_test,
        ) = (anis.fraction_inside, anis.test);
        (
            report.anis_per_step,
            report.anis_band,
            report.nis_runs_per_step,
        ) = (anis.per_step, anis.band, anis.runs_per_step);
        let present = normalized.iter().flatten().count();
        let lags = self.lags.min(present.saturating_sub(2));
        if lags > 0 {
            match whiteness(&normalized, lags, self.confidence) {
                Ok(w) => {
                    report.summary.whiteness_fraction_inside = Some(w.fraction_inside());
                    report.whiteness = Some(WhitenessReport {
                        run: self.run,
                        lags: w
                            .lags
                            .iter()
                            .map(|l| LagReport {
                                lag: l.lag,
                                autocorrelation: l.autocorrelation,
                                bound: l.bound,
                                pairs: l.pairs,
                                inside: l.inside(),
                            })
                            .collect(),
                        fraction_inside: w.fraction_inside(),
                        box_pierce: w.box_pierce,
                        p_value: w.p_value,
                        white: w.white(),
                    });
                }
                // Gaps can leave a lag with fewer than two pairs, and an all-zero innovation
                // sequence has no correlation: no whiteness section, not an error.
                Err(MetricsError::TooFewSamples { .. } | MetricsError::Degenerate { .. }) => {}
                Err(e) => return Err(e.into()),
            }
        }
        Ok(())
    }
}

/// Chi-square bands for the mean of `samples` normalised values, computed once per count.
pub(crate) struct BandCache {
    confidence: f64,
    cache: BTreeMap<(usize, usize), Band>,
}

impl BandCache {
    pub(crate) fn new(confidence: f64) -> Self {
        Self {
            confidence,
            cache: BTreeMap::new(),
        }
    }

    fn get(&mut self, dof: usize, samples: usize) -> Result<Band, MetricsError> {
        if let Some(b) = self.cache.get(&(dof, samples)) {
            return Ok(*b);
        }
        let b = ChiSquareBand::for_normalized_mean(dof as f64, samples, self.confidence)?;
        let b = Band {
            lower: b.lower,
            upper: b.upper,
        };
        self.cache.insert((dof, samples), b);
        Ok(b)
    }
}

type PerStep = (Vec<Option<f64>>, Vec<Option<Band>>, Vec<usize>);

/// A side's mean normalised statistic (ANEES or ANIS) as the report holds it: per step with
/// its band and the runs behind it, the fraction of steps inside their band, and the test of
/// the runs' time averages.
struct MeanReport {
    per_step: Vec<Option<f64>>,
    band: Vec<Option<Band>>,
    runs_per_step: Vec<usize>,
    fraction_inside: Option<f64>,
    test: Option<ConsistencyTest>,
}

impl Evaluation {
    /// The [`MeanReport`] of `statistic` (`"anees"`, `"anis"`) with `dof` degrees of freedom
    /// per sample, from its per-step means and its per-run sums.
    fn mean_report(
        &self,
        statistic: &str,
        dof: usize,
        means: &StepMean,
        per_run: &[(f64, usize)],
        bands: &mut BandCache,
    ) -> Result<MeanReport, EvalError> {
        let (per_step, band, runs_per_step) = per_step_stats(means, dof, bands)?;
        Ok(MeanReport {
            fraction_inside: fraction_inside(&per_step, &band),
            test: consistency_test(statistic, dof, per_run, self.confidence)?,
            per_step,
            band,
            runs_per_step,
        })
    }
}

fn per_step_stats(
    means: &StepMean,
    dof: usize,
    bands: &mut BandCache,
) -> Result<PerStep, MetricsError> {
    let mut values = Vec::with_capacity(means.steps());
    let mut band = Vec::with_capacity(means.steps());
    let mut counts = Vec::with_capacity(means.steps());
    for k in 0..means.steps() {
        let c = means.count(k) as usize;
        counts.push(c);
        let mean = means.mean(k);
        band.push(match mean {
            Some(_) => Some(bands.get(dof, c)?),
            None => None,
        });
        values.push(mean);
    }
    Ok((values, band, counts))
}

fn fraction_inside(values: &[Option<f64>], bands: &[Option<Band>]) -> Option<f64> {
    let pairs: Vec<(f64, Band)> = values
        .iter()
        .zip(bands)
        .filter_map(|(v, b)| Some(((*v)?, (*b)?)))
        .collect();
    (!pairs.is_empty())
        .then(|| pairs.iter().filter(|(v, b)| b.contains(*v)).count() as f64 / pairs.len() as f64)
}

/// The test of the mean normalised statistic: a t-test over the runs' time averages for
/// several runs, the chi-square band of the time average for one.
fn consistency_test(
    statistic: &str,
    dof: usize,
    per_run: &[(f64, usize)],
    confidence: f64,
) -> Result<Option<ConsistencyTest>, EvalError> {
    let samples: usize = per_run.iter().map(|r| r.1).sum();
    if samples == 0 {
        return Ok(None);
    }
    let value = per_run.iter().map(|r| r.0).sum::<f64>() / samples as f64;
    let averages: Vec<f64> = per_run
        .iter()
        .filter(|r| r.1 > 0)
        .map(|r| r.0 / r.1 as f64)
        .collect();
    let direction = |high: bool| {
        if high {
            VerdictKind::Optimistic
        } else {
            VerdictKind::Pessimistic
        }
    };
    if averages.len() >= 2 {
        let ones = vec![1.0; averages.len()];
        match paired_t_test(&averages, &ones) {
            Ok(t) => {
                let outcome = if t.p_value >= 1.0 - confidence {
                    VerdictKind::Consistent
                } else {
                    direction(t.statistic > 0.0)
                };
                return Ok(Some(ConsistencyTest {
                    statistic: statistic.into(),
                    value,
                    samples,
                    method: TestMethod::RunAverageT,
                    band: None,
                    t: Some(t.statistic),
                    p_value: Some(t.p_value),
                    outcome,
                }));
            }
            // Every run with the same average (a log copied across runs): fall back to the
            // chi-square band below.
            Err(MetricsError::Degenerate { .. }) => {}
            Err(e) => return Err(e.into()),
        }
    }
    let b = ChiSquareBand::for_normalized_mean(dof as f64, samples, confidence)?;
    let band = Band {
        lower: b.lower,
        upper: b.upper,
    };
    let outcome = if band.contains(value) {
        VerdictKind::Consistent
    } else {
        direction(value > band.upper)
    };
    Ok(Some(ConsistencyTest {
        statistic: statistic.into(),
        value,
        samples,
        method: TestMethod::TimeAverageChiSquare,
        band: Some(band),
        t: None,
        p_value: None,
        outcome,
    }))
}

pub(crate) fn verdict(summary: &Summary, confidence: f64, report: &Report) -> Verdict {
    let Some(test) = summary.anees_test.as_ref().or(summary.anis_test.as_ref()) else {
        return Verdict {
            kind: VerdictKind::Undetermined,
            statistic: None,
            evidence: "no valid NEES or NIS in the log".into(),
            test: String::new(),
        };
    };
    let name = test.statistic.to_uppercase();
    let fraction = if test.statistic == "anees" {
        summary.anees_fraction_inside
    } else {
        summary.anis_fraction_inside
    };
    let pct = 100.0 * confidence;
    let mut evidence = format!(
        "{name} = {:.4} over {} samples ({} runs x {} steps); {:.1}% of steps inside their {pct}% band",
        test.value,
        test.samples,
        report.runs,
        report.steps.len(),
        100.0 * fraction.unwrap_or(f64::NAN),
    );
    let test_words = match test.method {
        TestMethod::RunAverageT => {
            evidence += &format!(
                "; t = {:.3}, p = {:.3e}",
                test.t.unwrap_or(f64::NAN),
                test.p_value.unwrap_or(f64::NAN)
            );
            format!(
                "two-sided one-sample t-test at {pct}% of the runs' time-averaged {name} against 1 (runs independent)"
            )
        }
        TestMethod::TimeAverageChiSquare => {
            if let Some(b) = test.band {
                evidence += &format!("; band [{:.4}, {:.4}]", b.lower, b.upper);
            }
            format!(
                "time-averaged {name} against its two-sided {pct}% chi-square band (Bar-Shalom, Li and Kirubarajan 2001, sec. 5.4.2)"
            )
        }
    };
    if let Some(w) = &report.whiteness {
        evidence += &format!(
            "; innovations of run {} {} (Box-Pierce p = {:.3e})",
            w.run,
            if w.white { "white" } else { "not white" },
            w.p_value
        );
    }
    let f = &report.findings;
    if f.state.cells + f.innovation.cells > 0 {
        evidence += &format!(
            "; {} cells left out as findings",
            f.state.cells + f.innovation.cells
        );
    }
    Verdict {
        kind: test.outcome,
        statistic: Some(test.statistic.clone()),
        evidence,
        test: test_words,
    }
}

pub(crate) fn reason(err: MetricsError) -> Result<Reason, EvalError> {
    match err {
        MetricsError::Linalg(LinalgError::NonFinite { .. }) => Ok(Reason::NonFinite),
        MetricsError::Linalg(LinalgError::NotSymmetric { .. }) => Ok(Reason::NotSymmetric),
        MetricsError::Linalg(LinalgError::NotPositiveDefinite { .. }) => {
            Ok(Reason::NotPositiveDefinite)
        }
        other => Err(other.into()),
    }
}

/// Findings of one side, counted as cells come (fields open to the crate: an
/// [`crate::EvaluatorState`] writes and reads them).
#[derive(Default)]
pub(crate) struct FindingTally {
    pub(crate) count: FindingCount,
    pub(crate) steps: BTreeSet<usize>,
}

impl FindingTally {
    pub(crate) fn add(&mut self, array: &str, run: usize, step: usize, reason: Reason) {
        let c = &mut self.count;
        c.cells += 1;
        match reason {
            Reason::NonFinite => c.non_finite += 1,
            Reason::NotSymmetric => c.not_symmetric += 1,
            Reason::NotPositiveDefinite => c.not_positive_definite += 1,
            Reason::NonFiniteVector => c.non_finite_vector += 1,
        }
        self.steps.insert(step);
        // Cells may come in any order: the first is the one of the lowest (run, step).
        if c.first
            .as_ref()
            .is_none_or(|f| (run, step) < (f.run, f.step))
        {
            c.first = Some(Finding {
                array: array.into(),
                run,
                step,
                reason,
            });
        }
    }

    pub(crate) fn finish(mut self) -> FindingCount {
        self.count.steps = self.steps.len();
        self.count
    }
}

impl FindingTally {
    /// Adds `other`'s findings (cells of other runs or steps).
    pub(crate) fn merge(&mut self, other: FindingTally) {
        let (c, o) = (&mut self.count, other.count);
        c.cells += o.cells;
        c.non_finite += o.non_finite;
        c.not_symmetric += o.not_symmetric;
        c.not_positive_definite += o.not_positive_definite;
        c.non_finite_vector += o.non_finite_vector;
        if let Some(f) = o.first
            && c.first
                .as_ref()
                .is_none_or(|mine| (f.run, f.step) < (mine.run, mine.step))
        {
            c.first = Some(f);
        }
        self.steps.extend(other.steps);
    }
}
